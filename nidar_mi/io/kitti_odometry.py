"""A LiDAR sequence in the KITTI odometry layout (plus SemanticKITTI labels when present).

::

    OUT/velodyne/000000.bin    float32 x, y, z, intensity per point (LiDAR frame, m)
    OUT/labels/000000.label    uint32 per point: instance << 16 | semantic label
                               (SemanticKITTI; written when the clouds carry ``label``)
    OUT/poses.txt              per frame one line: the 3x4 row-major pose, 12 numbers
    OUT/times.txt              per frame its time in s
    OUT/calib.txt              ``NAME: 12 numbers`` per 3x4 matrix (``Tr`` at least)

KITTI's ``poses.txt`` holds the pose of the reference frame of frame k in the reference frame
of frame 0, ``T_{ref_0 <- ref_k}``, with the left camera as reference; ``Tr`` maps LiDAR points
into that camera. :func:`write_sequence` takes LiDAR poses in any world frame and writes
``Tr · T_{lidar_0 <- lidar_k} · Tr⁻¹``: with the default ``Tr`` = identity these are the LiDAR
poses themselves (the layout of ``nidar_mi.render --trajectory``), with a camera's ``Tr`` they
are the camera poses as KITTI gives them. (Geiger et al., "Are we ready for autonomous driving?
The KITTI vision benchmark suite", CVPR 2012, odometry development kit; Behley et al.,
SemanticKITTI, ICCV 2019, for the ``.label`` files.)

Every file is written atomically; a caller publishing the whole folder at once writes it into
:func:`nidar_mi.io.atomic.staged_directory`.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import NidarError
from .atomic import atomic_path, atomic_write_text
from .points import write_kitti_bin

__all__ = ["write_sequence", "read_poses", "semantic_kitti_labels"]


def _fmt_row(values) -> str:
    return " ".join(f"{float(v):.12e}" for v in np.ravel(values))


def semantic_kitti_labels(label: np.ndarray, instance: np.ndarray) -> np.ndarray:
    """(N,) uint32 ``instance << 16 | label`` (SemanticKITTI's ``.label`` words).

    Raises:
        NidarError: an instance id above 65535 (the word keeps 16 bits for it).
    """
    label = np.asarray(label).astype(np.uint32)
    instance = np.asarray(instance).astype(np.uint32)
    if instance.size and int(instance.max()) > 0xFFFF:
        raise NidarError(f"instance id {int(instance.max())} does not fit SemanticKITTI's 16 bits")
    return (instance << np.uint32(16)) | (label & np.uint32(0xFFFF))


def write_sequence(
    out: str | os.PathLike,
    clouds: Sequence[Mapping[str, np.ndarray]],
    poses: np.ndarray,
    times: Sequence[float],
    calib: Mapping[str, np.ndarray] | None = None,
) -> list[str]:
    """Write a sequence in the KITTI odometry layout (module docstring).

    Args:
        out: the sequence folder (created).
        clouds: per frame a points dict with ``xyz`` (N, 3) in the LiDAR frame and
            ``intensity`` (N,); ``label`` (and ``instance``) add the ``labels/`` files.
        poses: (F, 4, 4) LiDAR-to-world poses ``T_world_lidar_k``, one per frame.
        times: (F,) frame times in s.
        calib: 3x4 (or 4x4) matrices by name for ``calib.txt`` (e.g. ``P0`` .. ``P3``); ``Tr``
            (LiDAR to reference camera) defaults to the identity.

    Returns:
        The paths written.

    Raises:
        NidarError: counts or shapes that do not agree, non-finite values, a pose that is not
            rigid, or a write failure.
    """
    poses = np.asarray(poses, dtype=np.float64)
    times = np.asarray(times, dtype=np.float64)
    n = len(clouds)
    if n == 0:
        raise NidarError("a KITTI sequence needs at least one frame")
    if poses.shape != (n, 4, 4) or times.shape != (n,):
        raise NidarError(f"need {n} poses (4x4) and {n} times, got {poses.shape} and {times.shape}")
    if not (np.all(np.isfinite(poses)) and np.all(np.isfinite(times))):
        raise NidarError("poses and times must be finite")
    R = poses[:, :3, :3]
    if np.abs(R @ R.transpose(0, 2, 1) - np.eye(3)).max() > 1e-5:
        raise NidarError("a pose's rotation is not orthonormal")
    calib = {k: np.asarray(v, dtype=np.float64) for k, v in (calib or {}).items()}
    calib.setdefault("Tr", np.eye(4))
    for name, m in calib.items():
        if m.shape not in ((3, 4), (4, 4)) or not np.all(np.isfinite(m)):
            raise NidarError(f"calib '{name}' must be a finite 3x4 or 4x4 matrix, got {m.shape}")
    Tr = np.vstack([calib["Tr"][:3], [0.0, 0.0, 0.0, 1.0]])

    written = []
    for k, cloud in enumerate(clouds):
        if "xyz" not in cloud or "intensity" not in cloud:
            raise NidarError(f"frame {k}: a cloud needs 'xyz' and 'intensity'")
        path = os.path.join(out, "velodyne", f"{k:06d}.bin")
        write_kitti_bin(path, cloud["xyz"], cloud["intensity"])
        written.append(path)
        if "label" in cloud:
            inst = cloud.get("instance", np.zeros(len(cloud["label"]), np.uint32))
            words = semantic_kitti_labels(cloud["label"], inst)
            if len(words) != len(cloud["xyz"]):
                raise NidarError(f"frame {k}: 'label' and 'xyz' have different lengths")
            path = os.path.join(out, "labels", f"{k:06d}.label")
            with atomic_path(path) as tmp:
                words.astype("<u4").tofile(tmp)
            written.append(path)

    relative = np.linalg.inv(poses[0]) @ poses  # T_{lidar_0 <- lidar_k}
    ref = Tr @ relative @ np.linalg.inv(Tr)
    files = {
        "poses.txt": "".join(_fmt_row(T[:3]) + "\n" for T in ref),
        "times.txt": "".join(f"{t:.9e}\n" for t in times),
        "calib.txt": "".join(f"{name}: {_fmt_row(m[:3])}\n" for name, m in calib.items()),
    }
    for name, text in files.items():
        path = os.path.join(out, name)
        atomic_write_text(path, text)
        written.append(path)
    return written


def read_poses(path: str | os.PathLike) -> np.ndarray:
    """(F, 4, 4) float64 poses of a KITTI ``poses.txt``.

    Raises:
        NidarError: missing file, or a line that is not 12 numbers.
    """
    try:
        rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as e:
        raise NidarError(f"{path}: not a KITTI poses file ({e})") from None
    if rows.shape[1] != 12:
        raise NidarError(f"{path}: expected 12 numbers per line, got {rows.shape[1]}")
    out = np.tile(np.eye(4), (len(rows), 1, 1))
    out[:, :3, :] = rows.reshape(-1, 3, 4)
    return out
