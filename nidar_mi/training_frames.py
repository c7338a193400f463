"""The NIDAR training-frame format: the keys of a frame file, the splits and ``meta.json``.

Layout of a data folder ``DATA`` (built from renders by :mod:`nidar_mi.render_dataset`, from
KITTI by :mod:`nidar_mi.datasets.kitti_frames`)::

    DATA/meta.json                       ``source``, splits, ``intensity_scale`` and what the
                                         builder records (:func:`load_meta`)
    DATA/{train,val,test}/<frame>.npz    one frame per file (:func:`list_frames`)

A frame pairs one camera's images with the LiDAR returns it sees, splatted to their nearest
pixel (:func:`nidar_mi.geometry.camera_returns`). Training divides ``intensity`` by
``meta.json``'s ``intensity_scale`` and clips it to [0, 1]. Files are written atomically
(:func:`write_frame`) and read with ``allow_pickle=False`` (:func:`load_frame`); both check
every key against :data:`FRAME_KEYS`. This module reads and writes files only: it imports no
renderer. The keys of a frame (``H x W`` camera pixels), from :data:`FRAME_KEYS`:

"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path
from typing import NamedTuple

import numpy as np

from .errors import NidarError

__all__ = [
    "CORE_KEYS",
    "FRAME_KEYS",
    "FRAME_SOURCES",
    "R_TRUE_MIN",
    "SPLITS",
    "FrameKey",
    "check_frame",
    "frame_has",
    "list_frames",
    "load_frame",
    "load_meta",
    "write_frame",
]

#: The splits of a data folder, one sub-folder each.
SPLITS = ("train", "val", "test")
#: R_true below this counts as "no reflectance" for S_true.
R_TRUE_MIN = 1e-3


class FrameKey(NamedTuple):
    """dtype, shape and meaning of one frame key.

    A shape entry is an int, ``"H"``/``"W"`` (the camera image's height and width) or ``"N"``
    (the number of camera-visible LiDAR returns of the frame).
    """

    dtype: type
    shape: tuple
    meaning: str


#: Every key a frame file may hold.
FRAME_KEYS: dict[str, FrameKey] = {
    "rgb": FrameKey(np.uint8, ("H", "W", 3), "8-bit sRGB as a camera delivers it (rgb.png)"),
    "nir": FrameKey(np.float32, ("H", "W"), "NIR band radiance at the LiDAR wavelength, linear"),
    "intensity": FrameKey(
        np.float32,
        ("H", "W"),
        "sparse LiDAR intensity: range-compensated g·ρ·cosθ·exp(-2αd) (rendered), the stored "
        "reflectance in [0, 1] (KITTI)",
    ),
    "reflectance": FrameKey(np.float32, ("H", "W"), "sparse ρ at the LiDAR wavelength"),
    "range": FrameKey(np.float32, ("H", "W"), "sparse LiDAR range, m"),
    "mask": FrameKey(np.bool_, ("H", "W"), "M: pixels with a projected, unoccluded return"),
    "depth": FrameKey(np.float32, ("H", "W"), "camera z-depth, m, 0 where no surface"),
    "K": FrameKey(np.float64, (3, 3), "OpenCV intrinsics"),
    "T_cam_lidar": FrameKey(np.float64, (4, 4), "LiDAR frame -> camera frame"),
    "R_true": FrameKey(
        np.float32,
        ("H", "W"),
        "true ρ(λ)·T² per pixel, monostatic along the camera ray (reflectance.exr; frames whose "
        "LiDAR has the wavelength of nir.exr), 0 on the sky",
    ),
    "S_true": FrameKey(
        np.float32,
        ("H", "W"),
        "true shading π·nir/R_true (the irradiance at λ for a Lambertian surface), 0 where "
        f"R_true < {R_TRUE_MIN:g}",
    ),
    "R_surface": FrameKey(
        np.float32,
        ("H", "W"),
        "the surface's own diffuse reflectance at λ per pixel (no viewing-direction effect: "
        "gloss, opposition surge), 0 on the sky",
    ),
    "A_true": FrameKey(
        np.float32,
        ("H", "W", 3),
        "the surface's visible albedo colour per pixel: linear sRGB under D65 of its diffuse "
        "reflectance (shading-free), 0 on the sky",
    ),
    "points_xyz": FrameKey(
        np.float32, ("N", 3), "the LiDAR returns the camera sees (unoccluded), LiDAR frame, m"
    ),
    "points_intensity": FrameKey(np.float32, ("N",), "their intensity, as in ``intensity``"),
    "points_ring": FrameKey(np.int16, ("N",), "their ring (0 = the highest beam), -1 unknown"),
}

#: Keys every frame holds, whatever its source.
CORE_KEYS = ("rgb", "intensity", "range", "mask", "K", "T_cam_lidar")
#: The keys of the frames of each source (``meta.json``'s ``source``).
FRAME_SOURCES: dict[str, tuple[str, ...]] = {
    "render": tuple(FRAME_KEYS),
    "kitti": (*CORE_KEYS, "points_xyz", "points_intensity", "points_ring"),
}


def _keys_table() -> str:
    def shape(s):
        return "(" + ",".join(str(d) for d in s) + ")"

    rows = [
        (f"``{k}``", f"{np.dtype(v.dtype).name} {shape(v.shape)}", v.meaning)
        for k, v in FRAME_KEYS.items()
    ]
    widths = [max(len(r[i]) for r in rows) for i in range(3)]
    rule = "  ".join("=" * w for w in widths)
    body = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    head = "  ".join(c.ljust(w) for c, w in zip(("key", "dtype, shape", "meaning"), widths))
    sources = "".join(
        f"* ``{name}``: {', '.join(f'``{k}``' for k in keys)}\n"
        for name, keys in FRAME_SOURCES.items()
    )
    return (
        "\n".join([rule, head.rstrip(), rule, *body, rule])
        + "\n\nKeys by source (``meta.json``'s ``source``; ``H x W`` image, ``N`` returns):\n\n"
        + sources
    )


__doc__ += _keys_table()


# --------------------------------------------------------------------------- reading frames


def load_meta(data_dir: str | Path) -> dict:
    """Read ``DATA/meta.json``; checks that ``intensity_scale`` is a positive number."""
    path = Path(data_dir) / "meta.json"
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise NidarError(f"{path} not found: not a NIDAR training-data directory") from None
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise NidarError(f"cannot read {path}: {exc}") from None
    scale = meta.get("intensity_scale") if isinstance(meta, dict) else None
    if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not scale > 0:
        raise NidarError(f"{path}: 'intensity_scale' must be a positive number, got {scale!r}")
    return meta


def list_frames(data_dir: str | Path, split: str) -> list[Path]:
    """Sorted ``DATA/<split>/*.npz`` paths (empty when the split is absent)."""
    if split not in SPLITS:
        raise NidarError(f"unknown split {split!r}; choose one of {', '.join(SPLITS)}")
    return sorted((Path(data_dir) / split).glob("*.npz"))


def frame_has(path: str | Path, keys) -> bool:
    """True when the frame file holds every key of ``keys`` (e.g. rendered frames hold
    ``R_true`` and ``S_true``, real ones not).

    Raises:
        NidarError: the file cannot be read as a frame.
    """
    try:
        with np.load(path, allow_pickle=False) as npz:
            return set(keys) <= set(npz.files)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise NidarError(f"cannot read frame {path}: {exc}") from None


def load_frame(path: str | Path, keys=None) -> dict[str, np.ndarray]:
    """Load and check keys of one frame file.

    Args:
        path: the ``.npz`` frame.
        keys: the keys to load; None loads every key of :data:`FRAME_KEYS` the file holds
            (the :data:`CORE_KEYS` must be among them).

    Raises:
        NidarError: missing key, wrong dtype or shape, or an unreadable file.
    """
    path = Path(path)
    try:
        with np.load(path, allow_pickle=False) as npz:
            wanted = [k for k in FRAME_KEYS if k in npz.files] if keys is None else list(keys)
            need = list(CORE_KEYS) + wanted if keys is None else wanted
            missing = [k for k in dict.fromkeys(need) if k not in npz.files]
            if missing:
                raise NidarError(f"{path}: missing key(s) {', '.join(missing)}")
            unknown = [k for k in wanted if k not in FRAME_KEYS]
            if unknown:
                raise NidarError(f"{path}: unknown frame key(s) {', '.join(unknown)}")
            arrays = {k: npz[k] for k in wanted}
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise NidarError(f"cannot read frame {path}: {exc}") from None
    check_frame(arrays, str(path))
    return arrays


def check_frame(arrays: dict[str, np.ndarray], where: str = "frame") -> None:
    """Check dtypes and shapes of frame arrays against :data:`FRAME_KEYS`.

    Image keys must share one ``H x W``, point keys one ``N``.

    Raises:
        NidarError: an unknown key, a wrong dtype or a wrong shape (one line naming it).
    """
    dims: dict[str, int] = {}
    for key, arr in arrays.items():
        if key not in FRAME_KEYS:
            raise NidarError(f"{where}: unknown frame key {key!r}")
        dtype, shape, _ = FRAME_KEYS[key]
        if arr.dtype != dtype:
            raise NidarError(f"{where}: {key} has dtype {arr.dtype}, expected {np.dtype(dtype)}")
        ok = arr.ndim == len(shape)
        for n, d in zip(arr.shape, shape):
            if isinstance(d, str):
                ok = ok and dims.setdefault(d, n) == n
            else:
                ok = ok and n == d
        if not ok:
            expected = tuple(dims.get(d, d) if isinstance(d, str) else d for d in shape)
            raise NidarError(f"{where}: {key} has shape {arr.shape}, expected {expected}")


# --------------------------------------------------------------------------- writing frames


def write_frame(path: str | os.PathLike, frame: dict[str, np.ndarray]) -> None:
    """Check a frame against :data:`FRAME_KEYS` and write it atomically as ``.npz``.

    Raises:
        NidarError: a key, dtype or shape that the format does not allow.
    """
    from .io.atomic import atomic_path

    check_frame(frame, os.fspath(path))
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **frame)
