"""Readers of real datasets, each in its own layout.

* :mod:`~nidar_mi.datasets.kitti`: KITTI object-layout frames (Velodyne scan, camera-2
  image, calibration): :func:`~nidar_mi.datasets.kitti.frame_ids`,
  :func:`~nidar_mi.datasets.kitti.load_frame`,
  :func:`~nidar_mi.datasets.kitti.load_kitti_calib`.
"""

from .kitti import KITTI_IMAGE_SIZE, KittiFrame, frame_ids, load_frame, load_kitti_calib

__all__ = ["KITTI_IMAGE_SIZE", "KittiFrame", "frame_ids", "load_frame", "load_kitti_calib"]
