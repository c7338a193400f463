"""A tracked object's trail in the static surfaces, on constructed meshes with known answers: a
car's flank (a vertical panel facing the sensor, 2 m long) passing along x at -0.75 m per
frame, the layers two earlier frames left of it where no later ray reached, the road under it,
a wall behind it facing the same way and a pole beside its path facing across it."""

from __future__ import annotations

import numpy as np
import pytest

SPEED = -0.75  # m per frame along x
FLANK_Y, WALL_Y = 2.0, 4.0
FLANK_X, FLANK_Z = (0.0, 2.0), (-1.5, 0.0)  # the flank at the moving frame's time (m)


def _grid(x0, x1, a0, a1, step, place):
    """A regular triangulated patch: ``place(u, v) -> (N, 3)`` over u in [x0, x1], v in
    [a0, a1] at ``step`` m."""
    from nidar_mi.resim.mesh import Mesh

    u = np.arange(x0, x1 + 1e-9, step)
    v = np.arange(a0, a1 + 1e-9, step)
    uu, vv = np.meshgrid(u, v, indexing="ij")
    verts = place(uu.ravel(), vv.ravel())
    nu, nv = len(u), len(v)
    i, j = np.meshgrid(np.arange(nu - 1), np.arange(nv - 1), indexing="ij")
    a = (i * nv + j).ravel()
    faces = np.concatenate(
        [np.stack([a, a + nv, a + 1], 1), np.stack([a + 1, a + nv, a + nv + 1], 1)]
    )
    return Mesh(verts, faces)


def _flank(dx: float, step: float = 0.1):
    """The flank shifted by ``dx`` along x: a plane y = FLANK_Y (normal along y)."""
    return _grid(
        FLANK_X[0] + dx, FLANK_X[1] + dx, *FLANK_Z, step,
        lambda u, v: np.stack([u, np.full_like(u, FLANK_Y), v], 1),
    )  # fmt: skip


def _scene():
    """The static surfaces (each part's mesh, merged in this order) and the moving flank."""
    from nidar_mi.resim.mesh import merge_meshes

    parts = {
        # two earlier frames' layers: the flank 1 and 2 steps back (x + 0.75, x + 1.5), on a
        # slightly coarser grid than the moving mesh (another scan's sampling)
        "ghost1": _flank(-1 * SPEED, 0.12),
        "ghost2": _flank(-2 * SPEED, 0.12),
        "road": _grid(
            -4.0, 6.0, 0.0, 4.0, 0.2, lambda u, v: np.stack([u, v, np.full_like(u, -1.5)], 1)
        ),
        "wall": _grid(
            -4.0, 6.0, -1.5, 1.5, 0.2, lambda u, v: np.stack([u, np.full_like(u, WALL_Y), v], 1)
        ),
        # a pole's face across the path (normal along x) 0.1 m past the flank's end two frames
        # back: within TRAIL_M of the trail, facing across it
        "pole": _grid(
            1.9,
            2.1,
            -1.5,
            1.0,
            0.1,
            lambda u, v: np.stack([np.full_like(u, FLANK_X[1] - 2 * SPEED + 0.1), u, v], 1),
        ),
    }
    names = list(parts)
    static = merge_meshes([parts[n] for n in names])
    owner = np.concatenate([np.full(len(parts[n].faces), i) for i, n in enumerate(names)])
    return static, owner, names, _flank(0.0)


@pytest.mark.parametrize("at", [1.0, 2.0])
def test_the_trail_of_a_passing_flank_is_hidden_and_nothing_else(at):
    from nidar_mi.resim.moving import TRAIL_M, trail_faces

    static, owner, names, flank = _scene()
    velocity = np.tile([SPEED, 0.0, 0.0], (len(flank.vertices), 1))
    hidden = trail_faces(static, flank, velocity, steps=[-2, -1, 0], at=at)
    corners_x = static.vertices[static.faces][..., 0]
    # where the flank stands at the held-out time, x in [at * SPEED, 2 + at * SPEED]
    now_x1 = FLANK_X[1] + at * SPEED
    overlap = 0
    for i, name in enumerate(names):
        mine = owner == i
        if name.startswith("ghost"):
            # a ghost triangle whose corners all lie past the flank's end then (by more than
            # TRAIL_M) is the trail: hidden; one overlapping the flank then is kept
            past = mine & (corners_x.min(axis=1) > now_x1 + TRAIL_M + 1e-9)
            kept = mine & (corners_x.max(axis=1) < now_x1 + TRAIL_M - 0.13)
            assert past.sum() > 100 and hidden[past].all(), name
            assert not hidden[kept].any(), name
            overlap += kept.sum()
        else:
            assert not hidden[mine].any(), name  # road, wall, pole
    # one step on, the first layer overlaps the flank's new place (x 0.75 to 1.25): kept there
    assert overlap > 50 if at == 1.0 else overlap == 0


def test_nothing_is_hidden_for_an_object_not_tracked_or_steps_out_of_reach():
    from nidar_mi.resim.moving import TRAIL_FRAMES, trail_faces

    static, _, _, flank = _scene()
    still = np.zeros((len(flank.vertices), 3))
    assert not trail_faces(static, flank, still, steps=[-2, -1], at=1.0).any()
    velocity = np.tile([SPEED, 0.0, 0.0], (len(flank.vertices), 1))
    # only frames within TRAIL_FRAMES steps are followed; the ghosts lie 1 and 2 steps back
    far = [-(TRAIL_FRAMES + 1), -(TRAIL_FRAMES + 2)]
    assert not trail_faces(static, flank, velocity, steps=far, at=1.0).any()


def test_vertex_normals_of_a_plane_and_an_unused_vertex():
    from nidar_mi.resim.mesh import Mesh
    from nidar_mi.resim.moving import vertex_normals

    flank = _flank(0.0)
    n = vertex_normals(flank)
    np.testing.assert_allclose(np.abs(n[:, 1]), 1.0, atol=1e-12)
    extra = Mesh(np.vstack([flank.vertices, [[9.0, 9.0, 9.0]]]), flank.faces)
    np.testing.assert_array_equal(vertex_normals(extra)[-1], 0.0)


def test_grown_surfaces_carry_their_objects_velocity():
    from nidar_mi.resim.mesh import Mesh
    from nidar_mi.resim.moving import OBJECT_GAP_M, MovingSurfaces, carried_velocity

    # frame returns 2, 5, 9 moved (two objects: 2 and 5 at 7 m/frame-step along x, 9 still);
    # grown by returns 7 (beside 5), 11 (beside the untracked 9) and 13 (far from all)
    pts = {2: [0.0, 0, 0], 5: [1.0, 0, 0], 9: [10.0, 0, 0], 7: [1.2, 0, 0], 11: [10.1, 0, 0]}
    pts[13] = [1.0 + 2 * OBJECT_GAP_M, 5.0, 0]
    first = MovingSurfaces(
        3, Mesh(np.array([pts[i] for i in (2, 5, 9)]), np.zeros((0, 3), int)), np.array([2, 5, 9])
    )
    velocity = np.array([[7.0, 0, 0], [7.0, 0, 0], [0.0, 0, 0]])
    ids = np.array([2, 5, 7, 9, 11, 13])
    grown = MovingSurfaces(3, Mesh(np.array([pts[i] for i in ids]), np.zeros((0, 3), int)), ids)
    out = carried_velocity(grown, first, velocity)
    expect = {2: 7.0, 5: 7.0, 7: 7.0, 9: 0.0, 11: 0.0, 13: 0.0}
    np.testing.assert_array_equal(out[:, 0], [expect[i] for i in ids])
    np.testing.assert_array_equal(out[:, 1:], 0.0)
