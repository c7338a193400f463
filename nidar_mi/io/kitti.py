"""KITTI files: Velodyne ``.bin`` scans, ``poses.txt``, ``times.txt``, calibration files,
SemanticKITTI ``.label`` files, and a whole sequence in the odometry layout.

Every KITTI file of the project is read and written here, in one format each:

=========================  =====================================================================
``velodyne/ID.bin``        raw little-endian float32 rows ``x, y, z, intensity`` (LiDAR frame,
                           m; KITTI's intensity in [0, 1]); a file whose size is not a whole
                           number of 16-byte points (a truncated download) is refused
``poses.txt``              per frame one line: the row-major 3x4 ``[R | t]`` of a 4x4 pose,
                           12 numbers written ``%.12e``
``times.txt``              per frame its time in s, written ``%.9e``
``calib.txt``, ``calib/``  ``NAME: numbers`` per line (``P0..P3`` 3x4, ``R0_rect`` 3x3,
                           ``Tr_velo_to_cam`` 3x4, ``Tr`` 3x4); the raw-data names ``R_rect``
                           and ``Tr_velo_cam`` are read as ``R0_rect`` and ``Tr_velo_to_cam``
``labels/ID.label``        uint32 per point: ``instance << 16 | semantic label`` (SemanticKITTI)
=========================  =====================================================================

**Camera models** (:func:`load_kitti_calib`): the rectified camera ``n`` maps
``x_img ~ P_n R0_rect Tr_velo_to_cam x_velo``. ``P_n = [K | p]`` carries the stereo baseline in
``p``; since ``K`` is invertible, ``P_n = K [I | K^{-1} p]``, so the model is exactly ``K`` with
extrinsic ``[I | K^{-1} p] R0_rect Tr_velo_to_cam`` (and the depth equals the homogeneous
coordinate of ``P_n R0_rect Tr_velo_to_cam x_velo``). ``K`` is in pixels with pixel centres at
integer coordinates (:mod:`nidar_mi.geometry.camera_model`).

**Sequences** (:func:`write_sequence`), the odometry layout::

    OUT/velodyne/000000.bin    OUT/labels/000000.label (when the clouds carry ``label``)
    OUT/poses.txt              OUT/times.txt              OUT/calib.txt (``Tr`` at least)

KITTI's ``poses.txt`` holds the pose of the reference frame of frame k in the reference frame
of frame 0, ``T_{ref_0 <- ref_k}``, with the left camera as reference; ``Tr`` maps LiDAR points
into that camera. :func:`write_sequence` takes LiDAR poses in any world frame and writes
``Tr · T_{lidar_0 <- lidar_k} · Tr⁻¹``: with the default ``Tr`` = identity these are the LiDAR
poses themselves (the layout of ``nidar_mi.render --trajectory``), with a camera's ``Tr`` they
are the camera poses as KITTI gives them. (Geiger et al., "Are we ready for autonomous driving?
The KITTI vision benchmark suite", CVPR 2012, odometry development kit; Behley et al.,
SemanticKITTI, ICCV 2019, for the ``.label`` files.)

Every file is written atomically; a caller publishing a whole folder at once writes it into
:func:`nidar_mi.io.atomic.staged_directory`. Every reader raises a one-line
:class:`~nidar_mi.errors.NidarError` naming the file.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence

import numpy as np

from ..errors import NidarError
from ..geometry.camera_model import CameraModel
from .atomic import atomic_path, atomic_write_text, reading

__all__ = [
    "KITTI_IMAGE_SIZE",
    "ROTATION_TOLERANCE",
    "load_kitti_calib",
    "read_kitti_calib",
    "read_kitti_bin",
    "read_kitti_poses",
    "read_kitti_times",
    "semantic_kitti_labels",
    "write_kitti_calib",
    "write_kitti_bin",
    "write_kitti_poses",
    "write_sequence",
    "write_sequence_frame",
    "write_sequence_index",
    "write_kitti_times",
]

KITTI_IMAGE_SIZE = (1242, 375)
"""(width, height) in pixels of most KITTI object ``image_2`` frames; some are a few
pixels smaller."""

_CALIB_ALIASES = {"R_rect": "R0_rect", "Tr_velo_cam": "Tr_velo_to_cam"}


# --- Velodyne .bin -------------------------------------------------------------------------


def write_kitti_bin(path: str | os.PathLike, xyz: np.ndarray, intensity: np.ndarray) -> None:
    """Write points in the KITTI velodyne format: raw little-endian float32 rows x, y, z, i.

    Args:
        path: output ``.bin`` file.
        xyz: (N, 3) points in the LiDAR frame, m.
        intensity: (N,) intensity (KITTI's is in [0, 1]).

    Raises:
        NidarError: shapes that do not match, or a write failure.
    """
    xyz = np.asarray(xyz)
    intensity = np.asarray(intensity)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or intensity.shape != (len(xyz),):
        raise NidarError(
            f"need xyz (N,3) and intensity (N,), got {xyz.shape} and {intensity.shape}"
        )
    rows = np.empty((len(xyz), 4), dtype="<f4")
    rows[:, :3] = xyz
    rows[:, 3] = intensity
    with atomic_path(path) as tmp:
        rows.tofile(tmp)


def read_kitti_bin(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a KITTI velodyne ``.bin`` file.

    Returns:
        ``(xyz, intensity)``: (N, 3) and (N,) float32, in the stored order.

    Raises:
        NidarError: a missing file, or a size that is not a multiple of 16 bytes (a file that
            ends inside a point: a truncated download), naming the file and its size.
    """
    with reading(path) as p:
        size = p.stat().st_size
        if size % 16:
            raise ValueError(f"size {size} B is not a multiple of 16 B (4 float32 per point)")
        rows = np.fromfile(p, dtype="<f4").reshape(-1, 4).astype(np.float32)
        return np.ascontiguousarray(rows[:, :3]), rows[:, 3].copy()


# --- poses.txt, times.txt ------------------------------------------------------------------


def _matrix_row(values) -> str:
    return " ".join(f"{float(v):.12e}" for v in np.ravel(values))


def write_kitti_poses(path: str | os.PathLike, poses: np.ndarray) -> None:
    """Write (K, 4, 4) (or (K, 3, 4)) poses as a KITTI ``poses.txt``: per pose one line, its
    row-major 3x4 ``[R | t]`` (t in m), 12 numbers ``%.12e``."""
    poses = np.asarray(poses, dtype=np.float64)
    atomic_write_text(path, "".join(_matrix_row(P[:3, :]) + "\n" for P in poses))


#: How far the 3x3 part of a pose may be from a rotation (max |RᵀR - I|) to be read as one.
ROTATION_TOLERANCE = 1e-3


def read_kitti_poses(path: str | os.PathLike) -> np.ndarray:
    """(F, 4, 4) float64 poses of a KITTI ``poses.txt`` (also the KITTI odometry trajectories of
    :func:`nidar_mi.io.trajectory.read_trajectory`).

    Per line the row-major 3x4 ``[R | t]``: 12 numbers, separated by blanks or commas; ``#``
    starts a comment, blank lines are skipped. ``R`` must be a rotation to within
    :data:`ROTATION_TOLERANCE` (it is returned as written).

    Raises:
        NidarError: an unreadable file, no pose, or a line that is not 12 finite numbers of a
            pose (the message names the line).
    """
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as e:
        raise NidarError(f"{path}: not a KITTI poses file ({e})") from None
    poses = []
    for n, line in enumerate(lines, start=1):
        fields = line.split("#", 1)[0].replace(",", " ").split()
        if fields:
            poses.append(_pose_line(path, n, fields))
    if not poses:
        raise NidarError(f"{path}: no poses")
    return np.asarray(poses)


def _pose_line(path, n: int, fields: list[str]) -> np.ndarray:
    """(4, 4) pose of line ``n`` of a KITTI poses file, checked (:func:`read_kitti_poses`)."""
    if len(fields) != 12:
        raise NidarError(f"{path}:{n}: expected 12 numbers per line, got {len(fields)}")
    try:
        values = np.array([float(v) for v in fields])
    except ValueError:
        raise NidarError(f"{path}:{n}: not a number in '{' '.join(fields)}'") from None
    if not np.all(np.isfinite(values)):
        raise NidarError(f"{path}:{n}: a value is not finite")
    pose = np.eye(4)
    pose[:3, :] = values.reshape(3, 4)
    R = pose[:3, :3]
    if np.abs(R.T @ R - np.eye(3)).max() > ROTATION_TOLERANCE or np.linalg.det(R) <= 0:
        raise NidarError(f"{path}:{n}: the 3x3 part is not a rotation matrix")
    return pose


def write_kitti_times(path: str | os.PathLike, times: Sequence[float] | np.ndarray) -> None:
    """Write one time per line in s (KITTI ``times.txt``), ``%.9e``."""
    atomic_write_text(path, "".join(f"{t:.9e}\n" for t in np.asarray(times, dtype=np.float64)))


def read_kitti_times(path: str | os.PathLike) -> np.ndarray:
    """(F,) float64 times in s of a KITTI ``times.txt``.

    Raises:
        NidarError: a missing file, or a line that is not one number.
    """
    try:
        times = np.loadtxt(path, dtype=np.float64, ndmin=1)
    except (OSError, ValueError) as e:
        raise NidarError(f"{path}: not a times file ({e})") from None
    if times.ndim != 1:
        raise NidarError(f"{path}: expected one number per line, got {times.shape[1]}")
    return times


# --- calibration files ---------------------------------------------------------------------


def read_kitti_calib(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The ``NAME: numbers`` entries of a KITTI calibration file, as flat float64 arrays by
    name (``R_rect`` and ``Tr_velo_cam`` under their object-layout names).

    Raises:
        NidarError: an unreadable file, a line without ``:`` or a non-numeric value.
    """
    try:
        with open(path, encoding="ascii") as f:
            lines = f.read().splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise NidarError(f"{path}: cannot read KITTI calibration: {exc}") from None
    entries: dict[str, np.ndarray] = {}
    for n, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        key, sep, rest = line.partition(":")
        if not sep:
            raise NidarError(f"{path}:{n}: expected 'KEY: numbers'")
        try:
            values = np.array([float(x) for x in rest.split()])
        except ValueError:
            raise NidarError(f"{path}:{n}: non-numeric value in {key.strip()!r}") from None
        key = key.strip()
        entries[_CALIB_ALIASES.get(key, key)] = values
    return entries


def write_kitti_calib(path: str | os.PathLike, matrices: Mapping[str, np.ndarray]) -> None:
    """Write ``NAME: 12 numbers`` per matrix (the top 3x4 of each, ``%.12e``), in order."""
    text = "".join(
        f"{name}: {_matrix_row(np.asarray(m, dtype=np.float64)[:3])}\n"
        for name, m in matrices.items()
    )
    atomic_write_text(path, text)


def load_kitti_calib(
    path: str | os.PathLike[str],
    camera: str = "P2",
    *,
    width: int = KITTI_IMAGE_SIZE[0],
    height: int = KITTI_IMAGE_SIZE[1],
) -> CameraModel:
    """Rectified KITTI camera model from a ``calib/*.txt`` file.

    Args:
        path: the calib file.
        camera: ``"P0"``..``"P3"`` (``"P2"`` is the left colour camera, ``image_2``).
        width: image width in pixels (KITTI frames vary slightly; read it from the image).
        height: image height in pixels.

    Returns:
        An ``"opencv"`` :class:`~nidar_mi.geometry.camera_model.CameraModel` named
        ``camera`` whose projection equals ``P_camera R0_rect Tr_velo_to_cam`` exactly (see
        the module docstring); its ``T_cam_lidar`` maps Velodyne points (m) to the camera.

    Raises:
        NidarError: missing keys, wrong sizes or a ``P`` matrix that is not ``[K | p]``.
    """
    if camera not in ("P0", "P1", "P2", "P3"):
        raise NidarError(f"load_kitti_calib: camera must be P0..P3, not {camera!r}")
    entries = read_kitti_calib(path)
    sizes = {camera: 12, "R0_rect": 9, "Tr_velo_to_cam": 12}
    for key, size in sizes.items():
        if key not in entries:
            raise NidarError(f"{path}: missing {key!r}")
        if entries[key].size != size:
            raise NidarError(f"{path}: {key} has {entries[key].size} numbers, expected {size}")
    P = entries[camera].reshape(3, 4)
    K = P[:, :3]
    if not (np.array_equal(K[2], [0.0, 0.0, 1.0]) and K[1, 0] == 0.0):
        raise NidarError(f"{path}: {camera} is not of the form [K | p] with K upper triangular")
    R0 = np.eye(4)
    R0[:3, :3] = entries["R0_rect"].reshape(3, 3)
    Tr = np.vstack([entries["Tr_velo_to_cam"].reshape(3, 4), [0.0, 0.0, 0.0, 1.0]])
    baseline = np.eye(4)
    baseline[:3, 3] = np.linalg.solve(K, P[:, 3])
    T = baseline @ R0 @ Tr
    T[3] = [0.0, 0.0, 0.0, 1.0]
    try:
        return CameraModel(K=K, width=width, height=height, T_cam_lidar=T, name=camera)
    except NidarError as exc:
        raise NidarError(f"{path}: {exc}") from None


# --- SemanticKITTI labels and whole sequences ----------------------------------------------


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


def _checked_sequence(
    clouds: Sequence[Mapping[str, np.ndarray]],
    poses: np.ndarray,
    times: Sequence[float],
    calib: Mapping[str, np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """(poses, times, calib with ``Tr``) as float64, after the checks of :func:`write_sequence`."""
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
    return poses, times, calib


def write_sequence_frame(
    out: str | os.PathLike, k: int, cloud: Mapping[str, np.ndarray]
) -> list[str]:
    """Frame ``k``'s ``velodyne/`` file and, with ``label``, its ``labels/`` file (a sequence
    written frame by frame; :func:`write_sequence_index` completes it)."""
    if "xyz" not in cloud or "intensity" not in cloud:
        raise NidarError(f"frame {k}: a cloud needs 'xyz' and 'intensity'")
    path = os.path.join(out, "velodyne", f"{k:06d}.bin")
    write_kitti_bin(path, cloud["xyz"], cloud["intensity"])
    written = [path]
    if "label" in cloud:
        inst = cloud.get("instance", np.zeros(len(cloud["label"]), np.uint32))
        words = semantic_kitti_labels(cloud["label"], inst)
        if len(words) != len(cloud["xyz"]):
            raise NidarError(f"frame {k}: 'label' and 'xyz' have different lengths")
        path = os.path.join(out, "labels", f"{k:06d}.label")
        with atomic_path(path) as tmp:
            words.astype("<u4").tofile(tmp)
        written.append(path)
    return written


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
    _checked_sequence(clouds, poses, times, calib)
    written = []
    for k, cloud in enumerate(clouds):
        written += write_sequence_frame(out, k, cloud)
    return written + write_sequence_index(out, poses, times, calib)


def write_sequence_index(
    out: str | os.PathLike,
    poses: np.ndarray,
    times: Sequence[float],
    calib: Mapping[str, np.ndarray] | None = None,
) -> list[str]:
    """``poses.txt``, ``times.txt`` and ``calib.txt`` of a sequence whose frames
    :func:`write_sequence_frame` wrote (arguments as :func:`write_sequence`'s).

    Returns:
        The paths written.
    """
    poses, times, calib = _checked_sequence(range(len(poses)), poses, times, calib)
    Tr = np.vstack([calib["Tr"][:3], [0.0, 0.0, 0.0, 1.0]])
    relative = np.linalg.inv(poses[0]) @ poses  # T_{lidar_0 <- lidar_k}
    paths = {name: os.path.join(out, name) for name in ("poses.txt", "times.txt", "calib.txt")}
    write_kitti_poses(paths["poses.txt"], Tr @ relative @ np.linalg.inv(Tr))
    write_kitti_times(paths["times.txt"], times)
    write_kitti_calib(paths["calib.txt"], calib)
    return list(paths.values())
