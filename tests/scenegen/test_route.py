"""Drives: smooth, within the speed limits, in the right-hand lane, revisiting; their files."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.scenegen.route import (
    A_LAT,
    A_LONG,
    PITCH_PER_MS2,
    ROLL_PER_MS2,
    TURN_RADIUS_M,
    drive,
    revisits,
    route_polyline,
    route_start,
)
from nidar_mi.scenegen.streets import LIDAR_HEIGHT_M, sample_grid


@pytest.fixture(scope="module")
def grid():
    return sample_grid(np.random.default_rng(1), "city", (4, 3))


def test_route_is_a_closed_figure_eight_of_straights_and_quarter_arcs(grid):
    pts, curv = route_polyline(grid, laps=1)
    np.testing.assert_allclose(pts[0], pts[-1], atol=1e-9)  # closes on its start
    L = np.linalg.norm(np.diff(pts, axis=0), axis=1).sum()
    # 8 streets of one pitch and 8 quarter turns, each cutting 2R and adding a quarter circle
    expected = 8 * grid.pitch + 8 * (np.pi / 2 - 2) * TURN_RADIUS_M
    # the lane offset lengthens a left turn by 2 * (lane_w / 2) and shortens a right turn as
    # much: the four left turns of one loop cancel the four right turns of the other
    assert L == pytest.approx(expected, rel=2e-3)
    assert set(np.round(curv, 9)) == {0.0, round(1 / TURN_RADIUS_M, 9)}


def test_drive_respects_the_speed_limits_and_looks_along_its_path(grid):
    traj = drive(grid, 650, rate_hz=10.0, speed=10.0)
    p = traj.positions()
    v = np.linalg.norm(np.diff(p, axis=0), axis=1) * 10.0
    assert v.max() <= 10.0 + 1e-6
    assert v.min() >= np.sqrt(A_LAT * TURN_RADIUS_M) * 0.95  # never slower than the turn speed
    step = np.diff(p[:, :2], axis=0)
    heading = np.arctan2(step[:, 1], step[:, 0])
    yaw = np.arctan2(traj.poses[:-1, 1, 0], traj.poses[:-1, 0, 0])
    err = np.angle(np.exp(1j * (heading - yaw)))
    assert np.abs(err).max() < np.radians(12)  # the chord lags the tangent in turns only
    assert np.abs(p[:, 2] - LIDAR_HEIGHT_M).max() <= 0.01 + 1e-9  # heave
    np.testing.assert_allclose(np.linalg.det(traj.poses[:, :3, :3]), 1.0)
    x, y, h = route_start(grid)
    np.testing.assert_allclose(p[0, :2], (x, y)) and h == pytest.approx(90.0)
    # right-hand lane: the first street is driven north, half a lane east of its centreline
    assert x == pytest.approx(grid.nx // 2 * grid.pitch + grid.lane_w / 2)
    assert revisits(traj) >= 2


def test_revisits_by_hand():
    # out along x and straight back 2 m to the side: one revisit run
    from nidar_mi.scenegen.route import DrivePoses

    x = np.r_[np.arange(0, 50.0), np.arange(49, -1, -1.0)]
    y = np.r_[np.zeros(50), np.full(50, 2.0)]
    poses = np.tile(np.eye(4), (100, 1, 1))
    poses[:, 0, 3], poses[:, 1, 3] = x, y
    d = np.r_[0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))]
    traj = DrivePoses(times=np.arange(100) / 10, poses=poses, distance=d)
    assert revisits(traj, radius_m=5.0, min_gap_m=30.0) == 1
    assert revisits(traj, radius_m=1.0, min_gap_m=30.0) == 0


def test_tum_files_round_trip(grid, tmp_path):
    from nidar_mi.io.trajectory import read_trajectory, write_tum

    traj = drive(grid, 50)
    write_tum(tmp_path / "d.tum", traj.times, traj.poses, "a drive")
    back = read_trajectory(tmp_path / "d.tum")
    assert back.format == "tum"
    np.testing.assert_allclose(back.times, traj.times, atol=1e-9)
    np.testing.assert_allclose(back.poses, traj.poses, atol=1e-6)
    assert (tmp_path / "d.tum").read_text().startswith("# a drive\n")


def test_bad_input(grid):
    with pytest.raises(NidarError, match=r"`frames` must lie in \[2, 10000\] \(got 1\)"):
        drive(grid, 1)
    with pytest.raises(NidarError, match=r"`rate` must lie in \(0, 100\] Hz \(got 0\)"):
        drive(grid, 10, rate_hz=0)


@pytest.mark.parametrize(
    "frames, rate, speed, words",
    [
        (100_000_000, 10.0, 10.0, "`frames` must lie in [2, 10000]"),
        (20, 0.0001, 10.0, "a drive of 1900 km, longer than 10 km"),
        (500, 10.0, float("nan"), "`speed` must lie in (0, 70] m/s (got nan)"),
        (500, float("inf"), 10.0, "`rate` must lie in (0, 100] Hz (got inf)"),
    ],
)
def test_a_drive_is_bounded_before_it_is_laid_out(frames, rate, speed, words):
    """20 frames at 0.0001 Hz used to lay out a 1900 km route lap by lap for minutes."""
    from nidar_mi.scenegen.route import check_drive

    with pytest.raises(NidarError) as info:
        check_drive(frames, rate, speed)
    assert words in str(info.value)
    check_drive(10_000, 10.0, 10.0)  # the longest drive allowed: 10 km


def test_body_leans_out_of_turns_and_pitches_when_braking(grid):
    from scipy.spatial.transform import Rotation

    traj = drive(grid, 650)
    yaw, pitch, roll = np.degrees(Rotation.from_matrix(traj.poses[:, :3, :3]).as_euler("ZYX")).T
    rate = np.degrees(np.gradient(np.unwrap(np.radians(yaw))))  # deg per frame
    left, right = rate > 3.3, rate < -3.3  # well inside a turn (3.5 deg per frame)
    assert left.any() and right.any()
    lean = ROLL_PER_MS2 * A_LAT  # 1.5 deg, plus at most 0.15 deg of road excitation
    assert np.all(np.abs(roll[left] - lean) <= 0.15 + 0.2)
    assert np.all(np.abs(roll[right] + lean) <= 0.15 + 0.2)
    assert np.abs(pitch).max() <= PITCH_PER_MS2 * A_LONG + 0.35 + 1e-6
    level = drive(grid, 50, body_motion=False)
    np.testing.assert_allclose(level.poses[:, 2, :3], [[0, 0, 1]] * 50, atol=1e-12)
    np.testing.assert_allclose(level.poses[:, 2, 3], LIDAR_HEIGHT_M)
    # the phases follow the seed, the path does not
    other = drive(grid, 650, seed=1)
    np.testing.assert_allclose(other.poses[:, :2, 3], traj.poses[:, :2, 3])
    assert not np.allclose(other.poses[:, :3, :3], traj.poses[:, :3, :3])


def test_generated_drive_files_hold_rig_poses(tmp_path):
    """``render --trajectory`` puts the LiDAR at T_rig · T_mount (T_mount: its pose in the XML)."""
    import json

    from nidar_mi.scenegen.city import sample_city
    from nidar_mi.scenegen.generate import generate, scene_rng

    generate(
        str(tmp_path), 1, 7, kind="suburb", progress=False, blocks=(2, 1), drive={"frames": 30}
    )
    entry = json.loads((tmp_path / "index.json").read_text())["scenes"][0]
    assert entry["drive"]["frames"] == 30 and entry["drive"]["revisits"] == 0
    from nidar_mi.io.trajectory import read_trajectory

    rig = read_trajectory(tmp_path / entry["drive"]["files"]["tum"]).poses
    mount = np.array(entry["lidar"]["T_world_lidar"])
    # at the start the LiDAR is where the scene puts it, but for the body's roll, pitch and heave
    first = rig[0] @ mount
    assert np.abs(first[:3, 3] - mount[:3, 3]).max() < 0.02
    assert np.abs(first[:3, :3] - mount[:3, :3]).max() < np.radians(1.0)
    _, grid = sample_city(scene_rng(7, 0), "suburb", (2, 1))
    seed = int(np.random.SeedSequence(7, spawn_key=(0,)).generate_state(1)[0])
    np.testing.assert_allclose(rig @ mount, drive(grid, 30, seed=seed).poses, atol=1e-6)
