"""The laser ring of every point of a raw KITTI HDL-64E cloud, and its ground plane.

**Rings.** KITTI stores a Velodyne cloud laser by laser, the lasers sorted by elevation (ring 0
highest), each sweep starting near azimuth 0 and turning counter-clockwise: azimuth rises to
+180° (+90° in clouds cut to x > 0), wraps to -180° (-90°) and comes back towards 0, where the
next ring begins. :func:`scan_rings` finds the wraps (a fall of more than 100°, one per ring)
and, between two wraps, the split that leaves the fewest points on the wrong side of 0 (points near 0 jitter in
azimuth because of the per-laser corrections).

A scan cut short (a truncated file) ends inside a ring: after its last wrap the azimuth comes
back to 0 and the next ring starts; that start gets a ring of its own. :func:`checked_rings`
accepts the result only when it looks like a scan: at most 64 rings, and the median elevation of
each ring's far returns (> 10 m, where the lasers' mounting offsets no longer matter) decreasing
from ring to ring. On the 84 shared KITTI scans this recovers 64 rings (39 in the truncated raw
frame 000077) with strictly decreasing elevations. Where the order is lost (a filtered or
re-sorted cloud) :func:`elevation_rings` assigns each point the ring of the nearest beam elevation
in a table instead. That is approximate: measured against the storage order on the shared scans,
the nearest of the per-ring median elevations gives the right ring for 29 % of the returns closer
than 5 m, 63 % at 5-10 m and 80 % at 10-20 m (the lasers sit up to ~0.2 m apart, which moves a
near return by several rings' elevation).

**Ground.** :func:`ground_plane` fits the road plane by RANSAC to the low points near the car
(3-15 m horizontally, z < -1 m, normal within 14° of vertical), then refines it by least squares.
Far away a real road leaves that plane (a 0.4° slope lifts it 0.35 m at 50 m), so
:func:`grow_ground` grows the ground outward ring by ring along each azimuth: a point is ground
when it is within 0.2 m of the plane, or when the point of the next lower ring at its azimuth is
ground and the step between them is further out and at most 6° steep (a car or a kerb face is
steeper). :func:`pose_over_plane` gives the sensor's pose over its road plane (height and tilt),
from which a simulated sweep can be cast over a flat road as the real one was.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "HDL64E_RINGS",
    "azimuth_deg",
    "checked_rings",
    "elevation_rings",
    "ground_plane",
    "grow_ground",
    "nearest_in_ring",
    "pose_over_plane",
    "scan_rings",
]

#: Lasers of KITTI's Velodyne HDL-64E.
HDL64E_RINGS = 64
#: Returns farther than this (m) date a ring's elevation in :func:`checked_rings`.
_FAR_M = 10.0


def azimuth_deg(xyz: np.ndarray) -> np.ndarray:
    """(N,) azimuth in degrees, counter-clockwise from +x, in (-180, 180]."""
    return np.degrees(np.arctan2(xyz[:, 1], xyz[:, 0]))


def scan_rings(xyz: np.ndarray) -> np.ndarray:
    """(N,) int ring of each point from the storage order (0 = first stored = highest laser).

    Args:
        xyz: (N, 3) points in storage order.

    Returns:
        Ring indices 0..R-1, R = the number of azimuth wraps (each ring wraps once; 64 for an
        HDL-64E sweep).
    """
    az = azimuth_deg(np.asarray(xyz, dtype=np.float64))
    wraps = np.flatnonzero(np.diff(az) < -100.0) + 1
    ring = np.empty(len(az), dtype=np.int64)
    bounds = np.concatenate([[0], wraps, [len(az)]])
    ring[: bounds[1]] = 0
    for k in range(1, len(bounds) - 1):
        a, e = bounds[k], bounds[k + 1]
        if k == len(bounds) - 2:  # after the last wrap: the end of the last ring, then (in a
            # scan cut short) the start of one more: a run of >= 10 points back at azimuth >= 0
            seg = az[a:e]
            starts = np.flatnonzero((seg[:-1] < 0.0) & (seg[1:] >= 0.0)) + 1
            j = e - a
            if len(starts) and e - a - starts[-1] >= 10 and (seg[starts[-1] :] >= 0).mean() > 0.9:
                j = int(starts[-1])
            ring[a : a + j] = k - 1
            ring[a + j : e] = k
            continue
        positive = az[a:e] >= 0.0
        # points left on the wrong side when splitting before index j (0..e-a)
        wrong = np.concatenate([[0], np.cumsum(positive)]) + (
            (~positive).sum() - np.concatenate([[0], np.cumsum(~positive)])
        )
        j = int(np.argmin(wrong))
        ring[a : a + j] = k - 1  # the end of the ring that wrapped
        ring[a + j : e] = k
    return ring


def _elevation_deg(xyz: np.ndarray) -> np.ndarray:
    x, y, z = (np.asarray(xyz[:, k], dtype=np.float64) for k in range(3))
    return np.degrees(np.arctan2(z, np.hypot(x, y)))


def checked_rings(xyz: np.ndarray, max_rings: int = HDL64E_RINGS) -> np.ndarray | None:
    """:func:`scan_rings` when the storage order looks like a scan (module docstring), else None.

    Args:
        xyz: (N, 3) points in storage order, sensor frame, m.
        max_rings: most rings the sensor has.

    Returns:
        (N,) int16 rings, 0 = the highest laser; None when there are more than ``max_rings``
        rings or the rings' far elevations do not decrease.
    """
    xyz = np.asarray(xyz)
    if len(xyz) == 0:
        return np.zeros(0, dtype=np.int16)
    ring = scan_rings(xyz)
    n = int(ring.max()) + 1
    if n > max_rings:
        return None
    far = np.linalg.norm(xyz, axis=1) > _FAR_M
    el = _elevation_deg(xyz)
    med = [
        np.median(el[far & (ring == r)]) for r in range(n) if np.count_nonzero(far & (ring == r))
    ]
    if len(med) >= 2 and np.any(np.diff(med) >= 0.0):
        return None
    return ring.astype(np.int16)


def elevation_rings(xyz: np.ndarray, elevations_deg: np.ndarray) -> np.ndarray:
    """Ring of each point as the beam whose elevation is nearest (approximate, see the module).

    Args:
        xyz: (N, 3) points, sensor frame, m.
        elevations_deg: (R,) beam elevations in degrees, ring 0 first.

    Returns:
        (N,) int16 ring indices into ``elevations_deg``.

    Raises:
        ValueError: an empty or non-finite table.
    """
    table = np.asarray(elevations_deg, dtype=np.float64).reshape(-1)
    if table.size == 0 or not np.all(np.isfinite(table)):
        raise ValueError("elevation_rings: the elevation table must be finite and non-empty")
    el = _elevation_deg(np.asarray(xyz))
    order = np.argsort(table)
    sorted_t = table[order]
    if len(sorted_t) == 1:
        return np.zeros(len(el), dtype=np.int16)
    pos = np.clip(np.searchsorted(sorted_t, el), 1, len(sorted_t) - 1)
    left, right = sorted_t[pos - 1], sorted_t[pos]
    nearest = np.where(np.abs(el - left) <= np.abs(el - right), pos - 1, pos)
    return order[nearest].astype(np.int16)


def ground_plane(
    xyz: np.ndarray, rng: np.random.Generator, iterations: int = 400
) -> tuple[np.ndarray, float]:
    """The road plane ``n · x + c = 0`` (``n`` unit, pointing up; ``c`` = sensor height).

    Args:
        xyz: (N, 3) points in the sensor frame (z up).
        rng: the only randomness (RANSAC samples).
        iterations: RANSAC draws.

    Raises:
        ValueError: too few candidate points near the car.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    rho = np.hypot(xyz[:, 0], xyz[:, 1])
    cand = xyz[(rho > 3.0) & (rho < 15.0) & (xyz[:, 2] < -1.0)]
    if len(cand) < 100:
        raise ValueError(f"only {len(cand)} low points 3-15 m from the sensor")
    best_n, best_c, best_k = np.array([0.0, 0.0, 1.0]), float(-np.median(cand[:, 2])), -1
    cos_max = np.cos(np.radians(14.0))
    for _ in range(iterations):
        s = cand[rng.choice(len(cand), 3, replace=False)]
        n = np.cross(s[1] - s[0], s[2] - s[0])
        norm = np.linalg.norm(n)
        if norm < 1e-9:
            continue
        n = n / norm * np.sign(n[2] or 1.0)
        if n[2] < cos_max:
            continue
        c = -float(n @ s[0])
        k = int(np.sum(np.abs(cand @ n + c) < 0.08))
        if k > best_k:
            best_n, best_c, best_k = n, c, k
    n, c = best_n, best_c
    for tol in (0.10, 0.06):
        inliers = cand[np.abs(cand @ n + c) < tol]
        centre = inliers.mean(axis=0)
        n = np.linalg.svd(inliers - centre, full_matrices=False)[2][2]
        n = n * np.sign(n[2])
        c = -float(n @ centre)
    return n, c


def pose_over_plane(n: np.ndarray, c: float) -> np.ndarray:
    """(4, 4) the sensor's pose in the frame of its road plane ``n · x + c = 0``: the plane is
    ``z = 0``, the sensor ``c`` above it, its x axis projected onto the plane (yaw 0).

    Args:
        n: (3,) the plane's unit normal in the sensor frame, pointing up.
        c: the sensor's height above the plane, m.
    """
    z = np.asarray(n, dtype=np.float64)
    z = z / np.linalg.norm(z)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    x /= np.linalg.norm(x)
    T = np.eye(4)
    T[:3, :3] = np.stack([x, np.cross(z, x), z])  # rows: the road axes in sensor coordinates
    T[2, 3] = c
    return T


def nearest_in_ring(az_ring: np.ndarray, az_query: np.ndarray, step_deg: float):
    """For each query azimuth, the index (into ``az_ring``) of the nearest point of a ring in
    azimuth and whether it lies within 0.6 of an azimuth step (the ring fired there).

    Returns:
        ``(index, present)``; ``index`` is 0 where the ring is empty.
    """
    if len(az_ring) == 0:
        return np.zeros(len(az_query), np.int64), np.zeros(len(az_query), bool)
    order = np.argsort(az_ring)
    a = az_ring[order]
    if len(a) == 1:
        return np.zeros(len(az_query), np.int64), np.abs(a[0] - az_query) < 0.6 * step_deg
    j = np.clip(np.searchsorted(a, az_query), 1, len(a) - 1)
    near = np.where(np.abs(a[j - 1] - az_query) < np.abs(a[j] - az_query), j - 1, j)
    return order[near], np.abs(a[near] - az_query) < 0.6 * step_deg


def grow_ground(
    xyz: np.ndarray,
    ring: np.ndarray,
    plane: tuple[np.ndarray, float],
    step_deg: float,
    *,
    tolerance_m: float = 0.2,
    max_slope_deg: float = 6.0,
) -> np.ndarray:
    """(N,) bool ground mask: near the plane, or grown outward from the next lower ring.

    Args:
        xyz: (N, 3) points; ring: (N,) their rings (0 = highest).
        plane: ``(n, c)`` from :func:`ground_plane`.
        step_deg: the azimuth step between columns.
    """
    n, c = plane
    ground = np.abs(xyz @ n + c) < tolerance_m
    height = xyz @ n + c
    rho = np.hypot(xyz[:, 0], xyz[:, 1])
    az = azimuth_deg(xyz)
    tan_max = np.tan(np.radians(max_slope_deg))
    for r in range(int(ring.max()) - 1, -1, -1):
        own = np.flatnonzero(ring == r)
        low = np.flatnonzero(ring == r + 1)
        idx, present = nearest_in_ring(az[low], az[own], step_deg)
        below = low[idx]
        d_rho = rho[own] - rho[below]
        grown = (
            present
            & ground[below]
            & (d_rho > 0)
            & (np.abs(height[own] - height[below]) <= tan_max * d_rho + 0.05)
        )
        ground[own] |= grown
    return ground
