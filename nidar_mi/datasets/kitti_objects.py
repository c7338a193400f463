"""KITTI frames in the object-detection layout: frame ids and whole frames.

**Layout.** A KITTI folder holds, per frame id ``ID`` (e.g. ``000003``):
``velodyne/ID.bin`` (float32 x, y, z in metres in the Velodyne frame, reflectance in
[0, 1]), ``image_2/ID.png`` (the left colour camera, 8-bit sRGB) and ``calib/ID.txt``.
KITTI raw frames converted to this layout (the calibration composed from
``calib_cam_to_cam`` and ``calib_velo_to_cam``) read the same way.

The files are read by :mod:`nidar_mi.io.kitti` (the scan by
:func:`~nidar_mi.io.kitti.read_kitti_bin`, camera 2 by
:func:`~nidar_mi.io.kitti.load_kitti_calib`, which documents the calibration's conventions).

Rings (lasers) come from the storage order: :mod:`nidar_mi.datasets.kitti_rings`.

**Short scans.** A scan may end early: it then has fewer than 64 rings, all of them the top
ones. A file that ends inside a point (a truncated download) is refused.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from nidar_mi.errors import NidarError
from nidar_mi.geometry.camera_model import CameraModel
from nidar_mi.io.images import read_rgb8
from nidar_mi.io.kitti import load_kitti_calib, read_kitti_bin

__all__ = ["CENTRE_TOLERANCE", "KittiFrame", "frame_ids", "load_kitti_frame"]

#: How far from the image centre camera 2's principal point may lie, as a fraction of the
#: image's width and height (KITTI's lie within 4 %; a half-size image puts it at ~48 %).
CENTRE_TOLERANCE = 0.2


def _frame_paths(kitti_dir: str | os.PathLike[str], frame_id: str) -> dict[str, str]:
    return {
        "velodyne": os.path.join(kitti_dir, "velodyne", f"{frame_id}.bin"),
        "image": os.path.join(kitti_dir, "image_2", f"{frame_id}.png"),
        "calib": os.path.join(kitti_dir, "calib", f"{frame_id}.txt"),
    }


def frame_ids(kitti_dir: str | os.PathLike[str]) -> list[str]:
    """Frame ids with a Velodyne scan, a camera-2 image and a calibration file, sorted.

    Returns:
        The ids (file stems, e.g. ``"000003"``); empty when ``kitti_dir/velodyne`` is absent.
    """
    vel = os.path.join(kitti_dir, "velodyne")
    if not os.path.isdir(vel):
        return []
    ids = []
    for name in sorted(os.listdir(vel)):
        stem, ext = os.path.splitext(name)
        if ext != ".bin":
            continue
        paths = _frame_paths(kitti_dir, stem)
        if os.path.isfile(paths["image"]) and os.path.isfile(paths["calib"]):
            ids.append(stem)
    return ids


@dataclass(frozen=True, eq=False)
class KittiFrame:
    """One KITTI frame: the Velodyne scan, the camera-2 image and its camera model.

    Attributes:
        xyz: (N, 3) float32 points in the Velodyne frame, metres.
        intensity: (N,) float32 Velodyne reflectance in [0, 1], as stored.
        rgb: (H, W, 3) uint8 sRGB camera-2 image.
        camera: camera 2 (``P2``) at the image's size, ``T_cam_lidar`` from the Velodyne.
        frame_id: the frame id, e.g. ``"000003"``.
    """

    xyz: np.ndarray
    intensity: np.ndarray
    rgb: np.ndarray
    camera: CameraModel
    frame_id: str


def load_kitti_frame(kitti_dir: str | os.PathLike[str], frame_id: str) -> KittiFrame:
    """Read ``velodyne/ID.bin``, ``image_2/ID.png`` and ``calib/ID.txt`` (camera P2).

    Args:
        kitti_dir: folder with ``velodyne/``, ``image_2/`` and ``calib/``.
        frame_id: the frame id, e.g. ``"000003"``.

    Returns:
        The frame; the camera takes its width and height from the image.

    Raises:
        NidarError: a missing or malformed file (one-line message naming it).
    """
    paths = _frame_paths(kitti_dir, frame_id)
    for what, p in paths.items():
        if not os.path.isfile(p):
            raise NidarError(f"KITTI frame {frame_id}: missing {what} file {p}")
    xyz, intensity = read_kitti_bin(paths["velodyne"])
    rgb = read_rgb8(paths["image"])
    cam = load_kitti_calib(paths["calib"], "P2", width=rgb.shape[1], height=rgb.shape[0])
    cx, cy = float(cam.K[0, 2]), float(cam.K[1, 2])
    h, w = rgb.shape[:2]
    if abs(cx - w / 2) > CENTRE_TOLERANCE * w or abs(cy - h / 2) > CENTRE_TOLERANCE * h:
        raise NidarError(
            f"KITTI frame {frame_id}: {paths['image']} is {w}x{h} but calib P2's principal "
            f"point ({cx:.0f}, {cy:.0f}) is far from its centre: the image does not match the "
            "calibration (resized or cropped?)"
        )
    return KittiFrame(xyz=xyz, intensity=intensity, rgb=rgb, camera=cam, frame_id=frame_id)
