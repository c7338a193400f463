"""The per-vertex reflectance solved through the surfaces' interpolation
(:mod:`nidar_mi.resim.vertex_rho`): exact on noise-free samples, harmonic where no sample
reaches, closer to a smooth truth than the unsmoothed solve on noisy samples."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.resim.inversion import edges_of
from nidar_mi.resim.vertex_rho import interpolated_rho


def _grid(n=8):
    """An n x n vertex grid of unit squares, two triangles each: (V, 2) positions, (T, 3)."""
    a, b = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="ij")
    idx = np.arange(n * n).reshape(n, n)
    q = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    faces = np.concatenate(
        [np.column_stack([q[0], q[1], q[2]]), np.column_stack([q[0], q[2], q[3]])]
    )
    return np.column_stack([a.ravel(), b.ravel()]), faces


def _hits(faces, count, rng):
    """``count`` random hits: (S, 3) corners and (S, 3) barycentric weights (uniform in each
    triangle)."""
    tri = rng.integers(0, len(faces), count)
    u, v = rng.uniform(size=(2, count))
    flip = u + v > 1
    u, v = np.where(flip, 1 - u, u), np.where(flip, 1 - v, v)
    return faces[tri], np.column_stack([1 - u - v, u, v])


def test_noise_free_samples_give_the_vertices_back_and_the_nearest_corner_does_not():
    from nidar_mi.resim.inversion import _solve_rho

    rng = np.random.default_rng(0)
    pos, faces = _grid()
    rho = rng.uniform(0.05, 0.9, len(pos))
    corners, w = _hits(faces, 4000, rng)
    a = rng.uniform(0.3, 1.2, len(corners))  # the sensor's factor of each sample
    y = a * np.sum(w * rho[corners], axis=1)
    got = interpolated_rho(corners, w, y, a, edges_of(faces), len(pos), smooth=0.0)
    np.testing.assert_allclose(got, rho, rtol=1e-4, atol=1e-5)
    near = corners[np.arange(len(corners)), w.argmax(axis=1)]
    hard, _ = _solve_rho(near, y, a, len(pos))
    assert np.max(np.abs(hard - rho)) > 0.1  # each sample read as if it fell on a vertex


def test_vertices_without_samples_are_the_harmonic_interpolation():
    """A path of 10 vertices with samples only on its two end vertices (weight 1): the ends
    keep their data (within 1 % at λ = 0.01) and the eight between lie on the straight line
    between the ends' values (within 1e-4: the weak tie to the median ρ)."""
    edges = np.column_stack([np.arange(9), np.arange(1, 10)])
    corners = np.array([[0, 1, 2]] * 50 + [[9, 8, 7]] * 50)
    w = np.tile([1.0, 0.0, 0.0], (100, 1))
    y = np.r_[np.full(50, 0.2), np.full(50, 0.8)]
    got = interpolated_rho(corners, w, y, np.ones(100), edges, 10, smooth=0.01)
    assert got[0] == pytest.approx(0.2, rel=0.01) and got[9] == pytest.approx(0.8, rel=0.01)
    np.testing.assert_allclose(
        got, np.linspace(got[0], got[9], 10), atol=1e-4
    )  # the tie to the median


def test_the_edges_prior_brings_noisy_samples_closer_to_a_smooth_truth():
    """A smooth ρ field, three samples per vertex with noise of 0.1: the error at the vertices
    (RMS) with λ = 0.1 below 0.75 of the error without the prior (seeded)."""
    rng = np.random.default_rng(3)
    pos, faces = _grid(12)
    rho = 0.4 + 0.2 * np.sin(pos[:, 0] / 3.0) * np.cos(pos[:, 1] / 4.0)
    corners, w = _hits(faces, 3 * len(pos), rng)
    a = np.ones(len(corners))
    y = np.sum(w * rho[corners], axis=1) + rng.normal(0, 0.1, len(corners))
    edges = edges_of(faces)
    err = {
        lam: np.sqrt(np.mean((interpolated_rho(corners, w, y, a, edges, len(pos), lam) - rho) ** 2))
        for lam in (0.0, 0.1)
    }
    assert err[0.1] < 0.75 * err[0.0], err


def test_refusals():
    edges = np.array([[0, 1]])
    with pytest.raises(ValueError, match="at least 0"):
        interpolated_rho(
            np.zeros((1, 3), int), np.ones((1, 3)), np.ones(1), np.ones(1), edges, 2, -1.0
        )
    with pytest.raises(ValueError, match="no samples"):
        interpolated_rho(
            np.zeros((0, 3), int), np.ones((0, 3)), np.ones(0), np.ones(0), edges, 2, 0.1
        )
