"""The optimisation loop shared by the training stages, and the training log.

:func:`run_stage` trains one network: Adam, fixed batches per epoch from a permutation seeded
by ``(seed, epoch)``, a linear warm-up factor handed to the loss, a checkpoint every
``cfg.checkpoint_every`` steps and at the end of every epoch, and a validation pass per
epoch. A run resumed from a checkpoint continues with the same batches (bitwise identical
on the CPU, where deterministic algorithms are enforced).

``OUT/train_log.json`` maps a stage name to ``{"steps": [...], "epochs": [...], "done":
bool}``: per step the loss and its terms, per epoch the mean training loss, the validation
loss and its terms.
"""

from __future__ import annotations

import contextlib
import json
import logging
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn
from torch.utils.data import DataLoader
from tqdm.auto import tqdm

from ..errors import NidarError
from .checkpoint import (
    atomic_write,
    latest_checkpoint,
    load_checkpoint,
    prune_checkpoints,
    save_checkpoint,
)
from .config import OptimConfig, TrainConfig
from .data import FrameDataset
from .losses import linear_warmup
from .model_io import resolve_device

__all__ = [
    "LossFn",
    "Stage",
    "run_stage",
    "validate",
    "deterministic",
    "read_train_log",
    "write_stage_log",
]

log = logging.getLogger(__name__)

#: ``loss_fn(model, batch, warmup_factor) -> (loss, {term: float})``.
LossFn = Callable[[nn.Module, dict[str, torch.Tensor], float], tuple[torch.Tensor, dict]]


def read_train_log(out_dir: Path) -> dict[str, Any]:
    """Contents of ``OUT/train_log.json`` (empty when absent)."""
    path = out_dir / "train_log.json"
    if not path.is_file():
        return {}
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None


def write_stage_log(out_dir: Path, stage: str, stage_log: dict[str, Any]) -> None:
    """Replace the entry of ``stage`` in ``OUT/train_log.json`` (atomically)."""
    full = read_train_log(out_dir)
    full[stage] = stage_log
    atomic_write(out_dir / "train_log.json", json.dumps(full, indent=1))


@contextlib.contextmanager
def deterministic(device: torch.device):
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


@dataclass
class Stage:
    """One network's training: what is optimised, on which data, under which loss."""

    name: str
    model: nn.Module
    optim: OptimConfig
    train_set: FrameDataset
    val_set: FrameDataset
    loss_fn: LossFn
    warmup_epochs: float = 0.0


def run_stage(
    stage: Stage, cfg: TrainConfig, out_dir: Path, resume: bool, progress: bool
) -> dict[str, Any]:
    """Optimise ``stage.model`` in place; returns the stage log."""
    name, model, optim_cfg = stage.name, stage.model, stage.optim
    train_set, val_set, loss_fn = stage.train_set, stage.val_set, stage.loss_fn
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
    if not resume:  # checkpoints of an abandoned run must not be taken for this run's
        prune_checkpoints(ckpt_dir, name, keep=0)
    ckpt = latest_checkpoint(ckpt_dir, name) if resume else None
    if ckpt is not None:
        side = load_checkpoint(ckpt, model, optimizer, device)
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
    with deterministic(device):
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
                factor = linear_warmup(step, stage.warmup_epochs * steps_per_epoch)
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
            val = validate(model, val_set, loss_fn, batch, device)
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
            write_stage_log(out_dir, name, stage_log)
            checkpoint(epoch + 1 if complete else epoch, 0 if complete else done_in_epoch)
    return stage_log


@torch.no_grad()
def validate(model, val_set, loss_fn: LossFn, batch: int, device) -> dict[str, Any]:
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
