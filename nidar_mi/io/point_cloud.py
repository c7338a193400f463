"""Point-cloud files of any supported format, the reader chosen by the file extension."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..errors import NidarError
from .kitti import read_kitti_bin
from .las import read_las
from .pcd import read_pcd
from .points import read_npz, read_ply

__all__ = ["read_point_cloud"]


def _read_bin(path: str | os.PathLike) -> dict[str, np.ndarray]:
    xyz, intensity = read_kitti_bin(path)
    return {"xyz": xyz, "intensity": intensity}


_READERS = {
    ".npz": read_npz,
    ".ply": read_ply,
    ".las": read_las,
    ".laz": read_las,
    ".bin": _read_bin,
    ".pcd": read_pcd,
}


def read_point_cloud(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read a point cloud, choosing the reader from the extension.

    Supported: ``.npz`` ``.ply`` ``.las`` ``.laz`` ``.bin`` (KITTI) ``.pcd``.

    Returns:
        A points dict (:mod:`nidar_mi.io.points`) with at least ``xyz`` (N, 3) and, when the
        file has it, ``intensity``.

    Raises:
        NidarError: unknown extension, or a missing or malformed file.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in _READERS:
        raise NidarError(
            f"cannot read {path}: unknown point cloud extension {suffix or '(none)'!r} "
            f"(expected one of {' '.join(_READERS)})"
        )
    points = _READERS[suffix](path)
    xyz = points.get("xyz")
    if xyz is None or xyz.ndim != 2 or xyz.shape[1] != 3:
        raise NidarError(f"cannot read {path}: no (N,3) 'xyz' array")
    return points
