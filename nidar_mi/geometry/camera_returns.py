"""The LiDAR returns a camera sees, and those returns splatted onto its pixel grid.

Every builder of camera-visible returns (the rendered training frames of
:mod:`nidar_mi.render_dataset`, the KITTI frames of :mod:`nidar_mi.datasets.kitti_frames`, the
evaluation frames of :mod:`nidar_mi.eval.rendered`) takes the same three steps here:

1. **project** each return into the camera (:func:`~nidar_mi.geometry.projection.project`);
2. keep those in front of it, inside the image and not hidden
   (:func:`~nidar_mi.geometry.visibility.visible_mask`, default tolerances; against the
   rendered depth image when there is one, else the cloud's own z-buffer);
3. **splat** per-return values to the nearest pixel ``(rint(v), rint(u))`` (clipped to the
   image); where several returns land on one pixel the one with the smallest camera depth wins
   (the first in input order on equal depths).

Pixel coordinates ``(u, v)`` are ``(column, row)``, pixel centres at integers; depths in metres.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .camera_model import CameraModel
from .projection import project
from .visibility import visible_mask

__all__ = ["CameraReturns", "camera_returns", "splat_points"]


@dataclass(frozen=True)
class CameraReturns:
    """The returns one camera sees (``M`` of the ``N`` given) and their sparse pixel maps.

    Attributes:
        index: (M,) int64 indices of the visible returns into the input, ascending.
        uv: (M, 2) float64 pixel coordinates of the visible returns.
        depth: (M,) float64 camera-forward depths of the visible returns, m.
        maps: name -> (H, W) float32 map of each splatted value, 0 where no return landed.
        mask: (H, W) bool, the pixels a visible return landed on.
    """

    index: np.ndarray
    uv: np.ndarray
    depth: np.ndarray
    maps: dict[str, np.ndarray]
    mask: np.ndarray


def camera_returns(
    xyz_lidar: np.ndarray,
    cam: CameraModel,
    values: dict[str, np.ndarray] | None = None,
    *,
    depth_image: np.ndarray | None = None,
) -> CameraReturns:
    """Project LiDAR returns into a camera, keep the visible ones and splat their values.

    Args:
        xyz_lidar: (N, 3) returns in the LiDAR frame, m.
        cam: the camera.
        values: name -> (N,) per-return values to splat (None: none, only the mask).
        depth_image: optional (H, W) rendered camera-forward depth, m (0 = no surface), for the
            occlusion test; without it the projected cloud's own z-buffer is used.

    Returns:
        The :class:`CameraReturns` (module docstring for the rules).
    """
    uv, depth, in_front = project(xyz_lidar, cam)
    index = np.flatnonzero(in_front & visible_mask(uv, depth, cam, depth_image=depth_image))
    maps, mask = _splat(uv[index], depth[index], index, values or {}, cam)
    return CameraReturns(index, uv[index], depth[index], maps, mask)


def _splat(
    uv: np.ndarray, depth: np.ndarray, index: np.ndarray, values: dict, cam: CameraModel
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """(H, W) float32 maps of ``values[name][index]`` at ``uv`` (nearest depth wins a pixel) and
    the (H, W) bool mask of the occupied pixels."""
    H, W = cam.height, cam.width
    u = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, W - 1)
    v = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, H - 1)
    # nearest first; np.unique keeps the first occurrence of every pixel
    order = np.argsort(depth, kind="stable")
    pix = (v * W + u)[order]
    _, first = np.unique(pix, return_index=True)
    keep = index[order][first]
    flat = pix[first]
    mask = np.zeros(H * W, dtype=bool)
    mask[flat] = True
    maps = {}
    for name, vals in values.items():
        m = np.zeros(H * W, dtype=np.float32)
        m[flat] = np.asarray(vals, dtype=np.float32)[keep]
        maps[name] = m.reshape(H, W)
    return maps, mask.reshape(H, W)


def splat_points(
    xyz_lidar: np.ndarray,
    values: dict[str, np.ndarray],
    cam: CameraModel,
    *,
    depth_image: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """The sparse maps of :func:`camera_returns` alone: ``(maps, mask)``.

    Args:
        xyz_lidar: (N, 3) points in the LiDAR frame, m.
        values: name -> (N,) per-point values to splat.
        cam: the camera.
        depth_image: optional (H, W) rendered camera-forward depth, m (0 = no surface).

    Returns:
        ``(maps, mask)``: name -> (H, W) float32 map, 0 where no point landed; (H, W) bool
        mask of the pixels a point landed on.
    """
    r = camera_returns(xyz_lidar, cam, values, depth_image=depth_image)
    return r.maps, r.mask
