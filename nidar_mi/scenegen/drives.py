"""The drive files of a city or suburb scene (written by ``python -m nidar_mi.scenegen``).

The files hold *rig* poses, the convention of ``render --trajectory``: every sensor keeps its
pose in the scene XML as its mounting on the rig, so at frame k the LiDAR is at
``T_rig(k) · T_mount`` with ``T_mount`` the pose of ``lidar_top`` in the XML (``T_world_lidar`` in
the scene's ``index.json`` entry). The rig is at the identity when the LiDAR is at its scene pose;
the files give ``T_rig(k) = T_world_lidar(k) · T_mount⁻¹``. For scene ``ID`` in folder ``DIR``:

==========================  ==================================================================
file                        content
==========================  ==================================================================
``DIR/ID_drive.tum``        ``t x y z qx qy qz qw`` per frame: the rig pose (TUM format; what
                            ``render --trajectory`` reads)
``DIR/ID_drive_kitti.txt``  the same poses as 3x4 row-major matrices (KITTI odometry poses)
``DIR/ID_drive_times.txt``  the frame times in s (KITTI odometry ``times.txt``)
==========================  ==================================================================
"""

from __future__ import annotations

import dataclasses
import os

import numpy as np

from ..io.kitti import write_kitti_poses, write_kitti_times
from ..io.trajectory import write_tum
from .route import drive, revisits
from .streets import StreetGrid

__all__ = ["DEFAULT_FRAMES", "write_drive"]

#: Frames of a drive unless asked otherwise (50 s at 10 Hz: about 300 m, most of a lap of the
#: figure eight in a city of the default size).
DEFAULT_FRAMES = 500


def write_drive(
    out_dir: str,
    scene: str,
    grid: StreetGrid,
    mount: np.ndarray,
    *,
    frames: int = DEFAULT_FRAMES,
    rate_hz: float = 10.0,
    speed: float = 10.0,
    seed: int = 0,
    body_motion: bool = True,
) -> dict:
    """Write the drive files of ``scene`` into ``out_dir`` (atomically, replacing older ones).

    ``mount`` is the (4, 4) pose of the scene's LiDAR (module docstring); ``seed`` draws the
    phases of the body's oscillations and ``body_motion`` turns them on (:func:`.trajectory.drive`).

    Returns:
        The index record: file names, frames, rate (Hz), cruising speed (m/s), length (m) and the
        number of revisits (:func:`.trajectory.revisits`).
    """
    lidar = drive(grid, frames, rate_hz, speed, seed=seed, body_motion=body_motion)
    traj = dataclasses.replace(lidar, poses=lidar.poses @ np.linalg.inv(mount))
    files = {
        "tum": f"{scene}_drive.tum",
        "kitti": f"{scene}_drive_kitti.txt",
        "times": f"{scene}_drive_times.txt",
    }
    comment = "t x y z qx qy qz qw  (T_rig, T_world_lidar = T_rig @ T_mount; s, m)"
    write_tum(os.path.join(out_dir, files["tum"]), traj.times, traj.poses, comment)
    write_kitti_poses(os.path.join(out_dir, files["kitti"]), traj.poses)
    write_kitti_times(os.path.join(out_dir, files["times"]), traj.times)
    return {
        "files": files,
        "frames": frames,
        "rate_hz": rate_hz,
        "speed_m_s": speed,
        "body_motion": body_motion,
        "length_m": round(float(lidar.distance[-1]), 3),
        "revisits": revisits(lidar),
        "poses": "rig: T_world_lidar = T_rig @ T_mount, T_mount = lidar T_world_lidar",
        "grid": {"kind": grid.kind, "blocks": [grid.nx, grid.ny], "pitch_m": grid.pitch},
    }
