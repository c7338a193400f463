"""File writers and readers: point sets, images, camera calibration, KITTI files, trajectories,
and atomic output.

Every writer creates parent directories and writes atomically (a temporary file renamed
onto the target), so a failure never leaves a half-written file. Every reader raises
:class:`nidar_mi.errors.NidarError` with a one-line message naming the file when the file
is missing or malformed. The points-dict schema is documented in :mod:`nidar_mi.io.points`.
"""

from .atomic import atomic_path, atomic_write_json, atomic_write_text, reading
from .calib import camera_from_dict, camera_to_dict, load_calib, save_calib
from .images import (
    linear_to_srgb,
    read_exr,
    read_png,
    srgb_to_linear,
    write_colormap_png,
    write_exr,
    write_png,
    write_srgb_png,
)
from .kitti import read_kitti_bin, write_kitti_bin
from .las import LAS_SCALE_M, read_las, write_las
from .pcd import read_pcd, write_pcd
from .point_cloud import read_point_cloud
from .points import read_npz, read_ply, write_npz, write_ply

__all__ = [
    "atomic_path",
    "atomic_write_json",
    "atomic_write_text",
    "reading",
    "load_calib",
    "save_calib",
    "camera_from_dict",
    "camera_to_dict",
    "linear_to_srgb",
    "srgb_to_linear",
    "write_png",
    "read_png",
    "write_exr",
    "read_exr",
    "write_colormap_png",
    "write_srgb_png",
    "LAS_SCALE_M",
    "write_las",
    "read_las",
    "read_pcd",
    "write_pcd",
    "write_npz",
    "read_npz",
    "write_ply",
    "read_ply",
    "write_kitti_bin",
    "read_kitti_bin",
    "read_point_cloud",
]
