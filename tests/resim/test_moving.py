"""Moving surfaces put back at a held-out frame's time, on a constructed drive with known
answers: a wall at y = 8 m seen by a sensor driving along x, and a 2 m panel at y = 4 m in front
of it in the first frames only. The static surfaces are the wall; the panel comes back from the
training frame nearest in time, and a held-out frame's beams land on it (analytic ranges)."""

from __future__ import annotations

import numpy as np
import pytest

WALL_Y, PANEL_Y = 8.0, 4.0
PANEL_HALF = 1.0  # the panel spans x in [-1, 1], z in [-1, 1] m (world)
PANEL_UNTIL = 7  # the panel is there in frames 0-6
STEP = 0.25  # m of travel along x per frame
RINGS, COLS = 48, 240  # beams 0.85 deg apart in elevation, 0.5 deg in azimuth


def _scan(k: int, with_panel: bool = True):
    """Frame k's returns (LiDAR frame, the sensor at (x_k, 0, 0)), ScanGrid, directions, ranges
    and whether each return is on the panel (none without ``with_panel``)."""
    from nidar_mi.resim.range_image import ScanGrid

    el = np.radians(np.linspace(20.0, -20.0, RINGS))[:, None]
    az = np.radians(np.linspace(30.0, 150.0, COLS))[None, :]
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) + 0 * az], -1)
    d = d.reshape(-1, 3)
    t = WALL_Y / d[:, 1]
    tp = PANEL_Y / d[:, 1]
    x, z = k * STEP + tp * d[:, 0], tp * d[:, 2]
    panel = with_panel & (k < PANEL_UNTIL) & (np.abs(x) <= PANEL_HALF) & (np.abs(z) <= PANEL_HALF)
    t = np.where(panel, tp, t)
    ring, col = np.meshgrid(np.arange(RINGS), np.arange(COLS), indexing="ij")
    return d * t[:, None], ScanGrid(ring.ravel(), col.ravel(), RINGS, 3 * COLS, True), d, t, panel


def _pose(k: int) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = k * STEP
    return T


def _rays(k: int):
    from nidar_mi.resim.beam_rays import Rays

    xyz, grid, d, t, panel = _scan(k)
    o = np.tile(_pose(k)[:3, 3], (len(d), 1))
    return xyz, grid, Rays(o, d, t, grid.ring, np.full(len(d), k)), panel


def _load(tmp_path, mesh, name="m.ply"):
    from nidar_mi.resim.scene_files import write_surfaces_ply
    from nidar_mi.resim.surfaces import surface_scene

    write_surfaces_ply(tmp_path / name, mesh, {"rho": np.full(len(mesh.vertices), 0.5)})
    return surface_scene(tmp_path / name)


def _wall(tmp_path):
    """The static surfaces: the wall as frames 0-15 see it without the panel (what the
    transient step leaves)."""
    from nidar_mi.resim.mesh import fuse_meshes, scan_mesh

    meshes = [scan_mesh(*_scan(k, False)[:2]).transformed(_pose(k)) for k in range(16)]
    wall = fuse_meshes(meshes, 0.1)
    return wall, _load(tmp_path, wall, "wall.ply")


def test_the_nearest_frame_in_time_earlier_on_a_tie():
    from nidar_mi.resim.moving import nearest_frame

    train = [0, 1, 2, 3, 4, 6, 7, 10]
    assert [nearest_frame(k, train) for k in (5, 8, 9, 12, -1)] == [4, 7, 10, 10, 0]
    with pytest.raises(ValueError):
        nearest_frame(3, [])


def test_unexplained_returns_follow_the_samples_rule():
    from nidar_mi.resim.moving import unexplained_returns

    # gap |t - d| * max(cos, 0.05) against 0.1 m: on the surface, 0.1 m in front of it seen
    # head-on (0.1: explained), 0.2 m (not), 1 m at grazing cos 0.02 (0.05 counted: explained),
    # 3 m at it (not), no hit (not)
    t = np.array([10.0, 10.1, 10.2, 11.0, 13.0, np.inf])
    cos = np.array([1.0, 1.0, 1.0, 0.02, 0.02, 0.0])
    d = np.full(6, 10.0)
    np.testing.assert_array_equal(
        unexplained_returns(t, cos, d), [False, False, True, False, True, True]
    )


def test_a_panel_that_left_comes_back_at_its_time(variant, tmp_path):
    from nidar_mi.resim.carve import hit_depths
    from nidar_mi.resim.mesh import Mesh
    from nidar_mi.resim.moving import moving_surfaces

    wall, static = _wall(tmp_path)
    xyz, grid, rays, panel = _rays(4)  # the training frame nearest to held-out frame 5
    moving = moving_surfaces(xyz, grid, rays, static, 4, wrap=False)[0]
    v = moving.mesh.vertices
    assert len(moving.mesh.faces) > 100
    np.testing.assert_allclose(v[:, 1], PANEL_Y, atol=1e-9)  # the panel and nothing of the wall
    assert panel[moving.returns].all()
    np.testing.assert_allclose(v, xyz[moving.returns] + _pose(4)[:3, 3], atol=1e-9)
    assert np.isin(np.flatnonzero(panel), moving.returns).mean() >= 0.95  # its edge may be lost

    # held-out frame 5's beams cast into the wall and the panel: on the panel where it is,
    # on the wall elsewhere (analytic ranges). The panel's mesh lacks a border strip one beam
    # wide (the triangles joining it to the wall have a corner the wall explains): of its
    # 57 x 33 beams about 55 x 31 are covered, 91 %
    both = Mesh(
        np.concatenate([wall.vertices, v]),
        np.concatenate([wall.faces, moving.mesh.faces + len(wall.vertices)]),
    )
    _, _, beams, panel5 = _rays(5)
    t = hit_depths(_load(tmp_path, both, "both.ply"), beams)[0]
    close = np.abs(t - beams.range_m) < 0.02
    assert close[panel5].mean() >= 0.9
    assert close[~panel5].mean() >= 0.99
    t_static = hit_depths(static, beams)[0]
    assert (np.abs(t_static - beams.range_m) < 0.02)[panel5].mean() == 0.0  # the wall alone

    # a frame after the panel left sees nothing the wall does not explain
    xyz, grid, rays, _ = _rays(12)
    assert len(moving_surfaces(xyz, grid, rays, static, 12, wrap=False)[0].mesh.faces) == 0


def test_moving_reflectance_inverts_the_return_model(variant, tmp_path):
    from nidar_mi.resim.inversion import KNOTS_M, SensorFit
    from nidar_mi.resim.mesh import Mesh, scan_triangles
    from nidar_mi.resim.moving import MovingSurfaces, moving_rho

    xyz, grid, rays, panel = _rays(4)
    tris = scan_triangles(xyz, grid)
    tris = tris[panel[tris].all(axis=1)]
    used = np.unique(tris)
    remap = np.full(len(xyz), -1)
    remap[used] = np.arange(len(used))
    world = xyz[used] + _pose(4)[:3, 3]
    moving = MovingSurfaces(4, Mesh(world, remap[tris]), used)
    rng = np.random.default_rng(3)
    sensor = SensorFit(
        gains=rng.uniform(0.7, 1.3, RINGS),
        knots_m=KNOTS_M,
        response=rng.uniform(0.5, 1.5, len(KNOTS_M)),
        offset=0.02,
        threshold=0.01,
        noise=0.01,
    )
    rho = 0.2 + 0.05 * world[:, 0]  # a gradient across the panel
    d = rays.range_m[used]
    cos = np.abs(rays.direction[used, 1])  # the panel faces -y
    y = np.zeros(len(xyz))
    y[used] = sensor.gains[rays.ring[used]] * sensor.response_at(d) * rho * cos - sensor.offset

    def load(mesh):
        return _load(tmp_path, mesh, "moving.ply")

    # ρ = (y + b) / (G_l r(d) cos θ), cos θ on the plane's normal: float32 rounding
    np.testing.assert_allclose(moving_rho(moving, rays, y, sensor, load), rho, rtol=1e-5)
    # a return read as 0 says E <= b, and it was detected (E >= T): E = max(b, 2 T), here
    # b = 0.02, over its unit
    y0 = y.copy()
    y0[used[0]] = 0.0
    unit = sensor.gains[rays.ring[used[0]]] * sensor.response_at(d[0]) * cos[0]
    got = moving_rho(moving, rays, y0, sensor, load)[0]
    np.testing.assert_allclose(got, 0.02 / unit, rtol=1e-5)
    empty = MovingSurfaces(4, Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64)), np.zeros(0, int))
    assert moving_rho(empty, rays, y, sensor, load).shape == (0,)

    # seen again by the partner frame (frame 5's beams, its panel moved 1 m towards the
    # sensor, each vertex's shift saying so, and its ρ 0.1 higher there): the mean of its own
    # ρ and that of the partner's nearest return, inverted on the panel's normal with that
    # return's laser and range
    from scipy.spatial import cKDTree

    from nidar_mi.resim.beam_rays import Rays

    _, _, rays5, panel5 = _rays(5)
    on = np.flatnonzero(panel5)
    w5 = rays5.origin[on] + rays5.direction[on] * rays5.range_m[on, None]
    d5 = rays5.range_m[on]
    y5 = sensor.gains[rays5.ring[on]] * sensor.response_at(d5) * (0.3 + 0.05 * w5[:, 0])
    y5 = y5 * np.abs(rays5.direction[on, 1]) - sensor.offset
    step = np.array([0.0, -1.0, 0.0])
    moved5 = Rays(rays5.origin[on] + step, rays5.direction[on], d5, rays5.ring[on], rays5.frame[on])
    expect = 0.5 * (rho + 0.3 + 0.05 * w5[cKDTree(w5).query(world)[1], 0])
    shift = np.tile(step, (len(world), 1))
    got = moving_rho(moving, rays, y, sensor, load, (moved5, y5, shift))
    np.testing.assert_allclose(got, expect, rtol=1e-5)
    # without the shift its returns lie 1 m off the vertices: each keeps its own return's ρ
    got = moving_rho(moving, rays, y, sensor, load, (moved5, y5, 0 * shift))
    np.testing.assert_allclose(got, rho, rtol=1e-5)
    # the shift on the panel's left half alone: that half averaged, the right half its own
    left = world[:, 0] < 0
    got = moving_rho(moving, rays, y, sensor, load, (moved5, y5, shift * left[:, None]))
    assert 0.3 < left.mean() < 0.7
    np.testing.assert_allclose(got, np.where(left, expect, rho), rtol=1e-5)


def test_the_partner_frame_times_the_motion_from_the_other_side_or_before():
    from nidar_mi.resim.moving import partner_frame

    train = [0, 1, 2, 3, 4, 6, 7, 10]
    # between training frames: the nearest on the held-out frame's other side
    assert partner_frame(5, 4, train) == 6 and partner_frame(8, 7, train) == 10
    assert partner_frame(9, 10, train) == 7
    # past either end: the nearest on the nearest frame's side away from it
    assert partner_frame(12, 10, train) == 7 and partner_frame(-2, 0, train) == 1
    assert partner_frame(5, 3, [3]) is None


def _blob(centre, n=12, seed=0):
    """A curved patch of (n x n) vertices around ``centre``, its grid's triangles."""
    from nidar_mi.resim.mesh import Mesh

    u, v = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-0.6, 0.6, n), indexing="ij")
    xyz = np.stack([u, 0.3 * u**2 + 0.1 * v, v], -1).reshape(-1, 3) + centre
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, 1:].ravel(),
    )
    return Mesh(xyz, np.concatenate([np.column_stack([a, b, c]), np.column_stack([b, d, c])]))


def test_objects_are_found_where_they_went():
    """Two objects seen again 1.4 m and 0.5 m on (part of the first seen, a third object
    beside them): each one's translation within 1 cm; an object not seen again, and one that
    went farther than the fastest motion allowed, stay put."""
    from nidar_mi.resim.mesh import Mesh, compact, merge_meshes
    from nidar_mi.resim.moving import object_labels, track_shifts

    car, van, gone = _blob([5.0, 0, 0]), _blob([0.0, 6, 0]), _blob([-8.0, -8, 0])
    moving = merge_meshes([car, van, gone])
    assert len(np.unique(object_labels(moving))) == 3
    go_car, go_van = np.array([1.4, 0.2, 0.0]), np.array([0.0, -0.5, 0.05])
    half = Mesh(car.vertices + go_car, car.faces[: len(car.faces) // 2])  # its front alone
    target = merge_meshes(
        [compact(half), Mesh(van.vertices + go_van, van.faces), _blob([9.0, 9, 0])]
    )
    got = track_shifts(moving, target, max_shift_m=3.0)
    n = len(car.vertices)
    np.testing.assert_allclose(got[:n], np.tile(go_car, (n, 1)), atol=0.01)
    np.testing.assert_allclose(got[n : 2 * n], np.tile(go_van, (n, 1)), atol=0.01)
    np.testing.assert_array_equal(got[2 * n :], 0.0)
    slow = track_shifts(moving, target, max_shift_m=1.0)
    np.testing.assert_array_equal(slow[:n], 0.0)  # 1.4 m: too far
    np.testing.assert_allclose(slow[n : 2 * n], np.tile(go_van, (n, 1)), atol=0.01)
    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    np.testing.assert_array_equal(track_shifts(moving, empty, 3.0), 0.0)
