"""Training frames: LiDAR returns projected into a camera as sparse maps.

A frame pairs one camera's images with the LiDAR returns it sees. Each return is projected with
the camera's calibration (:func:`nidar_mi.nidar.projection.project`), kept when the rendered depth
does not hide it (:func:`~nidar_mi.nidar.projection.visible_mask`), and written to its nearest
pixel; when several returns land on one pixel the nearest to the camera wins (a z-buffer).
"""

from __future__ import annotations

import numpy as np

from .projection import CameraModel, project, visible_mask

__all__ = ["sparse_maps"]


def sparse_maps(
    xyz_lidar: np.ndarray,
    values: dict[str, np.ndarray],
    cam: CameraModel,
    *,
    depth_image: np.ndarray | None = None,
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Project LiDAR points into a camera and splat per-point values to pixels.

    Args:
        xyz_lidar: (N, 3) points in the LiDAR frame, m.
        values: name -> (N,) per-point values to splat.
        cam: the camera (pixel centres at integer coordinates).
        depth_image: optional (H, W) rendered z-depth (m, 0 = no surface) for the occlusion test;
            without it the projected cloud's own z-buffer is used.

    Returns:
        (maps name -> (H, W) float32, 0 where no return; mask (H, W) bool).
    """
    H, W = cam.height, cam.width
    uv, depth, in_front = project(xyz_lidar, cam)
    seen = in_front & visible_mask(uv, depth, cam, depth_image=depth_image)
    idx = np.nonzero(seen)[0]
    u = np.clip(np.rint(uv[idx, 0]).astype(np.int64), 0, W - 1)
    v = np.clip(np.rint(uv[idx, 1]).astype(np.int64), 0, H - 1)
    # nearest first; np.unique keeps the first occurrence of every pixel
    order = np.argsort(depth[idx], kind="stable")
    pix = (v * W + u)[order]
    _, first = np.unique(pix, return_index=True)
    keep = idx[order][first]
    flat = pix[first]
    mask = np.zeros(H * W, dtype=bool)
    mask[flat] = True
    maps = {}
    for name, vals in values.items():
        m = np.zeros(H * W, dtype=np.float32)
        m[flat] = np.asarray(vals, dtype=np.float32)[keep]
        maps[name] = m.reshape(H, W)
    return maps, mask.reshape(H, W)
