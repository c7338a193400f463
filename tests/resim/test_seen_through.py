"""What the training scans next to a held-out frame saw through (:mod:`nidar_mi.resim.seen_through`).

A sensor on a line (x = 0, 0.5, 1 m; the middle frame held out) scans a wall 10 m ahead. The
held-out frame's re-simulation also holds a box 5 m ahead that the real scans never saw (a layer
that is not there any more): its points on the box's faces, and only those, are seen through
by the frames on either side, and the box's triangles hidden, the wall's kept; when the real
scans see the box too, nothing is. Hand-placed
returns around one probe check the margin.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from nidar_mi.resim.directions import direction_tree
from nidar_mi.resim.range_image import ScanGrid
from nidar_mi.resim.seen_through import THROUGH_M, SeenThrough, seen_through
from tests.helpers.wall_scans import drive_of

ELEVATIONS = np.arange(2.0, -8.01, -0.4)  # ring 0 highest, degrees
COLUMNS = 1800  # 0.2 degrees
BOX = (np.array([4.8, -0.5, -0.5]), np.array([5.2, 0.5, 0.5]))  # m
WALL_X = 10.0


def _scan(origin: np.ndarray, box: bool):
    """(N, 3) LiDAR-frame returns from ``origin`` (no rotation) on the wall, and on the box's
    face where the beams meet it first when ``box``; their grid."""
    az = np.radians(-180.0 + (np.arange(COLUMNS) + 0.5) * 360.0 / COLUMNS)
    th = np.radians(ELEVATIONS)[:, None]
    d = np.stack(
        np.broadcast_arrays(np.cos(th) * np.cos(az), np.cos(th) * np.sin(az), np.sin(th)), -1
    )
    ring, col = np.meshgrid(np.arange(len(ELEVATIONS)), np.arange(COLUMNS), indexing="ij")
    ahead = d[..., 0] > 0.5
    u = d[ahead]
    t = (WALL_X - origin[0]) / u[:, 0]
    if box:
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (BOX[0] - origin) / u, (BOX[1] - origin) / u
        lo = np.nanmax(np.minimum(t1, t2), axis=1)
        hi = np.nanmin(np.maximum(t1, t2), axis=1)
        meets = (hi >= np.maximum(lo, 0.0)) & (lo < t)
        t = np.where(meets, lo, t)
    grid = ScanGrid(ring[ahead], col[ahead], len(ELEVATIONS), COLUMNS, True)
    return u * t[:, None], grid


def _on_box(p: np.ndarray) -> np.ndarray:
    return np.all((p >= BOX[0] - 1e-6) & (p <= BOX[1] + 1e-6), axis=1)


def _drive(real_box: bool):
    origins = [np.array(o, float) for o in ([0, 0, 0], [0.5, 0, 0], [1, 0, 0])]
    scans = [_scan(o, box=real_box) for o in origins]
    frames, poses = drive_of(scans, origins, ELEVATIONS, COLUMNS)
    sim, _ = _scan(origins[1], box=True)  # the re-simulation holds the box
    in_view = np.abs(np.degrees(np.arctan2(sim[:, 1], sim[:, 0]))) < 45.0
    return frames, poses, sim[in_view], origins


def test_a_layer_the_scans_saw_through_is_hidden():
    frames, poses, sim, origins = _drive(real_box=False)
    world = sim + origins[1]
    box = _on_box(world)
    assert box.sum() > 200
    test = SeenThrough(frames, poses, [0, 2])
    # every beam of frames 0 and 2 around a point on the box reached the wall 5 m behind it;
    # the wall's own returns are never seen through
    assert np.array_equal(test.points(1, world), box)
    # as a mesh: a patch of the box's front face (x = 4.8 m) and of the wall behind it, two
    # triangles each; the face's are hidden, the wall's kept
    y, z = (-0.4, 0.4), (-0.4, 0.1)  # inside the beams from frames 0 and 2
    quad = lambda x: np.array([[x, y[0], z[0]], [x, y[1], z[0]], [x, y[1], z[1]], [x, y[0], z[1]]])  # noqa: E731
    vertices = np.vstack([quad(BOX[0][0]), quad(WALL_X)])
    faces = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    assert test.faces(1, vertices, faces).tolist() == [True, True, False, False]
    assert test.hidden[1] == 2
    # again with the same evidence frames: the same answer; with other evidence, computed anew
    assert test.faces(1, vertices, faces).tolist() == [True, True, False, False]
    # frame 0's evidence is frame 2 alone (x = 1 m): the box 3.8 m ahead of it, the wall 9 m
    assert test.faces(0, vertices, faces).tolist() == [True, True, False, False]
    assert test._last[0] == (2,) and test.hidden[0] == 2


def test_a_surface_the_scans_saw_is_kept():
    frames, poses, sim, origins = _drive(real_box=True)
    assert not SeenThrough(frames, poses, [0, 2]).points(1, sim + origins[1]).any()


def test_a_scan_without_returns_sees_through_nothing():
    frames, poses, sim, origins = _drive(real_box=False)
    lost = SimpleNamespace(**{**vars(frames), "xyz": [frames.xyz[0][:0], *frames.xyz[1:]]})
    assert not SeenThrough(lost, poses, [0, 2]).points(1, sim + origins[1]).any()


def test_the_margin_on_hand_placed_returns():
    # a probe 5 m away; the scan's returns at 0.3 degrees on either side of it
    probe = np.array([[5.0, 0.0, 0.0]])
    a = np.radians([-0.3, 0.3])

    def through(ranges, margin=THROUGH_M):
        real = np.column_stack([np.cos(a), np.sin(a), 0 * a]) * np.asarray(ranges)[:, None]
        return bool(seen_through(probe, real, direction_tree(real), 0.7, margin)[0])

    assert through([6.1, 8.0])  # all more than 1 m beyond
    assert not through([5.9, 8.0])  # one within the margin
    assert not through([4.0, 8.0])  # one in front of it
    assert through([5.9, 8.0], margin=0.5)
    # the return nearest in direction beyond, another within the margin or in front: not
    b = np.radians([0.1, 0.5])
    for second in (5.9, 4.0):
        real = np.column_stack([np.cos(b), np.sin(b), 0 * b]) * np.array([[8.0], [second]])
        assert not seen_through(probe, real, direction_tree(real), 0.7)[0]
    # no return within the radius: a hole, not seen through
    far = 7.0 * np.array([[np.cos(np.radians(2.0)), np.sin(np.radians(2.0)), 0.0]])
    assert not seen_through(probe, far, direction_tree(far), 0.7)[0]
