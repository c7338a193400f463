"""The beams of a recorded scan as world rays: the return of laser ``r`` at point ``p`` (LiDAR
frame) left the laser's own origin (its vertical offset ``v_r``, :mod:`.laser_layout`) towards ``p``.

:func:`return_rays` gives one ray per return (its measured range along it); :func:`miss_rays`
one per beam of the coverage that returned nothing, along the layout's direction at the
column's centre. Both in world coordinates, NumPy; :func:`jit_rays` makes a ``mi.Ray3f``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .laser_layout import RingLayout
from .range_image import ScanGrid, column_azimuth_deg

__all__ = ["Rays", "return_rays", "miss_rays", "concat", "jit_rays"]


class Rays(NamedTuple):
    """World rays: origins (N, 3), unit directions (N, 3), measured range (N,) m (inf for a
    miss), ring (N,), frame (N,)."""

    origin: np.ndarray
    direction: np.ndarray
    range_m: np.ndarray
    ring: np.ndarray
    frame: np.ndarray


def _origins(layout: RingLayout, ring: np.ndarray, phi: np.ndarray) -> np.ndarray:
    """(N, 3) beam origins in the LiDAR frame for rings ``ring`` at azimuth ``phi`` (rad)."""
    th = np.radians(layout.elevation_deg[ring])
    v = layout.vertical_offset_m[ring]
    return v[:, None] * np.column_stack(
        [-np.sin(th) * np.cos(phi), -np.sin(th) * np.sin(phi), np.cos(th)]
    )


def _to_world(o, d, T):
    return o @ T[:3, :3].T + T[:3, 3], d @ T[:3, :3].T


def return_rays(xyz: np.ndarray, grid: ScanGrid, layout: RingLayout, T: np.ndarray, frame: int):
    """One ray per return of a scan.

    Args:
        xyz: (N, 3) returns, LiDAR frame, m; grid: their cells; layout: the sensor's layout;
        T: (4, 4) the frame's LiDAR-to-world pose; frame: the frame's index (stored per ray).
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    o = _origins(layout, grid.ring, np.arctan2(xyz[:, 1], xyz[:, 0]))
    d = xyz - o
    rng = np.linalg.norm(d, axis=1)
    d = d / np.maximum(rng, 1e-9)[:, None]
    ow, dw = _to_world(o, d, T)
    return Rays(ow, dw, rng, grid.ring, np.full(len(xyz), frame))


def miss_rays(grid: ScanGrid, coverage: np.ndarray, layout: RingLayout, T: np.ndarray, frame: int):
    """One ray per beam (ring, column) inside ``coverage`` (columns,) that returned nothing."""
    occ = grid.occupancy()
    ring, col = np.nonzero(~occ & coverage[None, :])
    phi = np.radians(column_azimuth_deg(col, grid.columns))
    th = np.radians(layout.elevation_deg[ring])
    d = np.column_stack([np.cos(th) * np.cos(phi), np.cos(th) * np.sin(phi), np.sin(th)])
    o = _origins(layout, ring, phi)
    ow, dw = _to_world(o, d, T)
    return Rays(ow, dw, np.full(len(ring), np.inf), ring, np.full(len(ring), frame))


def concat(rays: list[Rays]) -> Rays:
    """The rays of several scans, one after the other."""
    return Rays(*(np.concatenate([getattr(r, f) for r in rays]) for f in Rays._fields))


def jit_rays(rays: Rays, start: int = 0, stop: int | None = None):
    """``mi.Ray3f`` of rays ``start..stop``."""
    import mitsuba as mi

    from ..lidar.rays import jit_float

    s = slice(start, stop)
    o = mi.Point3f(*(jit_float(rays.origin[s, i]) for i in range(3)))
    d = mi.Vector3f(*(jit_float(rays.direction[s, i]) for i in range(3)))
    return mi.Ray3f(o, d)
