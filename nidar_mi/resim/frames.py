"""The scans of a drive in memory: returns, intensities, their (ring, column) cells, and the
drive's columns per revolution, layout and coverage.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from .drive_folder import Drive
from .laser_layout import RingLayout, fit_layout
from .range_image import ScanGrid, azimuth_coverage, columns_per_revolution, scan_grid

log = logging.getLogger("nidar_mi.reconstruct")

__all__ = ["Frames", "load_frames", "RINGS"]

#: Lasers of the drives' sensor (KITTI's HDL-64E).
RINGS = 64
#: Returns closer than this are the car itself (m); they are left out.
MIN_RANGE_M = 2.5
#: The fewest returns beyond MIN_RANGE_M a scan may hold (a recorded HDL-64E scan holds
#: 50 000-120 000; one cut to the camera's view about a half).
MIN_RETURNS = 1000


@dataclass
class Frames:
    """Every frame of a drive (training and held out), in the drive's order.

    Attributes:
        xyz: per frame (N, 3) float64 returns, LiDAR frame, m (closer than 2.5 m left out).
        intensity: per frame (N,) float32.
        grid: per frame the cells.
        columns: columns per revolution.
        layout: the layout fitted on the training frames.
        coverage: (columns,) bool, the columns the training frames cover.
    """

    xyz: list[np.ndarray]
    intensity: list[np.ndarray]
    grid: list[ScanGrid]
    columns: int
    layout: RingLayout
    coverage: np.ndarray

    @property
    def cut(self) -> bool:
        """The scans cover less than a whole revolution (clouds cut to a sector)."""
        return bool(self.coverage.mean() < 0.95)


def _read(drive: Drive, frame_id: str):
    """``(xyz, intensity, dropped, clipped)``: the scan's finite points, their intensities
    clipped to KITTI's [0, 1], and how many points were dropped and intensities clipped."""
    from ..io.kitti import read_kitti_bin

    xyz, intensity = read_kitti_bin(drive.scan_path(frame_id))
    xyz = np.asarray(xyz, dtype=np.float64)
    keep = np.isfinite(xyz).all(axis=1) & np.isfinite(intensity)
    out = (intensity[keep] < 0.0) | (intensity[keep] > 1.0)
    return (
        xyz[keep],
        np.clip(intensity[keep], 0.0, 1.0),
        int(np.sum(~keep)),
        int(np.sum(out)),
    )


def load_frames(drive: Drive, *, progress: bool = False) -> Frames:
    """Read every scan, find its cells and fit the layout on the training frames.

    A scan whose storage order is lost gets its rings from the fitted layout's elevations.
    """
    from ..errors import NidarError
    from ..progress import progress_bar
    from .range_image import recovered_rings

    raw = []
    for i in progress_bar(drive.ids, show=progress, desc="read"):
        xyz, intensity, dropped, clipped = _read(drive, i)
        returns = int(np.sum(np.linalg.norm(xyz, axis=1) >= MIN_RANGE_M))
        if returns < MIN_RETURNS:
            raise NidarError(
                f"{drive.scan_path(i)}: {returns} returns beyond {MIN_RANGE_M:g} m; a scan needs "
                f"at least {MIN_RETURNS}"
            )
        if dropped or clipped:
            log.warning(
                "%s: %d non-finite points dropped, %d intensities outside [0, 1] clipped",
                drive.scan_path(i), dropped, clipped,
            )  # fmt: skip
        raw.append((xyz, intensity))
    train = [drive.index(i) for i in drive.train]
    rings = [recovered_rings(raw[k][0]) for k in range(len(raw))]
    ordered = [k for k in train if rings[k] is not None and len(raw[k][0])]
    if not ordered:
        raise NidarError(
            f"{drive.root}: no training scan keeps the sensor's storage order (rings unknown)"
        )
    columns = columns_per_revolution(raw[ordered[0]][0], rings[ordered[0]])
    try:
        layout = fit_layout([raw[k][0] for k in ordered], [rings[k] for k in ordered], RINGS)
    except ValueError as e:  # too few returns per ring
        raise NidarError(f"{drive.root}: {e}") from None
    xyz, intensity, grids = [], [], []
    for p, i in raw:
        near = np.linalg.norm(p, axis=1) >= MIN_RANGE_M
        g = scan_grid(p, columns, layout.elevation_deg)
        xyz.append(p[near])
        intensity.append(i[near])
        grids.append(ScanGrid(g.ring[near], g.column[near], g.rings, g.columns, g.ordered))
    coverage = azimuth_coverage([grids[k] for k in train], columns)
    return Frames(xyz, intensity, grids, columns, layout, coverage)
