"""Weights and resumable checkpoints as safetensors plus a JSON sidecar (no pickle anywhere).

* Weights: ``<name>.safetensors`` holding a model's ``state_dict`` and string metadata
  (e.g. the network's configuration as JSON).
* Checkpoints: ``<stage>_step<NNNNNNNN>.safetensors`` holds the tensors (``model.*``,
  optimiser state ``optim.<param>.<key>``, RNG states ``rng.*``);
  ``<stage>_step<NNNNNNNN>.json`` holds everything else (configuration, epoch, step, position
  in the epoch, optimiser hyper-parameters, training log). The sidecar is written last, so a
  checkpoint counts only once its sidecar exists.

Every file is written to a temporary name and moved into place with :func:`os.replace`.
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import load_file
from safetensors.torch import save as st_save
from torch import nn

from ..errors import NidarError
from ..io.atomic import atomic_path

__all__ = [
    "atomic_write",
    "save_weights",
    "load_weights",
    "read_weights_metadata",
    "save_checkpoint",
    "load_checkpoint",
    "latest_checkpoint",
    "prune_checkpoints",
]

_CKPT_RE = re.compile(r"^(?P<stage>[a-z0-9_]+)_step(?P<step>\d{8})\.json$")


def atomic_write(path: str | Path, data: bytes | str) -> Path:
    """Write ``data`` to ``path`` atomically (see :func:`nidar_mi.io.atomic.atomic_path`)."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data.encode() if isinstance(data, str) else data)
    return Path(path)


def _cpu(tensors: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    return {k: v.detach().to("cpu").contiguous() for k, v in tensors.items()}


def save_weights(path: str | Path, model: nn.Module, metadata: dict[str, str] | None = None):
    """Save ``model.state_dict()`` to a safetensors file with string ``metadata``."""
    return atomic_write(path, st_save(_cpu(model.state_dict()), metadata=metadata or {}))


def read_weights_metadata(path: str | Path) -> dict[str, str]:
    """String metadata of a safetensors file."""
    try:
        with safe_open(str(path), framework="pt") as fh:
            return dict(fh.metadata() or {})
    except (OSError, SafetensorError) as exc:
        raise NidarError(f"cannot read weights {path}: {exc}") from None


def _load_tensors(path: Path, device: str | torch.device) -> dict[str, torch.Tensor]:
    try:
        return load_file(str(path), device=str(device))
    except (OSError, SafetensorError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None


def load_weights(
    path: str | Path, model: nn.Module, device: str | torch.device = "cpu"
) -> dict[str, str]:
    """Load a :func:`save_weights` file into ``model`` (strictly); returns its metadata."""
    tensors = _load_tensors(Path(path), device)
    try:
        model.load_state_dict(tensors, strict=True)
    except RuntimeError as exc:
        first = str(exc).splitlines()[0]
        raise NidarError(f"{path} does not fit the network: {first}") from None
    return read_weights_metadata(path)


def _stem(directory: Path, stage: str, step: int) -> Path:
    return directory / f"{stage}_step{step:08d}"


def save_checkpoint(
    directory: str | Path,
    stage: str,
    model: nn.Module,
    optimizer: torch.optim.Optimizer,
    state: dict[str, Any],
) -> Path:
    """Write a resumable checkpoint; returns the sidecar path.

    Args:
        directory: checkpoint directory.
        stage: ``"stn"`` or ``"irnet"`` (lower-case letters, digits, ``_``).
        model, optimizer: what to save.
        state: JSON-compatible training state; must contain an integer ``"step"``.
    """
    directory = Path(directory)
    step = int(state["step"])
    tensors = {f"model.{k}": v for k, v in model.state_dict().items()}
    opt = optimizer.state_dict()
    scalars: dict[str, dict[str, Any]] = {}
    for idx, pstate in opt["state"].items():
        for key, value in pstate.items():
            if isinstance(value, torch.Tensor):
                tensors[f"optim.{idx}.{key}"] = value
            else:
                scalars.setdefault(str(idx), {})[key] = value
    tensors["rng.torch_cpu"] = torch.get_rng_state()
    if torch.cuda.is_available():
        for i, s in enumerate(torch.cuda.get_rng_state_all()):
            tensors[f"rng.cuda.{i}"] = s
    stem = _stem(directory, stage, step)
    atomic_write(stem.with_suffix(".safetensors"), st_save(_cpu(tensors), {"step": str(step)}))
    sidecar = {
        "format": "nidar_mi.checkpoint",
        "version": 1,
        "stage": stage,
        "tensors": stem.with_suffix(".safetensors").name,
        "optimizer": {"param_groups": opt["param_groups"], "scalar_state": scalars},
        **state,
    }
    return atomic_write(stem.with_suffix(".json"), json.dumps(sidecar, indent=1))


def load_checkpoint(
    path: str | Path,
    model: nn.Module,
    optimizer: torch.optim.Optimizer | None = None,
    device: str | torch.device = "cpu",
    restore_rng: bool = True,
) -> dict[str, Any]:
    """Restore a checkpoint written by :func:`save_checkpoint`; returns its sidecar dict.

    Args:
        path: the sidecar (``.json``) path.
        model: network with the checkpoint's architecture.
        optimizer: optimiser over ``model.parameters()`` to restore, or None.
        device: device of the restored tensors.
        restore_rng: also restore the torch CPU (and CUDA) RNG states.
    """
    path = Path(path)
    try:
        sidecar = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise NidarError(f"cannot read checkpoint {path}: {exc}") from None
    if sidecar.get("format") != "nidar_mi.checkpoint":
        raise NidarError(f"{path} is not a nidar_mi checkpoint")
    tensor_path = path.with_name(sidecar["tensors"])
    if read_weights_metadata(tensor_path).get("step") != str(sidecar["step"]):
        raise NidarError(f"{tensor_path} does not belong to {path.name} (step mismatch)")
    tensors = _load_tensors(tensor_path, "cpu")
    model_sd = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
    try:
        model.load_state_dict(model_sd, strict=True)
    except RuntimeError as exc:
        raise NidarError(f"{path} does not fit the network: {str(exc).splitlines()[0]}") from None
    model.to(device)
    if optimizer is not None:
        state: dict[int, dict[str, Any]] = {}
        for key, value in tensors.items():
            if key.startswith("optim."):
                _, idx, name = key.split(".", 2)
                state.setdefault(int(idx), {})[name] = value
        for idx, extra in sidecar["optimizer"]["scalar_state"].items():
            state.setdefault(int(idx), {}).update(extra)
        # load_state_dict moves the state to the parameters' device and dtype.
        optimizer.load_state_dict(
            {"state": state, "param_groups": sidecar["optimizer"]["param_groups"]}
        )
    if restore_rng:
        torch.set_rng_state(tensors["rng.torch_cpu"])
        cuda = [tensors[k] for k in sorted(tensors) if k.startswith("rng.cuda.")]
        if cuda and torch.cuda.is_available() and len(cuda) == torch.cuda.device_count():
            torch.cuda.set_rng_state_all(cuda)
    return sidecar


def _checkpoints(directory: Path, stage: str) -> list[tuple[int, Path]]:
    found = []
    for p in directory.glob(f"{stage}_step*.json") if directory.is_dir() else []:
        m = _CKPT_RE.match(p.name)
        if m and m["stage"] == stage:
            found.append((int(m["step"]), p))
    return sorted(found)


def latest_checkpoint(directory: str | Path, stage: str) -> Path | None:
    """Sidecar of the checkpoint with the highest step for ``stage``, or None."""
    found = _checkpoints(Path(directory), stage)
    return found[-1][1] if found else None


def prune_checkpoints(directory: str | Path, stage: str, keep: int) -> None:
    """Delete all but the ``keep`` most recent checkpoints of ``stage``."""
    found = _checkpoints(Path(directory), stage)
    for _, sidecar in found[: max(0, len(found) - keep)]:
        sidecar.unlink(missing_ok=True)
        sidecar.with_suffix(".safetensors").unlink(missing_ok=True)
