"""Camera-calibration files: a small YAML/JSON schema, and the renderer's own ``calib.json``.

**YAML / JSON schema** (:func:`load_calib`, :func:`save_calib`). Either a top-level list of
cameras or a mapping with key ``cameras`` holding that list. Each camera::

    name: front                 # optional label
    K: [[fx, s, cx], [0, fy, cy], [0, 0, 1]]   # pixels; or the keys fx, fy, cx, cy (+ optional skew)
    width: 1920                 # pixels
    height: 1280
    T_cam_lidar: [[...], [...], [...], [0, 0, 0, 1]]  # LiDAR -> camera, metres
    # or T_lidar_cam (camera -> LiDAR, e.g. Waymo's camera extrinsic); exactly one of the two
    convention: opencv          # or waymo; default opencv

Matrices are row-major, nested (3x3, 4x4 or 3x4 with ``[0, 0, 0, 1]`` implied) or flat
(9, 16 or 12 numbers). Intrinsics follow the pixel convention of
:mod:`nidar_mi.geometry.camera_model` (pixel centres at integer coordinates).

**Renderer calib.json** (:func:`load_calib` only). ``python -m nidar_mi.render`` writes
``OUT/<camera>/calib.json``: one camera as a mapping with ``convention``, ``width``,
``height``, ``K``, ``T_world_cam`` and ``T_cam_lidar`` mapping each LiDAR id of the scene to
its (4, 4) LiDAR -> camera transform (plus ``nir_wavelength_nm`` and ``png_exposure``, not
used here). Its camera takes the name of the folder holding the file and the
``T_cam_lidar`` of the scene's only LiDAR, or of the one named by ``lidar=``.

KITTI calib files are read by :func:`nidar_mi.io.kitti.load_kitti_calib`.
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
from nidar_mi.geometry.camera_model import CameraModel
from nidar_mi.io.atomic import atomic_write_text

__all__ = [
    "render_calib_model",
    "camera_from_dict",
    "camera_to_dict",
    "is_render_calib",
    "load_calib",
    "save_calib",
]


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


def _is_render_calib(data: Any) -> bool:
    return (
        isinstance(data, Mapping)
        and "cameras" not in data
        and isinstance(data.get("T_cam_lidar"), Mapping)
    )


def is_render_calib(path: str | os.PathLike) -> bool:
    """Whether ``path`` is a renderer ``calib.json`` (False for any other or unreadable file)."""
    path = Path(path)
    if path.suffix.lower() != ".json":
        return False
    try:
        return _is_render_calib(json.loads(path.read_text(encoding="utf-8")))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return False


def render_calib_model(
    data: Mapping[str, Any], name: str, lidar: str | None = None, where: str | None = None
) -> CameraModel:
    """The camera model of a renderer ``calib.json`` (or its manifest entry) for one LiDAR.

    Args:
        data: the calib.json mapping (``K``, ``width``, ``height``, ``T_cam_lidar`` per LiDAR).
        name: the camera's name (its folder).
        lidar: the LiDAR whose extrinsic is used; None: the only one.
        where: what to name in error messages (default: ``name``).

    Raises:
        NidarError: no such LiDAR, several without ``lidar``, or a malformed entry.
    """
    path = where or name
    poses = data["T_cam_lidar"]
    ids = sorted(str(k) for k in poses)
    if lidar is None:
        if len(ids) != 1:
            listed = ", ".join(ids) if ids else "none"
            raise NidarError(
                f"{path}: T_cam_lidar has {len(ids)} LiDARs ({listed}); choose one with `lidar`"
            )
        lidar = ids[0]
    elif lidar not in poses:
        raise NidarError(f"{path}: no LiDAR {lidar!r} in T_cam_lidar (has {', '.join(ids)})")
    entry = {k: data[k] for k in ("K", "width", "height", "convention") if k in data}
    entry["T_cam_lidar"] = poses[lidar]
    entry["name"] = name
    return camera_from_dict(entry, f"{path}: LiDAR {lidar!r}")


def load_calib(path: str | os.PathLike[str], *, lidar: str | None = None) -> list[CameraModel]:
    """Read cameras from a YAML or JSON file (schema in the module docstring).

    ``.json`` files are parsed as JSON, anything else with ``yaml.safe_load``. A renderer
    ``calib.json`` (a mapping whose ``T_cam_lidar`` maps LiDAR ids to transforms) gives one
    camera, named after the file's folder, with the extrinsic of its only LiDAR or of
    ``lidar``.

    Args:
        path: the calibration file.
        lidar: LiDAR id, for a renderer ``calib.json`` of a scene with several LiDARs.

    Returns:
        The cameras, in file order.

    Raises:
        NidarError: unreadable file, syntax error, schema violation, ``lidar`` given for a
            file that is not a renderer ``calib.json``, or a LiDAR that is missing or
            ambiguous (one-line message).
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
    if _is_render_calib(data):
        return [render_calib_model(data, path.parent.name, lidar, str(path))]
    if lidar is not None:
        raise NidarError(f"{path}: `lidar` applies to a renderer calib.json only")
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
