"""Moving objects out of the fused surfaces, on a constructed drive with known answers: a wall
at y = 8 m seen by a sensor driving along x, and a 2 m panel at y = 4 m that stands in front of
it for the first frames and is gone in the later ones."""

from __future__ import annotations

import numpy as np

WALL_Y, BOX_Y = 8.0, 4.0
BOX_HALF = 1.0  # the panel spans x in [-1, 1], z in [-1, 1] m (world)
FRAMES, BOX_UNTIL = 16, 7  # the panel is there in frames 0-6, gone in 7-15
STEP = 0.25  # m of travel along x per frame
RINGS, COLS = 48, 240  # beams 0.85 deg apart in elevation, 0.5 deg in azimuth


def _scan(k: int):
    """Frame k's returns (LiDAR frame: the sensor at (x_k, 0, 0), axes as the world's) on a
    RINGS x COLS grid looking at +y; their ScanGrid and ranges."""
    from nidar_mi.resim.range_image import ScanGrid

    el = np.radians(np.linspace(20.0, -20.0, RINGS))[:, None]
    az = np.radians(np.linspace(30.0, 150.0, COLS))[None, :]
    d = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el) + 0 * az], -1)
    d = d.reshape(-1, 3)
    t = WALL_Y / d[:, 1]
    if k < BOX_UNTIL:
        tb = BOX_Y / d[:, 1]
        x, z = k * STEP + tb * d[:, 0], tb * d[:, 2]
        t = np.where((np.abs(x) <= BOX_HALF) & (np.abs(z) <= BOX_HALF), tb, t)
    ring, col = np.meshgrid(np.arange(RINGS), np.arange(COLS), indexing="ij")
    return d * t[:, None], ScanGrid(ring.ravel(), col.ravel(), RINGS, 3 * COLS, True), d, t


def _pose(k: int) -> np.ndarray:
    T = np.eye(4)
    T[0, 3] = k * STEP
    return T


def _drive(train):
    """The fused mesh of the frames ``train`` and their return rays (world)."""
    from nidar_mi.resim.beam_rays import Rays, concat
    from nidar_mi.resim.mesh import fuse_meshes, scan_mesh

    meshes, rays = [], []
    for k in train:
        xyz, grid, d, t = _scan(k)
        meshes.append(scan_mesh(xyz, grid).transformed(_pose(k)))
        o = np.tile(_pose(k)[:3, 3], (len(d), 1))
        rays.append(Rays(o, d, t, grid.ring, np.full(len(d), k)))
    return fuse_meshes(meshes, 0.1), concat(rays)


def _loader(tmp_path):
    from nidar_mi.resim.scene_files import write_surfaces_ply
    from nidar_mi.resim.surfaces import surface_scene

    def load(mesh):
        write_surfaces_ply(tmp_path / "m.ply", mesh, {"rho": np.full(len(mesh.vertices), 0.5)})
        return surface_scene(tmp_path / "m.ply")

    return load


def _panel_faces(mesh) -> int:
    return int((mesh.vertices[mesh.faces][:, :, 1].mean(axis=1) < 6.0).sum())


def test_a_panel_that_left_is_removed_and_the_wall_behind_it_stays(variant, tmp_path):
    from nidar_mi.resim.carve import carve, hit_depths
    from nidar_mi.resim.transient import remove_transient

    held = 9  # a later frame, held out: it sees the wall where the panel stood
    train = [k for k in range(FRAMES) if k != held]
    fused, rays = _drive(train)
    load = _loader(tmp_path)
    carved, _ = carve(fused, rays, load)
    # weighed over all frames, the panel's rays end on it more often than they pass through it
    assert _panel_faces(carved) > 100
    wall_before = len(carved.faces) - _panel_faces(carved)
    clean, removed = remove_transient(carved, rays, load)
    assert _panel_faces(clean) == 0 and sum(removed) == _panel_faces(carved)
    assert len(clean.faces) == wall_before  # not one wall triangle lost

    # the held-out frame's beams, cast into the surfaces, land on the wall (analytic ranges)
    from nidar_mi.resim.beam_rays import Rays

    _, grid, d, t_wall = _scan(held)
    o = np.tile(_pose(held)[:3, 3], (len(d), 1))
    beams = Rays(o, d, t_wall, grid.ring, np.full(len(d), held))
    on_wall = [np.abs(hit_depths(load(m), beams)[0] - t_wall) < 0.02 for m in (carved, clean)]
    assert on_wall[0].mean() < 0.95  # carving alone: the panel hides the wall
    assert on_wall[1].mean() >= 0.999


def test_votes_and_runs_per_frame():
    from nidar_mi.resim.transient import end_through_run, frame_votes

    # element 0: frames 0-2 on, 3-5 through (it left); 1: through and on alternating, from
    # through, ending on (a run at the start: it came, and stays); 2: on, through, through, on
    # (a stray stretch in the middle); 3: unseen
    prim = np.array([0, 0, 0, 0, 0, 0, 0, 1, 1, 1, 1, 1, 1, 2, 2, 2, 2])
    frame = np.array([0, 1, 2, 3, 4, 5, 5, 0, 1, 2, 3, 4, 5, 0, 1, 2, 3])
    through = np.array([0, 0, 0, 1, 1, 1, 1, 1, 0, 1, 0, 1, 0, 0, 1, 1, 0], bool)
    tri, frm, vote = frame_votes(prim, frame, through, ~through)
    np.testing.assert_array_equal(tri, [0] * 6 + [1] * 6 + [2] * 4)
    np.testing.assert_array_equal(frm, list(range(6)) * 2 + list(range(4)))
    np.testing.assert_array_equal(vote, [1, 1, 1, -1, -1, -1, -1, 1, -1, 1, -1, 1, 1, -1, -1, 1])
    np.testing.assert_array_equal(end_through_run(tri, vote, 4), [3, 0, 0, 0])
    # the same votes in reverse time: element 1 now ends with one through vote, 0 starts with 3
    back = np.lexsort((-frm, tri))
    np.testing.assert_array_equal(end_through_run(tri[back], vote[back], 4), [0, 1, 0, 0])
