"""Trajectory files: timed poses of a moving rig, read from three formats and written as TUM
(KITTI ``poses.txt`` and ``times.txt`` are written by :mod:`nidar_mi.io.kitti`).

Formats read by :func:`read_trajectory` (``#`` starts a comment in all three):

=================  ============================================================================
KITTI odometry     12 numbers per line: the row-major 3×4 ``[R | t]`` of one pose; no time (pose
                   ``k`` is at ``k / rate`` s, the rate given by the caller)
TUM                8 numbers per line: ``t x y z qx qy qz qw`` (time in s, quaternion scalar last;
                   the TUM RGB-D benchmark format)
CSV (``.csv``)     a header naming the columns ``t, x, y, z, qx, qy, qz, qw`` (any order, other
                   columns ignored; ``time``/``timestamp`` are accepted for ``t``), then one pose
                   per row
=================  ============================================================================

Poses are world-from-rig transforms in metres. KITTI odometry lines are read by
:func:`nidar_mi.io.kitti.read_kitti_poses` (to within 1e-3 rotations already) and
re-orthonormalised; quaternions are normalised. Times must increase.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError
from .atomic import atomic_write_text, reading
from .kitti import read_kitti_poses

__all__ = ["Trajectory", "read_trajectory", "write_tum"]


@dataclass(frozen=True)
class Trajectory:
    """Timed poses.

    Attributes:
        times: (K,) float64 strictly increasing times, s.
        poses: (K, 4, 4) float64 world-from-rig poses.
        format: ``kitti``, ``tum`` or ``csv``.
        path: the file read.
    """

    times: np.ndarray
    poses: np.ndarray
    format: str
    path: str

    @property
    def span(self) -> tuple[float, float]:
        return float(self.times[0]), float(self.times[-1])

    def at(self, t: np.ndarray) -> np.ndarray:
        """(M, 4, 4) SE(3)-interpolated poses at times ``t`` (inside :attr:`span`)."""
        from ..geometry.se3 import interpolate_poses

        try:
            return interpolate_poses(self.times, self.poses, np.atleast_1d(t))
        except ValueError as e:
            raise NidarError(f"{self.path}: {e}") from None


def _rows(path: str) -> list[tuple[int, list[str]]]:
    out = []
    with open(path, encoding="utf-8") as f:
        for lineno, line in enumerate(f, 1):
            text = line.split("#", 1)[0].strip()
            if text:
                out.append((lineno, text.replace(",", " ").split()))
    return out


def _numbers(path: str, lineno: int, fields: list[str]) -> list[float]:
    try:
        values = [float(v) for v in fields]
    except ValueError:
        raise NidarError(f"{path}:{lineno}: not a number in '{' '.join(fields)}'") from None
    if not all(np.isfinite(values)):
        raise NidarError(f"{path}:{lineno}: a value is not finite")
    return values


def _orthonormal(R: np.ndarray) -> np.ndarray:
    """(K, 3, 3) nearest rotations to near-rotation matrices (SVD)."""
    u, _, vt = np.linalg.svd(R)
    return u @ vt


def _quaternion_poses(path: str, lines, cols) -> tuple[np.ndarray, np.ndarray]:
    from scipy.spatial.transform import Rotation

    times, poses = [], []
    for lineno, values in lines:
        t, x, y, z, qx, qy, qz, qw = (values[c] for c in cols)
        q = np.array([qx, qy, qz, qw])
        if np.linalg.norm(q) < 1e-9:
            raise NidarError(f"{path}:{lineno}: the quaternion is zero")
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat(q / np.linalg.norm(q)).as_matrix()
        T[:3, 3] = (x, y, z)
        times.append(t)
        poses.append(T)
    return np.asarray(times), np.asarray(poses)


def read_trajectory(path: str | os.PathLike, *, rate: float | None = None) -> Trajectory:
    """Read a KITTI odometry, TUM or CSV trajectory (module docstring).

    Args:
        path: the file.
        rate: Hz, the sample rate of a KITTI odometry file (its poses carry no time); pose ``k``
            is at ``k / rate``. Ignored for the timed formats.

    Raises:
        NidarError: a missing or malformed file (one line, with the line number).
    """
    path = os.fspath(path)
    with reading(path):
        rows = _rows(path)
    if len(rows) < 1:
        raise NidarError(f"{path}: no poses")
    if path.lower().endswith(".csv"):
        header = [h.strip().lower() for h in rows[0][1]]
        alias = {"time": "t", "timestamp": "t"}
        header = [alias.get(h, h) for h in header]
        need = ["t", "x", "y", "z", "qx", "qy", "qz", "qw"]
        missing = [c for c in need if c not in header]
        if missing:
            raise NidarError(f"{path}: the CSV header has no column {', '.join(missing)}")
        lines = [(n, _numbers(path, n, f)) for n, f in rows[1:]]
        for n, v in lines:
            if len(v) != len(header):
                raise NidarError(f"{path}:{n}: {len(v)} values, the header names {len(header)}")
        times, poses = _quaternion_poses(path, lines, [header.index(c) for c in need])
        fmt = "csv"
    else:
        lines = [(n, _numbers(path, n, f)) for n, f in rows]
        width = len(lines[0][1])
        for n, v in lines:
            if len(v) != width:
                raise NidarError(f"{path}:{n}: {len(v)} values, the first pose has {width}")
        if width == 12:
            if rate is None or not rate > 0:
                raise NidarError(f"{path}: KITTI odometry poses carry no time; give the rate (Hz)")
            poses = read_kitti_poses(path)
            poses[:, :3, :3] = _orthonormal(poses[:, :3, :3])
            times = np.arange(len(poses)) / float(rate)
            fmt = "kitti"
        elif width == 8:
            times, poses = _quaternion_poses(path, lines, list(range(8)))
            fmt = "tum"
        else:
            raise NidarError(
                f"{path}: {width} values per line; expected 12 (KITTI odometry) or 8 (TUM)"
            )
    if len(times) > 1 and np.any(np.diff(times) <= 0):
        bad = int(np.flatnonzero(np.diff(times) <= 0)[0]) + 1
        raise NidarError(f"{path}: times must increase (pose {bad} is not after pose {bad - 1})")
    return Trajectory(np.asarray(times, dtype=np.float64), poses, fmt, path)


def write_tum(
    path: str | os.PathLike, times: np.ndarray, poses: np.ndarray, comment: str = ""
) -> None:
    """Write timed (K, 4, 4) poses as TUM ``t x y z qx qy qz qw`` lines (quaternion scalar last,
    ``qw >= 0``), after ``# comment`` when given."""
    from scipy.spatial.transform import Rotation

    poses = np.asarray(poses, dtype=np.float64)
    q = Rotation.from_matrix(poses[:, :3, :3]).as_quat()
    q = np.where(q[:, 3:4] < 0, -q, q)
    rows = np.column_stack([np.asarray(times, dtype=np.float64), poses[:, :3, 3], q])
    lines = [f"# {comment}"] if comment else []
    lines += [" ".join(f"{v:.9g}" for v in r) for r in rows]
    atomic_write_text(path, "\n".join(lines) + "\n")
