"""Camera geometry shared by simulation, learning and evaluation.

* :mod:`~nidar_mi.geometry.camera_model`: :class:`CameraModel` (pinhole intrinsics ``K`` in
  pixels, LiDAR-to-camera extrinsic in metres) and the camera-axis and pixel conventions.
* :mod:`~nidar_mi.geometry.projection`: :func:`project`, :func:`unproject`,
  :func:`in_image`, :func:`bilinear_sample`.
* :mod:`~nidar_mi.geometry.visibility`: :func:`visible_mask` (occlusion against a rendered
  depth image or the cloud's own z-buffer).
* :mod:`~nidar_mi.geometry.camera_returns`: :func:`camera_returns` (the LiDAR returns a
  camera sees: project, :func:`visible_mask`, splat to a sparse pixel map, nearest return
  wins) and :func:`splat_points` (its maps alone).
* :mod:`~nidar_mi.geometry.fusion`: :func:`sample_cameras` (a per-point value from several
  cameras, fused by a rule) and :func:`locate_in_cameras` (its geometric half: which points
  each camera sees, and where, before any image exists): the one camera-sampling path, in
  NumPy on the host, whatever device made the images (docs/ARCHITECTURE.md says why).
* :mod:`~nidar_mi.geometry.normals`: :func:`estimate_normals` (plane fits to each point's
  neighbours) and :func:`incidence_cosine` (the ray's ``|cos θ|`` on the surface).
* :mod:`~nidar_mi.geometry.se3`: SE(3) exponential and logarithm, poses interpolated along a
  trajectory (constant twist between samples), a Mitsuba transform as a NumPy pose.

Pixel centres are at integer ``(u, v) = (column, row)``; lengths and depths are in metres.
"""

from .camera_model import CONVENTIONS, R_OPENCV_FROM_WAYMO, CameraModel
from .camera_returns import CameraReturns, camera_returns, splat_points
from .fusion import FUSION_RULES, Sightings, locate_in_cameras, sample_cameras
from .normals import estimate_normals, incidence_cosine
from .projection import bilinear_sample, in_image, project, unproject
from .visibility import DEFAULT_ABS_TOL, DEFAULT_REL_TOL, DEFAULT_ZBUFFER_CELL, visible_mask

__all__ = [
    "CONVENTIONS",
    "DEFAULT_ABS_TOL",
    "DEFAULT_REL_TOL",
    "DEFAULT_ZBUFFER_CELL",
    "FUSION_RULES",
    "R_OPENCV_FROM_WAYMO",
    "CameraModel",
    "CameraReturns",
    "Sightings",
    "bilinear_sample",
    "camera_returns",
    "estimate_normals",
    "in_image",
    "incidence_cosine",
    "locate_in_cameras",
    "project",
    "sample_cameras",
    "splat_points",
    "unproject",
    "visible_mask",
]
