"""Each return of a recorded scan on the sensor's (ring, column) grid, and the beams that
returned nothing.

Rings come from the storage order (:func:`nidar_mi.datasets.kitti_rings.checked_rings`; where
its strict test fails, the storage order is still taken when it gives at most 64 rings whose far
elevations fall with the ring index at a rank correlation below -0.95: two lasers of different
blocks whose beams lie within a few hundredths of a degree may swap there), or, for a cloud
whose order is lost, from the nearest ring elevation of the drive's layout. Columns
come from the azimuth: ``column = floor((azimuth + 180°) / step)`` with ``step = 360° / C``, C
the sensor's columns per revolution (:func:`columns_per_revolution`, from the azimuth step
between neighbouring returns of a ring). The scan's coverage (:func:`azimuth_coverage`) is the
set of columns where any ring returned: a cloud cut to the front half covers half of them. A beam
(ring, column) inside the coverage with no return is a miss.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..datasets.kitti_rings import azimuth_deg, checked_rings, elevation_rings, scan_rings

__all__ = [
    "ScanGrid",
    "recovered_rings",
    "columns_per_revolution",
    "scan_grid",
    "azimuth_coverage",
    "column_azimuth_deg",
]


@dataclass(frozen=True)
class ScanGrid:
    """One scan on the (ring, column) grid.

    Attributes:
        ring: (N,) int, 0 = the highest laser.
        column: (N,) int in [0, columns).
        rings: rings of the sensor.
        columns: columns per revolution.
        ordered: the rings come from the storage order (else from elevations).
    """

    ring: np.ndarray
    column: np.ndarray
    rings: int
    columns: int
    ordered: bool

    def occupancy(self) -> np.ndarray:
        """(rings, columns) bool: the beams that returned."""
        occ = np.zeros((self.rings, self.columns), dtype=bool)
        occ[self.ring, self.column] = True
        return occ


def columns_per_revolution(xyz: np.ndarray, ring: np.ndarray) -> int:
    """Columns per revolution from the median azimuth step between consecutive returns of a
    ring (storage order), rounded to a multiple of 2; 2048 when it cannot be told."""
    az = azimuth_deg(np.asarray(xyz, dtype=np.float64))
    step = np.abs(np.diff(az))[(np.diff(ring) == 0)]
    step = step[(step > 0.01) & (step < 2.0)]
    if len(step) < 100:
        return 2048
    return int(2 * round(180.0 / float(np.median(step))))


def column_azimuth_deg(column, columns: int):
    """Azimuth (degrees, counter-clockwise from +x) of a column's centre."""
    return -180.0 + (np.asarray(column) + 0.5) * 360.0 / columns


def recovered_rings(xyz: np.ndarray, max_rings: int = 64) -> np.ndarray | None:
    """(N,) rings from the storage order, or None when it does not look like a scan (module
    docstring)."""
    from scipy.stats import spearmanr

    ring = checked_rings(xyz, max_rings)
    if ring is not None or len(xyz) < 100:
        return ring
    ring = scan_rings(xyz)
    n = int(ring.max()) + 1
    if n > max_rings or n < 8:
        return None
    far = np.linalg.norm(xyz, axis=1) > 10.0
    el = np.degrees(np.arctan2(xyz[:, 2], np.hypot(xyz[:, 0], xyz[:, 1])))
    rows = [r for r in range(n) if np.count_nonzero(far & (ring == r)) >= 5]
    if len(rows) < 8:
        return None
    med = [float(np.median(el[far & (ring == r)])) for r in rows]
    return ring if spearmanr(rows, med).statistic < -0.95 else None


def scan_grid(xyz: np.ndarray, columns: int, elevations_deg: np.ndarray | None = None) -> ScanGrid:
    """The (ring, column) of every return.

    Args:
        xyz: (N, 3) points in storage order, LiDAR frame, m.
        columns: columns per revolution.
        elevations_deg: (R,) ring elevations (ring 0 highest), used when the storage order is
            lost; None: 64 rings from the storage order or nothing.

    Raises:
        ValueError: the order is lost and no elevation table is given.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    ring = recovered_rings(xyz)
    ordered = ring is not None
    if ring is None:
        if elevations_deg is None:
            raise ValueError("the scan's storage order is lost and no elevation table is given")
        ring = elevation_rings(xyz, elevations_deg)
    rings = int(len(elevations_deg)) if elevations_deg is not None else 64
    rings = max(rings, int(ring.max()) + 1 if len(ring) else 1)
    col = np.floor((azimuth_deg(xyz) + 180.0) * columns / 360.0).astype(np.int64) % columns
    return ScanGrid(ring.astype(np.int64), col, rings, columns, ordered)


def azimuth_coverage(grids: list[ScanGrid], columns: int, min_share: float = 0.02) -> np.ndarray:
    """(columns,) bool: the columns a drive's scans cover (a cut cloud covers part of them).

    A column is covered when, over the scans, at least ``min_share`` of the rings returned in it
    or in a neighbouring column (a column of the sky alone returns nothing from the upper rings,
    but the lower rings see the road everywhere the sensor looks).
    """
    hits = np.zeros(columns)
    for g in grids:
        hits += np.bincount(g.column, minlength=columns)[:columns] / max(g.rings, 1)
    hits /= max(len(grids), 1)
    near = np.maximum.reduce([np.roll(hits, s) for s in (-2, -1, 0, 1, 2)])
    return near >= min_share
