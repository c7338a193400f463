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

from ..errors import NidarError
from ..progress import progress_bar
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
    "learning_rate",
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


def learning_rate(optim: OptimConfig, step: int, total: int) -> float:
    """Learning rate of optimiser step ``step`` (0-based) of a ``total``-step run.

    ``"constant"``: ``optim.lr``. ``"onecycle"``: PyTorch's ``OneCycleLR`` with its defaults
    (``pct_start`` 0.1, cosine annealing, ``div_factor`` 25, ``final_div_factor`` 1e4) as a
    pure function of the step, so that a resumed run continues on the same curve.
    """
    if optim.schedule == "constant" or total <= 1:
        return float(optim.lr)
    peak, start = float(optim.lr), float(optim.lr) / 25.0
    end = start / 1e4
    rise = float(0.1 * total) - 1.0
    last = total - 1.0
    if step <= rise:
        t, lo, hi = step / max(rise, 1e-9), start, peak
    else:
        t, lo, hi = (step - rise) / max(last - rise, 1e-9), peak, end
    t = min(max(t, 0.0), 1.0)
    return hi + (lo - hi) * (1.0 + np.cos(np.pi * t)) / 2.0


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
    run = _StageRun(stage, cfg, out_dir)
    epoch0, skip = run.restore(resume)
    if stage.val_set is None or len(stage.val_set) == 0:
        log.warning("%s: no validation frames: the validation loss is not computed", stage.name)
    log.info(
        "%s: %d steps of batch %d on %s", stage.name, run.total, stage.optim.batch_size, run.device
    )
    with deterministic(run.device):
        for epoch in range(epoch0, stage.optim.epochs):
            if run.step >= run.total:
                break
            done_in_epoch = run.train_epoch(epoch, skip, progress)
            skip = 0
            run.end_epoch(epoch, done_in_epoch)
    return run.log


class _StageRun:
    """One stage's optimisation: the optimiser, the step count and log, and their checkpoints.

    Attributes:
        steps_per_epoch: full batches per epoch (a last partial batch is dropped).
        total: steps of the whole run (``epochs × steps_per_epoch``, capped by ``max_steps``).
        step: steps taken so far.
        log: the stage log (``steps``, ``epochs``, ``done``).
    """

    def __init__(self, stage: Stage, cfg: TrainConfig, out_dir: Path) -> None:
        self.stage, self.cfg, self.out_dir = stage, cfg, out_dir
        self.device = resolve_device(cfg.device)
        stage.model.to(self.device)
        self.optimizer = torch.optim.Adam(
            stage.model.parameters(), lr=stage.optim.lr, weight_decay=stage.optim.weight_decay
        )
        batch = stage.optim.batch_size
        self.steps_per_epoch = len(stage.train_set) // batch
        if self.steps_per_epoch == 0:
            raise NidarError(
                f"{stage.name}: {len(stage.train_set)} training frames < batch size {batch}"
            )
        self.total = stage.optim.epochs * self.steps_per_epoch
        if stage.optim.max_steps is not None:
            self.total = min(self.total, stage.optim.max_steps)
        self.ckpt_dir = out_dir / "checkpoints"
        self.step = 0
        self.log: dict[str, Any] = {"steps": [], "epochs": [], "done": False}

    def restore(self, resume: bool) -> tuple[int, int]:
        """Continue from the latest checkpoint when resuming, else drop the stage's checkpoints
        (those of an abandoned run must not be taken for this run's).

        Returns:
            (epoch to start in, batches of it already done).
        """
        name = self.stage.name
        if not resume:
            prune_checkpoints(self.ckpt_dir, name, keep=0)
            return 0, 0
        ckpt = latest_checkpoint(self.ckpt_dir, name)
        if ckpt is None:
            return 0, 0
        side = load_checkpoint(ckpt, self.stage.model, self.optimizer, self.device)
        self.step, self.log = side["step"], side["log"]
        log.info("%s: resumed from %s (step %d)", name, ckpt.name, self.step)
        return side["epoch"], side["batch_in_epoch"]

    def checkpoint(self, epoch: int, in_epoch: int) -> None:
        """Save weights, optimiser and progress (resume at batch ``in_epoch`` of ``epoch``)."""
        state = {
            "epoch": epoch,
            "batch_in_epoch": in_epoch,
            "step": self.step,
            "config": self.cfg.to_dict(),
            "rng": {"seed": self.cfg.seed},
            "log": self.log,
        }
        save_checkpoint(self.ckpt_dir, self.stage.name, self.stage.model, self.optimizer, state)
        prune_checkpoints(self.ckpt_dir, self.stage.name, self.cfg.keep_checkpoints)

    def batches(self, epoch: int) -> list[list[int]]:
        """The epoch's batches: a permutation of the training frames seeded by (seed, epoch)."""
        batch = self.stage.optim.batch_size
        gen = torch.Generator().manual_seed(self.cfg.seed * 1_000_003 + epoch)
        order = torch.randperm(len(self.stage.train_set), generator=gen).tolist()
        return [order[i * batch : (i + 1) * batch] for i in range(self.steps_per_epoch)]

    def train_epoch(self, epoch: int, skip: int, progress: bool) -> int:
        """Train on the epoch's batches after the first ``skip``, until :attr:`total` steps.

        Returns:
            Batches of the epoch done (including the skipped ones).
        """
        stage, cfg = self.stage, self.cfg
        stage.train_set.set_epoch(epoch)
        loader = DataLoader(
            stage.train_set,
            batch_sampler=self.batches(epoch)[skip:],
            num_workers=cfg.num_workers,
            pin_memory=self.device.type == "cuda",
        )
        stage.model.train()
        done_in_epoch = skip
        bar = progress_bar(
            total=self.steps_per_epoch,
            initial=skip,
            show=progress,
            desc=f"{stage.name} {epoch + 1}/{stage.optim.epochs}",
        )
        for item in loader:
            if self.step >= self.total:
                break
            loss, terms = self.optimisation_step(item)
            self.step += 1
            done_in_epoch += 1
            self.log["steps"].append({"step": self.step, "epoch": epoch, "loss": loss, **terms})
            bar.update(1)
            bar.set_postfix(loss=f"{loss:.4f}")
            if self.step % cfg.checkpoint_every == 0 and done_in_epoch < self.steps_per_epoch:
                self.checkpoint(epoch, done_in_epoch)
        bar.close()
        return done_in_epoch

    def optimisation_step(self, item: dict[str, torch.Tensor]) -> tuple[float, dict]:
        """One Adam step on a batch, the loss warmed up by the step count; returns the loss
        and its terms."""
        stage = self.stage
        item = {k: v.to(self.device, non_blocking=True) for k, v in item.items()}
        factor = linear_warmup(self.step, stage.warmup_epochs * self.steps_per_epoch)
        for group in self.optimizer.param_groups:
            group["lr"] = learning_rate(stage.optim, self.step, self.total)
        loss, terms = stage.loss_fn(stage.model, item, factor)
        if not torch.isfinite(loss):
            raise NidarError(f"{stage.name}: the loss became {float(loss)} at step {self.step}")
        self.optimizer.zero_grad(set_to_none=True)
        loss.backward()
        self.optimizer.step()
        return float(loss.detach()), terms

    def end_epoch(self, epoch: int, done_in_epoch: int) -> None:
        """Validate, log the epoch, write the stage log and checkpoint where to go on."""
        stage = self.stage
        complete = done_in_epoch == self.steps_per_epoch
        losses = [s["loss"] for s in self.log["steps"] if s["epoch"] == epoch]
        val = validate(
            stage.model, stage.val_set, stage.loss_fn, stage.optim.batch_size, self.device
        )
        self.log["epochs"].append(
            {
                "epoch": epoch,
                "step": self.step,
                "complete": complete,
                "train_loss": float(np.mean(losses)) if losses else None,
                **val,
            }
        )
        log.debug(
            "%s: epoch %d, step %d, val loss %s", stage.name, epoch, self.step, val["val_loss"]
        )
        write_stage_log(self.out_dir, stage.name, self.log)
        self.checkpoint(epoch + 1 if complete else epoch, 0 if complete else done_in_epoch)


@torch.no_grad()
def validate(model, val_set, loss_fn: LossFn, batch: int, device) -> dict[str, Any]:
    """Mean validation loss (and terms) over centre crops, with full loss weights."""
    if val_set is None or len(val_set) == 0:
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
