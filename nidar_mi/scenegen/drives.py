"""The drive files of a city or suburb scene (written by ``python -m nidar_mi.scenegen``).

For scene ``ID`` in folder ``DIR``:

==========================  ==================================================================
file                        content
==========================  ==================================================================
``DIR/ID_drive.tum``        ``t x y z qx qy qz qw`` per frame: the LiDAR pose in the world
                            frame (TUM format; what ``render --trajectory`` reads)
``DIR/ID_drive_kitti.txt``  the same poses as 3x4 row-major ``T_world_lidar`` (KITTI odometry
                            poses, world frame rather than relative to the first frame)
``DIR/ID_drive_times.txt``  the frame times in s (KITTI odometry ``times.txt``)
==========================  ==================================================================
"""

from __future__ import annotations

import os

from .city import StreetGrid
from .trajectory import drive, revisits, write_kitti, write_times, write_tum

__all__ = ["DEFAULT_FRAMES", "write_drive"]

#: Frames of a drive unless asked otherwise (50 s at 10 Hz: about 300 m, most of a lap of the
#: figure eight in a city of the default size).
DEFAULT_FRAMES = 500


def write_drive(
    out_dir: str,
    scene: str,
    grid: StreetGrid,
    *,
    frames: int = DEFAULT_FRAMES,
    rate_hz: float = 10.0,
    speed: float = 10.0,
    seed: int = 0,
) -> dict:
    """Write the drive files of ``scene`` into ``out_dir`` (atomically, replacing older ones).

    ``seed`` draws the phases of the body's oscillations (:func:`.trajectory.drive`).

    Returns:
        The index record: file names, frames, rate (Hz), cruising speed (m/s), length (m) and the
        number of revisits (:func:`.trajectory.revisits`).
    """
    traj = drive(grid, frames, rate_hz, speed, seed=seed)
    files = {
        "tum": f"{scene}_drive.tum",
        "kitti": f"{scene}_drive_kitti.txt",
        "times": f"{scene}_drive_times.txt",
    }
    write_tum(os.path.join(out_dir, files["tum"]), traj)
    write_kitti(os.path.join(out_dir, files["kitti"]), traj)
    write_times(os.path.join(out_dir, files["times"]), traj)
    return {
        "files": files,
        "frames": frames,
        "rate_hz": rate_hz,
        "speed_m_s": speed,
        "length_m": round(float(traj.distance[-1]), 3),
        "revisits": revisits(traj),
        "grid": {"kind": grid.kind, "blocks": [grid.nx, grid.ny], "pitch_m": grid.pitch},
    }
