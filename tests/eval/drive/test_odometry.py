"""ATE / RPE against hand-computed cases and the KITTI devkit as kiss-icp compiles it."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nidar_mi.eval.drive.odometry import ate, end_drift, path_length, rpe_kitti, umeyama


def _pose(R=None, t=(0.0, 0.0, 0.0)):
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = np.eye(3) if R is None else R, t
    return T


def _line(n: int, step: float = 1.0) -> np.ndarray:
    """Poses moving along +x by ``step`` m per frame, no rotation."""
    return np.stack([_pose(t=(k * step, 0.0, 0.0)) for k in range(n)])


def test_umeyama_recovers_a_rigid_transform_and_scale():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(50, 3))
    R = Rotation.from_euler("zyx", [40, -10, 25], degrees=True).as_matrix()
    t = np.array([1.0, -2.0, 3.0])
    R_, t_, s_ = umeyama(src, src @ R.T + t)
    np.testing.assert_allclose(R_, R, atol=1e-12)
    np.testing.assert_allclose(t_, t, atol=1e-12)
    assert s_ == 1.0
    R_, t_, s_ = umeyama(src, 2.5 * src @ R.T + t, with_scale=True)
    np.testing.assert_allclose([s_], [2.5], rtol=1e-12)
    np.testing.assert_allclose(R_, R, atol=1e-12)


def test_umeyama_never_returns_a_reflection():
    src = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [-1, -1, -1]])
    R, _, _ = umeyama(src, src * np.array([1, 1, -1]))  # a mirror image
    assert np.linalg.det(R) == pytest.approx(1.0)


def test_ate_is_zero_for_a_rigidly_moved_copy():
    gt = np.stack(
        [
            _pose(Rotation.from_euler("z", 3 * k, degrees=True).as_matrix(), (k, k**0.5, 0))
            for k in range(20)
        ]
    )
    T = _pose(Rotation.from_euler("xyz", [5, -7, 60], degrees=True).as_matrix(), (10, -4, 2))
    res = ate(gt, T @ gt)
    assert res["rmse"] < 1e-10


def test_ate_of_a_scaled_symmetric_trajectory_is_the_scale_excess():
    # four poses at (+-1, 0), (0, +-1): scaling the positions by (1 + eps) leaves the optimal
    # rigid alignment at the identity (by symmetry) and every residual at eps
    eps = 0.1
    pts = [(1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0)]
    gt = np.stack([_pose(t=p) for p in pts])
    est = np.stack([_pose(t=(1 + eps) * np.array(p, float)) for p in pts])
    T = _pose(Rotation.from_euler("z", 33, degrees=True).as_matrix(), (5, 6, 7))
    res = ate(gt, T @ est)
    assert res["rmse"] == pytest.approx(eps, abs=1e-12)
    assert res["max"] == pytest.approx(eps, abs=1e-12)


def test_rpe_of_a_stretched_line_is_the_stretch():
    # 1 m per frame; the devkit's segment of length L ends at the first frame *past* L m, so it
    # spans L + 1 m, and an estimate stretched by 1 % is off by 0.01 (L + 1) m over it
    gt = _line(301)
    est = _line(301, step=1.01)
    res = rpe_kitti(gt, est, lengths=(100,))
    assert res["t_err_pct"] == pytest.approx(100 * 0.01 * 101 / 100, rel=1e-9)
    assert res["r_err_deg_per_m"] == pytest.approx(0.0, abs=1e-9)
    # segments start every 10th frame and need 101 frames after the start: 0, 10, ..., 190
    assert res["segments"] == 20


def test_rpe_rotation_error_of_a_yaw_drift():
    delta = np.radians(0.01)  # the estimate turns 0.01 deg per frame more than the truth
    gt = _line(301)
    est = np.stack(
        [_pose(Rotation.from_euler("z", k * delta).as_matrix(), (k, 0, 0)) for k in range(301)]
    )
    res = rpe_kitti(gt, est, lengths=(100,))
    assert res["r_err_deg_per_m"] == pytest.approx(np.degrees(delta * 101 / 100), rel=1e-9)


def test_rpe_without_a_long_enough_segment_reports_none():
    res = rpe_kitti(_line(20), _line(20), lengths=(100,))
    assert res == {"t_err_pct": None, "r_err_deg_per_m": None, "segments": 0, "per_length": {}}


def test_rpe_matches_the_kitti_devkit_in_kiss_icp():
    from kiss_icp.metrics import sequence_error

    rng = np.random.default_rng(1)
    n = 900
    yaw = np.cumsum(rng.normal(0, 0.02, n))
    step = np.stack([np.cos(yaw), np.sin(yaw), rng.normal(0, 0.01, n)], -1)
    gt = np.stack(
        [_pose(Rotation.from_euler("z", y).as_matrix(), p) for y, p in zip(yaw, np.cumsum(step, 0))]
    )
    noise = [
        _pose(Rotation.from_rotvec(rng.normal(0, 0.002, 3)).as_matrix(), rng.normal(0, 0.02, 3))
        for _ in range(n)
    ]
    est = gt.copy()
    for k in range(1, n):  # accumulate noisy increments
        est[k] = est[k - 1] @ (np.linalg.inv(gt[k - 1]) @ gt[k]) @ noise[k]
    t_ref, r_ref = sequence_error(gt, est)
    res = rpe_kitti(gt, est)
    assert res["t_err_pct"] == pytest.approx(t_ref, rel=1e-6)
    # kiss-icp converts rad to deg with 180 / 3.14 rather than 180 / pi
    assert res["r_err_deg_per_m"] == pytest.approx(r_ref * 3.14 / np.pi, rel=1e-6)


def test_end_drift_and_path_length():
    gt = _line(11)
    est = gt.copy()
    est[-1, 1, 3] = 0.5  # the last pose 0.5 m to the side
    np.testing.assert_allclose(path_length(gt), np.arange(11.0))
    res = end_drift(gt, est)
    assert res["error_m"] == pytest.approx(0.5)
    assert res["pct"] == pytest.approx(5.0)


def test_bad_input_is_refused():
    with pytest.raises(ValueError, match="pose arrays"):
        ate(_line(5), _line(4))
    bad = _line(5)
    bad[2, 0, 3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        rpe_kitti(_line(5), bad)


def test_remove_ground_follows_a_tilted_road():
    from nidar_mi.eval.drive.kiss import remove_ground

    rng = np.random.default_rng(0)
    xy = rng.uniform(-30, 30, (5000, 2))
    # the road seen from a LiDAR 1.73 m up, rolled by 1.5 deg and pitched by 0.8 deg
    z = -1.73 + np.tan(np.radians(1.5)) * xy[:, 1] + np.tan(np.radians(0.8)) * xy[:, 0]
    road = np.column_stack([xy, z + rng.normal(0, 0.01, len(z))])
    wall = np.column_stack([np.full(300, 8.0), rng.uniform(-5, 5, 300), rng.uniform(-1.2, 3, 300)])
    kept = remove_ground(np.vstack([road, wall]))
    assert len(kept) == 300
    np.testing.assert_array_equal(kept[:, 0], 8.0)


def test_overlap_counts_the_aligned_points_within_the_distance():
    from nidar_mi.eval.drive.kiss import GROUND_Z_M, aligned_overlap

    # a 1 m grid of points above the ground, 30 x 30 m; two ground points that never count
    g = np.arange(-15.0, 15.0)
    xyz = np.stack(np.meshgrid(g, g, [0.0], indexing="ij"), -1).reshape(-1, 3)
    xyz = np.vstack([xyz, [[0.0, 0.0, GROUND_Z_M - 1], [1.0, 0.0, GROUND_Z_M - 1]]])
    T = np.eye(4)
    assert aligned_overlap(xyz, xyz, T) == 1.0
    T[0, 3] = 0.2  # every point 0.2 m from its old place
    assert aligned_overlap(xyz, xyz, T) == 1.0 and aligned_overlap(xyz, xyz, T, within_m=0.1) == 0.0
    T[0, 3] = 0.5  # half a cell: 0.5 m from two points
    assert aligned_overlap(xyz, xyz, T) == 0.0
    T[0, 3] = 20.0  # 20 m along x: a third of the columns land 0 m from a point
    assert aligned_overlap(xyz, xyz, T) == pytest.approx(10 / 30)


def _hall_points(rng, T=None, n=60000):
    """A closed hall, 40 x 30 m, floor at -1.2 m and ceiling at 3 m, with three pillars and two
    boxes, drawn at random on its surfaces and seen from pose ``T`` (points in the sensor's
    frame: ``T`` maps them into the hall's)."""
    u = rng.uniform(size=(n, 2))
    size = np.array([40.0, 30.0, 4.2])
    lo = np.array([-15.0, -12.0, -1.2])
    faces = []
    for axis in range(3):  # the six faces, points in proportion to their areas
        a, b = [k for k in range(3) if k != axis]
        for side in (0.0, 1.0):
            m = int(n * size[a] * size[b] / 1300)
            p = np.empty((m, 3))
            p[:, axis] = lo[axis] + side * size[axis]
            p[:, a] = lo[a] + u[:m, 0] * size[a]
            p[:, b] = lo[b] + u[:m, 1] * size[b]
            faces.append(p)
    for cx, cy in ((5.0, 5.0), (-8.0, -6.0), (12.0, -4.0)):  # pillars, r = 0.3 m
        ang = u[: n // 10, 0] * 2 * np.pi
        z = lo[2] + u[: n // 10, 1] * size[2]
        faces.append(np.c_[cx + 0.3 * np.cos(ang), cy + 0.3 * np.sin(ang), z])
    for cx, cy, h in ((0.0, -5.0, 1.5), (-10.0, 6.0, 2.5)):  # boxes 2 x 1 m, their sides
        m = n // 6
        side = rng.integers(0, 4, m)
        s = u[:m, 0] * 2 - 1
        x = np.where(side < 2, cx + s, cx + np.where(side == 2, -1.0, 1.0))
        y = np.where(side < 2, cy + np.where(side == 0, -0.5, 0.5), cy + s * 0.5)
        faces.append(np.c_[x, y, lo[2] + u[:m, 1] * h])
    world = np.concatenate(faces)
    T = np.eye(4) if T is None else T
    return (world - T[:3, 3]) @ T[:3, :3]


def test_register_pair_recovers_a_known_motion_and_agrees_with_kiss_icp():
    """Two draws of the same hall, the second seen from a pose 1.2 m ahead, 0.4 m to the side
    and turned 6 degrees: register_pair finds that pose from a guess ~1 m and 3 degrees off,
    and KISS-ICP's own registration finds the same on the same down-sampled scans."""
    from kiss_icp.mapping import VoxelHashMap
    from kiss_icp.registration import Registration

    from nidar_mi.eval.drive.kiss import register_pair, voxel_down_sample
    from nidar_mi.geometry.se3 import se3_exp

    rng = np.random.default_rng(3)
    target = _hall_points(rng)
    T_true = se3_exp(np.array([1.2, 0.4, 0.0, 0.0, 0.0, np.radians(6.0)]))
    source = _hall_points(rng, T_true)  # T_true maps it onto the target
    guess = se3_exp(np.array([0.3, -0.2, 0.0, 0.0, 0.0, np.radians(3.0)]))
    T = register_pair(source, target, guess)
    np.testing.assert_allclose(T[:3, 3], T_true[:3, 3], atol=0.03)
    assert abs(np.arctan2(T[1, 0], T[0, 0]) - np.radians(6.0)) < np.radians(0.1)
    # the same down-sampled scans through KISS-ICP's registration
    ref_map = VoxelHashMap(voxel_size=1.0, max_distance=100.0, max_points_per_voxel=20)
    ref_map.add_points(voxel_down_sample(target, 0.5))
    reg = Registration(max_num_iterations=500, convergence_criterion=1e-4, max_num_threads=2)
    ref = guess
    for sigma in (2.0, 1.0, 0.3):
        ref = reg.align_points_to_map(
            voxel_down_sample(source, 1.5), ref_map, ref, 3 * sigma, sigma
        )
    np.testing.assert_allclose(T[:3, 3], ref[:3, 3], atol=0.03)
    np.testing.assert_allclose(T[:3, :3], ref[:3, :3], atol=2e-3)


def test_voxel_down_sample_keeps_the_first_point_of_each_cube():
    from nidar_mi.eval.drive.kiss import voxel_down_sample

    xyz = np.array([[0.1, 0.1, 0.1], [0.9, 0.2, 0.3], [1.1, 0.0, 0.0], [0.2, 0.2, -0.5]])
    np.testing.assert_array_equal(voxel_down_sample(xyz, 1.0), xyz[[0, 2, 3]])
    assert voxel_down_sample(np.zeros((0, 3)), 1.0).shape == (0, 3)
