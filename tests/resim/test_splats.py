"""The splats of returns that no triangle holds: where they are, how large, which way they face
and that the sensor, cast at them, finds them at their returns' ranges."""

from __future__ import annotations

import numpy as np
import pytest


def test_ring_spacing_is_half_the_gap_between_neighbours():
    from nidar_mi.resim.splats import ring_spacing_rad

    got = np.degrees(ring_spacing_rad(np.array([2.0, 1.0, -1.0, -5.0])))
    # inner rings: (2 - (-1)) / 2, (1 - (-5)) / 2; the ends: their one neighbour's gap
    np.testing.assert_allclose(got, [1.0, 1.5, 3.0, 4.0], atol=1e-12)
    with pytest.raises(ValueError):
        ring_spacing_rad(np.array([1.0]))


def test_unmeshed_returns_are_those_no_triangle_names():
    from nidar_mi.resim.splats import unmeshed_returns

    got = unmeshed_returns(6, np.array([[0, 1, 2], [2, 1, 4]]))
    np.testing.assert_array_equal(got, [False, False, False, True, False, True])


def test_a_splat_is_its_cell_centred_on_the_return_and_facing_the_sensor():
    from nidar_mi.resim.splats import ring_spacing_rad, scan_splats

    rng = np.random.default_rng(3)
    u = rng.normal(size=(50, 3))
    u[:, 2] *= 0.2
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    d = rng.uniform(3.0, 80.0, 50)
    xyz = u * d[:, None]
    ring = rng.integers(0, 4, 50)
    spacing = ring_spacing_rad(np.array([2.0, 0.0, -3.0, -8.0]))
    m = scan_splats(xyz, ring, 2000, spacing)
    assert m.vertices.shape == (200, 3) and m.faces.shape == (100, 3)
    corners = m.vertices.reshape(50, 4, 3)
    np.testing.assert_allclose(corners.mean(axis=1), xyz, atol=1e-9)
    offsets = corners - xyz[:, None]
    np.testing.assert_allclose(np.einsum("nkj,nj->nk", offsets, u), 0.0, atol=1e-9)
    width = np.linalg.norm(corners[:, 1] - corners[:, 0], axis=1)
    height = np.linalg.norm(corners[:, 3] - corners[:, 0], axis=1)
    np.testing.assert_allclose(width, d * 2 * np.pi / 2000, rtol=1e-9)
    np.testing.assert_allclose(height, d * spacing[ring], rtol=1e-9)
    v = m.vertices[m.faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert np.all(np.einsum("ij,ij->i", n, v.mean(axis=1)) < 0)  # towards the origin
    with pytest.raises(ValueError, match="origin"):
        scan_splats(np.zeros((1, 3)), np.zeros(1, int), 2000, spacing)


def test_neighbouring_cells_splats_tile_and_the_sensor_finds_them(variant, tmp_path):
    """Returns of one ring at 20 m in neighbouring columns: their splats meet (the edges within
    the tangent-versus-arc difference, < 1e-4 of the range), and rays through the returns and
    between them (0.3 and 0.7 of the way) hit the splats at the returns' range (within 0.1 %)."""
    from nidar_mi.resim.build import drop_scratch, scratch_scene
    from nidar_mi.resim.splats import ring_spacing_rad, scan_splats

    columns = 1000
    az = np.arange(-20, 21) * 2 * np.pi / columns
    xyz = 20.0 * np.column_stack([np.cos(az), np.sin(az), np.zeros_like(az)])
    m = scan_splats(xyz, np.ones(len(az), int), columns, ring_spacing_rad(np.array([1, 0, -1.0])))
    corners = m.vertices.reshape(-1, 4, 3)
    # corner 1 (left, bottom) of one splat meets corner 0 (right, bottom) of the next
    gap = np.linalg.norm(corners[:-1, 1] - corners[1:, 0], axis=1)
    assert gap.max() < 1e-4 * 20.0
    scene = scratch_scene(str(tmp_path))(m)
    drop_scratch(str(tmp_path))
    import mitsuba as mi

    step = az[1] - az[0]
    for angles in (az, az[:-1] + 0.3 * step, az[:-1] + 0.7 * step):
        d = np.column_stack([np.cos(angles), np.sin(angles), np.zeros_like(angles)])
        ray = mi.Ray3f(mi.Point3f(np.zeros((3, len(d)))), mi.Vector3f(d.T))
        si = scene.ray_intersect(ray)
        assert np.all(si.is_valid().numpy())
        np.testing.assert_allclose(si.t.numpy(), 20.0, rtol=1e-3)


def _three_splats():
    from nidar_mi.resim.splats import Splats, ring_spacing_rad, scan_splats

    xyz = np.array([[10.0, 0, 0], [0, 20.0, 1], [-30.0, -4, -1]])
    ring = np.array([0, 1, 2])
    mesh = scan_splats(xyz, ring, 2000, ring_spacing_rad(np.array([2.0, 1.0, 0.0])))
    d = np.linalg.norm(xyz, axis=1)
    return Splats(
        mesh, np.repeat(ring, 4), np.repeat(d, 4), np.repeat([0.3, 0.0, 0.1], 4), np.ones(12)
    )


def test_kept_splats_keep_each_vertex_with_its_return():
    from nidar_mi.resim.splats import Splats

    s = _three_splats()
    # faces: the first triangles of the three splats, then the second ones
    keep = np.array([True, False, True, True, False, False])
    k = s.kept(keep)
    assert len(k.mesh.faces) == 3 and len(k.mesh.vertices) == 4 + 3
    np.testing.assert_array_equal(k.ring, [0, 0, 0, 0, 2, 2, 2])
    # the kept faces in their order: splat 0's first, splat 2's first, splat 0's second
    assert np.all(k.ring[k.mesh.faces[1]] == 2) and np.all(k.ring[k.mesh.faces[[0, 2]]] == 0)
    np.testing.assert_allclose(
        np.linalg.norm(k.mesh.vertices[4:], axis=1), np.hypot(30, np.hypot(4, 1)), rtol=1e-3
    )
    both = Splats.join([s, k])
    assert len(both.mesh.vertices) == 12 + 7 and both.mesh.faces.max() == 18
    np.testing.assert_array_equal(both.intensity[12:], k.intensity)
    assert len(Splats.join([]).mesh.faces) == 0


def test_a_splat_gives_back_its_return_and_a_zero_reading_stays_detected():
    """ρ = (y + b) / (G_l r(d)) on a splat (cos θ = 1: it faces its ray); a return read as 0
    gets the ρ whose expected intensity is twice the threshold."""
    from nidar_mi.resim.inversion import KNOTS_M, SensorFit

    s = _three_splats()
    sensor = SensorFit(
        gains=np.array([0.8, 1.0, 1.25]),
        knots_m=KNOTS_M,
        response=np.linspace(1.2, 0.6, len(KNOTS_M)),
        offset=0.01,
        threshold=0.004,
        noise=0.002,
    )
    got = s.reflectance(sensor)[::4]
    unit = sensor.gains * sensor.response_at(s.range_m[::4])
    np.testing.assert_allclose(got, np.array([0.31, 0.01, 0.11]) / unit, rtol=1e-12)
    sensor.offset = 0.0  # a zero reading: E = 2 T = 0.008
    np.testing.assert_allclose(s.reflectance(sensor)[4], 0.008 / unit[1], rtol=1e-12)
    # re-scanned, the splat's expected intensity minus the offset is its return again
    np.testing.assert_allclose(s.reflectance(sensor)[::4][[0, 2]] * unit[[0, 2]], [0.3, 0.1])


def test_local_normals_of_a_road_and_of_foliage():
    """Returns on the road plane z = -1.73 m give its normal (to 1e-6, either sign); an
    isotropic cloud (foliage) and a return whose neighbours lie far off give none."""
    from nidar_mi.resim.splats import local_normals

    rng = np.random.default_rng(5)
    road = np.column_stack(
        [rng.uniform(5, 15, 2000), rng.uniform(-5, 5, 2000), np.full(2000, -1.73)]
    )
    bush = rng.normal(size=(200, 3)) * 0.3 + [8.0, 8.0, 0.0]
    lone = np.array([[40.0, -30.0, 5.0]])
    xyz = np.concatenate([road, bush, lone])
    n = local_normals(xyz, np.arange(len(xyz)))
    np.testing.assert_allclose(np.abs(n[:2000, 2]), 1.0, atol=1e-6)
    assert np.isnan(n[2000:2200, 0]).mean() > 0.9 and np.isnan(n[2200]).all()
    assert local_normals(xyz[:5], np.arange(5)).shape == (5, 3)  # fewer returns than neighbours


def test_a_splat_on_the_road_is_its_cells_footprint_there():
    """A ground return's splat lies in the road plane; up to MAX_TILT_DEG each corner is the
    ray-facing square's corner moved along the ray (the footprint); past it, its length along
    the ray's trace is that at MAX_TILT_DEG, its width unchanged."""
    from nidar_mi.resim.splats import MAX_TILT_DEG, ring_spacing_rad, scan_splats

    spacing = ring_spacing_rad(np.array([-2.0, -2.4, -2.8]))
    cols = 2000
    up = np.array([[0.0, 0, 1]])
    near = np.array([[4.0, 3.0, -1.73]])  # 5 m out: 19° above grazing, within MAX_TILT_DEG
    facing = scan_splats(near, [1], cols, spacing).vertices
    flat = scan_splats(near, [1], cols, spacing, up).vertices
    np.testing.assert_allclose(flat[:, 2], -1.73, atol=1e-12)
    u = near[0] / np.linalg.norm(near[0])
    moved = flat - facing
    np.testing.assert_allclose(np.cross(moved, u), 0.0, atol=1e-12)  # along the ray
    far = np.array([[60.0, 0.0, -1.73]])  # 88.3° from the road's normal
    v = scan_splats(far, [1], cols, spacing, up).vertices
    np.testing.assert_allclose(v[:, 2], -1.73, atol=1e-12)
    length = np.ptp(v[:, 0])
    cell = np.linalg.norm(far[0]) * spacing[1]
    np.testing.assert_allclose(length, cell / np.cos(np.radians(MAX_TILT_DEG)), rtol=1e-3)
    np.testing.assert_allclose(
        np.ptp(v[:, 1]), np.linalg.norm(far[0]) * 2 * np.pi / cols, rtol=1e-6
    )
    nan = scan_splats(far, [1], cols, spacing, np.full((1, 3), np.nan)).vertices
    np.testing.assert_allclose(nan, scan_splats(far, [1], cols, spacing).vertices, atol=1e-12)


def test_passed_by_measures_the_gap_across_the_surface():
    from nidar_mi.resim.splats import PASS_M, passed_by

    r = np.full(6, 10.0)
    t = np.array([np.inf, 10.05, 10.0 + 2 * PASS_M, 11.0, 11.0, 9.0])
    cos = np.array([0.0, 1.0, 1.0, 1.0, 0.05, 1.0])
    # no hit; on the surface; beyond it; a metre beyond; a metre beyond a grazing road
    # (5 cm across it); in front of the return (another surface hides it): not passed by
    assert passed_by(r, t, cos).tolist() == [True, False, True, True, False, False]


def test_a_dark_walls_scattered_returns_are_splatted_where_the_mesh_has_holes(variant, tmp_path):
    """A wall 5 m ahead returns on every fourth column (too sparse for the range-image mesh).
    The fused mesh holds 1 cm triangles, one per 10 cm, over the wall, so that every return lies
    within 0.3 m of a vertex, and a quad over its left half: the returns on the left half get
    no splat, those on the right half whose rays pass the tiny triangles by get one each (measured:
    all of them here; every other return is held by its scan's triangles and gets none),
    centred on them in the world of a turned and moved sensor whose beams start off its
    centre."""
    from types import SimpleNamespace

    from scipy.spatial import cKDTree

    from nidar_mi.resim.build import drive_splats, scratch_scene
    from nidar_mi.resim.laser_layout import RingLayout
    from nidar_mi.resim.mesh import Mesh
    from nidar_mi.resim.range_image import ScanGrid

    elev, columns = np.arange(2.0, -8.01, -0.4), 1800
    az = np.radians(-180.0 + (np.arange(0, columns, 4) + 0.5) * 360.0 / columns)
    th = np.radians(elev)
    ring, col = np.meshgrid(np.arange(len(elev)), np.arange(0, columns, 4), indexing="ij")
    d = np.stack([np.cos(th)[:, None] * np.cos(az), np.cos(th)[:, None] * np.sin(az)], -1)
    d = np.concatenate([d, np.broadcast_to(np.sin(th)[:, None, None], d.shape[:2] + (1,))], -1)
    xyz = d * (5.0 / d[..., :1])
    on = (np.abs(xyz[..., 1]) < 1.0) & (np.abs(xyz[..., 2]) < 0.5)
    xyz, ring, col = xyz[on], ring[on], col[on]
    grid = ScanGrid(ring, col, len(elev), columns, True)
    y, z = np.meshgrid(np.arange(-1.0, 1.01, 0.1), np.arange(-0.5, 0.51, 0.1))
    dots = np.column_stack([np.full(y.size, 5.0), y.ravel(), z.ravel()])
    tiny = np.concatenate([dots, dots + [0, 0.01, 0], dots + [0, 0, 0.01]])
    n = len(dots)
    half = np.array([[5.0, -1.0, -0.6], [5.0, 0.0, -0.6], [5.0, 0.0, 0.6], [5.0, -1.0, 0.6]])
    mesh = Mesh(
        np.concatenate([tiny, half]),
        np.concatenate(
            [np.column_stack([np.arange(n), np.arange(n) + n, np.arange(n) + 2 * n]),
             3 * n + np.array([[0, 1, 2], [0, 2, 3]])]
        ),
    )  # fmt: skip
    assert cKDTree(mesh.vertices).query(xyz)[0].max() < 0.3  # all near a vertex
    # the sensor turned 30° and moved; its rings' beams start off its centre; every other
    # return unmeshed (the rest held by their scan's triangles: never splatted)
    c, s_ = np.cos(np.radians(30.0)), np.sin(np.radians(30.0))
    pose = np.eye(4)
    pose[:3, :3] = [[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]]
    pose[:3, 3] = [3.0, -2.0, 0.4]
    mesh = mesh.transformed(pose)
    drive = SimpleNamespace(train=["a"], index=lambda fid: 0)
    offsets = np.linspace(0.1, -0.1, len(elev))
    frames = SimpleNamespace(
        xyz=[xyz],
        grid=[grid],
        intensity=[np.full(len(xyz), 0.02)],
        layout=RingLayout(elev, offsets, np.ones(len(elev))),
    )
    unmeshed = [np.arange(len(xyz)) % 2 == 0]
    given = unmeshed[0].copy()
    splats = drive_splats(drive, frames, [pose], mesh, unmeshed, scratch_scene(str(tmp_path)))
    centres = splats.mesh.vertices.reshape(-1, 4, 3).mean(axis=1)
    right = xyz[:, 1] > 0.0
    assert not (unmeshed[0] & ~(right & given)).any()  # the covered half, the meshed: none
    assert unmeshed[0][right & given].mean() > 0.9 and len(centres) == unmeshed[0].sum()
    world = xyz @ pose[:3, :3].T + pose[:3, 3]
    np.testing.assert_allclose(centres, world[unmeshed[0]], atol=1e-9)
