"""Training of the NIDAR networks: STN on RGB/NIR pairs, then IRNet on sparse LiDAR intensity.

Stages (paper Sec. III-IV):

1. ``stn``: the spectral translation network learns RGB -> NIR on the rendered pairs
   (L1 + SSIM at every pyramid scale). The paper uses the pretrained cs-stereo STN, whose
   weights are not available here; this stage replaces it.
2. ``irnet``: the STN is frozen and its pseudo-NIR images are computed once per frame (whole
   frames, cached under ``OUT/cache``); IRNet is trained on them (or on RGB for the
   diagnostic variant) with the full intrinsic objective and masked intensity supervision,
   ``lambda_int`` warmed up linearly.

Outputs in ``OUT``: ``stn.safetensors``, ``irnet.safetensors``, ``config.json`` (the
resolved configuration and the data's ``meta.json`` values), ``train_log.json`` (losses per
step, training and validation loss per epoch), and ``checkpoints/`` (resumable, see
:mod:`nidar_mi.nidar.checkpoint`). Runs are deterministic given ``cfg.seed``: weights are
initialised after ``torch.manual_seed(seed)``, batches come from a permutation seeded by
``(seed, epoch)``, crops and flips from generators seeded by ``(seed, epoch, frame)``, and
CPU runs use deterministic algorithms; a resumed run continues with the same batches.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from ..dataset import list_frames, load_frame, load_meta
from ..errors import NidarError
from .checkpoint import atomic_write
from .config import TrainConfig
from .data import IRNetDataset, STNDataset
from .infer import pseudo_nir
from .loop import Stage, read_train_log, run_stage, write_stage_log
from .losses import irnet_objective, photo_stn_loss, stn_loss
from .model_io import build_irnet, build_stn, load_stn, resolve_device, save_irnet, save_stn
from .stn import image_pyramid

__all__ = ["train", "train_stn", "train_stn_photos", "train_irnet"]


# --------------------------------------------------------------------------- public API


def train(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    stn_weights: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
    photos: str | Path | None = None,
) -> dict[str, Path]:
    """Train both stages (the STN is skipped when ``stn_weights`` is given, and for RGB-input
    IRNet without ``stn_weights``). With ``photos`` (a folder of RGB/NIR photo pairs) the STN
    is trained on them (:func:`train_stn_photos`), else on the dataset's renders.

    Returns:
        ``{"stn": path, "irnet": path}`` (``"stn"`` absent when no STN was used).
    """
    out: dict[str, Path] = {}
    if stn_weights is None and cfg.irnet.input == "pseudo_nir":
        if photos is not None:
            stn_weights = out["stn"] = train_stn_photos(
                cfg, photos, data_dir, out_dir, resume=resume, progress=progress
            )
        else:
            stn_weights = out["stn"] = train_stn(
                cfg, data_dir, out_dir, resume=resume, progress=progress
            )
    out["irnet"] = train_irnet(
        cfg, data_dir, out_dir, stn_weights, resume=resume, progress=progress
    )
    if (Path(out_dir) / "stn.safetensors").is_file():
        out["stn"] = Path(out_dir) / "stn.safetensors"
    return out


def train_stn(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    resume: bool = False,
    progress: bool = True,
) -> Path:
    """Train the STN on ``DATA/{train,val}``; returns ``OUT/stn.safetensors``."""
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    _begin(cfg, data_dir, out_dir, "stn", resume)
    torch.manual_seed(cfg.seed)
    model = build_stn(cfg.stn)
    _check_crop(cfg.crop_size, model.stride, "STN")
    train_set = STNDataset(_frames(data_dir, "train"), cfg.crop_size, cfg.seed, train=True)
    val_set = STNDataset(list_frames(data_dir, "val"), cfg.crop_size, cfg.seed, train=False)
    alpha = cfg.loss.stn_ssim_alpha

    def loss_fn(net, batch, _factor):
        if not hasattr(net, "forward_pyramid"):  # a lowres STN: one output, gain-blind loss
            return photo_stn_loss(net(batch["rgb"]), batch["nir"], cfg.photos.ssim_weight), {}
        preds = net.forward_pyramid(batch["rgb"])
        loss = stn_loss(preds, image_pyramid(batch["nir"], len(preds)), alpha)
        return loss, {}

    stage = Stage("stn", model, cfg.stn_optim, train_set, val_set, loss_fn)
    with _torch_threads(cfg.threads):
        run_stage(stage, cfg, out_dir, resume, progress)
    path = save_stn(out_dir / "stn.safetensors", model, cfg.stn)
    _mark_done(out_dir, "stn")
    return path


def train_stn_photos(
    cfg: TrainConfig,
    photos_dir: str | Path,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    resume: bool = False,
    progress: bool = True,
) -> Path:
    """Train the STN on real RGB/NIR photo pairs; returns ``OUT/stn.safetensors``.

    The pairs of ``photos_dir`` (:mod:`nidar_mi.datasets.rgbnir`) are split by image with
    :func:`~nidar_mi.datasets.rgbnir.split_pairs` (seed 0, every category in every split): the
    network is fitted on the ``train`` and ``val`` pairs, ``val`` crops are logged, and the
    ``test`` pairs are never read (the photo evaluation scores them,
    :mod:`nidar_mi.eval.photos`). With ``cfg.photos.render_fraction > 0`` that share of the
    crops comes from the rendered RGB/NIR pairs of ``data_dir/train``. Loss:
    :func:`~nidar_mi.nidar.losses.photo_stn_loss`; crops: :mod:`nidar_mi.nidar.photo_data`.
    The network is ``cfg.stn`` (``kind`` ``"lowres"`` is the shipped one).
    """
    from tqdm.auto import tqdm

    from ..datasets.rgbnir import list_pairs, load_pair, split_pairs
    from .photo_data import PhotoCropDataset, render_pair

    data_dir, out_dir = Path(data_dir), Path(out_dir)
    pairs = {p.name: p for p in list_pairs(photos_dir)}
    split = split_pairs(list(pairs.values()))
    _begin(cfg, data_dir, out_dir, "stn", resume)
    torch.manual_seed(cfg.seed)
    model = build_stn(cfg.stn)
    _check_crop(cfg.crop_size, model.stride, "STN")
    pc = cfg.photos
    names = split["train"] + split["val"]
    fit = [load_pair(pairs[n]) for n in tqdm(names, desc="photos", disable=not progress)]
    val = [load_pair(pairs[n]) for n in split["val"]]
    renders = []
    if pc.render_fraction > 0:
        renders = [render_pair(f) for f in _frames(data_dir, "train")]
    common = dict(zoom_min=pc.zoom_min, renders=renders, render_fraction=pc.render_fraction)
    train_set = PhotoCropDataset(fit, cfg.crop_size, pc.crops_per_epoch, cfg.seed, True, **common)
    val_set = PhotoCropDataset(val, cfg.crop_size, 8 * len(val), cfg.seed, False, **common)

    def loss_fn(net, batch, _factor):
        return photo_stn_loss(net(batch["rgb"]), batch["nir"], pc.ssim_weight), {}

    stage = Stage("stn", model, cfg.stn_optim, train_set, val_set, loss_fn)
    with _torch_threads(cfg.threads):
        run_stage(stage, cfg, out_dir, resume, progress)
    path = save_stn(out_dir / "stn.safetensors", model, cfg.stn)
    _mark_done(out_dir, "stn")
    return path


def train_irnet(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    stn_weights: str | Path | None = None,
    *,
    resume: bool = False,
    progress: bool = True,
    frames: dict[str, Sequence[str | Path]] | None = None,
    cache_dir: str | Path | None = None,
) -> Path:
    """Train IRNet; returns ``OUT/irnet.safetensors``.

    Args:
        cfg: configuration (``cfg.irnet.input`` selects pseudo-NIR or RGB input;
            ``cfg.scale`` the network resolution).
        data_dir: training data (its ``meta.json`` gives the intensity scale).
        out_dir: output directory.
        stn_weights: trained STN (default ``OUT/stn.safetensors``); copied into ``OUT`` when
            it lies elsewhere. Required for pseudo-NIR input, optional for RGB input.
        resume: continue from the latest checkpoint in ``OUT/checkpoints``.
        progress: show tqdm progress bars.
        frames: ``{"train": [...], "val": [...]}`` frame files to use instead of the data's
            ``train`` and ``val`` splits (e.g. a leave-one-out fold, or every frame for a
            model to ship; an empty ``val`` list skips validation).
        cache_dir: folder of the pseudo-NIR cache (default ``OUT/cache``; runs on the same
            frames with the same STN and scale can share one).
    """
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    meta = load_meta(data_dir)
    source = Path(stn_weights) if stn_weights is not None else out_dir / "stn.safetensors"
    if source.is_file():
        cfg = _with_stn_config(cfg, source)  # config.json describes the STN actually used
    _begin(cfg, data_dir, out_dir, "irnet", resume)
    device = resolve_device(cfg.device)
    if frames is None:
        split_frames = {"train": _frames(data_dir, "train"), "val": list_frames(data_dir, "val")}
    else:
        split_frames = {k: [Path(f) for f in frames.get(k, ())] for k in ("train", "val")}
        if not split_frames["train"]:
            raise NidarError("no training frames given")
        _record_frames(out_dir, split_frames)
    input_dirs: dict[str, Path | None] = {"train": None, "val": None}
    local = out_dir / "stn.safetensors"
    if stn_weights is None and local.is_file():
        stn_weights = local
    if stn_weights is not None:
        stn_weights = Path(stn_weights)
        if not stn_weights.is_file():
            raise NidarError(f"STN weights {stn_weights} not found")
        if stn_weights.resolve() != local.resolve():
            if local.is_file() and local.read_bytes() != stn_weights.read_bytes():
                raise NidarError(f"{local} exists and differs from {stn_weights}")
            load_stn(stn_weights, "cpu")  # a file that is no STN fails here, before the copy
            atomic_write(local, stn_weights.read_bytes())
    with _torch_threads(cfg.threads):
        if cfg.irnet.input == "pseudo_nir":
            if stn_weights is None:
                raise NidarError(
                    "IRNet with pseudo-NIR input needs STN weights (train the STN first)"
                )
            stn = load_stn(local, device)
            digest = hashlib.sha256(local.read_bytes()).hexdigest()[:16]
            tag = f"pseudo_nir_{digest}" + (f"_x{cfg.scale:g}" if cfg.scale != 1.0 else "")
            cache = Path(cache_dir) if cache_dir is not None else out_dir / "cache"
            for split, fs in split_frames.items():
                input_dirs[split] = _cache_pseudo_nir(stn, fs, cache / tag, cfg.scale)
            del stn

        torch.manual_seed(cfg.seed)
        model = build_irnet(cfg.irnet)
        for side in cfg.crop_shape:
            _check_crop(side, model.stride, "IRNet")
        scale = float(meta["intensity_scale"])
        common = dict(crop_size=cfg.crop_shape, seed=cfg.seed, scale=cfg.scale)
        train_set = IRNetDataset(
            split_frames["train"], scale, train=True, input_dir=input_dirs["train"], **common
        )
        val_set = IRNetDataset(
            split_frames["val"], scale, train=False, input_dir=input_dirs["val"], **common
        )

        def loss_fn(net, batch, factor):
            x = batch["x"]
            loss, terms = irnet_objective(
                net(x), net.intrinsic_target(x), batch["intensity"], batch["mask"], cfg.loss, factor
            )
            return loss, {**terms, "int_factor": factor}

        warmup = cfg.loss.int_warmup_epochs
        stage = Stage("irnet", model, cfg.irnet_optim, train_set, val_set, loss_fn, warmup)
        run_stage(stage, cfg, out_dir, resume, progress)
    path = save_irnet(out_dir / "irnet.safetensors", model, cfg.irnet)
    _mark_done(out_dir, "irnet")
    return path


# --------------------------------------------------------------------------- run bookkeeping


def _frames(data_dir: Path, split: str) -> list[Path]:
    frames = list_frames(data_dir, split)
    if not frames:
        raise NidarError(f"no frames in {data_dir / split}")
    return frames


def _check_crop(crop: int, stride: int, name: str) -> None:
    if crop % stride:
        raise NidarError(f"crop_size {crop} is not a multiple of the {name} stride {stride}")


def _mark_done(out_dir: Path, stage: str) -> None:
    stage_log = read_train_log(out_dir).get(stage, {"steps": [], "epochs": []})
    write_stage_log(out_dir, stage, {**stage_log, "done": True})


#: Settings that may change when a run is resumed (they do not change what a step computes).
_RESUMABLE_CHANGES = ("device", "num_workers", "checkpoint_every", "keep_checkpoints", "threads")
_SCHEDULE_KEYS = ("epochs", "max_steps")


def _comparable(train_cfg: dict[str, Any]) -> dict[str, Any]:
    d = json.loads(json.dumps(train_cfg))
    for key in _RESUMABLE_CHANGES:
        d.pop(key, None)
    for optim in ("stn_optim", "irnet_optim"):
        for key in _SCHEDULE_KEYS:
            d.get(optim, {}).pop(key, None)
    return d


def _begin(cfg: TrainConfig, data_dir: Path, out_dir: Path, stage: str, resume: bool) -> None:
    """Validate the configuration and write ``OUT/config.json``.

    A directory may hold one run: its configuration may only differ in the schedule
    (epochs, max_steps) and in settings that do not change the computation, and a stage that
    has made progress continues only with ``resume``.
    """
    cfg.validate()
    meta = load_meta(data_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    record = {
        "train": cfg.to_dict(),
        "data": {
            "dir": str(data_dir),
            "intensity_scale": meta["intensity_scale"],
            "wavelength_nm": meta.get("wavelength_nm"),
        },
    }
    cfg_path = out_dir / "config.json"
    if cfg_path.is_file():
        try:
            old = json.loads(cfg_path.read_text())["train"]
        except (OSError, json.JSONDecodeError, KeyError, TypeError) as exc:
            raise NidarError(f"cannot read {cfg_path}: {exc}") from None
        if _comparable(old) != _comparable(record["train"]):
            raise NidarError(f"{out_dir} holds a run with a different configuration")
    if read_train_log(out_dir).get(stage, {}).get("steps") and not resume:
        raise NidarError(f"{out_dir} already holds a {stage} run; resume it or use a new directory")
    atomic_write(cfg_path, json.dumps(record, indent=2))


def _cache_pseudo_nir(stn: nn.Module, frames: list[Path], cache_dir: Path, scale: float) -> Path:
    """Write ``<frame>.npy`` pseudo-NIR images ``(1, H, W)`` (the STN run at ``scale``, as at
    inference) that are not cached yet."""
    for path in frames:
        target = cache_dir / f"{path.stem}.npy"
        if target.is_file():
            continue
        image = pseudo_nir(stn, load_frame(path, ("rgb",))["rgb"], scale=scale)
        buf = io.BytesIO()
        np.save(buf, image[None].astype(np.float32), allow_pickle=False)
        atomic_write(target, buf.getvalue())
    return cache_dir


@contextlib.contextmanager
def _torch_threads(threads: int | None):
    """torch's intra-op thread count set to ``threads`` (None: unchanged), then restored."""
    if threads is None:
        yield
        return
    previous = torch.get_num_threads()
    torch.set_num_threads(int(threads))
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _with_stn_config(cfg: TrainConfig, stn_path: Path) -> TrainConfig:
    """``cfg`` with the network configuration stored in the STN weights file ``stn_path``."""
    import dataclasses

    from .checkpoint import read_weights_metadata
    from .config import STNConfig, dataclass_from_dict

    meta = read_weights_metadata(stn_path)
    if meta.get("format") != "nidar_mi.stn" or "config" not in meta:
        raise NidarError(f"{stn_path} does not hold STN weights")
    try:
        stn_cfg = dataclass_from_dict(STNConfig, json.loads(meta["config"]), f"{stn_path} config")
    except json.JSONDecodeError:
        raise NidarError(f"{stn_path}: invalid network configuration") from None
    return dataclasses.replace(cfg, stn=stn_cfg)


def _record_frames(out_dir: Path, split_frames: dict[str, list[Path]]) -> None:
    """Add the frames a run was given to ``OUT/config.json`` (``data.frames``)."""
    path = out_dir / "config.json"
    record = json.loads(path.read_text())
    record["data"]["frames"] = {k: sorted(f.stem for f in v) for k, v in split_frames.items()}
    atomic_write(path, json.dumps(record, indent=2))
