"""The layout fit, the range-image mesh, the fusion and the carving on constructed cases with
known answers."""

from __future__ import annotations

import numpy as np


def _beam_points(elev_deg, v, dist):
    """Velodyne point model: laser at elevation θ with vertical offset v, ranges ``dist``
    along azimuths spread over the front: (N, 3) points."""
    th = np.radians(elev_deg)
    phi = np.linspace(-1.2, 1.2, len(dist))
    rho = dist * np.cos(th) - v * np.sin(th)
    z = dist * np.sin(th) + v * np.cos(th)
    return np.column_stack([rho * np.cos(phi), rho * np.sin(phi), z])


def test_layout_recovers_elevations_and_offsets():
    from nidar_mi.resim.laser_layout import fit_layout

    rng = np.random.default_rng(0)
    elev = np.linspace(2.0, -20.0, 8)
    offs = np.where(np.arange(8) < 4, 0.21, 0.12)
    pts, rings = [], []
    for r in range(8):
        p = _beam_points(elev[r], offs[r], rng.uniform(3.0, 40.0, 300))
        p[:, 2] += rng.normal(0, 0.002, len(p))
        pts.append(p)
        rings.append(np.full(len(p), r))
    lay = fit_layout([np.concatenate(pts)], [np.concatenate(rings)], 8)
    np.testing.assert_allclose(lay.elevation_deg, elev, atol=0.01)
    np.testing.assert_allclose(lay.vertical_offset_m, offs, atol=0.003)


def _plane_scan(rings=6, cols=40, x0=10.0):
    """Returns of a wall at x = x0 on a (rings x cols) grid; its ScanGrid."""
    from nidar_mi.resim.range_image import ScanGrid

    el = np.radians(np.linspace(5, -5, rings))[:, None]
    az = np.radians(np.linspace(-10, 10, cols))[None, :]
    d = x0 / (np.cos(el) * np.cos(az))
    xyz = np.stack([d * np.cos(el) * np.cos(az), d * np.cos(el) * np.sin(az), d * np.sin(el)], -1)
    ring, col = np.meshgrid(np.arange(rings), np.arange(cols), indexing="ij")
    grid = ScanGrid(ring.ravel(), col.ravel(), rings, 4 * cols, True)
    return xyz.reshape(-1, 3), grid


def test_range_image_mesh_of_a_wall_is_two_triangles_per_cell_facing_the_sensor():
    from nidar_mi.resim.mesh import scan_mesh

    xyz, grid = _plane_scan()
    m = scan_mesh(xyz, grid)
    assert len(m.faces) == 2 * 5 * 39
    v = m.vertices[m.faces]
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    assert np.all(n[:, 0] < 0)  # towards the sensor at the origin
    np.testing.assert_allclose(m.vertices[:, 0], 10.0)


def test_a_depth_jump_is_not_bridged():
    from nidar_mi.resim.mesh import scan_mesh

    xyz, grid = _plane_scan()
    right = np.arctan2(xyz[:, 1], xyz[:, 0]) > 0
    xyz[right] *= 3.0  # the right half 20 m further: a discontinuity along the rays
    m = scan_mesh(xyz, grid)
    d = np.linalg.norm(m.vertices[m.faces], axis=2)
    assert np.all(d.max(axis=1) / d.min(axis=1) < 1.5)


def test_fusing_a_mesh_with_itself_gives_it_back_and_carving_removes_a_blocker(variant, tmp_path):
    from nidar_mi.resim.beam_rays import Rays
    from nidar_mi.resim.carve import carve
    from nidar_mi.resim.mesh import Mesh, fuse_meshes, scan_mesh
    from nidar_mi.resim.scene_files import write_surfaces_ply
    from nidar_mi.resim.surfaces import surface_scene

    xyz, grid = _plane_scan()
    wall = scan_mesh(xyz, grid)
    fused = fuse_meshes([wall, wall], 0.01)
    assert len(fused.faces) == len(wall.faces) and len(fused.vertices) == len(wall.vertices)
    blocker = Mesh(
        np.array([[5.0, -0.3, -0.3], [5.0, 0.3, -0.3], [5.0, 0.0, 0.3]]), np.array([[0, 1, 2]])
    )
    both = Mesh(
        np.concatenate([wall.vertices, blocker.vertices]),
        np.concatenate([wall.faces, blocker.faces + len(wall.vertices)]),
    )
    d = np.linalg.norm(xyz, axis=1)
    rays = Rays(np.zeros_like(xyz), xyz / d[:, None], d, grid.ring, np.zeros(len(d), int))

    def load(mesh):
        write_surfaces_ply(tmp_path / "m.ply", mesh, {"rho": np.full(len(mesh.vertices), 0.5)})
        return surface_scene(tmp_path / "m.ply")

    carved, removed = carve(both, rays, load)
    assert removed[0] == 1 and len(carved.faces) == len(wall.faces)


def test_crease_vertices_are_the_box_edges_whatever_the_winding():
    """A box made of quad grids (0.25 m cells; corners shared after fusing by position): the
    vertices on an edge of the box (two of their coordinates on the box's bounds) are creases,
    the others are not; reversing half of the triangles changes nothing; a plane has none."""
    from nidar_mi.resim.mesh import Mesh, crease_vertices, fuse_meshes
    from nidar_mi.resim.synthetic import _grid

    lo, hi = np.zeros(3), np.array([2.0, 1.0, 1.5])
    sides = [
        _grid((0, 0, 0), (2, 0, 0), (0, 1, 0), 8, 4),
        _grid((0, 0, 1.5), (2, 0, 0), (0, 1, 0), 8, 4),
        _grid((0, 0, 0), (2, 0, 0), (0, 0, 1.5), 8, 6),
        _grid((0, 1, 0), (2, 0, 0), (0, 0, 1.5), 8, 6),
        _grid((0, 0, 0), (0, 1, 0), (0, 0, 1.5), 4, 6),
        _grid((2, 0, 0), (0, 1, 0), (0, 0, 1.5), 4, 6),
    ]
    box = fuse_meshes(sides, voxel=0.01)
    v = box.vertices
    on_bound = (np.isclose(v, lo, atol=1e-6) | np.isclose(v, hi, atol=1e-6)).sum(axis=1)
    np.testing.assert_array_equal(crease_vertices(box), on_bound >= 2)
    flipped = box.faces.copy()
    flipped[::2] = flipped[::2, ::-1]
    np.testing.assert_array_equal(crease_vertices(Mesh(v, flipped)), on_bound >= 2)
    assert not crease_vertices(sides[0]).any()


def test_fusing_meshes_without_a_vertex_gives_an_empty_mesh():
    """Scans that make no triangle fuse into nothing, for the caller to refuse in one line."""
    from nidar_mi.resim.mesh import Mesh, fuse_meshes

    empty = Mesh(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    fused = fuse_meshes([empty, empty], 0.1)
    assert fused.vertices.shape == (0, 3) and fused.faces.shape == (0, 3)
