"""Camera calibration files: a small YAML/JSON schema.

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

KITTI calib files are read by :func:`nidar_mi.datasets.kitti.load_kitti_calib`.
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

__all__ = ["camera_from_dict", "camera_to_dict", "load_calib", "save_calib"]


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
