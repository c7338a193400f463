"""Which projected LiDAR points a camera sees (splatting them: :mod:`.camera_returns`).

Pixel coordinates ``(u, v)`` are ``(column, row)`` in pixels with pixel centres at integer
coordinates (see :mod:`nidar_mi.geometry.camera_model`); depths and tolerances are in metres,
depth meaning the camera-forward coordinate.

**Occlusion.** A point that projects into a camera can still be hidden from it by a nearer
surface (the LiDAR and camera do not share a viewpoint). :func:`visible_mask` rejects it
against a rendered depth image when one exists (exact up to the tolerance), else against a
z-buffer of the projected cloud itself (coarser: it needs cells large enough that
foreground points cover them, and a grazing surface may hide its own far points).

What the test changes (measured with this module's defaults, 4 px cells, ``rel_tol`` 0.2,
``abs_tol`` 0.1 m):

* Analytic street (ground, wall at 30 m, three boxes; 64-beam LiDAR, 800x300 camera with
  f = 400 px; ground-truth visibility by ray casting). Camera 1.2 m from the LiDAR: 2.5 %
  of the in-image points are truly hidden and, without a test, take the occluder's value
  (3.2 % of observed points get a wrong value, the rest being bilinear mixing at
  silhouettes). The depth-image test keeps 23 hidden points of 1104, drops none visible
  (0.8 % wrong values); the z-buffer keeps 27 and drops 153 visible (0.3 %) points (0.8 %
  wrong). Camera 2.1 m away: 3.6 % hidden; none / depth image / z-buffer give 4.1 % /
  0.7 % / 0.8 % wrong values. KITTI-like 0.28 m baseline: only 0.1 % hidden; 0.9 % /
  0.8 % / 0.7 % wrong values, the z-buffer dropping 1.1 % visible points.
* KITTI object frames 000000-000003 (real Velodyne, camera 2, 0.27 m baseline): the
  z-buffer hides 1.8 % of the in-image points; the same test from a virtual camera at the
  LiDAR origin, from which nothing can be hidden, hides 1.5 %. So with a small baseline
  the NIDAR paper (which has no occlusion test) loses little, and a cloud z-buffer removes
  mostly visible points at silhouettes; the test matters for cameras far from the LiDAR,
  and a rendered depth image is the reliable way to do it.
"""

from __future__ import annotations

from types import MappingProxyType
from typing import Any

import numpy as np

from nidar_mi.errors import NidarError

from .camera_model import CameraModel
from .projection import check_uv, in_image

__all__ = [
    "DEFAULT_ABS_TOL",
    "DEFAULT_REL_TOL",
    "DEFAULT_ZBUFFER_CELL",
    "visible_mask",
]

DEFAULT_REL_TOL = MappingProxyType({"depth_image": 0.05, "zbuffer": 0.2})
"""Default relative tolerance per occlusion test (see the module docstring for how the
z-buffer value was chosen)."""
DEFAULT_ABS_TOL = 0.1
"""Absolute slack (m) added to the relative tolerance."""
DEFAULT_ZBUFFER_CELL = 4
"""Z-buffer cell size in pixels for the cloud-only occlusion test."""


def _nearest_pixel(uv: np.ndarray, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    col = np.clip(np.floor(uv[:, 0] + 0.5).astype(np.int64), 0, width - 1)
    row = np.clip(np.floor(uv[:, 1] + 0.5).astype(np.int64), 0, height - 1)
    return row, col


def visible_mask(
    uv: Any,
    depth: Any,
    cam: CameraModel,
    *,
    depth_image: Any = None,
    depth_kind: str = "z",
    rel_tol: float | None = None,
    abs_tol: float = DEFAULT_ABS_TOL,
    zbuffer_cell: int = DEFAULT_ZBUFFER_CELL,
) -> np.ndarray:
    """Which projected points are seen by the camera (in the image and not occluded).

    A point at depth ``z`` is hidden by a surface at depth ``z_occ`` when
    ``z > z_occ * (1 + rel_tol) + abs_tol``.

    * With ``depth_image`` (H, W): ``z_occ`` is the rendered depth at the point's nearest
      pixel. Pixels that are not finite or ``<= 0`` mean "no surface" and hide nothing.
      ``depth_kind="z"`` means the image holds camera-forward depth; ``"range"`` means
      Euclidean distance from the camera centre (as a ray-distance depth AOV), and the
      point's range is compared instead.
    * Without: ``z_occ`` is the smallest depth of the projected points (``uv``, ``depth``
      themselves) in the same ``zbuffer_cell`` x ``zbuffer_cell`` pixel cell, cells tiling
      the image from its corner ``(-0.5, -0.5)``.

    Args:
        uv: (N, 2) pixel coordinates from :func:`~nidar_mi.geometry.projection.project`.
        depth: (N,) camera-forward depths from
            :func:`~nidar_mi.geometry.projection.project`, metres.
        cam: the camera.
        depth_image: optional (H, W) rendered depth in metres.
        depth_kind: ``"z"`` or ``"range"``, what ``depth_image`` holds.
        rel_tol: relative depth tolerance; None: 0.05 against a depth image, 0.2 against the
            z-buffer (:data:`DEFAULT_REL_TOL`).
        abs_tol: absolute depth tolerance in metres.
        zbuffer_cell: z-buffer cell size in pixels (>= 1).

    Returns:
        (N,) bool, True for points inside the image, in front of the camera and unoccluded.
    """
    uv = check_uv(uv)
    depth = np.asarray(depth, dtype=np.float64).reshape(-1)
    if depth.shape[0] != uv.shape[0]:
        raise NidarError(f"visible_mask: {uv.shape[0]} pixels but {depth.shape[0]} depths")
    if rel_tol is None:
        rel_tol = DEFAULT_REL_TOL["zbuffer" if depth_image is None else "depth_image"]
    if rel_tol < 0 or abs_tol < 0:
        raise NidarError("visible_mask: tolerances must be non-negative")
    with np.errstate(invalid="ignore"):
        cand = in_image(uv, cam) & np.isfinite(depth) & (depth > 0)
    visible = np.zeros(uv.shape[0], dtype=bool)
    idx = np.flatnonzero(cand)
    if idx.size == 0:
        return visible
    uvc, zc = uv[idx], depth[idx]
    if depth_image is not None:
        dimg = np.asarray(depth_image, dtype=np.float64)
        if dimg.shape != (cam.height, cam.width):
            raise NidarError(
                f"visible_mask: depth image is {dimg.shape}, camera is {(cam.height, cam.width)}"
            )
        if depth_kind == "z":
            own = zc
        elif depth_kind == "range":
            homog = np.concatenate([uvc, np.ones((idx.size, 1))], axis=1)
            rays = np.linalg.solve(cam.K, homog.T).T  # (x_n, y_n, 1)
            own = zc * np.linalg.norm(rays, axis=1)
        else:
            raise NidarError(f"visible_mask: depth_kind must be 'z' or 'range', not {depth_kind!r}")
        row, col = _nearest_pixel(uvc, cam.width, cam.height)
        occ = dimg[row, col]
        with np.errstate(invalid="ignore"):
            no_surface = ~np.isfinite(occ) | (occ <= 0)
            visible[idx] = no_surface | (own <= occ * (1.0 + rel_tol) + abs_tol)
        return visible
    cell = int(zbuffer_cell)
    if cell < 1:
        raise NidarError(f"visible_mask: zbuffer_cell must be >= 1, got {zbuffer_cell!r}")
    ncols = (cam.width + cell - 1) // cell
    cu = np.floor((uvc[:, 0] + 0.5) / cell).astype(np.int64)
    cv = np.floor((uvc[:, 1] + 0.5) / cell).astype(np.int64)
    key = cv * ncols + cu
    zmin = np.full(int(key.max()) + 1, np.inf)
    np.minimum.at(zmin, key, zc)
    visible[idx] = zc <= zmin[key] * (1.0 + rel_tol) + abs_tol
    return visible
