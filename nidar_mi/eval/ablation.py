"""Ablations in the paper's form (§IV "Ablation Studies").

* **IRNet structural ablation**: every variant of
  :data:`nidar_mi.nidar.config.IRNET_VARIANTS` (backbone alone or backbone + intensity head)
  trained with the same settings on the same data, from the same fixed STN; scored on the
  direct head Î against the projected LiDAR intensity of the held-out frames (RMSE, MAE, SSIM,
  PSNR on the masked pixels, mean over frames).
* **Pseudo-NIR vs RGB diagnostic**: the paper's model (``unet+deeplabv3``) trained on
  pseudo-NIR and on RGB input; for each, the final validation loss and MAE/RMSE/SSIM of Î raw,
  R raw and R remapped (R through the distance encoding + quantile map fitted on the training
  split, :func:`nidar_mi.datasets.profile_fitting.fit_split_calibration`).

The networks are trained by :func:`nidar_mi.nidar.training.train_irnet` into
``OUT/<input>__<variant>/``; a finished run (its ``irnet.safetensors`` exists) is reused, so an
interrupted ablation resumes where it stopped. :class:`AblationSettings` are deliberately
reduced (narrow networks, small crops, few epochs) so that 11 runs fit on a CPU; the same
settings hold for every run.
"""

from __future__ import annotations

import dataclasses
import json
import logging
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NidarError
from .metrics import mae, psnr, rmse, scale_intensity, ssim

__all__ = [
    "AblationSettings",
    "ablation_config",
    "map_scores",
    "train_variant",
    "evaluate_run",
    "run_ablation",
]

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class AblationSettings:
    """Training settings shared by every ablation run (a reduced version of the full model's)."""

    width: int = 8
    """IRNet base channel count (the shipped model uses 12)."""
    crop_size: int = 64
    """Side of the square training crops, px (shipped: 128)."""
    batch_size: int = 8
    """Frames per step."""
    epochs: int = 6
    """Passes over the training split (shipped: 40)."""
    lr: float = 1e-3
    """Adam learning rate (shipped: 5e-4; higher to make up for the few steps)."""
    int_warmup_epochs: float = 1.0
    """Warm-up of the intensity loss weight, epochs (shipped: 2)."""
    seed: int = 0
    """Seed of initialisation, crops and shuffling."""
    device: str = "cpu"
    """Training device."""

    def to_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def ablation_config(settings: AblationSettings, variant: str, input_mode: str = "pseudo_nir"):
    """The :class:`~nidar_mi.nidar.config.TrainConfig` of one ablation run."""
    from ..nidar.config import IRNetConfig, LossConfig, OptimConfig, TrainConfig

    optim = OptimConfig(lr=settings.lr, batch_size=settings.batch_size, epochs=settings.epochs)
    cfg = TrainConfig(
        irnet=IRNetConfig(variant=variant, input=input_mode, width=settings.width),
        loss=LossConfig(int_warmup_epochs=settings.int_warmup_epochs),
        irnet_optim=optim,
        stn_optim=dataclasses.replace(optim),
        crop_size=settings.crop_size,
        seed=settings.seed,
        device=settings.device,
        checkpoint_every=10_000,
        keep_checkpoints=1,
    )
    cfg.validate()
    return cfg


def train_variant(
    data_dir: str | Path,
    out_dir: str | Path,
    stn_weights: str | Path,
    variant: str,
    input_mode: str,
    settings: AblationSettings,
) -> Path:
    """Train one IRNet variant (skipped when ``out_dir/irnet.safetensors`` exists)."""
    from ..nidar.training import train_irnet

    out_dir = Path(out_dir)
    if (out_dir / "irnet.safetensors").is_file():
        log.info("ablation: reusing the finished run %s", out_dir)
        return out_dir
    log.info("ablation: training %s on %s input", variant, input_mode)
    cfg = ablation_config(settings, variant, input_mode)
    resume = (out_dir / "train_log.json").is_file()
    train_irnet(cfg, data_dir, out_dir, stn_weights, resume=resume, progress=False)
    return out_dir


def map_scores(pred: np.ndarray, gt: np.ndarray, mask: np.ndarray) -> dict[str, float]:
    """MAE, RMSE, SSIM, PSNR of (H, W) maps on the [0, 1] scale over the masked pixels."""
    p = np.clip(np.asarray(pred, dtype=np.float64), 0.0, 1.0)
    return {
        "mae": mae(p, gt, mask),
        "rmse": rmse(p, gt, mask),
        "ssim": ssim(p, gt, mask),
        "psnr": psnr(p, gt, mask),
    }


def _mean_scores(scores: list[dict[str, float]]) -> dict[str, float]:
    return {k: float(np.mean([s[k] for s in scores])) for k in scores[0]}


def evaluate_run(
    run_dir: str | Path, data_dir: str | Path, split: str = "test", *, remap: bool = False
) -> dict[str, Any]:
    """Scores of a trained run on a dataset split (mean over frames).

    Args:
        run_dir: weights folder of the run.
        data_dir: the dataset.
        split: frames to score on.
        remap: also score R raw and R remapped (fits the calibration on the training split).

    Returns:
        ``{"val_loss": last epoch's validation loss, "I_hat": scores, ["R": scores,
        "R_remap": scores]}``, scores from :func:`map_scores`.
    """
    from ..datasets.profile_fitting import fit_split_calibration
    from ..nidar.pipeline import NidarModel
    from ..training_frames import list_frames, load_meta

    run_dir = Path(run_dir)
    scale = float(load_meta(data_dir).get("intensity_scale", 1.0))
    model = NidarModel.load(run_dir, device="cpu")
    calib = fit_split_calibration(model, data_dir, "train") if remap else None
    frames = list_frames(data_dir, split)
    if not frames:
        raise NidarError(f"{data_dir}: no '{split}' frames")
    acc: dict[str, list] = {"I_hat": [], "R": [], "R_remap": []}
    for path in frames:
        with np.load(path, allow_pickle=False) as z:
            rgb, inten, mask, rng = z["rgb"], z["intensity"], z["mask"], z["range"]
        if not mask.any():
            continue
        gt = scale_intensity(inten, scale)
        maps = model.predict_image(rgb)
        acc["I_hat"].append(map_scores(maps["I_hat"], gt, mask))
        if remap:
            acc["R"].append(map_scores(maps["R"], gt, mask))
            remapped = np.zeros(mask.shape)
            remapped[mask] = calib(maps["R"][mask], rng[mask])
            acc["R_remap"].append(map_scores(remapped, gt, mask))
    log_path = run_dir / "train_log.json"
    epochs = json.loads(log_path.read_text()).get("irnet", {}).get("epochs", [])
    out: dict[str, Any] = {"val_loss": epochs[-1].get("val_loss") if epochs else None}
    for k, v in acc.items():
        if v:
            out[k] = _mean_scores(v)
    return out


def run_ablation(
    data_dir: str | Path,
    out_dir: str | Path,
    stn_weights: str | Path,
    settings: AblationSettings | None = None,
    *,
    variants: tuple[str, ...] | None = None,
    split: str = "test",
) -> dict[str, Any]:
    """Train and score the structural ablation and the pseudo-NIR-vs-RGB pair.

    Args:
        data_dir: the dataset (train/val for training, ``split`` for scoring).
        out_dir: folder of the runs.
        stn_weights: the fixed STN every pseudo-NIR run uses.
        settings: shared training settings (default :class:`AblationSettings`).
        variants: IRNet variants (default all of :data:`IRNET_VARIANTS`).
        split: frames to score on.

    Returns:
        ``{"settings", "split", "structural": [{"variant", "val_loss", "rmse", "mae", "ssim",
        "psnr"}], "input": [{"input", "val_loss", "output", "mae", "rmse", "ssim"}]}``.
    """
    from ..nidar.config import IRNET_VARIANTS

    settings = settings or AblationSettings()
    variants = tuple(variants or IRNET_VARIANTS)
    if not Path(stn_weights).is_file():
        raise NidarError(f"ablation: STN weights {stn_weights} not found")
    out_dir = Path(out_dir)
    structural, inputs = [], []
    paper = "unet+deeplabv3"
    for variant in variants:
        run = train_variant(
            data_dir,
            out_dir / f"pseudo_nir__{variant}",
            stn_weights,
            variant,
            "pseudo_nir",
            settings,
        )
        res = evaluate_run(run, data_dir, split, remap=variant == paper)
        structural.append({"variant": variant, "val_loss": res["val_loss"], **res["I_hat"]})
        if variant == paper:
            inputs.extend(_input_rows("pseudo-NIR", res))
    if paper in variants:
        run = train_variant(
            data_dir, out_dir / f"rgb__{paper}", stn_weights, paper, "rgb", settings
        )
        inputs.extend(_input_rows("RGB", evaluate_run(run, data_dir, split, remap=True)))
    return {
        "settings": settings.to_dict(),
        "split": split,
        "structural": structural,
        "input": inputs,
    }


def _input_rows(label: str, res: dict[str, Any]) -> list[dict[str, Any]]:
    names = {"I_hat": ("Î", "raw"), "R": ("R", "raw"), "R_remap": ("R", "remapped")}
    rows = []
    for key, (output, post) in names.items():
        if key in res:
            s = res[key]
            rows.append(
                {
                    "input": label,
                    "val_loss": res["val_loss"],
                    "output": output,
                    "post": post,
                    "mae": s["mae"],
                    "rmse": s["rmse"],
                    "ssim": s["ssim"],
                    "psnr": s["psnr"],
                }
            )
    return rows
