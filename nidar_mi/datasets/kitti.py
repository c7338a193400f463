"""KITTI frames in the object-detection layout: frame ids, calibration files, whole frames.

**Layout.** A KITTI folder holds, per frame id ``ID`` (e.g. ``000003``):
``velodyne/ID.bin`` (float32 x, y, z in metres in the Velodyne frame, reflectance in
[0, 1]), ``image_2/ID.png`` (the left colour camera, 8-bit sRGB) and ``calib/ID.txt``.
KITTI raw frames converted to this layout (the calibration composed from
``calib_cam_to_cam`` and ``calib_velo_to_cam``) read the same way.

**Calibration** (:func:`load_kitti_calib`): the calib files with ``P0..P3`` (3x4),
``R0_rect`` (3x3) and ``Tr_velo_to_cam`` (3x4); the raw-data names ``R_rect`` and
``Tr_velo_cam`` are accepted too. The rectified camera ``n`` maps
``x_img ~ P_n R0_rect Tr_velo_to_cam x_velo``. ``P_n = [K | p]`` carries the stereo baseline
in ``p``; since ``K`` is invertible, ``P_n = K [I | K^{-1} p]``, so the model is exactly
``K`` with extrinsic ``[I | K^{-1} p] R0_rect Tr_velo_to_cam`` (and the depth equals the
homogeneous coordinate of ``P_n R0_rect Tr_velo_to_cam x_velo``). ``K`` is in pixels with
pixel centres at integer coordinates (:mod:`nidar_mi.geometry.camera_model`).

Rings (lasers) come from the storage order: :mod:`nidar_mi.datasets.kitti_rings`.

**Short scans.** A scan may end early (a truncated file): it then has fewer than 64 rings, all
of them the top ones; :func:`load_frame` reads whole points and drops a trailing partial one with
a warning.
"""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nidar_mi.errors import NidarError
from nidar_mi.geometry.camera_model import CameraModel
from nidar_mi.io.images import read_png

__all__ = [
    "KITTI_IMAGE_SIZE",
    "KittiFrame",
    "frame_ids",
    "load_frame",
    "load_kitti_calib",
    "read_scan",
]

KITTI_IMAGE_SIZE = (1242, 375)
"""(width, height) in pixels of most KITTI object ``image_2`` frames; some are a few
pixels smaller."""

_KITTI_ALIASES = {"R_rect": "R0_rect", "Tr_velo_cam": "Tr_velo_to_cam"}


def _parse_kitti(path: Path) -> dict[str, np.ndarray]:
    try:
        lines = path.read_text(encoding="ascii").splitlines()
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
        entries[_KITTI_ALIASES.get(key, key)] = values
    return entries


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
    path = Path(path)
    if camera not in ("P0", "P1", "P2", "P3"):
        raise NidarError(f"load_kitti_calib: camera must be P0..P3, not {camera!r}")
    entries = _parse_kitti(path)
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


def _frame_paths(kitti_dir: str | os.PathLike[str], frame_id: str) -> dict[str, str]:
    return {
        "velodyne": os.path.join(kitti_dir, "velodyne", f"{frame_id}.bin"),
        "image": os.path.join(kitti_dir, "image_2", f"{frame_id}.png"),
        "calib": os.path.join(kitti_dir, "calib", f"{frame_id}.txt"),
    }


def frame_ids(kitti_dir: str | os.PathLike[str]) -> list[str]:
    """Frame ids with a Velodyne scan, a camera-2 image and a calibration file, sorted.

    Returns:
        The ids (file stems, e.g. ``"000003"``); empty when ``kitti_dir/velodyne`` is absent.
    """
    vel = os.path.join(kitti_dir, "velodyne")
    if not os.path.isdir(vel):
        return []
    ids = []
    for name in sorted(os.listdir(vel)):
        stem, ext = os.path.splitext(name)
        if ext != ".bin":
            continue
        paths = _frame_paths(kitti_dir, stem)
        if os.path.isfile(paths["image"]) and os.path.isfile(paths["calib"]):
            ids.append(stem)
    return ids


def read_scan(path: str | os.PathLike[str]) -> tuple[np.ndarray, np.ndarray]:
    """A KITTI ``.bin`` scan: (N, 3) float32 xyz (m) and (N,) float32 reflectance.

    A file that ends inside a point (a truncated download) gives its whole points and a warning.

    Raises:
        NidarError: a missing or unreadable file.
    """
    from nidar_mi.io.atomic import reading

    with reading(path) as p:
        size = p.stat().st_size
        rows = np.fromfile(p, dtype="<f4", count=(size // 16) * 4).reshape(-1, 4)
    if size % 16:
        warnings.warn(
            f"{path}: {size % 16} trailing bytes are not a whole point (a truncated scan); "
            f"read {len(rows)} points",
            RuntimeWarning,
            stacklevel=2,
        )
    return np.ascontiguousarray(rows[:, :3], dtype=np.float32), rows[:, 3].astype(np.float32)


@dataclass(frozen=True, eq=False)
class KittiFrame:
    """One KITTI frame: the Velodyne scan, the camera-2 image and its camera model.

    Attributes:
        xyz: (N, 3) float32 points in the Velodyne frame, metres.
        intensity: (N,) float32 Velodyne reflectance in [0, 1], as stored.
        rgb: (H, W, 3) uint8 sRGB camera-2 image.
        camera: camera 2 (``P2``) at the image's size, ``T_cam_lidar`` from the Velodyne.
        frame_id: the frame id, e.g. ``"000003"``.
    """

    xyz: np.ndarray
    intensity: np.ndarray
    rgb: np.ndarray
    camera: CameraModel
    frame_id: str


def load_frame(kitti_dir: str | os.PathLike[str], frame_id: str) -> KittiFrame:
    """Read ``velodyne/ID.bin``, ``image_2/ID.png`` and ``calib/ID.txt`` (camera P2).

    Args:
        kitti_dir: folder with ``velodyne/``, ``image_2/`` and ``calib/``.
        frame_id: the frame id, e.g. ``"000003"``.

    Returns:
        The frame; the camera takes its width and height from the image.

    Raises:
        NidarError: a missing or malformed file (one-line message naming it).
    """
    paths = _frame_paths(kitti_dir, frame_id)
    for what, p in paths.items():
        if not os.path.isfile(p):
            raise NidarError(f"KITTI frame {frame_id}: missing {what} file {p}")
    xyz, intensity = read_scan(paths["velodyne"])
    rgb = read_png(paths["image"])[..., :3]
    cam = load_kitti_calib(paths["calib"], "P2", width=rgb.shape[1], height=rgb.shape[0])
    return KittiFrame(xyz=xyz, intensity=intensity, rgb=rgb, camera=cam, frame_id=frame_id)
