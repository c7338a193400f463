"""Camera calibration files: a small YAML/JSON schema and KITTI object ``calib/*.txt``.

**YAML / JSON schema** (:func:`load_calib`, :func:`save_calib`). Either a top-level list of
cameras or a mapping with key ``cameras`` holding that list. Each camera::

    name: front                 # optional label
    K: [[fx, s, cx], [0, fy, cy], [0, 0, 1]]   # or the keys fx, fy, cx, cy (+ optional skew)
    width: 1920                 # pixels
    height: 1280
    T_cam_lidar: [[...], [...], [...], [0, 0, 0, 1]]  # LiDAR -> camera, metres
    # or T_lidar_cam (camera -> LiDAR, e.g. Waymo's camera extrinsic); exactly one of the two
    convention: opencv          # or waymo; default opencv

Matrices are row-major, nested (3x3, 4x4 or 3x4 with ``[0, 0, 0, 1]`` implied) or flat
(9, 16 or 12 numbers). Intrinsics follow the pixel convention of
:mod:`nidar_mi.nidar.projection` (pixel centres at integer coordinates).

**KITTI** (:func:`load_kitti_calib`): the object-detection calib files with ``P0..P3``
(3x4), ``R0_rect`` (3x3) and ``Tr_velo_to_cam`` (3x4). The rectified camera ``n`` maps
``x_img ~ P_n R0_rect Tr_velo_to_cam x_velo``. ``P_n = [K | p]`` carries the stereo baseline
in ``p``; since ``K`` is invertible, ``P_n = K [I | K^{-1} p]``, so the model is exactly
``K`` with extrinsic ``[I | K^{-1} p] R0_rect Tr_velo_to_cam`` (and the depth equals the
homogeneous coordinate of ``P_n R0_rect Tr_velo_to_cam x_velo``).
"""

from __future__ import annotations

import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from nidar_mi.errors import NidarError
from nidar_mi.io.atomic import atomic_write_text
from nidar_mi.nidar.projection import CameraModel

__all__ = [
    "KITTI_IMAGE_SIZE",
    "camera_from_dict",
    "camera_to_dict",
    "load_calib",
    "load_kitti_calib",
    "save_calib",
]

KITTI_IMAGE_SIZE = (1242, 375)
"""(width, height) of most KITTI object ``image_2`` frames; some are a few pixels smaller."""


def _matrix(value: Any, shapes: Sequence[tuple[int, int]], what: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise NidarError(f"{what} must be a numeric matrix") from None
    for shape in shapes:
        if arr.shape == shape or (arr.ndim == 1 and arr.size == shape[0] * shape[1]):
            arr = arr.reshape(shape)
            if not np.all(np.isfinite(arr)):
                raise NidarError(f"{what} contains NaN or inf")
            return arr
    wanted = " or ".join(f"{r}x{c}" for r, c in shapes)
    raise NidarError(f"{what} must be {wanted}, got shape {arr.shape}")


def _homogeneous(m: np.ndarray) -> np.ndarray:
    if m.shape == (4, 4):
        return m
    return np.vstack([m, [0.0, 0.0, 0.0, 1.0]])


def camera_from_dict(entry: Mapping[str, Any], label: str = "camera") -> CameraModel:
    """Build a :class:`CameraModel` from one schema entry (see the module docstring)."""
    if not isinstance(entry, Mapping):
        raise NidarError(f"{label}: expected a mapping")
    if "K" in entry:
        K = _matrix(entry["K"], [(3, 3)], f"{label}: K")
    else:
        missing = [k for k in ("fx", "fy", "cx", "cy") if k not in entry]
        if missing:
            raise NidarError(f"{label}: needs K or fx, fy, cx, cy (missing {', '.join(missing)})")
        try:
            fx, fy, cx, cy = (float(entry[k]) for k in ("fx", "fy", "cx", "cy"))
            s = float(entry.get("skew", 0.0))
        except (TypeError, ValueError):
            raise NidarError(f"{label}: fx, fy, cx, cy, skew must be numbers") from None
        K = np.array([[fx, s, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
    for key in ("width", "height"):
        if key not in entry:
            raise NidarError(f"{label}: missing {key!r}")
    has_cl, has_lc = "T_cam_lidar" in entry, "T_lidar_cam" in entry
    if has_cl == has_lc:
        raise NidarError(f"{label}: give exactly one of T_cam_lidar and T_lidar_cam")
    key = "T_cam_lidar" if has_cl else "T_lidar_cam"
    T = _homogeneous(_matrix(entry[key], [(4, 4), (3, 4)], f"{label}: {key}"))
    if has_lc:
        if abs(np.linalg.det(T)) < 1e-12:
            raise NidarError(f"{label}: T_lidar_cam is singular")
        T = np.linalg.inv(T)
        T[3] = [0.0, 0.0, 0.0, 1.0]
    name = str(entry.get("name", ""))
    try:
        return CameraModel(
            K=K,
            width=entry["width"],
            height=entry["height"],
            T_cam_lidar=T,
            convention=str(entry.get("convention", "opencv")),
            name=name,
        )
    except NidarError as exc:
        raise NidarError(f"{label}: {exc}") from None


def camera_to_dict(cam: CameraModel) -> dict[str, Any]:
    """Schema entry for a camera (``K`` and ``T_cam_lidar`` as nested lists)."""
    return {
        "name": cam.name,
        "K": cam.K.tolist(),
        "width": cam.width,
        "height": cam.height,
        "T_cam_lidar": cam.T_cam_lidar.tolist(),
        "convention": cam.convention,
    }


def load_calib(path: str | os.PathLike[str]) -> list[CameraModel]:
    """Read cameras from a YAML or JSON file (schema in the module docstring).

    ``.json`` files are parsed as JSON, anything else with ``yaml.safe_load``.

    Raises:
        NidarError: unreadable file, syntax error or schema violation (one-line message).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise NidarError(f"{path}: cannot read camera calibration: {exc}") from None
    try:
        data = json.loads(text) if path.suffix.lower() == ".json" else yaml.safe_load(text)
    except (json.JSONDecodeError, yaml.YAMLError) as exc:
        msg = " ".join(str(exc).split())
        raise NidarError(f"{path}: cannot parse camera calibration: {msg}") from None
    if isinstance(data, Mapping):
        data = data.get("cameras")
    if not isinstance(data, list) or not data:
        raise NidarError(f"{path}: expected a non-empty list of cameras (or a 'cameras' key)")
    cams = []
    for k, entry in enumerate(data):
        name = entry.get("name") if isinstance(entry, Mapping) else None
        label = f"{path}: camera {k}" + (f" ({name!r})" if name else "")
        cams.append(camera_from_dict(entry, label))
    return cams


def save_calib(path: str | os.PathLike[str], cameras: Sequence[CameraModel]) -> None:
    """Write cameras in the schema, as JSON for ``.json`` paths else YAML, atomically."""
    path = Path(path)
    data = {"cameras": [camera_to_dict(c) for c in cameras]}
    if path.suffix.lower() == ".json":
        text = json.dumps(data, indent=2) + "\n"
    else:
        text = yaml.safe_dump(data, sort_keys=False)
    atomic_write_text(path, text)


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
    """Rectified KITTI camera model from an object-detection ``calib/*.txt`` file.

    Args:
        path: the calib file.
        camera: ``"P0"``..``"P3"`` (``"P2"`` is the left colour camera, ``image_2``).
        width: image width in pixels (KITTI frames vary slightly; read it from the image).
        height: image height in pixels.

    Returns:
        An ``"opencv"`` :class:`CameraModel` whose projection equals
        ``P_camera R0_rect Tr_velo_to_cam`` exactly (see the module docstring).

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
    Tr = _homogeneous(entries["Tr_velo_to_cam"].reshape(3, 4))
    baseline = np.eye(4)
    baseline[:3, 3] = np.linalg.solve(K, P[:, 3])
    T = baseline @ R0 @ Tr
    T[3] = [0.0, 0.0, 0.0, 1.0]
    try:
        return CameraModel(K=K, width=width, height=height, T_cam_lidar=T, name=camera)
    except NidarError as exc:
        raise NidarError(f"{path}: {exc}") from None
