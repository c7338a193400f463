"""The poses of a drive's frames: from its poses file, or from KISS-ICP odometry.

KISS-ICP (Vizzo et al., RA-L 2023; the ``kiss-icp`` package, through its public
:class:`kiss_icp.kiss_icp.KissICP` and :func:`kiss_icp.config.load_config`) registers each scan
to a local map of the scans before it and returns ``T_{lidar_0 <- lidar_k}``; on a slow drive its
poses jitter by a few tenths of a degree and centimetres from frame to frame, which blurs a fused
mesh. :func:`refine_poses` then registers every frame again, point to plane (Open3D's
``registration_icp``, Zhou, Park and Koltun 2018), to the returns of its training neighbours on
both sides, over a few passes. Every frame, held out or not, is registered, because the
re-simulated scan of a held-out frame needs its pose (a vehicle's localisation gives that pose at
run time); the held-out scans enter nothing else (:mod:`.reconstruction`), nor any refinement's
map. Scans are not de-skewed: the re-simulation casts each frame from one pose.

:func:`pose_quality` measures what the mesh's Chamfer target cares about: how far the returns of
each frame lie from those of its neighbours once both are placed with their poses (the median
nearest-neighbour distance over returns closer than 30 m).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

__all__ = ["REFINE_DISTANCES_M", "odometry_poses", "refine_poses", "pose_quality"]


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


#: Point-to-plane correspondence distances (m), coarse to fine, of :func:`refine_poses`.
REFINE_DISTANCES_M = (0.5, 0.2)


def refine_poses(
    load: Callable[[int], np.ndarray],
    poses: np.ndarray,
    train: np.ndarray,
    *,
    neighbours: int = 2,
    sweeps: int = 3,
    voxel_m: float = 0.25,
    normal_radius_m: float = 1.0,
    progress: bool = False,
) -> np.ndarray:
    """(F, 4, 4) ``poses`` refined by point-to-plane ICP of each frame against its neighbours.

    Every frame k, in order, is registered (Open3D's ``registration_icp`` with
    ``TransformationEstimationPointToPlane`` and a Tukey kernel, correspondence distances
    :data:`REFINE_DISTANCES_M`) to a local map: the returns of the ``neighbours`` training frames
    nearest to k in sequence order (k itself left out), placed with their current poses,
    down-sampled to ``voxel_m`` cubes, normals from their 30 nearest neighbours within
    ``normal_radius_m``. The cubes and the radius are wider than a ring's point spacing and
    narrower than the spacing of its rings on the road: with finer ones the normals of the road's
    rings are fitted along each ring and lie in the road, and the registration pulls each scan's
    rings onto its neighbours' (their sensor's position) instead of the surfaces onto each other.
    Its pose is replaced at once (Gauss-Seidel), and the pass over all frames repeated
    ``sweeps`` times: a frame's error is averaged with its neighbours' until consecutive poses
    agree. Held-out frames are registered like the others but their returns never enter a map.

    Args:
        load: ``load(k) -> (N, 3)`` the returns of frame k, LiDAR frame, m.
        poses: (F, 4, 4) initial poses (odometry), any common frame.
        train: (F,) bool, the frames whose returns may form the maps.
        neighbours: training frames per local map.
        sweeps: passes over the drive.
        voxel_m: down-sampling cube side, m.
        normal_radius_m: the radius of the normals' neighbourhoods, m.
        progress: progress bar on stderr.
    """
    import open3d as o3d

    from ..progress import progress_bar

    reg = o3d.pipelines.registration
    poses = np.array(poses, dtype=np.float64)
    train = np.asarray(train, dtype=bool)
    clouds = [_cloud(load(k)).voxel_down_sample(voxel_m) for k in range(len(poses))]
    points = [np.asarray(c.points) for c in clouds]
    candidates = np.flatnonzero(train)
    search = o3d.geometry.KDTreeSearchParamHybrid(radius=normal_radius_m, max_nn=30)
    steps = progress_bar(
        range(sweeps * len(poses)), show=progress, desc="pose refinement", unit="frame"
    )
    for step in steps:
        k = step % len(poses)
        others = candidates[candidates != k]
        near = others[np.argsort(np.abs(others - k), kind="stable")[:neighbours]]
        if len(near) == 0:
            continue
        world = [points[j] @ poses[j, :3, :3].T + poses[j, :3, 3] for j in near]
        target = _cloud(np.concatenate(world)).voxel_down_sample(voxel_m)
        target.estimate_normals(search)
        T = poses[k]
        for dist in REFINE_DISTANCES_M:
            estimation = reg.TransformationEstimationPointToPlane(reg.TukeyLoss(k=dist))
            criteria = reg.ICPConvergenceCriteria(max_iteration=30)
            T = reg.registration_icp(
                clouds[k], target, dist, T, estimation, criteria
            ).transformation
        poses[k] = T
    return poses


def _cloud(xyz: np.ndarray):
    """An Open3D point cloud of (N, 3) points."""
    import open3d as o3d

    xyz = np.ascontiguousarray(xyz, dtype=np.float64)
    return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(xyz))
