"""Torch datasets over the training frames: crops, flips and tensors for the networks.

The frame format (files, keys, dtypes) belongs to :mod:`nidar_mi.dataset`; these classes only
read it. Intensity is divided by ``intensity_scale`` and clipped to [0, 1].
Crops and flips are drawn from a generator seeded by ``(seed, epoch, index)``, so a sample
does not depend on worker processes or on where a run was resumed.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from ..dataset import load_frame
from ..errors import NidarError
from .preprocess import prepare_nir, prepare_rgb

__all__ = [
    "FrameDataset",
    "STNDataset",
    "IRNetDataset",
]


def _crop_box(h: int, w: int, crop: int, rng: np.random.Generator | None):
    if crop > h or crop > w:
        raise NidarError(f"crop size {crop} exceeds the frame size {h}x{w}")
    if rng is None:
        return (h - crop) // 2, (w - crop) // 2
    return int(rng.integers(0, h - crop + 1)), int(rng.integers(0, w - crop + 1))


class FrameDataset(Dataset):
    """Base of the datasets: frame files, square crops, per-(seed, epoch, index) randomness.

    Args:
        frames: frame files.
        crop_size: side of the square crops.
        seed: seed of crops and flips.
        train: random crops and horizontal flips if True, centre crops otherwise.
    """

    def __init__(self, frames, crop_size: int, seed: int = 0, train: bool = True) -> None:
        self.frames = [Path(f) for f in frames]
        self.crop_size = int(crop_size)
        self.seed = int(seed)
        self.train = bool(train)
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Select the crops and flips of epoch ``epoch``."""
        self.epoch = int(epoch)

    def __len__(self) -> int:
        return len(self.frames)

    def _window(self, index: int, h: int, w: int):
        """Crop slices and a flip flag for sample ``index``."""
        rng = np.random.default_rng([self.seed, self.epoch, index]) if self.train else None
        y, x = _crop_box(h, w, self.crop_size, rng)
        flip = bool(rng.integers(0, 2)) if rng is not None else False
        return (slice(y, y + self.crop_size), slice(x, x + self.crop_size)), flip

    @staticmethod
    def _apply(arr: np.ndarray, window, flip: bool) -> torch.Tensor:
        """Crop a ``(C, H, W)`` array and flip it horizontally if asked."""
        out = arr[:, window[0], window[1]]
        if flip:
            out = out[..., ::-1]
        return torch.from_numpy(np.ascontiguousarray(out))


class STNDataset(FrameDataset):
    """RGB -> NIR pairs for the spectral translation network.

    Args:
        frames: frame files.
        crop_size: side of the square crops.
        seed: seed of crops and flips.
        train: random crops and flips if True, centre crops otherwise.

    Items: ``{"rgb": (3, c, c), "nir": (1, c, c)}`` float32, both exposure-normalised over
    the whole frame (:mod:`nidar_mi.nidar.preprocess`).
    """

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        arrays = load_frame(self.frames[index], ("rgb", "nir"))
        rgb, nir = prepare_rgb(arrays["rgb"]), prepare_nir(arrays["nir"])
        window, flip = self._window(index, *rgb.shape[1:])
        return {"rgb": self._apply(rgb, window, flip), "nir": self._apply(nir, window, flip)}


class IRNetDataset(FrameDataset):
    """Network input and sparse intensity supervision for IRNet.

    Args:
        frames: frame files.
        intensity_scale: divisor of the stored intensity (``meta.json``); the quotient is
            clipped to [0, 1].
        crop_size: side of the square crops.
        seed: seed of crops and flips.
        train: random crops and flips if True, centre crops otherwise.
        input_dir: directory with ``<frame>.npy`` pseudo-NIR images ``(1, H, W)`` float32
            (the frozen STN's output); None gives the prepared RGB image as input.
        intrinsic_targets: also give the rendered frames' true reflectance and shading
            (``R_true``, ``S_true``; frames without them are an error).

    Items: ``{"x": (1 or 3, c, c), "intensity": (1, c, c), "mask": (1, c, c)}`` float32
    (the mask as 0/1), plus ``"R_true"`` and ``"S_true"`` ``(1, c, c)`` float32 (the same crop
    and flip) with ``intrinsic_targets``.
    """

    def __init__(
        self,
        frames,
        intensity_scale: float,
        crop_size: int,
        seed: int = 0,
        train: bool = True,
        input_dir: str | Path | None = None,
        intrinsic_targets: bool = False,
    ) -> None:
        super().__init__(frames, crop_size, seed, train)
        self.intensity_scale = float(intensity_scale)
        self.input_dir = Path(input_dir) if input_dir is not None else None
        self.intrinsic_targets = bool(intrinsic_targets)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        path = self.frames[index]
        keys = ("intensity", "mask") if self.input_dir is not None else ("rgb", "intensity", "mask")
        if self.intrinsic_targets:
            keys = (*keys, "R_true", "S_true")
        arrays = load_frame(path, keys)
        if self.input_dir is None:
            x = prepare_rgb(arrays["rgb"])
        else:
            x = np.load(self.input_dir / f"{path.stem}.npy", allow_pickle=False)
            if x.shape != (1, *arrays["mask"].shape):
                raise NidarError(f"pseudo-NIR cache of {path.name} has shape {x.shape}")
        mask = arrays["mask"][None].astype(np.float32)
        # LiDAR4D-style scaling: divide by the stated scale and clip to [0, 1] (retroreflectors
        # would otherwise dominate every squared loss)
        target = np.clip(arrays["intensity"][None] / np.float32(self.intensity_scale), 0, 1) * mask
        window, flip = self._window(index, *mask.shape[1:])
        item = {
            "x": self._apply(x.astype(np.float32), window, flip),
            "intensity": self._apply(target.astype(np.float32), window, flip),
            "mask": self._apply(mask, window, flip),
        }
        if self.intrinsic_targets:
            for key in ("R_true", "S_true"):
                item[key] = self._apply(arrays[key][None].astype(np.float32), window, flip)
        return item
