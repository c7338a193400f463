"""Real datasets: readers in their own layouts, and training data built from them.

* :mod:`~nidar_mi.datasets.kitti_objects`: KITTI object-layout frames (Velodyne scan, camera-2
  image, calibration): :func:`~nidar_mi.datasets.kitti_objects.frame_ids`,
  :func:`~nidar_mi.datasets.kitti_objects.load_kitti_frame` (the files are read by :mod:`nidar_mi.io.kitti`).
* :mod:`~nidar_mi.datasets.kitti_rings`: the laser ring of every point from the storage order
  (checked by elevation), and the road plane.
* :mod:`~nidar_mi.datasets.kitti_frames`: KITTI frames as NIDAR training frames (cached, with a
  held-out frame list).
* :mod:`~nidar_mi.datasets.rgbnir`: pixel-aligned RGB/NIR photo pairs and their held-out split.
* :mod:`~nidar_mi.datasets.paths`: where the data and the derived caches live.
* :mod:`~nidar_mi.datasets.profile_fitting`: the returns a sensor profile is fitted on (a
  sensor's scans, a training split's frames).
* :mod:`~nidar_mi.datasets.sensor_profiles`: the named profiles (``sim-905``, and
  ``kitti-hdl64e`` fitted on the KITTI frames at first use and cached).

The data is read from ``../shared/data`` (or ``$NIDAR_MI_DATA``, or a path given by the user)
and nothing derived from it is kept inside the project.
"""

from .kitti_objects import KittiFrame, frame_ids, load_kitti_frame

__all__ = ["KittiFrame", "frame_ids", "load_kitti_frame"]
