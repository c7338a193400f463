"""Building the networks from their configuration and loading trained weights.

A weights directory written by :mod:`nidar_mi.nidar.training` holds ``stn.safetensors``,
``irnet.safetensors``, ``config.json`` and ``train_log.json``. Each weights file carries its
network configuration as JSON in its safetensors metadata, so it can be loaded on its own.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import torch

from ..errors import NidarError
from .checkpoint import load_weights, read_weights_metadata, save_weights
from .config import INPUT_CHANNELS, IRNetConfig, STNConfig, TrainConfig, dataclass_from_dict
from .irnet import IRNet
from .stn import STN
from .stn_lowres import LowResSTN

__all__ = [
    "resolve_device",
    "build_stn",
    "build_irnet",
    "save_stn",
    "save_irnet",
    "load_stn",
    "load_irnet",
    "load_pipeline",
]


def resolve_device(name: str | None = "auto") -> torch.device:
    """``"auto"``/None -> CUDA when available, else CPU; other names are used as given."""
    if name in (None, "auto"):
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if str(name).startswith("cuda") and not torch.cuda.is_available():
        raise NidarError(f"device {name!r} requested but CUDA is not available")
    return torch.device(name)


def build_stn(cfg: STNConfig) -> STN | LowResSTN:
    """Untrained STN of the given configuration (``cfg.kind`` picks the network)."""
    if cfg.kind == "lowres":
        return LowResSTN(width=cfg.width, depth=cfg.depth, down=cfg.down)
    return STN(width=cfg.width, levels=cfg.levels, num_outputs=cfg.num_outputs)


def build_irnet(cfg: IRNetConfig) -> IRNet:
    """Untrained IRNet of the given configuration."""
    return IRNet(
        variant=cfg.variant,
        in_channels=INPUT_CHANNELS[cfg.input],
        input_mode=cfg.input,
        width=cfg.width,
        unet_depth=cfg.unet_depth,
        output_stride=cfg.output_stride,
        aspp_rates=tuple(cfg.aspp_rates),
    )


def _metadata(kind: str, cfg) -> dict[str, str]:
    return {"format": f"nidar_mi.{kind}", "config": json.dumps(dataclasses.asdict(cfg))}


def save_stn(path: str | Path, stn: STN, cfg: STNConfig) -> Path:
    """Save STN weights with their configuration."""
    return save_weights(path, stn, _metadata("stn", cfg))


def save_irnet(path: str | Path, irnet: IRNet, cfg: IRNetConfig) -> Path:
    """Save IRNet weights with their configuration."""
    return save_weights(path, irnet, _metadata("irnet", cfg))


def _load(kind: str, cfg_type, builder, path, device):
    meta = read_weights_metadata(path)
    if meta.get("format") != f"nidar_mi.{kind}":
        raise NidarError(f"{path} does not hold {kind.upper()} weights")
    try:
        cfg = dataclass_from_dict(cfg_type, json.loads(meta["config"]), f"{path} config")
    except (KeyError, json.JSONDecodeError):
        raise NidarError(f"{path}: missing or invalid network configuration") from None
    model = builder(cfg)
    load_weights(path, model)
    return model.to(resolve_device(device)).eval()


def load_stn(path: str | Path, device: str | None = "auto") -> STN:
    """STN from a weights file, in eval mode on ``device``."""
    return _load("stn", STNConfig, build_stn, path, device)


def load_irnet(path: str | Path, device: str | None = "auto") -> IRNet:
    """IRNet from a weights file, in eval mode on ``device``."""
    return _load("irnet", IRNetConfig, build_irnet, path, device)


def load_pipeline(
    weights_dir: str | Path, device: str | None = "auto"
) -> tuple[STN | None, IRNet, TrainConfig]:
    """Load trained NIDAR networks.

    Args:
        weights_dir: directory with ``irnet.safetensors``, ``config.json`` and (unless IRNet
            takes RGB input and no STN was trained) ``stn.safetensors``.
        device: ``"auto"``, ``"cpu"``, ``"cuda"``...

    Returns:
        ``(stn, irnet, config)``; ``stn`` is None when the directory has no STN.
    """
    weights_dir = Path(weights_dir)
    path = weights_dir / "config.json"
    try:
        saved = json.loads(path.read_text())
    except FileNotFoundError:
        raise NidarError(f"{path} not found") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None
    if not isinstance(saved, dict) or "train" not in saved:
        raise NidarError(
            f"cannot read {path}: no 'train' key (the training configuration a weights folder's "
            "config.json holds)"
        )
    try:
        cfg = TrainConfig.from_dict(saved["train"])
    except NidarError as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None
    except (KeyError, TypeError) as exc:
        raise NidarError(f"cannot read {path}: {type(exc).__name__} {exc}") from None
    irnet_path = weights_dir / "irnet.safetensors"
    if not irnet_path.is_file():
        raise NidarError(f"{irnet_path} not found")
    irnet = load_irnet(irnet_path, device)
    stn_path = weights_dir / "stn.safetensors"
    stn = load_stn(stn_path, device) if stn_path.is_file() else None
    if stn is None and cfg.irnet.input != "rgb":
        raise NidarError(f"{stn_path} not found (IRNet takes pseudo-NIR input)")
    return stn, irnet, cfg
