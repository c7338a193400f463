"""Where the training scans next to a held-out frame returned nothing: surfaces too dark for the
sensor, their beams dropped from the held-out scan.

A surface that sends too little light back (black paint, tinted glass, a wet road at a slant)
leaves a hole in every scan that looks at it: its beams return nothing, while the surfaces
behind it are known from the frames that saw them. The reconstruction holds only what returned,
so from a held-out pose beside those scans the re-simulated beams pass through the dark surface
to what lies behind it and return where the real sensor saw nothing. (On ``kitti_raw_0926`` a
dark car stands beside the stopped sensor: its side returns a few scattered points at 2.7 m
and the beams between them nothing, while the re-simulated ones reached the road 6 to 12 m
behind it, 2 to 3 m from any real return.)

The evidence is local in time, as such a surface may be a car that leaves (:mod:`.moving`). A
re-simulated return of held-out frame ``k`` is dropped when, seen from each training frame next
to ``k`` (:func:`hole_frames`: the one before and the one after; the last two before a frame
past the drive's end, the first two after one before its start), its point lies in a hole of
that frame's real scan (:func:`in_hole`): no real return within :data:`HOLE_RADIUS_DEG` of its
direction from the sensor, or none that reaches it where the scan is sparse (the reach test
below), within that radius of a beam (above the highest beam or below the
lowest no scan ever returns), on a beam (ring, column) that some training scan returned on (the
beams of the mounting's shadow never do: :mod:`.shadow`) and with the drive's coverage on both
sides of it (the edges of a cut scan are no hole). A return on a surface that moved
(:mod:`.moving`) is kept: where it stands at ``k`` the frames next to it may have seen nothing.
An evidence scan without a single return (a lost sweep) drops nothing.

**The radius, chosen on the training frames alone** (``benchmarks/resim_holes.py``): applied
to a training frame's own real returns, with its training neighbours as the evidence, the rule
should drop none of them. Over every third training frame of the ten real runs of
``docs/RESIMULATION.md``, the most it drops on any run is 0.390, 0.209, 0.114 and 0.060 % of
the returns at 0.3, 0.4, 0.5 and 0.7° (``kitti_raw_0926`` frames 0-24, stopped at a crossing
beside dark cars, but for 0.7°: ``r0005``); 0.7°, the smallest radius under the 0.1 % set
beforehand, is about two rings and four columns of an HDL-64E on either side (those figures
without the reach test, which counted every return in the radius).

**The reach test.** A dark car's side returns a few scattered points and nothing between them:
with one of them in the radius, a point on the road behind it would be kept, though the beams
that returned stopped metres short of it. So a point is also in a hole where the scan's returns
in the radius all stop more than :data:`REACH_M` short of it *and* the scan is sparse around it
(:func:`returned_share`: at most :data:`SPARSE_SHARE` of the beams around it returned). The
sparseness tells a dark surface from a bright one in front: past a drive's end both evidence
frames lie behind the held-out pose, and a box beside the road hides from both a wall the
held-out pose sees past its edge (parallax); without it the rendered drive of
``tests/resim/test_rendered_drive.py`` lost 1.7 % of its held-out returns, with it none. On the
training frames, as above, the most dropped on any run is 0.061 % at 1 m and a share of 0.5
(0.060 % without the reach test; 0.177 % with the reach test but no sparseness): the training
frames cannot tell margins of 0.25 to 2 m or shares of 0.3 to 0.9 apart, so both stand for what
they mean (well inside the dark car's 3 to 9 m; at most half the beams returned).

**A scan that cannot see the point.** The drives' scans are cut to the camera's half (x > 0):
a point beside a moving sensor lies in view of the frame before a held-out one and behind the
frame after it, which then kept every such point. An evidence scan for which the point lies
wholly outside the drive's coverage (:func:`out_of_view`) now abstains, and the other decides
alone, but only with returns that stop short of the point (the reach test's kind of hole): a
scan alone without a return around a point says less (a dark car's glossy side returns from
one viewpoint and not from the next), and dropping on that too took 0.314 % of a training
frame's returns on ``r0009`` (its dark car, 3.2 m away). As it stands, the training check
(``--abstain``) drops the same returns as without abstaining on every run but
``kitti_raw_0926``, one more on each of its two; at most 0.061 % on any run. A point no
evidence scan can see is kept. A drive with a single training frame has no other scan: that
one decides alone as before, on holes of either kind.
"""

from __future__ import annotations

import numpy as np

from .directions import TreeCache, around, chord, direction_tree, unit_directions

__all__ = [
    "HOLE_RADIUS_DEG",
    "SIDE_DEG",
    "MOVING_KEEP_M",
    "REACH_M",
    "SPARSE_SHARE",
    "returned_share",
    "hole_frames",
    "returned_beams",
    "beam_rings",
    "in_hole",
    "out_of_view",
    "Holes",
]

#: A point lies in a hole when no real return is within this angle of its direction, degrees.
HOLE_RADIUS_DEG = 0.7
#: The drive's coverage must hold the columns this far past the hole's edge on both sides, deg.
SIDE_DEG = 0.5
#: A re-simulated return within this distance of a surface that moved is never dropped, m.
MOVING_KEEP_M = 0.3
#: A real return in the radius reaches a point when it is at most this much nearer the sensor, m.
REACH_M = 1.0
#: The returns in the radius that stop short make a hole only where the scan is sparse: at most
#: this share of the beams around the point returned (a dark surface's scattered returns).
SPARSE_SHARE = 0.5


def hole_frames(k: int, train) -> list[int]:
    """The training frame indices whose scans are the evidence for held-out frame ``k``: the
    nearest one before and the nearest one after; where one side has none, the two nearest on
    the other (one when the drive has a single training frame)."""
    train = sorted(int(t) for t in train if t != k)
    before = [t for t in train if t < k]
    after = [t for t in train if t > k]
    if before and after:
        return [before[-1], after[0]]
    return before[-2:] if before else after[:2]


def returned_beams(grids) -> np.ndarray:
    """(rings, columns) bool: the beams some of the scans ``grids`` (:class:`.range_image.ScanGrid`)
    returned on."""
    occ = np.zeros((grids[0].rings, grids[0].columns), dtype=bool)
    for g in grids:
        occ |= g.occupancy()
    return occ


def beam_rings(points: np.ndarray, elevations_deg, offsets_m) -> tuple[np.ndarray, np.ndarray]:
    """``(ring, off)``: (M,) int the ring whose beam passes nearest each point (LiDAR frame, m)
    and (M,) float how far from it, as an angle seen from the sensor (degrees; a point above
    the highest beam or below the lowest is far from every one). Each beam is a line of
    elevation θ starting ``v`` above the sensor's centre along the normal of its direction
    (:class:`.laser_layout.RingLayout`): in the point's (horizontal range ρ, height z)
    half-plane its distance to the beam is ``|z cos θ − ρ sin θ − v|``. Near the sensor the
    offsets move a point by several rings from the one its elevation alone gives."""
    th = np.radians(np.asarray(elevations_deg, dtype=np.float64))
    v = np.asarray(offsets_m, dtype=np.float64)
    rho = np.hypot(points[:, 0], points[:, 1])[:, None]
    gap = np.abs(points[:, 2:3] * np.cos(th) - rho * np.sin(th) - v)
    ring = np.argmin(gap, axis=1)
    dist = np.maximum(np.linalg.norm(points, axis=1), 1e-9)
    off = np.degrees(np.arcsin(np.minimum(gap[np.arange(len(ring)), ring] / dist, 1.0)))
    return ring, off


def _short(points: np.ndarray, real: np.ndarray, tree, chord_len: float, reach_m):
    """``(none, short)``: (M,) bool each, no return of ``real`` within ``chord_len`` of a point's
    direction, and returns there that all stop more than ``reach_m`` short of it (None: never).
    The nearest direction first: where it reaches (nearly every point), the point is reached;
    only the others look at every return in the radius (a point with
    :data:`~.directions.RADIUS_NEIGHBOURS` of them is taken as reached)."""
    unit = unit_directions(points)
    d, i = tree.query(unit, k=1, distance_upper_bound=chord_len)
    none = ~np.isfinite(d)
    short = np.zeros(len(points), dtype=bool)
    if reach_m is None:
        return none, short
    dist = np.linalg.norm(points, axis=1)
    rng = np.linalg.norm(real, axis=1)
    idx = np.flatnonzero(~none)
    idx = idx[rng[i[idx]] < dist[idx] - reach_m]
    if len(idx):
        hit, i, full = around(tree, unit[idx], chord_len, len(real))
        far = np.where(hit, rng[i], -np.inf).max(axis=1)
        short[idx] = (far < dist[idx] - reach_m) & ~full
    return none, short


def returned_share(
    ring: np.ndarray, col: np.ndarray, returned: np.ndarray, beams: np.ndarray, layout, radius_deg
) -> np.ndarray:
    """(M,) the share of the beams around each (ring, column) that returned in one scan: of the
    beams some training scan returned on (``beams``), on the rings whose elevation is within
    ``radius_deg`` of the ring's and the columns within it on either side (wrapping), those
    ``returned`` (that scan's (rings, columns) bool occupancy) holds."""
    rings, columns = beams.shape
    w = int(np.floor(radius_deg * columns / 360.0))
    elev = np.asarray(layout.elevation_deg, dtype=np.float64)

    def sums(grid):  # per ring, the running count over the columns laid out three times
        run = np.cumsum(np.tile(grid.astype(np.int32), (1, 3)), axis=1)
        return np.concatenate([np.zeros((rings, 1), np.int32), run], axis=1)

    got, have = sums(returned & beams), sums(beams)
    lo, hi = col + columns - w, col + columns + w + 1
    num = np.zeros(len(ring))
    den = np.zeros(len(ring))
    for step in range(-rings + 1, rings):
        r = ring + step
        ok = (r >= 0) & (r < rings)
        r = np.clip(r, 0, rings - 1)
        ok &= np.abs(elev[r] - elev[ring]) <= radius_deg
        if not ok.any():
            continue
        num += np.where(ok, got[r, hi] - got[r, lo], 0)
        den += np.where(ok, have[r, hi] - have[r, lo], 0)
    return num / np.maximum(den, 1.0)


def in_hole(
    points: np.ndarray,
    real: np.ndarray,
    beams: np.ndarray,
    coverage: np.ndarray,
    layout,
    radius_deg: float = HOLE_RADIUS_DEG,
    tree=None,
    reach_m: float | None = REACH_M,
    returned: np.ndarray | None = None,
) -> np.ndarray:
    """(M,) bool: the points that lie in a hole of one real scan (module docstring).

    Args:
        points: (M, 3) points in that scan's LiDAR frame, m.
        real: (N, 3) the scan's returns, same frame, m.
        beams: (rings, columns) bool, the beams the drive's training scans returned on
            (:func:`returned_beams`).
        coverage: (columns,) bool, the columns the drive's scans cover.
        layout: the drive's :class:`.laser_layout.RingLayout` (each ring's elevation and offset).
        radius_deg: the hole's radius around a point's direction, degrees.
        tree: :func:`direction_tree` of ``real`` when the caller keeps it (one evidence scan
            serves every re-simulated scan of a held-out frame).
        reach_m: a point whose returns in the radius all stop more than this short of it, m,
            is in a hole where the scan is sparse around it (None: only where it has none).
        returned: (rings, columns) bool, the beams this scan returned on
            (``ScanGrid.occupancy``); without it, only a point with no return in the radius
            is in a hole (no reach test).
    """
    from ..datasets.kitti_rings import azimuth_deg

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(points) == 0:
        return np.zeros(0, dtype=bool)
    reach_m = None if returned is None else reach_m
    if len(real):
        tree = direction_tree(real) if tree is None else tree
        real = np.asarray(real, dtype=np.float64)
        out, short = _short(points, real, tree, chord(radius_deg), reach_m)
    else:
        out, short = np.ones(len(points), dtype=bool), np.zeros(len(points), dtype=bool)
    rings, columns = beams.shape
    az = azimuth_deg(points)
    col = lambda a: np.floor((a + 180.0) * columns / 360.0).astype(np.int64) % columns  # noqa: E731
    side = radius_deg + SIDE_DEG
    ring, off = beam_rings(points, layout.elevation_deg, layout.vertical_offset_m)
    if short.any():
        at = np.flatnonzero(short)
        share = returned_share(ring[at], col(az[at]), returned, beams, layout, radius_deg)
        out[at[share <= SPARSE_SHARE]] = True
    out &= off <= radius_deg  # inside the sensor's vertical field of view
    out &= beams[ring, col(az)] & coverage[col(az - side)] & coverage[col(az + side)]
    return out


def out_of_view(points: np.ndarray, coverage: np.ndarray, radius_deg: float = HOLE_RADIUS_DEG):
    """(M,) bool: the points (LiDAR frame, m) whose direction lies wholly outside the columns
    ``coverage`` ((columns,) bool) covers: neither its column nor those ``radius_deg`` +
    :data:`SIDE_DEG` to either side (a scan cut to the camera's half sees nothing behind it)."""
    from ..datasets.kitti_rings import azimuth_deg

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    columns = len(coverage)
    az = azimuth_deg(points)
    side = radius_deg + SIDE_DEG
    col = lambda a: np.floor((a + 180.0) * columns / 360.0).astype(np.int64) % columns  # noqa: E731
    return ~(coverage[col(az)] | coverage[col(az - side)] | coverage[col(az + side)])


class Holes:
    """The hole test of one drive: its training scans, poses and beams (module docstring).

    Args:
        frames: the drive's :class:`.frames.Frames`.
        poses: per frame (4, 4) LiDAR-to-world.
        train: the training frames' indices.
        radius_deg: the holes' radius (:data:`HOLE_RADIUS_DEG`).
        reach_m: the reach test's margin (:data:`REACH_M`; None: every return counts).
        abstain: an evidence scan that cannot see a point (:func:`out_of_view`) leaves the
            decision to the others (False: it keeps the point).
    """

    def __init__(
        self,
        frames,
        poses,
        train,
        radius_deg: float = HOLE_RADIUS_DEG,
        reach_m=REACH_M,
        abstain: bool = True,
    ):
        self.frames, self.poses, self.radius_deg = frames, poses, radius_deg
        self.reach_m, self.abstain = reach_m, abstain
        self.train = sorted(int(t) for t in train)
        self.beams = returned_beams([frames.grid[t] for t in self.train])
        #: held-out frame -> returns dropped from its first scan (the ``resim`` method's)
        self.dropped: dict[int, int] = {}
        self._tree = TreeCache(frames.xyz)  # the evidence scans' direction trees

    def _in_hole(self, j: int, local: np.ndarray, reach_m) -> np.ndarray:
        """:func:`in_hole` of points ``local`` (M, 3) in evidence scan ``j``'s frame; ``reach_m``
        None: only the points with no return of it in the radius."""
        returned = None if reach_m is None else self.frames.grid[j].occupancy()
        return in_hole(
            local,
            self.frames.xyz[j],
            self.beams,
            self.frames.coverage,
            self.frames.layout,
            self.radius_deg,
            tree=self._tree(j),
            reach_m=reach_m,
            returned=returned,
        )

    def mask(self, k: int, xyz: np.ndarray, moving: np.ndarray | None = None) -> np.ndarray:
        """(M,) bool: the returns of a re-simulated scan at frame ``k`` to drop.

        Args:
            k: the held-out frame's index.
            xyz: (M, 3) the re-simulated returns, frame ``k``'s LiDAR frame, m.
            moving: (V, 3) world points of the surfaces that moved, as they stand at ``k``
                (their returns are kept), or None.
        """
        from scipy.spatial import cKDTree

        xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
        evidence = hole_frames(k, self.train)
        # a scan without a return (a lost sweep) is no evidence of a dark surface anywhere
        if not evidence or len(xyz) == 0 or any(len(self.frames.xyz[j]) == 0 for j in evidence):
            self.dropped.setdefault(k, 0)
            return np.zeros(len(xyz), dtype=bool)
        Tk = self.poses[k]
        world = xyz @ Tk[:3, :3].T + Tk[:3, 3]
        local = [(world - self.poses[j][:3, 3]) @ self.poses[j][:3, :3] for j in evidence]
        away = [
            out_of_view(p, self.frames.coverage, self.radius_deg)
            if self.abstain
            else np.zeros(len(xyz), dtype=bool)
            for p in local
        ]
        drop = np.logical_or.reduce([~a for a in away])  # some evidence scan sees the point
        for j, p, a in zip(evidence, local, away):
            drop &= a | self._in_hole(j, p, self.reach_m)
        # a scan deciding alone (hole_frames gives at most two): only returns short of the point
        if len(evidence) > 1 and drop.any():
            some_away = np.logical_or.reduce(away)
            for j, p, a in zip(evidence, local, away):
                alone = np.flatnonzero(drop & ~a & some_away)
                if len(alone):
                    drop[alone[self._in_hole(j, p[alone], None)]] = False
        if moving is not None and len(moving) and drop.any():
            near, _ = cKDTree(moving).query(world[drop], k=1, distance_upper_bound=MOVING_KEEP_M)
            drop[np.flatnonzero(drop)[np.isfinite(near)]] = False
        self.dropped.setdefault(k, int(drop.sum()))
        return drop
