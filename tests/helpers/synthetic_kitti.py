"""Synthetic KITTI folders for tests: HDL-64E scans in KITTI's stored order, images, calib."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nidar_mi.io.images import write_png
from nidar_mi.io.kitti import write_kitti_bin
from nidar_mi.lidar.pattern import elevation_table

#: A KITTI calibration file (P2 looks ahead along the Velodyne's x axis; 1242 x 375 images).
CALIB = """P0: 7.0e+02 0 6.0e+02 0 0 7.0e+02 1.8e+02 0 0 0 1 0
P1: 7.0e+02 0 6.0e+02 -3.8e+02 0 7.0e+02 1.8e+02 0 0 0 1 0
P2: 7.0e+02 0 6.0e+02 4.5e+01 0 7.0e+02 1.8e+02 -3.0e-01 0 0 1 5.0e-03
P3: 7.0e+02 0 6.0e+02 -3.3e+02 0 7.0e+02 1.8e+02 2.3e+00 0 0 1 3.0e-03
R0_rect: 0.9999 0.0101 -0.0085 -0.0101 0.9999 -0.0040 0.0085 0.0041 0.9999
Tr_velo_to_cam: 0.0069 -0.9999 -0.0028 -0.0246 -0.0012 0.0027 -0.9999 -0.0613 0.9999 0.0069 -0.0011 -0.3321
"""


def kitti_order_scan(cols=720, front_only=False, rings=64, offset_m=0.05, seed=0):
    """An HDL-64E scan stored as KITTI stores it: laser after laser (top first), each sweep
    from azimuth 0 counter-clockwise; lasers mounted up to ``offset_m`` above/below the origin;
    a cylinder wall of radius 25 m and the ground 1.73 m below. Returns (xyz, ring, range)."""
    el = np.radians(elevation_table("hdl64e"))[:rings]
    z0 = np.random.default_rng(seed).uniform(-offset_m, offset_m, rings)
    az = np.radians((np.arange(cols) + 0.5) * 360.0 / cols)
    az = np.where(az > np.pi, az - 2 * np.pi, az)
    pts, ring = [], []
    for r in range(rings):
        d = np.stack(
            [np.cos(el[r]) * np.cos(az), np.cos(el[r]) * np.sin(az), np.full(cols, np.sin(el[r]))],
            1,
        )
        t = np.full(cols, 25.0)
        down = d[:, 2] < 0
        t[down] = np.minimum(t[down], (-1.73 - z0[r]) / d[down, 2])
        p = np.array([0.0, 0.0, z0[r]]) + d * t[:, None]
        keep = p[:, 0] > 0 if front_only else np.ones(cols, bool)
        pts.append(p[keep])
        ring.append(np.full(keep.sum(), r))
    xyz = np.concatenate(pts).astype(np.float32)
    return xyz, np.concatenate(ring), np.linalg.norm(xyz, axis=1)


def make_kitti(root: Path, frames: int = 3, cols: int = 360, seed: int = 0) -> Path:
    """A KITTI folder: ``frames`` scans of the synthetic street, an image each (a gradient plus
    noise) and the calibration. The reflectance is the image's green channel at the point's
    column (so that an image-based model has something to find), plus noise."""
    root = Path(root)
    for sub in ("velodyne", "image_2", "calib"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    xyz, _, _ = kitti_order_scan(cols=cols, front_only=True)
    rng = np.random.default_rng(seed)
    for k in range(frames):
        img = np.zeros((375, 1242, 3), np.uint8)
        img[..., 0] = np.linspace(30, 220, 1242, dtype=np.uint8)[None, :]
        img[..., 1] = rng.integers(0, 256, (1, 1242), dtype=np.uint8)
        img[..., 2] = 90 + 40 * k
        write_png(root / "image_2" / f"{k:06d}.png", img)
        col = np.clip((600 - 700 * xyz[:, 1] / np.maximum(xyz[:, 0], 0.1)).astype(int), 0, 1241)
        inten = np.clip(img[0, col, 1] / 255.0 + rng.normal(0, 0.05, len(xyz)), 0, 1)
        write_kitti_bin(root / "velodyne" / f"{k:06d}.bin", xyz, inten.astype(np.float32))
        (root / "calib" / f"{k:06d}.txt").write_text(CALIB)
    return root
