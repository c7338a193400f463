"""The ground under a LiDAR scan, and each point's height above it.

Ground plane fitting (GPF, Zermas et al., "Fast segmentation of 3D point clouds: a paradigm on
LiDAR data for autonomous vehicle applications", ICRA 2017) on the concentric zones of
Patchwork (Lim et al., "Patchwork: concentric zone-based region-wise ground segmentation with
ground likelihood estimation using a 3D LiDAR sensor", RA-L 2021):

1. **Global plane.** The lowest-point representative (LPR) is the mean height of the
   :data:`LPR_FRACTION` lowest points; points within :data:`SEED_M` of it seed a plane fit
   (principal component analysis: the normal is the direction of least spread); the points
   within :data:`DIST_M` of that plane are fitted again, :data:`ITERATIONS` times.
2. **Per zone.** The horizontal plane around the sensor is cut into rings (:data:`ZONES_M`)
   and :data:`SECTORS` sectors. In each bin, GPF runs again on the bin's points within
   :data:`PRIOR_M` of the global plane; the bin's plane replaces the global one there when it
   holds at least :data:`MIN_POINTS` ground points and is upright (normal within
   :data:`MAX_TILT_DEG` of the vertical), as Patchwork's uprightness test; otherwise the
   bin keeps the global plane.

A point's height is its signed distance to its bin's plane, positive above (normals point up,
``+z``). The scan is taken in the sensor frame with ``z`` up and the sensor roughly level
(a vehicle-mounted LiDAR); a tilt of a few degrees is what the per-bin planes absorb.

Why not a library: Open3D's ``segment_plane`` fits one RANSAC plane to the whole cloud (no
zones, so a sloping or cambered road is one plane) and its sampling is random; Patchwork's
reference implementation is C++ with its own build. GPF needs a sort and 3 × 3 principal
component fits, deterministic, in NumPy (a few milliseconds for a camera's ~20 000 returns).
"""

from __future__ import annotations

import numpy as np

from ..errors import NidarError

__all__ = [
    "DIST_M",
    "ITERATIONS",
    "LPR_FRACTION",
    "MAX_TILT_DEG",
    "MIN_POINTS",
    "PRIOR_M",
    "SECTORS",
    "SEED_M",
    "ZONES_M",
    "ground_height",
]

#: Edges of the concentric zones, horizontal distance from the sensor, m (the last is open).
ZONES_M = (0.0, 10.0, 20.0, 40.0)
#: Sectors per zone (equal azimuth spans).
SECTORS = 16
#: Share of the lowest points whose mean height is the lowest-point representative.
LPR_FRACTION = 0.02
#: Seeds: points within this of the lowest-point representative, m.
SEED_M = 0.4
#: Ground points: within this of the fitted plane, m.
DIST_M = 0.2
#: Refits of each plane on its ground points.
ITERATIONS = 3
#: Fewest ground points for a bin's own plane.
MIN_POINTS = 20
#: A bin's points considered for its plane: within this of the global plane, m.
PRIOR_M = 1.0
#: Largest tilt of a bin's plane from the vertical normal, degrees.
MAX_TILT_DEG = 20.0


def _plane(p: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The least-squares plane of (n, 3) points: ``(unit normal with n_z >= 0, offset)`` with
    ``normal · x = offset`` on the plane; None for fewer than 3 points or no plane."""
    if len(p) < 3:
        return None
    c = p.mean(axis=0)
    q = p - c
    w, v = np.linalg.eigh(q.T @ q)
    if not w[1] > 1e-12 * max(w[2], 1e-300):  # a point or a line
        return None
    n = v[:, 0] if v[2, 0] >= 0 else -v[:, 0]
    return n, float(n @ c)


def _gpf(p: np.ndarray, seeds: np.ndarray) -> tuple[np.ndarray, float, int] | None:
    """Ground plane fitting from the ``seeds`` (bool over ``p``): ``(normal, offset, ground
    points)`` after :data:`ITERATIONS` refits, None where no plane can be fitted."""
    plane = _plane(p[seeds])
    if plane is None:
        return None
    ground = int(seeds.sum())
    for _ in range(ITERATIONS):
        near = np.abs(p @ plane[0] - plane[1]) < DIST_M
        refit = _plane(p[near])
        if refit is None:
            break
        plane, ground = refit, int(near.sum())
    return plane[0], plane[1], ground


def _lowest_seeds(z: np.ndarray) -> np.ndarray:
    """Seeds of GPF: points within :data:`SEED_M` of the lowest-point representative."""
    m = max(1, int(np.ceil(LPR_FRACTION * len(z))))
    lpr = float(np.partition(z, m - 1)[:m].mean())
    return z < lpr + SEED_M


def _bins(p: np.ndarray) -> np.ndarray:
    """(N,) int64 bin of each point: zone × :data:`SECTORS` + sector."""
    r = np.hypot(p[:, 0], p[:, 1])
    zone = np.searchsorted(np.asarray(ZONES_M[1:]), r, side="right")
    az = np.arctan2(p[:, 1], p[:, 0])
    sector = np.minimum(((az + np.pi) / (2 * np.pi) * SECTORS).astype(np.int64), SECTORS - 1)
    return zone * SECTORS + sector


def ground_height(xyz) -> np.ndarray:
    """Height of each point above the ground (module docstring).

    Args:
        xyz: (N, 3) finite points in the sensor frame, ``z`` up, m.

    Returns:
        (N,) float64 signed distance to the ground plane of the point's zone, m (positive
        above). NaN for every point when no ground plane can be fitted (fewer than 3 points,
        or the lowest points on one line).

    Raises:
        NidarError: points not (N, 3) or not finite.
    """
    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise NidarError(f"ground_height: expected (N, 3) points, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise NidarError("ground_height: points must be finite")
    out = np.full(len(p), np.nan)
    if len(p) < 3:
        return out
    fit = _gpf(p, _lowest_seeds(p[:, 2]))
    if fit is None:
        return out
    normal, offset, _ = fit
    out[:] = p @ normal - offset
    prior = np.abs(out) < PRIOR_M
    bins = _bins(p)
    order = np.argsort(bins, kind="stable")
    edges = np.flatnonzero(np.diff(bins[order])) + 1
    upright = np.cos(np.radians(MAX_TILT_DEG))
    for idx in np.split(order, edges):
        cand = idx[prior[idx]]
        if len(cand) < MIN_POINTS:
            continue
        q = p[cand]
        local = _gpf(q, _lowest_seeds(q[:, 2]))
        if local is None or local[2] < MIN_POINTS or local[0][2] < upright:
            continue
        out[idx] = p[idx] @ local[0] - local[1]
    return out
