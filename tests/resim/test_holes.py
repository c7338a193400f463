"""The holes of the training scans next to a held-out frame (:mod:`nidar_mi.resim.holes`).

A sensor on a line (x = 0, 0.5, 1 m; the middle frame held out) scans a wall 10 m ahead
through a dark box 5 m ahead that returns nothing; a fourth training frame 3 m to the side sees
the whole wall on the beams the box hides from the others. The held-out frame's re-simulation,
which does not hold the box, returns on the wall everywhere. Checked against ray-box
intersection: no dropped return is one the box leaves in view (a return deeper than the radius
inside the box's shadow from both neighbours is, by convexity, hidden from the frame between
them), and at least half of those the box hides are dropped (measured: 74 % of 1 452), also when
the box returns on every third beam it hides, returns that stop 5 m short of the wall; the beams no
training scan returned on, the columns past the drive's coverage and the surfaces that moved
are never dropped. An evidence frame turned to look back cannot see the points and abstains:
the other decides alone (exactly its own holes of the reach test's kind; a box that returns
nothing drops nothing alone), where no frame can see them none is dropped,
and without abstaining nothing is. Beams with offsets: a point placed on each ring's beam 3 m away comes back
on that ring, where the nearest elevation from the sensor's centre is off by several rings.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from nidar_mi.resim.holes import (
    HOLE_RADIUS_DEG,
    SIDE_DEG,
    Holes,
    beam_rings,
    hole_frames,
    in_hole,
    out_of_view,
    returned_beams,
    returned_share,
)
from nidar_mi.resim.laser_layout import RingLayout
from nidar_mi.resim.range_image import ScanGrid
from tests.helpers.wall_scans import drive_of

ELEVATIONS = np.arange(2.0, -8.01, -0.4)  # ring 0 highest, degrees
COLUMNS = 1800  # 0.2 degrees
BOX = (np.array([4.8, -0.5, -0.5]), np.array([5.2, 0.5, 0.5]))  # the dark box, m
WALL_X = 10.0


@pytest.mark.parametrize(
    ("k", "train", "want"),
    [
        (5, [0, 1, 4, 7, 9], [4, 7]),  # inside the drive: the nearest before and after
        (12, [0, 1, 4, 7, 9], [7, 9]),  # past its end: the last two
        (0, [3, 5, 8], [3, 5]),  # before its start: the first two
        (4, [2], [2]),  # a single training frame
    ],
)
def test_hole_frames(k, train, want):
    assert hole_frames(k, train) == want


def _beam_points(t: float, az_deg: float, elev, offsets) -> np.ndarray:
    """(R, 3) the points ``t`` m along each ring's beam at azimuth ``az_deg``."""
    th, ph = np.radians(elev), np.radians(az_deg)
    d = np.column_stack([np.cos(th) * np.cos(ph), np.cos(th) * np.sin(ph), np.sin(th)])
    o = offsets[:, None] * np.column_stack(
        [-np.sin(th) * np.cos(ph), -np.sin(th) * np.sin(ph), np.cos(th)]
    )
    return o + t * d


def test_beam_rings_follow_the_offsets():
    offsets = np.linspace(0.2, -0.15, len(ELEVATIONS))
    pts = _beam_points(3.0, 30.0, ELEVATIONS, offsets)
    ring, off = beam_rings(pts, ELEVATIONS, offsets)
    assert np.array_equal(ring, np.arange(len(ELEVATIONS))) and off.max() < 1e-9
    centre = np.degrees(np.arcsin(pts[:, 2] / np.linalg.norm(pts, axis=1)))
    nearest = np.argmin(np.abs(centre[:, None] - ELEVATIONS[None, :]), axis=1)
    assert np.abs(nearest - np.arange(len(ELEVATIONS))).max() >= 3  # the offsets matter here


def _directions():
    """(rings, columns, 3) unit beam directions of the forward half (|azimuth| < 60°)."""
    az = np.radians(-180.0 + (np.arange(COLUMNS) + 0.5) * 360.0 / COLUMNS)
    th = np.radians(ELEVATIONS)[:, None]
    d = np.stack(
        np.broadcast_arrays(np.cos(th) * np.cos(az), np.cos(th) * np.sin(az), np.sin(th)), -1
    )
    return d


def _hits_box(o: np.ndarray, p: np.ndarray) -> np.ndarray:
    """(N,) bool: the segments from ``o`` to the points ``p`` cross the box (slab test)."""
    d = p - o
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (BOX[0] - o) / d, (BOX[1] - o) / d
    lo = np.nanmax(np.minimum(t1, t2), axis=1)
    hi = np.nanmin(np.maximum(t1, t2), axis=1)
    return (hi >= np.maximum(lo, 0.0)) & (lo <= 1.0)


def _box_entry(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """(N,) the distance along unit rays ``d`` from ``o`` to where they enter the box."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t1, t2 = (BOX[0] - o) / d, (BOX[1] - o) / d
    return np.nanmax(np.minimum(t1, t2), axis=1)


def _scan(origin: np.ndarray, box: bool, scatter: int = 0):
    """(N, 3) LiDAR-frame returns on the wall from ``origin`` (no rotation) and their grid;
    ``scatter``: the box returns on every ``scatter``-th ring and column it hides (0: none)."""
    d = _directions()
    ring, col = np.meshgrid(np.arange(len(ELEVATIONS)), np.arange(COLUMNS), indexing="ij")
    ahead = d[..., 0] > 0.5
    t = (WALL_X - origin[0]) / d[..., 0][ahead]
    p = d[ahead] * t[:, None]
    keep = np.ones(len(p), bool)
    if box:
        keep = ~_hits_box(origin, p + origin)
        if scatter:
            on = ~keep & (ring[ahead] % scatter == 0) & (col[ahead] % scatter == 0)
            p[on] = d[ahead][on] * _box_entry(origin, d[ahead][on])[:, None]
            keep |= on
    return p[keep], ScanGrid(ring[ahead][keep], col[ahead][keep], len(ELEVATIONS), COLUMNS, True)


def _drive(scatter: int = 0):
    origins = [np.array(o, float) for o in ([0, 0, 0], [0.5, 0, 0], [1, 0, 0], [0, 3, 0])]
    scans = [_scan(o, box=True, scatter=scatter) for o in origins]
    frames, poses = drive_of(scans, origins, ELEVATIONS, COLUMNS)
    sim, _ = _scan(origins[1], box=False)  # the re-simulation does not hold the box
    in_view = np.abs(np.degrees(np.arctan2(sim[:, 1], sim[:, 0]))) < 45.0
    return frames, poses, sim[in_view], origins


@pytest.fixture(scope="module")
def drive():
    return _drive()


def test_holes_drop_what_the_dark_box_hides(drive):
    frames, poses, sim, origins = drive
    holes = Holes(frames, poses, [0, 2, 3])
    drop = holes.mask(1, sim)
    hidden = _hits_box(origins[1], sim + origins[1])
    assert hidden.sum() > 200
    assert not (drop & ~hidden).any()  # nothing the box leaves in view
    assert drop[hidden].mean() >= 0.5  # most of what it hides (measured 0.74)
    assert holes.dropped[1] == drop.sum()


def test_scattered_returns_stop_short_of_the_wall():
    # the dark box returns on every third ring and column it hides: those returns lie in the
    # radius of nearly every hidden wall point, 5 m short of it; counting them (no reach test)
    # keeps most of the wall behind the box, counting only returns that reach the point drops it
    frames, poses, sim, origins = _drive(scatter=3)
    hidden = _hits_box(origins[1], sim + origins[1])
    drop = Holes(frames, poses, [0, 2, 3]).mask(1, sim)
    assert not (drop & ~hidden).any()  # nothing the box leaves in view
    assert drop[hidden].mean() >= 0.5  # measured 0.74, as with a box that returns nothing
    naive = Holes(frames, poses, [0, 2, 3], reach_m=None).mask(1, sim)
    assert naive[hidden].mean() <= 0.1  # measured 0.0


def _one_ring(az_deg, range_m):
    """(N, 3) returns at ``range_m`` on a single horizontal ring, and its (1, COLUMNS) beams."""
    a = np.radians(np.asarray(az_deg, float))
    col = np.floor((np.asarray(az_deg) + 180.0) * COLUMNS / 360.0).astype(int)
    returned = np.zeros((1, COLUMNS), bool)
    returned[0, col] = True
    return np.column_stack([np.cos(a), np.sin(a), 0 * a]) * np.asarray(range_m)[..., None], returned


def test_a_return_reaches_within_the_margin():
    # one probe 5 m away at azimuth 0.1 degrees (a column's centre); the scan's returns at
    # -0.3 and +0.5 degrees: 2 of the 7 beams within 0.7 degrees (columns of 0.2 degrees)
    layout = RingLayout(np.array([0.0]), np.zeros(1), np.ones(1))
    beams, cover = np.ones((1, COLUMNS), bool), np.ones(COLUMNS, bool)
    probe = 5.0 * np.array([[np.cos(np.radians(0.1)), np.sin(np.radians(0.1)), 0.0]])

    def got(az, rng, reach_m=1.0):
        real, returned = _one_ring(az, rng)
        return bool(
            in_hole(probe, real, beams, cover, layout, reach_m=reach_m, returned=returned)[0]
        )

    sparse = [-0.3, 0.5]
    assert got(sparse, [3.9, 3.9])  # 1.1 m short: stopped before the probe
    assert not got(sparse, [4.1, 4.1])  # 0.9 m short: within the margin
    assert not got(sparse, [7.0, 7.0])  # beyond it
    assert not got(sparse, [3.0, 6.0])  # one of them reaches
    # the return nearest in direction (at 0 degrees, 0.1 from the probe) short and the other
    # reaching, and the other way round: neither is a hole
    assert not got([0.0, 0.5], [3.0, 6.0]) and not got([0.0, 0.5], [6.0, 3.0])
    assert not got(sparse, [3.0, 3.0], reach_m=None)  # no reach test: a return is in the radius
    real, _ = _one_ring(sparse, [3.0, 3.0])
    assert not in_hole(probe, real, beams, cover, layout)[0]  # nor without the scan's beams
    # the same short returns on every beam around it (a bright surface in front: parallax,
    # not a dark surface): 7 of 7 returned, the probe is no hole
    dense = np.arange(-0.5, 0.71, 0.2)
    assert not got(dense, np.full(len(dense), 3.0))
    # 3 of 7 returned (0.43, sparse) against 4 of 7 (0.57, not)
    assert got(dense[::3], [3.0] * 3) and not got(dense[[0, 1, 3, 6]], [3.0] * 4)


def test_returned_share_counts_the_beams_in_the_radius():
    # 5 rings 0.4 degrees apart, 0.7 degrees: the ring itself and one on either side (the
    # next are 0.8 degrees away), 3 columns on either side: 3 x 7 beams around (2, 100)
    layout = RingLayout(np.arange(0.8, -0.81, -0.4), np.zeros(5), np.ones(5))
    beams = np.ones((5, COLUMNS), bool)
    returned = np.zeros((5, COLUMNS), bool)
    returned[1:4, 97:104] = True  # all 21
    returned[4, :] = True  # outside the radius: not counted
    returned[0, 0:3] = True  # past the seam of ring 0
    ring, col = np.array([2, 2, 0]), np.array([100, 104, 1799])
    share = returned_share(ring, col, returned, beams, layout, 0.7)
    # (2, 104): columns 101-107, 3 of 7 on rings 1-3; (0, 1799): rings 0 and 1, columns
    # 1796-1799 and 0-2 (wrapping): 3 of 7 on ring 0, none on ring 1
    np.testing.assert_allclose(share, [1.0, 9 / 21, 3 / 14])
    beams[1, :] = False  # beams no training scan returned on are not counted
    np.testing.assert_allclose(returned_share(ring, col, returned, beams, layout, 0.7)[:1], [1.0])


def test_holes_keep_the_moving_surfaces(drive):
    frames, poses, sim, origins = drive
    holes = Holes(frames, poses, [0, 2, 3])
    drop = holes.mask(1, sim)
    moved = sim[drop][:20] + origins[1]  # world points of a surface that moved there
    kept = holes.mask(1, sim, moving=moved)
    near = np.min(np.linalg.norm(sim[:, None] + origins[1] - moved[None], axis=2), axis=1) < 0.3
    assert drop[near].sum() >= 20 and not kept[near].any()
    assert np.array_equal(kept[~near], drop[~near])


def test_an_empty_scan_is_no_evidence(drive):
    frames, poses, sim, _ = drive
    lost = SimpleNamespace(**{**vars(frames), "xyz": [frames.xyz[0][:0], *frames.xyz[1:]]})
    holes = Holes(lost, poses, [0, 2, 3])
    assert not holes.mask(1, sim).any() and holes.dropped[1] == 0


def test_in_hole_needs_a_returned_beam_and_the_coverage(drive):
    frames, poses, sim, origins = drive
    local = sim + origins[1] - origins[0]  # the sim's points in frame 0's LiDAR frame
    beams = returned_beams([frames.grid[t] for t in (0, 2, 3)])
    full = in_hole(local, frames.xyz[0], beams, frames.coverage, frames.layout)
    assert full.sum() > 100
    # a ring no training scan returned on: its points are never in a hole
    none = beams.copy()
    ring, _ = beam_rings(local, ELEVATIONS, np.zeros(len(ELEVATIONS)))
    r = int(np.bincount(ring[full]).argmax())
    none[r] = False
    got = in_hole(local, frames.xyz[0], none, frames.coverage, frames.layout)
    assert not got[ring == r].any() and np.array_equal(got[ring != r], full[ring != r])
    # the coverage must reach past the hole on both sides
    cover = frames.coverage.copy()
    cover[(np.abs(-180.0 + (np.arange(COLUMNS) + 0.5) * 0.2) > 2.0)] = False
    narrow = in_hole(local, frames.xyz[0], beams, cover, frames.layout)
    az = np.degrees(np.arctan2(local[:, 1], local[:, 0]))
    assert narrow.any() and not narrow[np.abs(az) > 2.0 - HOLE_RADIUS_DEG - SIDE_DEG + 0.2].any()


def test_in_hole_is_the_angle_to_the_nearest_return():
    # returns every 0.2 degrees of azimuth on one ring, none between 9.8 and 12.2 degrees
    az = np.round(np.arange(-30.0, 30.0, 0.2), 6)
    az = az[(az <= 9.8) | (az >= 12.2)]
    real = np.column_stack([np.cos(np.radians(az)), np.sin(np.radians(az)), np.zeros_like(az)])
    layout = RingLayout(np.array([0.0]), np.zeros(1), np.ones(1))
    beams = np.ones((1, COLUMNS), bool)
    cover = np.ones(COLUMNS, bool)
    probe = np.array([10.2, 11.0, 11.6, 9.0, 12.0])  # 0.4, 1.2, 0.6, 0, 0.2 deg from a return
    pts = 5.0 * np.column_stack([np.cos(np.radians(probe)), np.sin(np.radians(probe)), [0] * 5])
    got = in_hole(pts, 10.0 * real, beams, cover, layout, radius_deg=0.55)
    assert got.tolist() == [False, True, True, False, False]
    # in the gap but 2 degrees above the sensor's only beam: outside its field of view
    up = 5.0 * np.array([[np.cos(np.radians(2.0)) * np.cos(np.radians(11.0)),
                          np.cos(np.radians(2.0)) * np.sin(np.radians(11.0)),
                          np.sin(np.radians(2.0))]])  # fmt: skip
    assert not in_hole(up, 10.0 * real, beams, cover, layout, radius_deg=0.55)[0]


def _turned(frames, poses, j):
    """The drive with training frame ``j`` turned to look back (yaw 180°, its scan unchanged
    in its own frame): every point ahead of the others lies behind it, out of its view."""
    turned = [p.copy() for p in poses]
    turned[j][:3, :3] = np.diag([-1.0, -1.0, 1.0])
    return frames, turned


def test_out_of_view_is_outside_the_coverage_and_its_margin():
    cover = np.abs(-180.0 + (np.arange(COLUMNS) + 0.5) * 360.0 / COLUMNS) < 50.0
    az = np.radians([0.0, 49.0, 50.0 + HOLE_RADIUS_DEG + SIDE_DEG - 0.3, 52.0, 180.0, -120.0])
    pts = 5.0 * np.column_stack([np.cos(az), np.sin(az), np.zeros_like(az)])
    assert out_of_view(pts, cover).tolist() == [False, False, False, True, True, True]


def test_a_scan_that_cannot_see_the_points_abstains():
    # the box returns on every third beam it hides; frame 2, after the held-out frame, is turned
    # to look back: frame 0 decides alone, and only where its returns stop short of the point
    frames, poses, sim, origins = _drive(scatter=3)
    both = Holes(frames, poses, [0, 2, 3]).mask(1, sim)
    frames, turned = _turned(frames, poses, 2)
    hidden = _hits_box(origins[1], sim + origins[1])
    drop = Holes(frames, turned, [0, 2, 3]).mask(1, sim)
    beams = returned_beams([frames.grid[t] for t in (0, 2, 3)])
    local = sim + origins[1] - origins[0]  # in frame 0's LiDAR frame
    returned = frames.grid[0].occupancy()
    alone = in_hole(local, frames.xyz[0], beams, frames.coverage, frames.layout, returned=returned)
    empty = in_hole(local, frames.xyz[0], beams, frames.coverage, frames.layout)
    assert np.array_equal(drop, alone & ~empty) and drop.sum() > 500
    assert not (drop & ~hidden).any()  # nothing the box leaves in view
    assert drop[hidden].mean() >= 0.4 and not (drop & ~both).any()
    # without abstaining, the scan that sees none of the points keeps every one of them
    assert not Holes(frames, turned, [0, 2, 3], abstain=False).mask(1, sim).any()
    # a point no evidence scan can see is kept
    frames, none = _turned(frames, turned, 0)
    assert not Holes(frames, none, [0, 2, 3]).mask(1, sim).any()


def test_alone_a_scan_without_returns_in_the_radius_drops_nothing(drive):
    frames, poses, sim, _ = drive  # the box returns nothing: no return stops short
    frames, turned = _turned(frames, poses, 2)
    assert Holes(frames, poses, [0, 2, 3]).mask(1, sim).sum() > 500
    assert not Holes(frames, turned, [0, 2, 3]).mask(1, sim).any()
