"""NIDAR's reflectance R at the mesh's vertices: the prior of the inversion where the camera
sees a surface the LiDAR rarely hit, and the ρ of the "NIDAR's ρ" baseline.

For up to :data:`MAX_FRAMES` training frames that have an ``image_2`` picture and a
calibration (KITTI layout: P2, R0_rect, Tr_velo_to_cam), the vertices are moved into the
frame's LiDAR frame and NIDAR (:meth:`nidar_mi.nidar.pipeline.NidarModel.point_intensity`,
branch R, occlusion test on) gives R at those its camera sees; a vertex's prior is the mean over
the frames that saw it.
"""

from __future__ import annotations

import logging

import numpy as np

from .drive_folder import Drive, evenly_spread

__all__ = ["MAX_FRAMES", "nidar_prior"]

#: Training frames NIDAR runs on (evenly spread over the drive).
MAX_FRAMES = 4


def _frames_with_images(drive: Drive) -> list[str]:
    usable = [i for i in drive.train if drive.image_path(i) and drive.calib_path(i)]
    return evenly_spread(usable, MAX_FRAMES)


def nidar_prior(drive: Drive, vertices: np.ndarray, poses: np.ndarray, *, weights=None):
    """(V,) NIDAR's R at each vertex (NaN where no camera saw it), or None when the drive has
    no images or NIDAR cannot run.

    Args:
        drive: the drive (its images and calibration).
        vertices: (V, 3) world coordinates.
        poses: (F, 4, 4) LiDAR-to-world poses of every frame.
        weights: NIDAR weights folder (None: the shipped model).
    """
    from ..datasets.kitti_objects import load_kitti_frame
    from ..errors import NidarError
    from ..extras import require

    frames = _frames_with_images(drive)
    if not frames:
        return None
    try:  # the fit runs without the prior when NIDAR cannot run, and says why
        require("nidar", "NIDAR's prior")
        from ..nidar.pipeline import NidarModel

        model = NidarModel.load(weights)
    except NidarError as e:
        logging.getLogger("nidar_mi.reconstruct").warning("no NIDAR prior: %s", e)
        return None
    total = np.zeros(len(vertices))
    count = np.zeros(len(vertices))
    for fid in frames:
        f = load_kitti_frame(drive.root, fid)
        T = np.linalg.inv(poses[drive.index(fid)])
        local = (vertices @ T[:3, :3].T + T[:3, 3]).astype(np.float32)
        res = model.point_intensity(local, [f.camera], [f.rgb], occlusion=True, branch="R")
        seen = np.asarray(res.observed, bool)
        total[seen] += np.asarray(res.reflectance, np.float64)[seen]
        count[seen] += 1
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, total / np.maximum(count, 1), np.nan)
