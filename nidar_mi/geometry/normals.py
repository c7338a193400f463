"""Surface normals of a point cloud and the incidence of the sensor's rays on them.

A LiDAR return's intensity falls with the angle between the ray and the surface (Lambert's
``cos θ`` for a diffuse surface, :mod:`nidar_mi.lidar`); a point cloud carries that angle in its
geometry. :func:`estimate_normals` fits a plane to each point's ``k`` nearest neighbours
(principal component analysis: the normal is the eigenvector of the neighbourhood's covariance
with the smallest eigenvalue, from a closed-form 3×3 eigen-solver: :func:`plane_eigen`) and :func:`incidence_cosine` gives ``|cos θ| = |n · d|`` with
``d`` the unit ray from the sensor at the origin to the point. Only the points are needed (no
rings, no mesh), so it applies to any sensor's scans, real or simulated.

Accuracy depends on the sampling: where a neighbourhood holds a single scan line (far ground
returns of a spinning LiDAR, between widely spaced rings) the plane is ill-determined; on the
simulator's scans of ``scenes_heldout`` the estimate correlates r ≈ 0.9 with the renderer's
exact cosine at the default ``k`` (tests/geometry/test_normals.py checks planes of known tilt).

Where no plane can be fitted (fewer than 3 points in all, or a neighbourhood whose points
coincide or lie on one line: its second principal spread below :data:`DEGENERATE` of its mean
squared distance from the origin) :func:`incidence_cosine` takes the ray as head-on
(``|cos θ| = 1``) and warns with the count; :func:`estimate_normals` gives those points a zero
normal. Points beyond :data:`MAX_COORDINATE` (no LiDAR return lies there) are head-on too, with
a warning, and take no part in the others' neighbourhoods.

Memory is bounded: neighbours are searched in chunks of :data:`CHUNK` points (an exact k-d
tree search, pykdtree's: the same neighbourhoods as any exact search, except which of several
points at exactly the k-th distance is taken), their scatter matrices summed in blocks of
:data:`BLOCK` (timings: the ``normals`` stage of docs/BENCHMARKS.md's NIDAR section).
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from ..errors import NidarError

__all__ = [
    "BLOCK",
    "CHUNK",
    "DEFAULT_NEIGHBOURS",
    "DEGENERATE",
    "MAX_COORDINATE",
    "WORKERS",
    "estimate_normals",
    "incidence_cosine",
]

#: Neighbours per plane fit (the point itself included).
DEFAULT_NEIGHBOURS = 20
#: Points whose neighbours are searched at once (bounds memory to ~CHUNK·k·16 bytes).
CHUNK = 100_000
#: Neighbourhoods whose scatter matrices are summed at once (their coordinates, BLOCK·k·24
#: bytes, stay in cache).
BLOCK = 2048
#: Largest coordinate magnitude :func:`estimate_normals` accepts, m.
MAX_COORDINATE = 1e7
#: Threads that fit the planes (at most 4; the scans of one camera take a few ms per thread).
WORKERS = max(1, min(4, os.cpu_count() or 1))
#: Relative second principal spread below which a neighbourhood has no plane (a point or a line).
DEGENERATE = 1e-12


def _points(xyz, bounded: bool = True) -> np.ndarray:
    """(N, 3) finite float64 points (within :data:`MAX_COORDINATE` when ``bounded``)."""
    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise NidarError(f"expected (N, 3) points, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise NidarError("points must be finite")
    if bounded and p.size and np.abs(p).max() > MAX_COORDINATE:
        raise NidarError(f"points lie beyond {MAX_COORDINATE:g} m of the origin")
    return p


def estimate_normals(xyz, k: int = DEFAULT_NEIGHBOURS) -> np.ndarray:
    """Unit normals of a point cloud by a plane fit to each point's neighbours.

    Args:
        xyz: (N, 3) points, m (any frame; N >= 3).
        k: neighbours per fit, the point included (3 or more; capped at N).

    Returns:
        (N, 3) float64 unit normals, oriented towards the origin (``n · p <= 0``); zero where
        the neighbours coincide or lie on one line (no plane; module docstring).

    Raises:
        NidarError: not (N, 3), non-finite or beyond :data:`MAX_COORDINATE`, fewer than 3
            points, or ``k < 3``.
    """
    p = _points(xyz)
    if int(k) < 3:
        raise NidarError(f"normals need at least 3 neighbours per point (got k={k})")
    if len(p) < 3:
        raise NidarError(f"normals need at least 3 points (got {len(p)})")
    return _plane_normals(p, k)[0]


def _plane_normals(p: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`estimate_normals` of checked (N, 3) points (N >= 3, ``k >= 3``): ``(normals,
    flat)``, (N, 3) float64 and (N,) bool, True where the normal is zero (no plane).

    The neighbour search and the plane fits of a chunk run on :data:`WORKERS` threads, each on
    its own share of the points (pykdtree and NumPy release the GIL; each point's neighbours
    and each neighbourhood's fit are the same however the points are split)."""
    from concurrent.futures import ThreadPoolExecutor

    k = min(int(k), len(p))
    p = np.ascontiguousarray(p)
    tree = neighbour_tree(p)
    normals = np.empty((3, len(p)))
    flat = np.empty(len(p), dtype=bool)
    with ThreadPoolExecutor(WORKERS) as pool:
        for start in range(0, len(p), CHUNK):
            q = p[start : start + CHUNK]
            cuts = np.linspace(0, len(q), min(WORKERS, -(-len(q) // BLOCK)) + 1).astype(int)
            shares = [q[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True)]
            fits = pool.map(lambda share: _planes(p, neighbour_indices(tree, share, k)), shares)
            vec, no_plane = (np.concatenate(a, axis=-1) for a in zip(*fits, strict=True))
            normals[:, start : start + CHUNK] = vec
            flat[start : start + CHUNK] = no_plane
    flip = (normals[0] * p[:, 0] + normals[1] * p[:, 1] + normals[2] * p[:, 2]) > 0
    normals[:, flip] *= -1.0
    return np.ascontiguousarray(normals.T), flat


def _planes(p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Plane fits of (n, k) neighbourhoods (indices into (N, 3) points ``p``): ``(normal,
    flat)``, (3, n) unit normals (any sign; zero where ``flat``) and (n,) bool, True where the
    neighbours coincide or lie on one line (or the normal is zero)."""
    cov, scale = neighbour_covariances(p, idx)
    second, smallest = plane_eigen(cov)
    smallest[:, ~(second > DEGENERATE * scale)] = 0.0  # a point or a line: no plane
    return smallest, ~smallest.any(axis=0)


def neighbour_tree(p: np.ndarray):
    """A k-d tree of (N, 3) C-contiguous float64 points (pykdtree's, leaves of 16 points)."""
    from pykdtree.kdtree import KDTree

    return KDTree(p, leafsize=16)


def neighbour_indices(tree, q: np.ndarray, k: int) -> np.ndarray:
    """(n, k) int64 indices of the ``k`` nearest points of ``tree`` to each of the (n, 3)
    C-contiguous query points ``q``, nearest first (exact Euclidean search; among points at
    equal distance the tree's order decides)."""
    _, idx = tree.query(q, k=k)
    return idx.astype(np.int64, copy=False).reshape(len(q), k)


def neighbour_covariances(p: np.ndarray, idx: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scatter matrices of neighbourhoods, in blocks of :data:`BLOCK` neighbourhoods.

    The coordinates of a block are gathered neighbour-major, ``(3, k, m)``, so that the sums
    over the neighbours add whole rows (contiguous, no strided reductions) and the block
    stays in cache.

    Args:
        p: (N, 3) points, m.
        idx: (n, k) indices into ``p``: each row a neighbourhood.

    Returns:
        ``(cov, scale)``: (6, n) entries ``xx, yy, zz, xy, xz, yz`` of the neighbourhoods'
        scatter matrices about their means, m², and (n,) the sums of their squared distances
        from the origin (k × the mean), m².
    """
    n, k = idx.shape
    coords = np.ascontiguousarray(p.T)  # (3, N)
    cov, scale = np.empty((6, n)), np.empty(n)
    for s in range(0, n, BLOCK):
        x = np.take(coords, np.ascontiguousarray(idx[s : s + BLOCK].T), axis=1)  # (3, k, m)
        scale[s : s + BLOCK] = np.einsum("ckm,ckm->m", x, x)
        x -= x.sum(axis=1, keepdims=True) / k
        for j, (a, b) in enumerate(_PAIRS):
            cov[j, s : s + BLOCK] = np.einsum("km,km->m", x[a], x[b])
    return cov, scale


#: Entries of a symmetric 3×3 matrix in the order ``xx, yy, zz, xy, xz, yz``.
_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def plane_eigen(cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form eigen-analysis of symmetric 3×3 matrices, vectorised.

    The eigenvalues come from the trigonometric solution of the characteristic cubic (on the
    matrix scaled by its largest entry), the smallest refined by two Newton steps on
    ``det(A - λI)``; its eigenvector is the longest cross product of two rows of ``A - λI``.
    On KITTI scans and the benchmark cloud the incidence cosines agree with LAPACK's ``eigh``
    to 2e-12.

    Args:
        cov: (6, n) entries ``xx, yy, zz, xy, xz, yz``.

    Returns:
        ``(second, smallest)``: (n,) the middle eigenvalue (same units as ``cov``) and (3, n)
        the unit eigenvector of the smallest one (any sign; zero for a zero matrix).
    """
    s = np.abs(cov).max(axis=0)
    s[s <= 0] = 1.0
    a00, a11, a22, a01, a02, a12 = cov / s
    q, top, low = trig_eigenvalues(a00, a11, a22, a01, a02, a12)
    for _ in range(2):  # Newton on det(A - λI), whose derivative is minus the minors' sum
        m00, m11, m22 = a00 - low, a11 - low, a22 - low
        slope = -(m11 * m22 - a12 * a12 + m00 * m22 - a02 * a02 + m00 * m11 - a01 * a01)
        f = _det(m00, m11, m22, a01, a02, a12)
        low = low - np.divide(f, slope, out=np.zeros_like(f), where=slope != 0)
    second = (3.0 * q - top - low) * s
    return second, _null_vector(a00 - low, a11 - low, a22 - low, a01, a02, a12)


def trig_eigenvalues(a00, a11, a22, a01, a02, a12):
    """``(q, top, low)``: the mean of the three eigenvalues, the largest and the smallest, of
    symmetric 3×3 matrices given by their (n,) entries, by the trigonometric solution of the
    characteristic cubic (exact to rounding where the eigenvalues are apart; about 1e-8 of the
    largest where two coincide)."""
    q = (a00 + a11 + a22) / 3.0
    off = a01 * a01 + a02 * a02 + a12 * a12
    p2 = ((a00 - q) ** 2 + (a11 - q) ** 2 + (a22 - q) ** 2 + 2.0 * off) / 6.0
    pp = np.sqrt(p2)
    det = _det(a00 - q, a11 - q, a22 - q, a01, a02, a12)
    r = np.clip(det / np.where(pp > 0, 2.0 * pp * p2, 1.0), -1.0, 1.0)
    phi = np.arccos(r) / 3.0
    top = q + 2.0 * pp * np.cos(phi)
    low = q + 2.0 * pp * np.cos(phi + 2.0 * np.pi / 3.0)
    return q, top, low


def _null_vector(m00, m11, m22, m01, m02, m12) -> np.ndarray:
    """(3, n) unit vectors orthogonal to the rows of the (nearly) singular symmetric matrices
    given by their (n,) entries: the longest of the three rows' cross products (the first of
    equal ones), normalised; zero where all three vanish."""
    r0, r1, r2 = (m00, m01, m02), (m01, m11, m12), (m02, m12, m22)
    crosses = [_cross(r0, r1), _cross(r0, r2), _cross(r1, r2)]
    length2 = [c[0] * c[0] + c[1] * c[1] + c[2] * c[2] for c in crosses]
    first = (length2[0] >= length2[1]) & (length2[0] >= length2[2])
    second = ~first & (length2[1] >= length2[2])
    vec = np.where(first, crosses[0], np.where(second, crosses[1], crosses[2]))
    length = np.sqrt(np.where(first, length2[0], np.where(second, length2[1], length2[2])))
    length[length <= 0] = 1.0
    return vec / length


def _cross(a, b) -> np.ndarray:
    """(3, n) cross products of two vectors given as triples of (n,) components."""
    return np.stack(
        [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
    )


def _det(m00, m11, m22, m01, m02, m12):
    """Determinants of symmetric 3×3 matrices given by their entries (arrays)."""
    return (
        m00 * (m11 * m22 - m12 * m12)
        - m01 * (m01 * m22 - m12 * m02)
        + m02 * (m01 * m12 - m11 * m02)
    )


def incidence_cosine(
    xyz, normals=None, k: int = DEFAULT_NEIGHBOURS, *, notes: list[str] | None = None
) -> np.ndarray:
    """``|cos θ|`` between each ray from the origin and the surface normal at its point.

    Args:
        xyz: (N, 3) points in the sensor frame (the sensor at the origin), m.
        normals: optional (N, 3) normals (e.g. a simulator's exact ones, any length); estimated
            from the cloud with :func:`estimate_normals` when None.
        k: neighbours per plane fit when estimating.
        notes: a list that receives the messages of the estimate's warnings (points too far,
            too few, or without a plane) instead of their being warned, for a caller that may
            discard the result; None: warned.

    Returns:
        (N,) float64 in [0, 1]; 1 for a ray along the normal, 0 for a grazing one. A point at the
        origin, one with a zero normal, and one without a plane (module docstring; a warning
        counts them) get 1.

    Raises:
        NidarError: points not (N, 3) or not finite, ``k < 3``, or normals of another shape or
            not finite.
    """
    p = _points(xyz, bounded=False)
    if normals is None:
        n = _estimated_normals(p, k, notes)
    else:
        n = np.asarray(normals, dtype=np.float64)
        if n.shape != p.shape or not np.all(np.isfinite(n)):
            raise NidarError(f"normals must be finite and shaped like the points {p.shape}")
    p, n = _unit_scale(p), _unit_scale(n)  # cos θ is scale-free; no overflow for huge values
    r = np.linalg.norm(p, axis=1)
    length = np.linalg.norm(n, axis=1)
    cos = np.abs(np.einsum("ni,ni->n", n, p)) / np.maximum(length * r, 1e-300)
    return np.where((r > 0) & (length > 0), np.clip(cos, 0.0, 1.0), 1.0)


def _unit_scale(v: np.ndarray) -> np.ndarray:
    """Rows divided by their largest absolute component (zero rows stay zero)."""
    a = np.abs(v)
    m = np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])  # the rows' maxima, column-wise
    m[m <= 0] = 1.0
    return v / m[:, None]


def _estimated_normals(p: np.ndarray, k: int, notes: list[str] | None = None) -> np.ndarray:
    """:func:`estimate_normals` of the points within :data:`MAX_COORDINATE`; zero rows (head-on)
    where there is no plane, with one warning per cause (its message appended to ``notes``
    instead, when given)."""

    def warn(message: str) -> None:
        if notes is None:
            warnings.warn(message, stacklevel=4)
        else:
            notes.append(message)

    if int(k) < 3:
        raise NidarError(f"normals need at least 3 neighbours per point (got k={k})")
    if not p.size or np.abs(p).max() <= MAX_COORDINATE:  # the usual case: no copies
        far = np.zeros(len(p), dtype=bool)
    else:
        far = np.abs(p).max(axis=1) > MAX_COORDINATE
        warn(f"{int(far.sum())} point(s) beyond {MAX_COORDINATE:g} m: incidence taken as head-on")
    near = len(p) - int(far.sum())
    if 0 < near < 3:
        warn(f"{near} point(s): too few for a surface normal, incidence taken as head-on")
    if near < 3:
        return np.zeros_like(p)
    if far.any():
        n = np.zeros_like(p)
        n[~far], flat = _plane_normals(p[~far], k)
    else:
        n, flat = _plane_normals(p, k)
    if flat.any():
        warn(
            f"{int(flat.sum())} of {near} points have neighbours that coincide or lie on one line "
            "(no plane): incidence taken as head-on"
        )
    return n
