"""The sensor's per-laser layout, recovered from its own returns.

A Velodyne driver places a return of laser ``r`` at range ``d`` on the beam line
``z = d·sinθ_r + v_r·cosθ_r``, ``ρ = d·cosθ_r - v_r·sinθ_r`` (ρ the horizontal distance; θ the
laser's elevation, v its ``vert_offset_correction``; :mod:`nidar_mi.lidar.layouts`), i.e. on
the straight line ``z = v_r / cosθ_r + ρ·tanθ_r`` in the (ρ, z) plane. :func:`fit_layout` fits
that line to every return of each ring of the training scans by iteratively reweighted least
squares (Huber weights at twice the robust residual scale): on ``kitti_raw_0926`` the returns
lie within 1.4 mm (robust scale) of their ring's line. A ring whose returns span less than a
factor 2 in distance (it sees only the road), or whose offset comes out beyond
:data:`MAX_OFFSET_M`, takes the offset interpolated from its neighbours and its elevation
refitted with that offset. The
azimuth corrections are already in the returns' azimuths, which define the columns, so they are
0 here; the horizontal offsets (~2.6 cm on an HDL-64E) are left at 0.

:func:`write_velodyne_yaml` writes the layout as the ROS velodyne driver's calibration YAML, which
the ``lidar`` plugin reads as its ``calibration_file``.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

__all__ = ["RingLayout", "fit_layout", "write_velodyne_yaml"]

#: Returns closer than this (horizontal distance, m) are left out of the fit.
MIN_RHO_M = 2.0
#: The largest vertical offset believed, m (an HDL-64E's are ~0.1-0.2 m).
MAX_OFFSET_M = 0.5


@dataclass(frozen=True)
class RingLayout:
    """Per ring (ring 0 highest): elevation θ (degrees), vertical offset v (m), returns used.

    Rings without returns take the elevation interpolated between their neighbours."""

    elevation_deg: np.ndarray
    vertical_offset_m: np.ndarray
    count: np.ndarray

    @property
    def rings(self) -> int:
        return len(self.elevation_deg)


def _line(rho: np.ndarray, z: np.ndarray, iterations: int = 10) -> tuple[float, float]:
    """Robust fit of ``z = a + b·rho`` (Huber weights); returns ``(a, b)``."""
    A = np.column_stack([np.ones_like(rho), rho])
    w = np.ones_like(z)
    coef = np.zeros(2)
    for _ in range(iterations):
        coef = np.linalg.lstsq(A * w[:, None], z * w, rcond=None)[0]
        res = z - A @ coef
        scale = 1.4826 * float(np.median(np.abs(res))) + 1e-4
        w = 1.0 / np.sqrt(np.maximum(1.0, np.abs(res) / (2.0 * scale)))
    return float(coef[0]), float(coef[1])


def fit_layout(points: list[np.ndarray], rings: list[np.ndarray], n_rings: int) -> RingLayout:
    """The per-ring elevation and vertical offset of the training scans.

    Args:
        points: per scan (N, 3) returns in the LiDAR frame, m.
        rings: per scan (N,) ring of each return.
        n_rings: rings of the sensor.

    Returns:
        The layout; elevations strictly decreasing (a ring whose fit would break the order, or
        that has fewer than 50 returns, is interpolated from its neighbours).
    """
    xyz = np.concatenate([np.asarray(p, dtype=np.float64) for p in points])
    ring = np.concatenate([np.asarray(r) for r in rings])
    rho = np.hypot(xyz[:, 0], xyz[:, 1])
    keep = rho > MIN_RHO_M
    xyz, ring, rho = xyz[keep], ring[keep], rho[keep]
    el = np.full(n_rings, np.nan)
    v = np.zeros(n_rings)
    count = np.bincount(ring, minlength=n_rings)[:n_rings]
    order = np.argsort(ring, kind="stable")
    bounds = np.searchsorted(ring[order], np.arange(n_rings + 1))
    offset_known = np.zeros(n_rings, bool)
    for r in range(n_rings):
        idx = order[bounds[r] : bounds[r + 1]]
        if len(idx) < 50:
            continue
        a, b = _line(rho[idx], xyz[idx, 2])
        theta = np.arctan(b)
        el[r], v[r] = np.degrees(theta), a * np.cos(theta)
        lo, hi = np.percentile(rho[idx], [5, 95])
        offset_known[r] = abs(v[r]) <= MAX_OFFSET_M and hi >= 2.0 * lo
    _refit_elevations(el, v, offset_known, rho, xyz[:, 2], order, bounds)
    known = np.isfinite(el)
    if known.sum() >= 2:  # a ring out of order is refitted from its neighbours
        bad = known.copy()
        bad[known] = np.concatenate([[False], np.diff(el[known]) >= 0])
        known &= ~bad
    if known.sum() < 2:
        raise ValueError("too few returns to recover the sensor's layout")
    idx = np.arange(n_rings)
    el = np.interp(idx, idx[known], el[known]) if not known.all() else el
    v = np.where(known, v, np.interp(idx, idx[known], v[known]))
    return RingLayout(el, v, count)


def _refit_elevations(el, v, offset_known, rho, z, order, bounds) -> None:
    """Rings whose returns span too narrow a range of distances (a ring that sees only the
    road) fix no offset: theirs is interpolated from the rings that do, and their elevation is
    refitted with it (in place)."""
    idx = np.arange(len(el))
    if offset_known.sum() < 2:
        v[:] = 0.0
        offset_known = np.ones(len(el), bool)
    v[~offset_known] = np.interp(idx[~offset_known], idx[offset_known], v[offset_known])
    for r in np.flatnonzero(~offset_known & np.isfinite(el)):
        sel = order[bounds[r] : bounds[r + 1]]
        el[r] = np.degrees(np.median(np.arctan2(z[sel] - v[r], rho[sel])))


def write_velodyne_yaml(path: str | os.PathLike, layout: RingLayout, laser_ids) -> None:
    """Write the layout as a ROS velodyne calibration YAML (radians, m).

    Args:
        path: the ``.yaml`` file.
        layout: per ring elevation and vertical offset.
        laser_ids: (R,) the laser id of each ring (the sensor's own numbering).
    """
    from ..io.atomic import atomic_write_text

    lines = [f"num_lasers: {layout.rings}", "distance_resolution: 0.002", "lasers:"]
    for r in range(layout.rings):
        lines.append(
            f"- {{laser_id: {int(laser_ids[r])}, "
            f"vert_correction: {np.radians(layout.elevation_deg[r]):.9f}, "
            "rot_correction: 0.0, "
            f"vert_offset_correction: {layout.vertical_offset_m[r]:.6f}, "
            "horiz_offset_correction: 0.0, dist_correction: 0.0}"
        )
    atomic_write_text(path, "\n".join(lines) + "\n")
