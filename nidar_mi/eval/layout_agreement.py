"""How well a LiDAR layout matches the elevations of real returns (KITTI's HDL-64E S2).

For every return of a real frame: its elevation ``atan2(z, √(x² + y²))`` against the elevation at
which the simulator's beam of the same laser would place a point at the same range (the beam
starts at its own origin: a laser whose line runs ``v`` above the sensor's axis looks
``atan(v / D)`` higher at range ``D``). Two figures:

* **ring-matched**: the return's own laser. KITTI stores a cloud laser by laser, highest first,
  each ring sweeping from azimuth 0 counter-clockwise;
  :func:`~nidar_mi.datasets.kitti_rings.scan_rings` recovers the ring of every return from that
  order, and ring ``r`` is the layout's ``r``-th highest laser.
* **nearest ring**: the laser closest in elevation, whatever the return's own laser. Any table of
  64 rings spanning the field of view scores about 0.1° here (every elevation lies within half a
  ring spacing of some ring), so this figure says little about a table's correctness.

Frames whose storage order does not give exactly the layout's ring count (a truncated cloud)
are skipped and listed.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field

import numpy as np

from ..datasets.kitti_rings import scan_rings

__all__ = ["predicted_elevation", "Agreement", "elevation_agreement"]


def predicted_elevation(pattern, ring: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Elevation (degrees) at which the simulator's beam of laser ``ring`` meets range |xyz|.

    Args:
        pattern: a :class:`~nidar_mi.lidar.pattern.BeamPattern`.
        ring: (N,) ring index per point.
        xyz: (N, 3) points, m (their azimuth picks the column, their range the distance).
    """
    table = pattern.table
    az = np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))
    col_az = az - table.array("azimuth_offset_deg")[ring]
    d, o = pattern.rays_at(ring, col_az)
    D = np.linalg.norm(xyz, axis=1)
    if o is None:
        p = d * D[:, None]
    else:  # |o + s d| = D
        od = np.sum(o * d, axis=1)
        s = -od + np.sqrt(np.maximum(od * od - np.sum(o * o, axis=1) + D * D, 0.0))
        p = o + s[:, None] * d
    return np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))


@dataclass
class Agreement:
    """Median and 90th percentile of |Δelevation| (degrees) over all returns of the frames.

    Attributes:
        frames: frames used.
        returns: returns compared.
        ring_matched_median, ring_matched_p90: against the return's own laser.
        nearest_median, nearest_p90: against the nearest laser.
        skipped: frames left out (storage order did not give the ring count).
    """

    frames: list[str]
    returns: int
    ring_matched_median: float
    ring_matched_p90: float
    nearest_median: float
    nearest_p90: float
    skipped: list[str] = field(default_factory=list)


def _nearest(pattern, xyz, el, chunk: int = 100_000) -> np.ndarray:
    rings = pattern.rings
    out = np.empty(len(el))
    for s in range(0, len(el), chunk):
        part = xyz[s : s + chunk]
        best = np.full(len(part), np.inf)
        for r in range(rings):
            pred = predicted_elevation(pattern, np.full(len(part), r), part)
            best = np.minimum(best, np.abs(el[s : s + chunk] - pred))
        out[s : s + chunk] = best
    return out


def elevation_agreement(pattern, velodyne_dir: str | os.PathLike) -> Agreement:
    """Agreement of ``pattern`` with every ``*.bin`` cloud in a KITTI ``velodyne`` folder.

    Raises:
        NidarError: no readable frame with the pattern's ring count.
    """
    from ..errors import NidarError
    from ..io.kitti import read_kitti_bin

    names = sorted(f for f in os.listdir(velodyne_dir) if f.endswith(".bin"))
    matched, nearest, used, skipped = [], [], [], []
    for name in names:
        xyz, _ = read_kitti_bin(os.path.join(velodyne_dir, name))
        xyz = xyz.astype(np.float64)
        ring = scan_rings(xyz)
        if ring.max() + 1 != pattern.rings:
            skipped.append(name)
            continue
        el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
        matched.append(np.abs(el - predicted_elevation(pattern, ring, xyz)))
        nearest.append(_nearest(pattern, xyz, el))
        used.append(name)
    if not used:
        raise NidarError(f"{velodyne_dir}: no frame with {pattern.rings} rings in storage order")
    m, n = np.concatenate(matched), np.concatenate(nearest)
    return Agreement(
        frames=used,
        returns=int(m.size),
        ring_matched_median=float(np.median(m)),
        ring_matched_p90=float(np.percentile(m, 90)),
        nearest_median=float(np.median(n)),
        nearest_p90=float(np.percentile(n, 90)),
        skipped=skipped,
    )
