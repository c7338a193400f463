"""Normals of a point cloud and the ray's incidence: analytic planes, spheres and the ground
under a raised sensor."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import estimate_normals, incidence_cosine
from nidar_mi.geometry import normals as normals_mod


def _plane(normal, offset, n=4000, seed=0, extent=6.0):
    """Points on the plane {x : n·x = offset} around its foot point, uniformly spread."""
    rng = np.random.default_rng(seed)
    nrm = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.cross(nrm, [0.0, 0.0, 1.0] if abs(nrm[2]) < 0.9 else [1.0, 0.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(nrm, a)
    st = rng.uniform(-extent, extent, (n, 2))
    return offset * nrm + st[:, :1] * a + st[:, 1:] * b, nrm


@pytest.mark.parametrize("normal", [(1, 0, 0), (1, 1, 0.3), (0.2, -0.5, 1.0)])
def test_a_planes_normal_and_the_analytic_incidence(normal):
    """On a plane n·x = 10 every estimated normal is ±n (to 1e-6), oriented to the sensor at
    the origin, and |cos θ| = 10 / |x| exactly (the foot point is 10 m away along n)."""
    pts, nrm = _plane(normal, 10.0)
    est = estimate_normals(pts)
    assert np.all(np.abs(est @ nrm) > 1 - 1e-6)
    assert np.all(np.einsum("ni,ni->n", est, pts) < 0)  # towards the origin
    np.testing.assert_allclose(incidence_cosine(pts), 10.0 / np.linalg.norm(pts, axis=1), atol=1e-6)


def test_ground_under_a_raised_sensor():
    """A flat ground 1.73 m under the sensor (KITTI's mounting height), sampled along rings as
    a spinning LiDAR does: cos θ = h / range, the grazing far returns included."""
    h = 1.73
    elev = np.radians(np.linspace(-24.8, -3.0, 40))
    az = np.radians(np.arange(0, 360, 0.4))
    e, a = np.meshgrid(elev, az, indexing="ij")
    rng = h / np.sin(-e)
    pts = np.stack(
        [rng * np.cos(e) * np.cos(a), rng * np.cos(e) * np.sin(a), np.full_like(e, -h)], -1
    ).reshape(-1, 3)
    cos = incidence_cosine(pts)
    np.testing.assert_allclose(cos, h / np.linalg.norm(pts, axis=1), atol=1e-6)


def test_a_sphere_around_the_sensor_is_seen_head_on():
    """Every ray from the centre of a sphere (r = 8 m) meets it along the normal: cos θ ≈ 1
    (the plane fit over a 20-point patch of a curved surface: within 1e-3)."""
    rng = np.random.default_rng(1)
    d = rng.normal(size=(20_000, 3))
    pts = 8.0 * d / np.linalg.norm(d, axis=1, keepdims=True)
    cos = incidence_cosine(pts)
    assert cos.min() > 1 - 1e-3


def test_given_normals_are_used_as_they_are():
    pts, nrm = _plane((0, 1, 0), 5.0, n=50)
    given = np.tile([0.0, 0.0, 3.0], (50, 1))  # not unit, not the plane's: used as given
    cos = incidence_cosine(pts, normals=given)
    np.testing.assert_allclose(cos, np.abs(pts[:, 2]) / np.linalg.norm(pts, axis=1), atol=1e-12)


def test_chunks_give_the_same_normals(monkeypatch):
    pts, _ = _plane((0.3, 1.0, 0.2), 7.0, n=3000, seed=2)
    pts = pts + np.random.default_rng(3).normal(0, 0.02, pts.shape)  # noisy: normals vary
    whole = estimate_normals(pts)
    monkeypatch.setattr(normals_mod, "CHUNK", 257)
    np.testing.assert_allclose(estimate_normals(pts), whole, atol=1e-12)


@pytest.mark.parametrize(
    "call, message",
    [
        (lambda: estimate_normals(np.zeros((5, 2))), r"expected \(N, 3\) points"),
        (lambda: estimate_normals(np.array([[0, 0, np.nan]] * 5)), "finite"),
        (lambda: estimate_normals(np.ones((2, 3))), "at least 3 points"),
        (lambda: estimate_normals(np.random.rand(10, 3), k=2), "at least 3 neighbours"),
        (lambda: incidence_cosine(np.random.rand(10, 3), normals=np.ones((9, 3))), "shaped like"),
    ],
)
def test_bad_input_is_one_error(call, message):
    with pytest.raises(NidarError, match=message):
        call()


def test_few_points_cap_k():
    """With fewer points than k every point is a neighbour: 4 coplanar points, their plane."""
    pts = np.array([[5.0, 0, 0], [5.0, 1, 0], [5.0, 0, 1], [5.0, 1, 1]])
    np.testing.assert_allclose(np.abs(estimate_normals(pts)[:, 0]), 1.0, atol=1e-12)


def test_too_few_points_are_head_on_with_a_warning():
    for n in (1, 2):
        with pytest.warns(UserWarning, match="too few for a surface normal"):
            cos = incidence_cosine(np.random.default_rng(n).uniform(1, 5, (n, 3)))
        np.testing.assert_array_equal(cos, np.ones(n))
    assert incidence_cosine(np.zeros((0, 3))).shape == (0,)


def test_coincident_neighbours_are_head_on_with_a_warning():
    """25 copies of one point beside a plane: their neighbourhoods have no spread."""
    pts, _ = _plane((1, 0, 0), 10.0, n=200)
    dup = np.tile([[3.0, 40.0, 2.0]], (25, 1))
    with pytest.warns(UserWarning, match="25 of 225 points have neighbours that coincide") as w:
        cos = incidence_cosine(np.vstack([pts, dup]))
    assert w[0].filename == __file__  # the warning names the caller's line
    np.testing.assert_array_equal(cos[200:], 1.0)
    np.testing.assert_allclose(cos[:200], 10.0 / np.linalg.norm(pts, axis=1), atol=1e-6)
    assert not np.any(estimate_normals(np.vstack([pts, dup]))[200:])
    notes: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # given notes, nothing is warned
        quiet = incidence_cosine(np.vstack([pts, dup]), notes=notes)
    np.testing.assert_array_equal(quiet, cos)
    assert len(notes) == 1 and notes[0].startswith("25 of 225 points have neighbours")


def test_noise_on_a_densely_sampled_wall():
    """A wall 8 m ahead at 40° sampled every 5 cm with 1 cm range noise: the estimate stays
    within 0.03 of the analytic cosine at the median (a plane fit averages the noise)."""
    pts, nrm = _plane((np.cos(0.7), np.sin(0.7), 0.0), 8.0, n=12_000, extent=2.7)
    d = pts / np.linalg.norm(pts, axis=1, keepdims=True)
    noisy = pts + d * np.random.default_rng(4).normal(0, 0.01, (len(pts), 1))
    err = np.abs(incidence_cosine(noisy) - np.abs(noisy @ nrm) / np.linalg.norm(noisy, axis=1))
    assert np.median(err) < 0.03


def test_implausible_coordinates_are_head_on_and_left_out():
    """A point beyond 1e7 m (no LiDAR return) is head-on with a warning and takes no part in the
    plane fits of the others; estimate_normals itself refuses it."""
    pts, _ = _plane((1, 0, 0), 10.0, n=300)
    cloud = np.vstack([pts, [[1e160, 0, 0]]])
    with pytest.warns(UserWarning, match="1 point.s. beyond 1e.07 m"):
        cos = incidence_cosine(cloud)
    assert cos[-1] == 1.0
    np.testing.assert_allclose(cos[:-1], 10.0 / np.linalg.norm(pts, axis=1), atol=1e-6)
    with pytest.raises(NidarError, match="beyond"):
        estimate_normals(cloud)


def test_points_on_one_line_are_head_on_with_a_warning():
    """Returns along one ray (or any line): no plane, so no incidence to estimate."""
    line = np.array([[10.0, 0, 0], [11.0, 0, 0], [12.0, 0, 0]])
    with pytest.warns(UserWarning, match="coincide or lie on one line"):
        np.testing.assert_array_equal(incidence_cosine(line), 1.0)
    dup = np.full((25, 3), 1.0 / 3.0)  # rounding leaves the mean a hair off the points
    with pytest.warns(UserWarning, match="25 of 25 points"):
        np.testing.assert_array_equal(incidence_cosine(dup), 1.0)


def _street_scan(cols=1024, seed=7):
    """(N, 3) returns of a 64-beam spinning LiDAR 1.73 m above a road, seen in a forward
    frustum: the road, a wall 30 m ahead, a box 8 m ahead with a face tilted by 35°, and 1 cm
    range noise."""
    from nidar_mi.lidar.pattern import beam_directions, elevation_table

    d = beam_directions(elevation_table("hdl64e"), cols).reshape(-1, 3).astype(np.float64)
    t = np.full(len(d), np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(d[:, 2] < 0, np.minimum(t, -1.73 / d[:, 2]), t)
        t = np.where(d[:, 0] > 0, np.minimum(t, 30.0 / d[:, 0]), t)
        n = np.array([np.cos(0.6), np.sin(0.6), 0.0])  # the box face: n·x = 8
        hit = 8.0 / (d @ n)
        p = d * hit[:, None]
        box = (hit > 0) & (np.abs(p[:, 1] - 1.0) < 2.0) & (p[:, 2] < 0.5)
    t = np.where(box, np.minimum(t, hit), t)
    p = d * t[:, None]
    p = p[np.isfinite(t) & (p[:, 0] > 0) & (np.abs(p[:, 1]) < p[:, 0])]
    return p + p / np.linalg.norm(p, axis=1, keepdims=True) * (
        np.random.default_rng(seed).normal(0.0, 0.01, (len(p), 1))
    )


def _reference_cosine(p, k):
    """|cos θ| by the textbook route: scipy's cKDTree neighbours, two-pass covariances, LAPACK's
    eigh; head-on (1) where the middle eigenvalue shows no plane."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(p).query(p, k=k)
    x = p[idx] - p[idx].mean(axis=1, keepdims=True)  # (n, k, 3)
    w, v = np.linalg.eigh(np.einsum("nki,nkj->nij", x, x))
    nrm = v[:, :, 0]
    flat = ~(w[:, 1] > normals_mod.DEGENERATE * np.einsum("nki,nki->n", p[idx], p[idx]))
    cos = np.abs(np.einsum("ni,ni->n", nrm, p)) / np.linalg.norm(p, axis=1)
    return np.where(flat, 1.0, np.clip(cos, 0.0, 1.0))


def test_the_fast_path_equals_a_textbook_reference_on_a_street_scan():
    """The incidence of a street scan's returns (a forward camera's share of a 64-beam scan,
    ~15 000 points) equals the textbook computation (cKDTree, centred covariances, eigh) to
    1e-9, at every point whose k-th neighbour is not tied with the next one (there, which of
    the equidistant points is taken is the search's choice)."""
    from scipy.spatial import cKDTree

    p = _street_scan()
    k = normals_mod.DEFAULT_NEIGHBOURS
    assert len(p) > 10_000
    dist, _ = cKDTree(p).query(p, k=k + 1)
    untied = dist[:, k - 1] < dist[:, k]
    assert untied.mean() > 0.99
    ref = _reference_cosine(p, k)
    np.testing.assert_allclose(incidence_cosine(p)[untied], ref[untied], rtol=0, atol=1e-9)


def test_the_plane_fits_do_not_depend_on_their_split(monkeypatch):
    """One thread or several, large blocks or small ones: the same normals, bit for bit."""
    p = _street_scan(cols=512)
    monkeypatch.setattr(normals_mod, "WORKERS", 1)
    one = estimate_normals(p)
    monkeypatch.setattr(normals_mod, "WORKERS", 3)
    monkeypatch.setattr(normals_mod, "BLOCK", 301)
    np.testing.assert_array_equal(estimate_normals(p), one)
