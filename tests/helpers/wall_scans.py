"""A drive of scans from sensors placed without rotation, as the evidence tests of the
re-simulation read it (``tests/resim/test_holes.py``, ``tests/resim/test_seen_through.py``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nidar_mi.resim.laser_layout import RingLayout


def drive_of(scans, origins, elevations_deg, columns: int, coverage_deg: float = 50.0):
    """``(frames, poses)``: the ``(xyz, grid)`` scans of sensors at the (3,) ``origins`` (no
    rotation) as a :class:`nidar_mi.resim.frames.Frames`-like namespace (the columns within
    ``coverage_deg`` of azimuth 0 covered; each ring's elevation, no offsets) and their (4, 4)
    LiDAR-to-world poses."""
    poses = []
    for o in origins:
        T = np.eye(4)
        T[:3, 3] = o
        poses.append(T)
    az = -180.0 + (np.arange(columns) + 0.5) * 360.0 / columns
    rings = len(elevations_deg)
    frames = SimpleNamespace(
        xyz=[s[0] for s in scans],
        grid=[s[1] for s in scans],
        coverage=np.abs(az) < coverage_deg,
        layout=RingLayout(np.asarray(elevations_deg), np.zeros(rings), np.ones(rings)),
    )
    return frames, poses
