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
import logging
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from ..errors import NidarError
from .checkpoint import atomic_write, latest_checkpoint, prune_checkpoints, save_checkpoint
from .checkpoint import load_checkpoint as _load_checkpoint
from .config import OptimConfig, TrainConfig
from .data import IRNetDataset, STNDataset, list_frames, load_frame, load_meta
from .infer import pseudo_nir
from .losses import irnet_objective, linear_warmup, stn_loss
from .model_io import build_irnet, build_stn, load_stn, resolve_device, save_irnet, save_stn
from .stn import image_pyramid

__all__ = ["train", "train_stn", "train_irnet"]

log = logging.getLogger(__name__)

LossFn = Callable[[nn.Module, dict[str, torch.Tensor], float], tuple[torch.Tensor, dict]]


# --------------------------------------------------------------------------- public API


def train(
    cfg: TrainConfig,
    data_dir: str | Path,
    out_dir: str | Path,
    *,
    stn_weights: str | Path | None = None,
    resume: bool = False,
    progress: bool = True,
) -> dict[str, Path]:
    """Train both stages (the STN is skipped when ``stn_weights`` is given, and for RGB-input
    IRNet without ``stn_weights``).

    Returns:
        ``{"stn": path, "irnet": path}`` (``"stn"`` absent when no STN was used).
    """
    out: dict[str, Path] = {}
    if stn_weights is None and cfg.irnet.input == "pseudo_nir":
        stn_weights = out["stn"] = train_stn(
            cfg, data_dir, out_dir, resume=resume, progress=progress
        )
    out["irnet"] = train_irnet(
        cfg, data_dir, out_dir, stn_weights, resume=resume, progress=progress
    )
    if stn_weights is not None:
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
        preds = net.forward_pyramid(batch["rgb"])
        loss = stn_loss(preds, image_pyramid(batch["nir"], len(preds)), alpha)
        return loss, {}

    _run_stage(
        "stn",
        model,
        cfg.stn_optim,
        train_set,
        val_set,
        loss_fn,
        0.0,
        cfg,
        out_dir,
        resume,
        progress,
    )
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
) -> Path:
    """Train IRNet; returns ``OUT/irnet.safetensors``.

    Args:
        cfg: configuration (``cfg.irnet.input`` selects pseudo-NIR or RGB input).
        data_dir: training data.
        out_dir: output directory.
        stn_weights: trained STN (default ``OUT/stn.safetensors``); copied into ``OUT`` when
            it lies elsewhere. Required for pseudo-NIR input, optional for RGB input.
        resume: continue from the latest checkpoint in ``OUT/checkpoints``.
        progress: show tqdm progress bars.
    """
    data_dir, out_dir = Path(data_dir), Path(out_dir)
    meta = load_meta(data_dir)
    _begin(cfg, data_dir, out_dir, "irnet", resume)
    device = resolve_device(cfg.device)
    train_frames, val_frames = _frames(data_dir, "train"), list_frames(data_dir, "val")
    input_dirs: dict[str, Path | None] = {"train": None, "val": None}
    local = out_dir / "stn.safetensors"
    if stn_weights is None and local.is_file():
        stn_weights = local
    if stn_weights is not None:
        stn_weights = Path(stn_weights)
        if not stn_weights.is_file():
            raise NidarError(f"STN weights {stn_weights} not found")
        if stn_weights.resolve() != local.resolve():
            atomic_write(local, stn_weights.read_bytes())
    if cfg.irnet.input == "pseudo_nir":
        if stn_weights is None:
            raise NidarError("IRNet with pseudo-NIR input needs STN weights (train the STN first)")
        stn = load_stn(local, device)
        digest = hashlib.sha256(local.read_bytes()).hexdigest()[:16]
        cache = out_dir / "cache" / f"pseudo_nir_{digest}"
        for split, frames in (("train", train_frames), ("val", val_frames)):
            input_dirs[split] = _cache_pseudo_nir(stn, frames, cache / split)
        del stn

    torch.manual_seed(cfg.seed)
    model = build_irnet(cfg.irnet)
    _check_crop(cfg.crop_size, model.stride, "IRNet")
    scale = float(meta["intensity_scale"])
    train_set = IRNetDataset(
        train_frames, scale, cfg.crop_size, cfg.seed, True, input_dirs["train"]
    )
    val_set = IRNetDataset(val_frames, scale, cfg.crop_size, cfg.seed, False, input_dirs["val"])

    def loss_fn(net, batch, factor):
        x = batch["x"]
        loss, terms = irnet_objective(
            net(x), net.intrinsic_target(x), batch["intensity"], batch["mask"], cfg.loss, factor
        )
        return loss, {**terms, "int_factor": factor}

    _run_stage(
        "irnet",
        model,
        cfg.irnet_optim,
        train_set,
        val_set,
        loss_fn,
        cfg.loss.int_warmup_epochs,
        cfg,
        out_dir,
        resume,
        progress,
    )
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


def _read_log(out_dir: Path) -> dict[str, Any]:
    path = out_dir / "train_log.json"
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None


def _write_stage_log(out_dir: Path, stage: str, stage_log: dict[str, Any]) -> None:
    full = _read_log(out_dir)
    full[stage] = stage_log
    atomic_write(out_dir / "train_log.json", json.dumps(full, indent=1))


def _mark_done(out_dir: Path, stage: str) -> None:
    full = _read_log(out_dir)
    full.setdefault(stage, {"steps": [], "epochs": []})["done"] = True
    atomic_write(out_dir / "train_log.json", json.dumps(full, indent=1))


#: Settings that may change when a run is resumed (they do not change what a step computes).
_RESUMABLE_CHANGES = ("device", "num_workers", "checkpoint_every", "keep_checkpoints")
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
    if _read_log(out_dir).get(stage, {}).get("steps") and not resume:
        raise NidarError(f"{out_dir} already holds a {stage} run; resume it or use a new directory")
    atomic_write(cfg_path, json.dumps(record, indent=2))


def _cache_pseudo_nir(stn: nn.Module, frames: list[Path], cache_dir: Path) -> Path:
    """Write ``<frame>.npy`` pseudo-NIR images ``(1, H, W)`` that are not cached yet."""
    for path in frames:
        target = cache_dir / f"{path.stem}.npy"
        if target.is_file():
            continue
        image = pseudo_nir(stn, load_frame(path, ("rgb",))["rgb"])
        buf = io.BytesIO()
        np.save(buf, image[None].astype(np.float32), allow_pickle=False)
        atomic_write(target, buf.getvalue())
    return cache_dir


@contextlib.contextmanager
def _deterministic(device: torch.device):
    """Deterministic algorithms for CPU runs (CUDA runs keep the fast kernels)."""
    if device.type != "cpu":
        yield
        return
    previous = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(previous)


# --------------------------------------------------------------------------- the loop


def _run_stage(
    name: str,
    model: nn.Module,
    optim_cfg: OptimConfig,
    train_set,
    val_set,
    loss_fn: LossFn,
    warmup_epochs: float,
    cfg: TrainConfig,
    out_dir: Path,
    resume: bool,
    progress: bool,
) -> dict[str, Any]:
    device = resolve_device(cfg.device)
    model.to(device)
    optimizer = torch.optim.Adam(
        model.parameters(), lr=optim_cfg.lr, weight_decay=optim_cfg.weight_decay
    )
    batch = optim_cfg.batch_size
    steps_per_epoch = len(train_set) // batch
    if steps_per_epoch == 0:
        raise NidarError(f"{name}: {len(train_set)} training frames < batch size {batch}")
    total = optim_cfg.epochs * steps_per_epoch
    if optim_cfg.max_steps is not None:
        total = min(total, optim_cfg.max_steps)
    ckpt_dir = out_dir / "checkpoints"
    stage_log: dict[str, Any] = {"steps": [], "epochs": [], "done": False}
    epoch0, skip, step = 0, 0, 0
    ckpt = latest_checkpoint(ckpt_dir, name) if resume else None
    if ckpt is not None:
        side = _load_checkpoint(ckpt, model, optimizer, device)
        epoch0, skip, step = side["epoch"], side["batch_in_epoch"], side["step"]
        stage_log = side["log"]
        log.info("%s: resumed from %s (step %d)", name, ckpt.name, step)

    def checkpoint(epoch: int, in_epoch: int) -> None:
        state = {
            "epoch": epoch,
            "batch_in_epoch": in_epoch,
            "step": step,
            "config": cfg.to_dict(),
            "rng": {"seed": cfg.seed},
            "log": stage_log,
        }
        save_checkpoint(ckpt_dir, name, model, optimizer, state)
        prune_checkpoints(ckpt_dir, name, cfg.keep_checkpoints)

    log.info("%s: %d steps of batch %d on %s", name, total, batch, device)
    with _deterministic(device):
        for epoch in range(epoch0, optim_cfg.epochs):
            if step >= total:
                break
            train_set.set_epoch(epoch)
            gen = torch.Generator().manual_seed(cfg.seed * 1_000_003 + epoch)
            order = torch.randperm(len(train_set), generator=gen).tolist()
            batches = [order[i * batch : (i + 1) * batch] for i in range(steps_per_epoch)]
            loader = DataLoader(
                train_set,
                batch_sampler=batches[skip:],
                num_workers=cfg.num_workers,
                pin_memory=device.type == "cuda",
            )
            model.train()
            done_in_epoch = skip
            bar = tqdm(
                total=steps_per_epoch,
                initial=skip,
                disable=not progress,
                desc=f"{name} {epoch + 1}/{optim_cfg.epochs}",
            )
            for item in loader:
                if step >= total:
                    break
                item = {k: v.to(device, non_blocking=True) for k, v in item.items()}
                factor = linear_warmup(step, warmup_epochs * steps_per_epoch)
                loss, terms = loss_fn(model, item, factor)
                if not torch.isfinite(loss):
                    raise NidarError(f"{name}: the loss became {float(loss)} at step {step}")
                optimizer.zero_grad(set_to_none=True)
                loss.backward()
                optimizer.step()
                step += 1
                done_in_epoch += 1
                stage_log["steps"].append(
                    {"step": step, "epoch": epoch, "loss": float(loss.detach()), **terms}
                )
                bar.update(1)
                bar.set_postfix(loss=f"{stage_log['steps'][-1]['loss']:.4f}")
                if step % cfg.checkpoint_every == 0 and done_in_epoch < steps_per_epoch:
                    checkpoint(epoch, done_in_epoch)
            bar.close()
            skip = 0
            complete = done_in_epoch == steps_per_epoch
            losses = [s["loss"] for s in stage_log["steps"] if s["epoch"] == epoch]
            val = _validate(model, val_set, loss_fn, batch, device)
            stage_log["epochs"].append(
                {
                    "epoch": epoch,
                    "step": step,
                    "complete": complete,
                    "train_loss": float(np.mean(losses)) if losses else None,
                    **val,
                }
            )
            log.info("%s: epoch %d, step %d, val loss %s", name, epoch, step, val["val_loss"])
            _write_stage_log(out_dir, name, stage_log)
            checkpoint(epoch + 1 if complete else epoch, 0 if complete else done_in_epoch)
    return stage_log


@torch.no_grad()
def _validate(model, val_set, loss_fn: LossFn, batch: int, device) -> dict[str, Any]:
    """Mean validation loss (and terms) over centre crops, with full loss weights."""
    if val_set is None or len(val_set) == 0:
        log.warning("no validation frames: the validation loss is not computed")
        return {"val_loss": None, "val_terms": {}}
    model.eval()
    totals: dict[str, float] = {}
    count = 0
    for item in DataLoader(val_set, batch_size=batch, shuffle=False):
        item = {k: v.to(device) for k, v in item.items()}
        loss, terms = loss_fn(model, item, 1.0)
        n = next(iter(item.values())).shape[0]
        terms = {k: v for k, v in terms.items() if k != "int_factor"}
        for key, value in {"loss": float(loss), **terms}.items():
            totals[key] = totals.get(key, 0.0) + value * n
        count += n
    model.train()
    means = {k: v / count for k, v in totals.items()}
    return {"val_loss": means.pop("loss"), "val_terms": means}
