"""The poses of a drive's frames: from its poses file, or from KISS-ICP odometry.

KISS-ICP (Vizzo et al., RA-L 2023; the ``kiss-icp`` package, through its public
:class:`kiss_icp.kiss_icp.KissICP` and :func:`kiss_icp.config.load_config`) registers each scan
to a local map of the scans before it and returns ``T_{lidar_0 <- lidar_k}``. Every frame, held
out or not, is registered, because the re-simulated scan of a held-out frame needs its pose
(a vehicle's localisation gives that pose at run time); the held-out scans enter nothing else
(:mod:`.reconstruction`). Scans are not de-skewed: the re-simulation casts each frame from one pose.

:func:`pose_quality` measures what the mesh's Chamfer target cares about: how far the returns of
each frame lie from those of its neighbours once both are placed with their poses (the median
nearest-neighbour distance over returns closer than 30 m).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["odometry_poses", "pose_quality"]


def odometry_poses(
    load: Callable[[int], np.ndarray], frames: int, *, progress: bool = False
) -> np.ndarray:
    """(frames, 4, 4) float64 LiDAR poses ``T_{lidar_0 <- lidar_k}`` from KISS-ICP.

    Args:
        load: ``load(k) -> (N, 3)`` the returns of frame k, LiDAR frame, m.
        frames: number of frames.
        progress: progress bar on stderr.
    """
    from kiss_icp.config import load_config
    from kiss_icp.kiss_icp import KissICP

    from ..progress import progress_bar

    cfg = load_config(None)  # the defaults (voxel size max_range / 100)
    cfg.data.deskew = False
    cfg.registration.max_num_threads = 2
    odom = KissICP(cfg)
    poses = np.zeros((frames, 4, 4))
    for k in progress_bar(range(frames), show=progress, desc="KISS-ICP", unit="frame"):
        odom.register_frame(np.asarray(load(k), dtype=np.float64), np.zeros(0))
        poses[k] = odom.last_pose
    return poses


def pose_quality(points: list[np.ndarray], poses: np.ndarray, max_range_m: float = 30.0):
    """(F-1,) median distance (m) from each frame's returns to the previous frame's, both in
    world coordinates; returns beyond ``max_range_m`` are left out."""
    from scipy.spatial import cKDTree

    world = []
    for xyz, T in zip(points, poses):
        xyz = np.asarray(xyz, dtype=np.float64)
        xyz = xyz[np.linalg.norm(xyz, axis=1) < max_range_m]
        world.append(xyz @ T[:3, :3].T + T[:3, 3])
    out = []
    for a, b in zip(world[:-1], world[1:]):
        d, _ = cKDTree(a).query(b, k=1)
        out.append(float(np.median(d)))
    return np.asarray(out)
