"""Per-vertex reflectance from samples that read it through the surfaces' interpolation, with
the mesh's edges as the prior where the samples are few.

A sample ``s`` hits a triangle at barycentric weights ``w_s`` of its three corners; the
surfaces' ``mesh_attribute`` texture gives it ``ρ(x_s) = Σ_c w_sc ρ_c``, and the model says
``y_s = a_s · ρ(x_s)`` (``a_s`` the sensor's factor: gain, range response, incidence). The
solve here minimises

    Σ_s (a_s Σ_c w_sc ρ_c - y_s)² + λ · m · Σ_(a,b) edges (ρ_a - ρ_b)² + ε · m · Σ_v (ρ_v - ρ̃)²

(``m`` the median over the vertices of their data weight ``Σ_s (a_s w_sv)²``, so that λ reads
"a vertex with the median number of samples listens to each neighbour λ times as much as to
one of its samples"; ε = 1e-6 ties a part of the mesh that no sample reaches to ρ̃, the
samples' median ρ). The normal equations ``(BᵀB + λ m L + ε m I) ρ = Bᵀy + ε m ρ̃`` (B the
(S, V) design, L the graph Laplacian of the edges) are sparse, symmetric and positive definite;
SciPy's conjugate gradients with a Jacobi preconditioner solve them from a start near the
answer (a warning if they stop before :data:`CG_RTOL`; the start kept if they go non-finite).
With λ > 0 the vertices no sample reaches take the harmonic interpolation of their neighbours;
with λ = 0, ρ̃.

Solving at the vertices with each sample given to one corner (its nearest) is the alternation's
fast step; it reads each sample as if it fell on a vertex, which the interpolation then blurs.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["edge_adjacency", "harmonic_fill", "interpolated_rho", "CG_RTOL", "CG_MAXITER"]

#: Relative residual at which the conjugate gradients stop, and their largest iteration count.
CG_RTOL = 1e-6
CG_MAXITER = 3000
#: Weight of the tie to the median ρ, relative to the median vertex's data weight.
TIE = 1e-6


def edge_adjacency(edges: np.ndarray, n: int):
    """(n, n) SciPy CSR adjacency of (E, 2) vertex-index ``edges`` (each edge once, both
    directions, value 1)."""
    import scipy.sparse as sp

    a, b = edges[:, 0], edges[:, 1]
    adj = sp.coo_matrix((np.ones(2 * len(a)), (np.r_[a, b], np.r_[b, a])), (n, n)).tocsr()
    adj.data[:] = 1.0  # an edge listed twice counts once
    return adj


def harmonic_fill(values: np.ndarray, known: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(V,) ``values`` at the ``known`` vertices, and at the others the harmonic interpolation
    over the mesh's edges (each unknown vertex the mean of its neighbours: the minimiser of
    Σ over edges of (x_a - x_b)² with the known values fixed; SciPy's sparse direct solver). A
    part of the mesh with no known vertex takes the known values' median.

    Args:
        values: (V,) float; known: (V,) bool; edges: (E, 2) vertex indices.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    x = np.asarray(values, dtype=np.float64).copy()
    known = np.asarray(known, bool)
    unknown = np.flatnonzero(~known)
    if len(unknown) == 0:
        return x
    fallback = float(np.median(x[known])) if known.any() else 0.3
    if not known.any():
        return np.full(len(x), fallback)
    adj = edge_adjacency(edges, len(x))
    degree = np.asarray(adj.sum(axis=1)).ravel()
    eps = 1e-9  # ties a part with no known vertex to the median; negligible elsewhere
    lhs = sp.diags(degree[unknown] + eps) - adj[unknown][:, unknown]
    rhs = adj[unknown][:, np.flatnonzero(known)] @ x[known] + eps * fallback
    x[unknown] = spsolve(lhs.tocsc(), rhs)
    return x


def interpolated_rho(
    corners: np.ndarray,
    weights: np.ndarray,
    y: np.ndarray,
    a: np.ndarray,
    edges: np.ndarray,
    vertices: int,
    smooth: float,
    start: np.ndarray | None = None,
) -> np.ndarray:
    """(V,) ρ at the vertices minimising the module docstring's objective.

    Args:
        corners: (S, 3) vertex indices of each sample's triangle.
        weights: (S, 3) their barycentric weights.
        y: (S,) the samples' intensities.
        a: (S,) the sensor's factor of each sample (``y ≈ a · ρ(x)``).
        edges: (E, 2) the mesh's edges.
        vertices: V.
        smooth: λ, the edges' weight relative to the median vertex's data weight (≥ 0).
        start: (V,) a start for the conjugate gradients (default: ρ̃ everywhere).

    Raises:
        ValueError: on a negative ``smooth`` or no sample.
    """
    import scipy.sparse as sp
    from scipy.sparse.linalg import cg

    if smooth < 0:
        raise ValueError(f"the smoothness weight must be at least 0, got {smooth}")
    if len(y) == 0:
        raise ValueError("no samples to solve the reflectance from")
    rows = np.repeat(np.arange(len(y)), 3)
    vals = (np.asarray(weights, np.float64) * np.asarray(a, np.float64)[:, None]).ravel()
    b = sp.csr_matrix((vals, (rows, np.asarray(corners, np.int64).ravel())), (len(y), vertices))
    btb = (b.T @ b).tocsr()
    data = btb.diagonal()
    seen = data > 1e-12
    m = float(np.median(data[seen])) if seen.any() else 1.0
    adj = edge_adjacency(edges, vertices)
    lap = sp.diags(np.asarray(adj.sum(axis=1)).ravel()) - adj
    # the median of the per-sample ratios: where the samples say nothing else
    ratio = y[a > 1e-9] / a[a > 1e-9]
    tie_value = float(np.median(ratio)) if len(ratio) else 0.3
    lhs = (btb + smooth * m * lap + TIE * m * sp.identity(vertices)).tocsr()
    rhs = b.T @ y + TIE * m * tie_value
    x0 = np.full(vertices, tie_value) if start is None else np.asarray(start, np.float64)
    jacobi = sp.diags(1.0 / np.maximum(lhs.diagonal(), 1e-300))
    x, info = cg(lhs, rhs, x0=x0, M=jacobi, rtol=CG_RTOL, maxiter=CG_MAXITER)
    if not np.isfinite(x).all():
        warnings.warn("reflectance solve: not finite; its start is kept", stacklevel=2)
        return x0
    if info != 0:
        warnings.warn(
            f"reflectance solve: not converged to {CG_RTOL:g} in {CG_MAXITER} iterations; "
            "its last iterate is kept",
            stacklevel=2,
        )
    return x
