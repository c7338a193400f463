"""Neighbourhood descriptors against analytic cases: a plane's planarity, a line's linearity,
lattice spacings, the normal's vertical component, and the incidence of the normals' estimate."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import incidence_cosine
from nidar_mi.geometry.local_features import geometry_feature_names, local_geometry


def _rotation(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q


def _lattice(n: int = 21, step: float = 0.1) -> np.ndarray:
    """An n × n square lattice in the xy plane, centred, (n², 3)."""
    g = (np.arange(n) - n // 2) * step
    u, v = np.meshgrid(g, g)
    return np.stack([u.ravel(), v.ravel(), np.zeros(n * n)], axis=1)


def _interior(p: np.ndarray, margin: float) -> np.ndarray:
    return (np.abs(p[:, 0]) < margin) & (np.abs(p[:, 1]) < margin)


def test_a_plane_has_planarity_one_in_any_orientation():
    """On a square lattice the 9 and 21 nearest points (the 3 × 3 block; the 5 × 5 block without
    its corners) spread equally in both directions of the plane: λ1 = λ2, λ3 = 0, so planarity
    is 1, linearity and scatter 0, wherever the plane lies and however it is turned (to the
    closed-form eigenvalues' 1e-8 where two coincide)."""
    lat = _lattice()
    inner = _interior(lat, 0.75)
    for seed in range(3):
        p = lat @ _rotation(seed).T + np.array([12.0, -3.0, 1.5])
        g = local_geometry(p, scales=(9, 21))
        for k in (9, 21):
            np.testing.assert_allclose(g.features[f"planarity_k{k}"][inner], 1.0, atol=1e-6)
            np.testing.assert_allclose(g.features[f"linearity_k{k}"][inner], 0.0, atol=1e-6)
            np.testing.assert_allclose(g.features[f"scatter_k{k}"][inner], 0.0, atol=1e-6)


def test_a_line_has_linearity_one_and_the_three_descriptors_sum_to_one():
    t = np.linspace(-2.0, 2.0, 81)
    d = np.array([0.3, 0.5, 0.81])
    p = np.array([8.0, 1.0, -0.5]) + t[:, None] * d / np.linalg.norm(d)
    g = local_geometry(p, scales=(5, 10), notes=[])
    np.testing.assert_allclose(g.features["linearity_k5"], 1.0, atol=1e-6)
    np.testing.assert_allclose(g.features["linearity_k10"], 1.0, atol=1e-6)
    rng = np.random.default_rng(0)
    q = rng.normal(size=(500, 3)) * [3.0, 1.0, 0.2] + [20.0, 0.0, 0.0]
    f = local_geometry(q, scales=(10, 20)).features
    for k in (10, 20):
        total = f[f"linearity_k{k}"] + f[f"planarity_k{k}"] + f[f"scatter_k{k}"]
        np.testing.assert_allclose(total, 1.0, atol=1e-12)
        assert np.all(f[f"scatter_k{k}"] >= 0) and np.all(f[f"linearity_k{k}"] >= 0)


def test_spacing_nz_and_incidence_on_level_ground():
    """A level lattice of step s 1.7 m under the sensor: the 10 nearest points of an interior
    point are itself, its 4 neighbours at s, the 4 diagonal ones at s·√2 and one of the 4 at
    2s (mean spacing (4 + 4√2 + 2)·s / 9); the normal is vertical (|n_z| = 1); the incidence
    equals the normals' own estimate."""
    s = 0.1
    p = _lattice(31, s) + np.array([10.0, 2.0, -1.7])
    g = local_geometry(p, scales=(5, 20))
    inner = _interior(p - [10.0, 2.0, 0.0], 1.0)
    gap = (4 + 4 * np.sqrt(2) + 2) * s / 9
    np.testing.assert_allclose(g.features["spacing"][inner], gap, rtol=1e-9)
    rng = np.linalg.norm(p, axis=1)
    np.testing.assert_allclose(g.features["spacing_rel"][inner], gap / rng[inner], rtol=1e-9)
    np.testing.assert_allclose(g.features["nz"], 1.0, atol=1e-9)
    np.testing.assert_allclose(g.features["z"], -1.7)
    np.testing.assert_allclose(g.cos_incidence, incidence_cosine(p), atol=1e-12)
    np.testing.assert_allclose(g.cos_incidence, 1.7 / rng, atol=1e-9)  # |n · p| / |p|
    assert list(g.features) == list(geometry_feature_names((5, 20)))


def test_coincident_points_have_no_shape_and_bad_input_is_refused():
    rng = np.random.default_rng(1)
    p = np.vstack([np.zeros((25, 3)) + [5.0, 0, 0], rng.normal(size=(30, 3)) - [5.0, 0, 0]])
    notes: list[str] = []
    g = local_geometry(p, scales=(5, 10), notes=notes)
    assert np.isnan(g.features["planarity_k5"][:25]).all()
    assert np.all(g.cos_incidence[:25] == 1.0)  # no plane: head-on, as the normals' estimate
    assert any("coincide or lie on one line" in m for m in notes)
    two = local_geometry(np.array([[1.0, 0, 0], [2.0, 0, 0]]))
    assert np.isnan(two.features["linearity_k10"]).all() and np.all(two.cos_incidence == 1.0)
    for bad in ((3, 3), (10, 5), (2,)):
        with pytest.raises(NidarError, match="scales must rise"):
            local_geometry(p, scales=bad)
    with pytest.raises(NidarError, match="finite"):
        local_geometry(np.array([[np.nan, 0, 0]] * 5))
