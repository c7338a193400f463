"""Torch datasets over the training frames: crops, flips and tensors for the networks.

The frame format (files, keys, dtypes) belongs to :mod:`nidar_mi.training_frames`; these classes only
read it. Intensity is divided by ``intensity_scale`` and clipped to [0, 1].
Crops and flips are drawn from a generator seeded by ``(seed, epoch, index)``, so a sample
does not depend on worker processes or on where a run was resumed.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from ..errors import NidarError
from ..training_frames import load_frame
from .preprocess import colour_input, prepare_nir, prepare_rgb

__all__ = [
    "R_TARGET_KEYS",
    "area_resize",
    "reduce_sparse",
    "FrameDataset",
    "STNDataset",
    "IntrinsicTargets",
    "IRNetDataset",
    "MixedDataset",
]


def _crop_box(h: int, w: int, crop: tuple[int, int], rng: np.random.Generator | None):
    ch, cw = crop
    if ch > h or cw > w:
        raise NidarError(f"crop size {ch}x{cw} exceeds the frame size {h}x{w}")
    if rng is None:
        return (h - ch) // 2, (w - cw) // 2
    return int(rng.integers(0, h - ch + 1)), int(rng.integers(0, w - cw + 1))


def _crop_shape(crop_size) -> tuple[int, int]:
    if isinstance(crop_size, (tuple, list)):
        ch, cw = (int(v) for v in crop_size)
    else:
        ch = cw = int(crop_size)
    return ch, cw


def reduce_sparse(
    mask: np.ndarray, range_m: np.ndarray, maps: dict[str, np.ndarray], size: tuple[int, int]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Sparse per-pixel maps re-projected onto a coarser pixel grid, the nearest return winning.

    Full-resolution pixel ``(v, u)`` falls into coarse pixel
    ``(floor((v + 0.5) h / H), floor((u + 0.5) w / W))`` (the coarse pixel whose area holds its
    centre); of the returns falling into one coarse pixel the one of least range is kept (ties:
    the first in row-major order), as when the returns are projected at that resolution.

    Args:
        mask: ``(H, W)`` bool, pixels holding a return.
        range_m: ``(H, W)`` range of the returns, m.
        maps: name -> ``(H, W)`` values at the returns.
        size: ``(h, w)`` of the coarse grid.

    Returns:
        ``(mask (h, w) bool, {name: (h, w) float32, 0 where no return})``.
    """
    big_h, big_w = mask.shape
    h, w = size
    v, u = np.nonzero(mask)
    row = np.minimum(((v + 0.5) * h / big_h).astype(np.int64), h - 1)
    col = np.minimum(((u + 0.5) * w / big_w).astype(np.int64), w - 1)
    cell = row * w + col
    order = np.lexsort((range_m[v, u], cell))  # by cell, then by range (stable)
    cell = cell[order]
    first = np.ones(len(cell), bool)
    first[1:] = cell[1:] != cell[:-1]
    keep, cells = order[first], cell[first]
    out_mask = np.zeros(h * w, bool)
    out_mask[cells] = True
    out = {}
    for name, values in maps.items():
        m = np.zeros(h * w, np.float32)
        m[cells] = values[v[keep], u[keep]]
        out[name] = m.reshape(h, w)
    return out_mask.reshape(h, w), out


def area_resize(x: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """``(C, H, W)`` float32 resized to ``(C, h, w)`` by area averaging, exactly as inference
    resizes its input (:func:`torch.nn.functional.interpolate`, ``mode="area"``)."""
    if tuple(x.shape[-2:]) == tuple(size):
        return x
    t = torch.from_numpy(np.ascontiguousarray(x, dtype=np.float32))[None]
    return torch.nn.functional.interpolate(t, size=size, mode="area")[0].numpy()


class FrameDataset(Dataset):
    """Base of the datasets: frame files, crops, per-(seed, epoch, index) randomness.

    Args:
        frames: frame files.
        crop_size: side of the square crops, or ``(height, width)``.
        seed: seed of crops and flips.
        train: random crops and horizontal flips if True, centre crops otherwise.
    """

    def __init__(self, frames, crop_size, seed: int = 0, train: bool = True) -> None:
        self.frames = [Path(f) for f in frames]
        self.crop_shape = _crop_shape(crop_size)
        self.crop_size = self.crop_shape[0]
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
        y, x = _crop_box(h, w, self.crop_shape, rng)
        flip = bool(rng.integers(0, 2)) if rng is not None else False
        ch, cw = self.crop_shape
        return (slice(y, y + ch), slice(x, x + cw)), flip

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


#: Frame keys each ``r_target`` reads beside ``R_true`` (:class:`~nidar_mi.nidar.config.LossConfig`).
R_TARGET_KEYS = {"monostatic": (), "surface": ("R_surface",), "colour": ("A_true",)}


def reflectance_target(arrays: dict, r_target: str, wavelength_nm: float) -> np.ndarray:
    """(H, W) float32 target of the supervised reflectance term, 0 where ``R_true`` has no surface.

    Args:
        arrays: a rendered frame's ``R_true`` and the key ``r_target`` reads (``R_surface``
            or ``A_true``).
        r_target: ``"monostatic"``, ``"surface"`` or ``"colour"``
            (:attr:`~nidar_mi.nidar.config.LossConfig.r_target`).
        wavelength_nm: the LiDAR wavelength of ``"colour"``'s map.
    """
    r_true = arrays["R_true"]
    if r_target == "monostatic":
        return r_true
    if r_target == "surface":
        target = arrays["R_surface"]
    else:
        from ..materials.visible_albedo import colour_reflectance_map

        target = colour_reflectance_map(wavelength_nm)(arrays["A_true"])
    from ..training_frames import R_TRUE_MIN

    return np.where(r_true >= R_TRUE_MIN, np.maximum(target, R_TRUE_MIN), 0.0).astype(np.float32)


@dataclass(frozen=True)
class IntrinsicTargets:
    """The rendered frames' true reflectance and shading as targets of IRNet's R and S.

    Attributes:
        r_target: what R is compared with (:attr:`~nidar_mi.nidar.config.LossConfig.r_target`,
            :func:`reflectance_target`).
        wavelength_nm: the LiDAR wavelength of the ``"colour"`` target's map.
        missing_zero: frames without true maps (real frames) give zero maps, which the
            supervised terms leave out (their pixel mask is ``R_true >= 1e-3``); False: such a
            frame is an error.
    """

    r_target: str = "monostatic"
    wavelength_nm: float = 905.0
    missing_zero: bool = False


class IRNetDataset(FrameDataset):
    """Network input and sparse intensity supervision for IRNet.

    Args:
        frames: frame files.
        intensity_scale: divisor of the stored intensity (``meta.json``); the quotient is
            clipped to [0, 1].
        crop_size: side of the square crops, or ``(height, width)``, at the network resolution.
        seed: seed of crops and flips.
        train: random crops and flips if True, centre crops otherwise.
        input_dir: directory with ``<frame>.npy`` pseudo-NIR images ``(1, H, W)`` float32
            (the frozen STN's output, full resolution); None gives the prepared RGB image as
            input.
        intrinsic: also give the rendered frames' true reflectance and shading (``R_true``,
            ``S_true``), as :class:`IntrinsicTargets` says; None: not.
        supervise_intensity: False gives an empty intensity mask (frames that only supervise
            the decomposition: renders of another sensor than the real frames').
        colour: with ``input_dir``, an IRNet input mode whose colour channels are stacked
            before the pseudo-NIR (``rgb+pseudo_nir``, ``chroma+pseudo_nir``:
            :func:`~nidar_mi.nidar.preprocess.colour_input`); None: the pseudo-NIR alone.
        scale: network resolution relative to the frames, in (0, 1]: frames become
            ``round(scale · H) x round(scale · W)`` (:func:`nidar_mi.nidar.infer.reduced_size`):
            the input and the dense true maps by area averaging (:func:`area_resize`), the
            sparse intensity and mask by :func:`reduce_sparse`. Reduced frames are kept in
            memory (they are read once).

    Items: ``{"x": (C, h, w), "intensity": (1, h, w), "mask": (1, h, w)}`` float32 (``C``: 1, 3
    or 4; the mask as 0/1), plus ``"R_true"`` and ``"S_true"`` ``(1, h, w)`` float32 (the same crop
    and flip) with ``intrinsic``; ``(h, w)`` is the crop shape.
    """

    def __init__(
        self,
        frames,
        intensity_scale: float,
        crop_size,
        seed: int = 0,
        train: bool = True,
        input_dir: str | Path | None = None,
        intrinsic: IntrinsicTargets | None = None,
        scale: float = 1.0,
        supervise_intensity: bool = True,
        colour: str | None = None,
    ) -> None:
        super().__init__(frames, crop_size, seed, train)
        targets = intrinsic or IntrinsicTargets()
        self.r_target = targets.r_target
        self.wavelength_nm = float(targets.wavelength_nm)
        self.colour = colour
        self.missing_targets_zero = bool(targets.missing_zero)
        self.supervise_intensity = bool(supervise_intensity)
        self.intensity_scale = float(intensity_scale)
        self.input_dir = Path(input_dir) if input_dir is not None else None
        self.intrinsic_targets = intrinsic is not None
        if not 0.0 < float(scale) <= 1.0:
            raise NidarError(f"scale must lie in (0, 1], got {scale}")
        self.scale = float(scale)
        self._reduced: dict[int, dict[str, np.ndarray]] = {}

    def frame_arrays(self, index: int) -> dict[str, np.ndarray]:
        """The whole frame ``index`` at the network resolution: ``x`` ``(C, h, w)``,
        ``intensity`` and ``mask`` ``(1, h, w)`` float32 (and ``R_true``, ``S_true``)."""
        if index in self._reduced:
            return self._reduced[index]
        path = self.frames[index]
        keys = ("rgb", "intensity", "mask")
        if self.input_dir is not None and self.colour is None:
            keys = keys[1:]
        if self.scale < 1.0:
            keys = (*keys, "range")
        zero_targets = False
        if self.intrinsic_targets:
            from ..training_frames import frame_has

            zero_targets = self.missing_targets_zero and not frame_has(path, ("R_true",))
            if not zero_targets:
                keys = (*keys, "R_true", "S_true", *R_TARGET_KEYS[self.r_target])
        arrays = load_frame(path, keys)
        if not zero_targets and self.intrinsic_targets:
            arrays["R_true"] = reflectance_target(arrays, self.r_target, self.wavelength_nm)
        if zero_targets:
            zeros = np.zeros(arrays["mask"].shape, np.float32)
            arrays["R_true"], arrays["S_true"] = zeros, zeros
        if not self.supervise_intensity:
            arrays["mask"] = np.zeros_like(arrays["mask"])
        if self.input_dir is None:
            x = prepare_rgb(arrays["rgb"])
        else:
            x = np.load(self.input_dir / f"{path.stem}.npy", allow_pickle=False)
            if x.shape != (1, *arrays["mask"].shape):
                raise NidarError(f"pseudo-NIR cache of {path.name} has shape {x.shape}")
            if self.colour is not None:
                x = np.concatenate((colour_input(arrays["rgb"], self.colour), x), 0)
        mask = arrays["mask"]
        # LiDAR4D-style scaling: divide by the stated scale and clip to [0, 1] (retroreflectors
        # would otherwise dominate every squared loss)
        target = np.clip(arrays["intensity"] / np.float32(self.intensity_scale), 0, 1) * mask
        dense = {"x": x.astype(np.float32)}
        if self.intrinsic_targets:
            dense |= {k: arrays[k][None].astype(np.float32) for k in ("R_true", "S_true")}
        if self.scale < 1.0:
            from .infer import reduced_size

            size = reduced_size(*mask.shape, self.scale)
            dense = {k: area_resize(v, size) for k, v in dense.items()}
            mask, sparse = reduce_sparse(mask, arrays["range"], {"intensity": target}, size)
            target = sparse["intensity"]
        out = dense | {
            "intensity": target[None].astype(np.float32),
            "mask": mask[None].astype(np.float32),
        }
        if self.scale < 1.0:
            self._reduced[index] = out
        return out

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        arrays = self.frame_arrays(index)
        window, flip = self._window(index, *arrays["mask"].shape[1:])
        return {k: self._apply(v, window, flip) for k, v in arrays.items()}


class MixedDataset(Dataset):
    """Several datasets as one (items in order: the first's, then the second's, ...), each
    keeping its own scale, input and crops; :meth:`set_epoch` reaches every part.

    The parts must give items with the same keys and crop shape (they are batched together).
    """

    def __init__(self, *parts: FrameDataset) -> None:
        self.parts = [p for p in parts if len(p)]
        if not self.parts:
            raise NidarError("no frames to train on")
        self.frames = [f for p in self.parts for f in p.frames]

    def set_epoch(self, epoch: int) -> None:
        """Select the crops and flips of epoch ``epoch`` in every part."""
        for p in self.parts:
            p.set_epoch(epoch)

    def __len__(self) -> int:
        return sum(len(p) for p in self.parts)

    def __getitem__(self, index: int) -> dict[str, torch.Tensor]:
        for p in self.parts:
            if index < len(p):
                return p[index]
            index -= len(p)
        raise IndexError(index)
