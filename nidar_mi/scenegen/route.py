"""Drives through a city layout: a smooth route along the streets, sampled as LiDAR poses.

:func:`drive` turns the figure eight of :func:`~.streets.drive_route` into a trajectory:

1. the crossings become a polyline in the right-hand lane (offset ``lane_w / 2`` to the right of
   the street centrelines), each turn rounded by a circular arc of radius :data:`TURN_RADIUS_M`;
2. a speed profile: at most ``speed`` (m/s), at most ``sqrt(a_lat · R)`` on an arc of radius R
   (lateral acceleration :data:`A_LAT`), changing by at most :data:`A_LONG` (m/s²);
3. the pose at every frame time ``k / rate_hz``: the LiDAR :data:`~.streets.LIDAR_HEIGHT_M` above the
   road, x along the direction of travel, z up;
4. the body's motion on its suspension (``body_motion``): roll of :data:`ROLL_PER_MS2` per m/s² of
   lateral acceleration (leaning out of a turn), pitch of :data:`PITCH_PER_MS2` per m/s² of
   braking or accelerating (nose down when braking), and the road's excitation of the body
   modes: pitch 0.25° at 1.3 Hz + 0.1° at 2.9 Hz, roll 0.15° at 1.1 Hz, heave 1 cm at 1.5 Hz,
   with phases drawn from ``seed``. (Real cars lean ~3-6° per g and pitch ~2-3° per g; without
   this motion every sweep of a flat road draws the same rings round the sensor.)

The route repeats until the drive has ``frames`` poses. :func:`revisits` counts how often the
drive comes back to where it has been. The files of a drive are written by :mod:`.drives` with
:mod:`nidar_mi.io.trajectory`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..errors import NidarError
from .streets import LIDAR_HEIGHT_M, StreetGrid, drive_route

__all__ = [
    "A_LAT",
    "A_LONG",
    "PITCH_PER_MS2",
    "ROLL_PER_MS2",
    "TURN_RADIUS_M",
    "DrivePoses",
    "MAX_DRIVE_FRAMES",
    "MAX_DRIVE_LENGTH_M",
    "MAX_DRIVE_RATE_HZ",
    "MAX_DRIVE_SPEED",
    "check_drive",
    "route_start",
    "route_polyline",
    "drive",
    "revisits",
]

#: The most poses of one drive (1000 s at 10 Hz): the route is laid out lap by lap, and a
#: drive of more frames is refused before any work.
MAX_DRIVE_FRAMES = 10_000
#: The longest drive, m: its duration times the cruising speed (the route's length is at most
#: that; turns are slower). 10 km, some 35 laps of a 4 x 3 city, laid out in a few seconds.
MAX_DRIVE_LENGTH_M = 10_000.0
#: The highest frame rate, Hz (a spinning LiDAR's highest rotation rate).
MAX_DRIVE_RATE_HZ = 100.0
#: The highest cruising speed, m/s (250 km/h).
MAX_DRIVE_SPEED = 70.0


def check_drive(frames: int, rate_hz: float, speed: float) -> None:
    """Refuse a drive that cannot be laid out, or not in bounded work: ``frames`` in
    [2, :data:`MAX_DRIVE_FRAMES`], ``rate_hz`` in (0, :data:`MAX_DRIVE_RATE_HZ`], ``speed`` in
    (0, :data:`MAX_DRIVE_SPEED`], all finite, and a length (``(frames - 1) / rate_hz · speed``)
    of at most :data:`MAX_DRIVE_LENGTH_M`.

    Raises:
        NidarError: one line naming the parameter (``frames``, ``rate``, ``speed``).
    """
    if not 2 <= frames <= MAX_DRIVE_FRAMES:
        raise NidarError(f"`frames` must lie in [2, {MAX_DRIVE_FRAMES}] (got {frames})")
    if not (math.isfinite(rate_hz) and 0 < rate_hz <= MAX_DRIVE_RATE_HZ):
        raise NidarError(f"`rate` must lie in (0, {MAX_DRIVE_RATE_HZ:g}] Hz (got {rate_hz})")
    if not (math.isfinite(speed) and 0 < speed <= MAX_DRIVE_SPEED):
        raise NidarError(f"`speed` must lie in (0, {MAX_DRIVE_SPEED:g}] m/s (got {speed})")
    length = (frames - 1) / rate_hz * speed
    if length > MAX_DRIVE_LENGTH_M:
        raise NidarError(
            f"`frames` {frames} at `rate` {rate_hz:g} Hz and `speed` {speed:g} m/s make a drive "
            f"of {length / 1000:.4g} km, longer than {MAX_DRIVE_LENGTH_M / 1000:g} km; fewer "
            "frames, a higher rate or a lower speed"
        )


#: Radius of the arcs that round the turns, m.
TURN_RADIUS_M = 8.0
#: Largest lateral acceleration in a turn, m/s².
A_LAT = 3.0
#: Largest change of speed, m/s².
A_LONG = 1.5
#: Body roll per lateral acceleration, degrees per m/s² (about 5° per g).
ROLL_PER_MS2 = 0.5
#: Body pitch per longitudinal acceleration, degrees per m/s² (about 3° per g).
PITCH_PER_MS2 = 0.3
_STEP_M = 0.05  # spacing of the dense path


@dataclass(frozen=True)
class DrivePoses:
    """LiDAR poses of a drive.

    Attributes:
        times: (N,) float64 s, frame start times (0, 1/rate, ...).
        poses: (N, 4, 4) float64 ``T_world_lidar`` at those times.
        distance: (N,) float64 m travelled since the first frame.
    """

    times: np.ndarray
    poses: np.ndarray
    distance: np.ndarray

    def __len__(self) -> int:
        return len(self.times)

    def positions(self) -> np.ndarray:
        """(N, 3) LiDAR positions in m."""
        return self.poses[:, :3, 3]


def _right(d: np.ndarray) -> np.ndarray:
    return np.array([d[1], -d[0]])


def route_start(g: StreetGrid) -> tuple[float, float, float]:
    """(x, y, heading in degrees) of the drive's first pose: the middle of the first street of
    :func:`~.city.drive_route`, in the right-hand lane."""
    pts, _ = route_polyline(g, laps=1)
    d = pts[1] - pts[0]
    return float(pts[0, 0]), float(pts[0, 1]), math.degrees(math.atan2(d[1], d[0]))


def route_polyline(g: StreetGrid, laps: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """The route driven ``laps`` times as a dense path.

    Returns:
        (P, 2) float64 points every ~:data:`_STEP_M` m, starting halfway along the first street;
        (P,) float64 curvature (1/m) at each point (0 on straights, 1/R on arcs).
    """
    nodes = drive_route(g)[:-1] * laps + [drive_route(g)[0]]
    xy = np.array([g.node(i, j) for i, j in nodes], dtype=np.float64)
    # start halfway along the first street, end there after the last lap
    xy = np.vstack([(xy[0] + xy[1]) / 2, xy[1:], (xy[0] + xy[1]) / 2])
    o = g.lane_w / 2
    R = TURN_RADIUS_M
    pts: list[np.ndarray] = []
    curv: list[np.ndarray] = []
    cursor = xy[0] + o * _right(_unit(xy[1] - xy[0]))

    def line_to(p: np.ndarray) -> None:
        nonlocal cursor
        n = max(int(np.ceil(np.linalg.norm(p - cursor) / _STEP_M)), 1)
        s = np.linspace(0.0, 1.0, n, endpoint=False)[:, None]
        pts.append(cursor + s * (p - cursor))
        curv.append(np.zeros(n))
        cursor = p

    for k in range(1, len(xy) - 1):
        d1, d2 = _unit(xy[k] - xy[k - 1]), _unit(xy[k + 1] - xy[k])
        cross = d1[0] * d2[1] - d1[1] * d2[0]
        if abs(cross) < 1e-9:  # straight on through the crossing
            continue
        corner = xy[k] + o * (_right(d1) + _right(d2))
        t1, t2 = corner - R * d1, corner + R * d2
        line_to(t1)
        centre = t1 + R * d2
        a1 = math.atan2(t1[1] - centre[1], t1[0] - centre[0])
        a2 = math.atan2(t2[1] - centre[1], t2[0] - centre[0])
        sweep = (a2 - a1 + math.pi) % (2 * math.pi) - math.pi  # a quarter turn, signed
        n = max(int(np.ceil(abs(sweep) * R / _STEP_M)), 1)
        a = a1 + sweep * np.linspace(0.0, 1.0, n, endpoint=False)
        pts.append(centre + R * np.stack([np.cos(a), np.sin(a)], -1))
        curv.append(np.full(n, 1.0 / R))
        cursor = t2
    end = xy[-1] + o * _right(_unit(xy[-1] - xy[-2]))
    line_to(end)
    pts.append(end[None])
    curv.append(np.zeros(1))
    return np.vstack(pts), np.concatenate(curv)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _speed_profile(s: np.ndarray, curv: np.ndarray, v_max: float) -> np.ndarray:
    """Speed (m/s) at each arc length ``s`` under the lateral and longitudinal limits."""
    v = np.minimum(v_max, np.sqrt(A_LAT / np.maximum(curv, 1e-9)))
    ds = np.diff(s)
    for i in range(1, len(v)):  # accelerate at most A_LONG
        v[i] = min(v[i], math.sqrt(v[i - 1] ** 2 + 2 * A_LONG * ds[i - 1]))
    for i in range(len(v) - 2, -1, -1):  # brake at most A_LONG
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2 * A_LONG * ds[i]))
    return v


def drive(
    g: StreetGrid,
    frames: int,
    rate_hz: float = 10.0,
    speed: float = 10.0,
    *,
    seed: int = 0,
    body_motion: bool = True,
) -> DrivePoses:
    """LiDAR poses of a drive round :func:`~.streets.drive_route` (repeated as needed).

    Args:
        g: the street grid of the layout.
        frames: number of poses (:func:`check_drive` bounds the three).
        rate_hz: frame rate, Hz.
        speed: cruising speed, m/s (slower in the turns).
        seed: draws the phases of the body's oscillations.
        body_motion: roll, pitch and heave of the body (module docstring); False: the LiDAR stays
            level at a constant height.

    Returns:
        The trajectory, starting under way (at the speed the next turn allows) at
        :func:`route_start`.
    """
    check_drive(frames, rate_hz, speed)
    duration = (frames - 1) / rate_hz
    laps = 1
    while True:
        pts, curv = route_polyline(g, laps)
        seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        s = np.concatenate([[0.0], np.cumsum(seg)])
        v = _speed_profile(s, curv, speed)  # already under way at the start
        t = np.concatenate([[0.0], np.cumsum(seg / np.maximum((v[1:] + v[:-1]) / 2, 1e-6))])
        if t[-1] >= duration:
            break
        laps += 1
    times = np.arange(frames, dtype=np.float64) / rate_hz
    s_f = np.interp(times, t, s)
    x, y = np.interp(s_f, s, pts[:, 0]), np.interp(s_f, s, pts[:, 1])
    # heading from the tangent of the dense path (a central difference over ~0.5 m)
    ahead = (
        np.interp(np.minimum(s_f + 0.25, s[-1]), s, pts[:, 0]),
        np.interp(np.minimum(s_f + 0.25, s[-1]), s, pts[:, 1]),
    )
    behind = (
        np.interp(np.maximum(s_f - 0.25, 0.0), s, pts[:, 0]),
        np.interp(np.maximum(s_f - 0.25, 0.0), s, pts[:, 1]),
    )
    yaw = np.arctan2(ahead[1] - behind[1], ahead[0] - behind[0])
    roll, pitch, heave = np.zeros(frames), np.zeros(frames), np.zeros(frames)
    if body_motion:
        roll, pitch, heave = _body_motion(times, s_f, s, t, v, pts, curv, seed)
    from scipy.spatial.transform import Rotation

    poses = np.tile(np.eye(4), (frames, 1, 1))
    poses[:, :3, :3] = Rotation.from_euler("ZYX", np.stack([yaw, pitch, roll], -1)).as_matrix()
    poses[:, 0, 3], poses[:, 1, 3], poses[:, 2, 3] = x, y, LIDAR_HEIGHT_M + heave
    return DrivePoses(times=times, poses=poses, distance=s_f - s_f[0])


def _body_motion(times, s_f, s, t, v, pts, curv, seed):
    """(roll, pitch, heave) per frame in rad, rad, m (module docstring, step 4)."""
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(0x626F6479,)))
    ph = rng.uniform(0.0, 2 * np.pi, 4)
    speed = np.interp(times, t, v)
    # signed curvature: + for a left turn (the tangent turns anticlockwise)
    d = np.diff(pts, axis=0)
    turn = np.sign(np.r_[0.0, d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0], 0.0])
    kappa = np.interp(s_f, s, curv * turn)
    a_lat = speed**2 * kappa
    dt = times[1] - times[0]
    a_long = np.gradient(speed, dt) if len(times) > 2 else np.zeros_like(times)
    roll = np.radians(ROLL_PER_MS2 * a_lat + 0.15 * np.sin(2 * np.pi * 1.1 * times + ph[0]))
    pitch = np.radians(
        -PITCH_PER_MS2 * a_long
        + 0.25 * np.sin(2 * np.pi * 1.3 * times + ph[1])
        + 0.1 * np.sin(2 * np.pi * 2.9 * times + ph[2])
    )
    heave = 0.01 * np.sin(2 * np.pi * 1.5 * times + ph[3])
    return roll, pitch, heave


def revisits(traj: DrivePoses, radius_m: float = 5.0, min_gap_m: float = 30.0) -> int:
    """How many times the drive returns within ``radius_m`` of a place it passed at least
    ``min_gap_m`` of driving earlier (runs of consecutive revisiting frames count once)."""
    p = traj.positions()[:, :2]
    d = traj.distance
    hit = np.zeros(len(p), dtype=bool)
    for i in range(len(p)):
        earlier = d <= d[i] - min_gap_m
        if earlier.any():
            hit[i] = np.min(np.linalg.norm(p[earlier] - p[i], axis=1)) < radius_m
    return int(np.count_nonzero(hit[1:] & ~hit[:-1]) + int(hit[0]))
