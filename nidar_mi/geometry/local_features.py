"""Each point's neighbourhood in its scan: multi-scale shape descriptors beside the normal.

What a LiDAR return's intensity depends on besides the surface's reflectance is largely in the
scan's own geometry: the incidence (:mod:`nidar_mi.geometry.normals`), whether the point lies on
a plane (a road, a wall), an edge or a pole, or in vegetation (scattered returns), how high it
is above the road, and how densely the scan samples it. :func:`local_geometry` computes all of
it from **one** k-nearest-neighbour query per scan (the largest of :data:`SCALES`; the smaller
neighbourhoods are its first columns, the neighbours sorted nearest first), the same exact
pykdtree search the normals use:

* ``normals`` and ``cos_incidence``: the plane fit of the :data:`~nidar_mi.geometry.normals.
  DEFAULT_NEIGHBOURS` nearest points (the incidence estimate's own neighbourhood and
  eigen-solver, so ``cos_incidence`` equals :func:`~nidar_mi.geometry.normals.incidence_cosine`
  up to which of several points at exactly the k-th distance is taken);
* per neighbourhood size ``k`` of :data:`SCALES`, with ``λ1 ≥ λ2 ≥ λ3 ≥ 0`` the eigenvalues
  of the neighbourhood's covariance (Demantké et al., "Dimensionality based scale selection in
  3D lidar point clouds", ISPRS 2011; Weinmann et al., ISPRS J. 2015): ``linearity_k =
  (λ1 − λ2)/λ1`` (1 on a line), ``planarity_k = (λ2 − λ3)/λ1`` (1 on a plane sampled
  evenly in all directions), ``scatter_k = λ3/λ1`` (1 for an isotropic cloud); the three sum
  to 1;
* ``nz``: ``|n_z|``, the vertical component of the unit normal (1 on level ground, 0 on a wall);
* ``z``: the point's height in the sensor frame, m; ``height``: above the ground
  (:func:`nidar_mi.geometry.ground.ground_height`), m;
* ``spacing``: the mean distance to the other :data:`SPACING_NEIGHBOURS` − 1 points of the
  point's nearest :data:`SPACING_NEIGHBOURS` (itself included), m, and
  ``spacing_rel``: that over the point's range (the scan's angular sampling, about constant
  on one surface; larger where the ray grazes it or the surface is sparse).

Descriptors of a neighbourhood whose points coincide (``λ1 = 0``) are NaN, as are all of a
point beyond :data:`~nidar_mi.geometry.normals.MAX_COORDINATE` (it takes no part in the
others' neighbourhoods; its incidence is head-on, with a warning, as the normals' estimate
does). A gradient-boosted profile reads NaN as a missing value.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError
from .ground import ground_height
from .normals import (
    BLOCK,
    DEFAULT_NEIGHBOURS,
    DEGENERATE,
    MAX_COORDINATE,
    WORKERS,
    incidence_cosine,
    neighbour_covariances,
    neighbour_indices,
    neighbour_tree,
    plane_eigen,
    trig_eigenvalues,
)

__all__ = [
    "GEOMETRY_FEATURES",
    "SCALES",
    "SHAPES",
    "SPACING_NEIGHBOURS",
    "LocalGeometry",
    "geometry_feature_names",
    "local_geometry",
]

#: Neighbourhood sizes of the shape descriptors, points (the point itself included).
SCALES = (10, 20, 50)
#: The shape descriptors per neighbourhood size.
SHAPES = ("linearity", "planarity", "scatter")
#: Neighbours (the point itself included) whose mean distance is the ``spacing``.
SPACING_NEIGHBOURS = 10


def geometry_feature_names(scales: tuple[int, ...] = SCALES) -> tuple[str, ...]:
    """The names of :attr:`LocalGeometry.features` for these neighbourhood sizes, in order."""
    shapes = tuple(f"{s}_k{k}" for k in scales for s in SHAPES)
    return ("z", "height", "nz", *shapes, "spacing", "spacing_rel")


#: The descriptor names at the default :data:`SCALES`.
GEOMETRY_FEATURES = geometry_feature_names()


@dataclass(frozen=True)
class LocalGeometry:
    """The neighbourhood descriptors of a scan's points (module docstring).

    Attributes:
        normals: (N, 3) float64 unit normals oriented towards the sensor; zero where no plane.
        cos_incidence: (N,) float64 ``|cos θ|`` in [0, 1] (1 where no plane).
        features: name -> (N,) float64, the names of :func:`geometry_feature_names`.
    """

    normals: np.ndarray
    cos_incidence: np.ndarray
    features: dict[str, np.ndarray]


def _checked(xyz, scales) -> tuple[np.ndarray, tuple[int, ...]]:
    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise NidarError(f"local_geometry: expected (N, 3) points, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise NidarError("local_geometry: points must be finite")
    ks = tuple(int(k) for k in scales)
    if not ks or min(ks) < 3 or list(ks) != sorted(set(ks)):
        raise NidarError(f"local_geometry: scales must rise, each at least 3 (got {scales})")
    return p, ks


def _shape(p: np.ndarray, idx: np.ndarray, normal: bool = True) -> tuple:
    """``(eigenvalues, normal, flat)`` of (n, k) neighbourhoods of (N, 3) points ``p``: (3, n)
    ``λ1 ≥ λ2 ≥ λ3 ≥ 0`` of each covariance, m² (the trigonometric solution, without the
    normals' Newton refinement of the smallest, which a double root throws off), and (3, n)
    the normals' unit eigenvector of the smallest (zero where ``flat``: the points coincide or
    lie on one line); without ``normal`` the last two are None."""
    cov, scale = neighbour_covariances(p, idx)
    vec = flat = None
    if normal:
        second, vec = plane_eigen(cov)
        flat = ~(second > DEGENERATE * scale)
        vec[:, flat] = 0.0
    s = np.abs(cov).max(axis=0)
    s[s <= 0] = 1.0
    q, top, low = trig_eigenvalues(*(cov / s))
    lam = np.stack([top, 3.0 * q - top - low, low]) * (s / idx.shape[1])
    return np.clip(lam, 0.0, None), vec, flat


def _descriptors(lam: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Linearity, planarity and scatter of (3, n) descending eigenvalues (NaN where ``λ1 = 0``)."""
    top = np.where(lam[0] > 0, lam[0], np.nan)
    return (lam[0] - lam[1]) / top, (lam[1] - lam[2]) / top, lam[2] / top


def _near_points(p: np.ndarray, notes: list[str] | None) -> np.ndarray:
    """(N,) bool: the points within :data:`MAX_COORDINATE`; the others warned about."""
    near = np.abs(p).max(axis=1) <= MAX_COORDINATE if p.size else np.ones(0, bool)
    if not near.all():
        message = (
            f"{int((~near).sum())} point(s) beyond {MAX_COORDINATE:g} m: no neighbourhood "
            "descriptors, incidence taken as head-on"
        )
        _note(message, notes, stacklevel=3)
    return near


def _note(message: str, notes: list[str] | None, stacklevel: int) -> None:
    """Warn ``message`` (``stacklevel`` as the caller's own), or append it to ``notes``."""
    if notes is None:
        warnings.warn(message, stacklevel=stacklevel + 1)
    else:
        notes.append(message)


def local_geometry(
    xyz, scales: tuple[int, ...] = SCALES, *, notes: list[str] | None = None
) -> LocalGeometry:
    """The neighbourhood descriptors of every point of a scan (module docstring).

    Args:
        xyz: (N, 3) points in the sensor frame (the sensor at the origin, ``z`` up), m.
        scales: neighbourhood sizes, rising, each at least 3 (capped at the number of points);
            the normals use :data:`~nidar_mi.geometry.normals.DEFAULT_NEIGHBOURS` (added to the
            query when larger than every scale).
        notes: receives the messages of the warnings (points too far, neighbourhoods without a
            plane) instead of their being warned; None: warned.

    Returns:
        The :class:`LocalGeometry`; with fewer than 3 usable points every descriptor is NaN and
        every incidence head-on.

    Raises:
        NidarError: points not (N, 3) or not finite, or invalid ``scales``.
    """
    p, ks = _checked(xyz, scales)
    n = len(p)
    names = geometry_feature_names(ks)
    feats = {name: np.full(n, np.nan) for name in names}
    normals = np.zeros((n, 3))
    near = _near_points(p, notes)
    q = np.ascontiguousarray(p[near])
    if len(q) >= 3:
        _fill(q, near, ks, feats, normals, notes)
    feats["z"] = p[:, 2].copy()
    cos = incidence_cosine(p, normals)
    return LocalGeometry(normals=normals, cos_incidence=cos, features=feats)


def _query(q: np.ndarray, k: int) -> np.ndarray:
    """(M, k) indices of the ``k`` nearest of the (M, 3) points ``q`` to each of them, nearest
    first; the queries split over :data:`~nidar_mi.geometry.normals.WORKERS` threads (each
    point's neighbours do not depend on the split)."""
    from concurrent.futures import ThreadPoolExecutor

    tree = neighbour_tree(q)
    cuts = np.linspace(0, len(q), min(WORKERS, -(-len(q) // BLOCK)) + 1).astype(int)
    shares = [q[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
    if len(shares) == 1:
        return neighbour_indices(tree, q, k)
    with ThreadPoolExecutor(len(shares)) as pool:
        return np.concatenate(
            list(pool.map(lambda share: neighbour_indices(tree, share, k), shares))
        )


def _fill(q, near, ks, feats, normals, notes) -> None:
    """:func:`local_geometry`'s descriptors of the (M, 3) usable points ``q`` (rows ``near``
    of the scan), written into ``feats`` and ``normals``."""
    kmax = min(max(*ks, DEFAULT_NEIGHBOURS), len(q))
    idx = _query(q, kmax)
    shapes = {min(k, kmax): None for k in (*ks, DEFAULT_NEIGHBOURS)}
    k_normal = min(DEFAULT_NEIGHBOURS, kmax)
    for k in shapes:
        shapes[k] = _shape(q, idx[:, :k], normal=k == k_normal)
    for k in ks:
        lam = shapes[min(k, kmax)][0]
        for name, values in zip(SHAPES, _descriptors(lam), strict=True):
            feats[f"{name}_k{k}"][near] = values
    _, vec, flat = shapes[k_normal]
    vec = vec.copy()
    flip = (vec * q.T).sum(axis=0) > 0
    vec[:, flip] *= -1.0
    normals[near] = vec.T
    if flat.any():
        message = (
            f"{int(flat.sum())} of {len(q)} points have neighbours that coincide or lie on one "
            "line (no plane): incidence taken as head-on"
        )
        _note(message, notes, stacklevel=4)
    feats["nz"][near] = np.abs(vec[2])
    k0 = min(SPACING_NEIGHBOURS, kmax)
    gap = np.linalg.norm(q[idx[:, 1:k0]] - q[:, None, :], axis=2).mean(axis=1)
    feats["spacing"][near] = gap
    rng = np.linalg.norm(q, axis=1)
    feats["spacing_rel"][near] = gap / np.where(rng > 0, rng, np.nan)
    feats["height"][near] = ground_height(q)
