"""Pose-graph correction on a hand-made loop."""

import numpy as np
from scipy.spatial.transform import Rotation

from nidar_mi.eval.drive.odometry import ate
from nidar_mi.eval.drive.pose_graph import optimise


def _pose(yaw, x, y):
    T = np.eye(4)
    T[:3, :3] = Rotation.from_euler("z", yaw).as_matrix()
    T[:2, 3] = x, y
    return T


def test_a_loop_closure_removes_the_drift_of_a_square():
    # true drive: a 10 m square, 1 m steps, back at the start; odometry turns 5 % too little
    gt, odo = [_pose(0, 0, 0)], [_pose(0, 0, 0)]
    for _side in range(4):
        for step in range(10):
            turn = np.pi / 2 if step == 9 else 0.0
            rel = _pose(turn, 1.0, 0.0)
            rel_odo = _pose(turn * 0.95, 1.0, 0.0)
            gt.append(gt[-1] @ rel)
            odo.append(odo[-1] @ rel_odo)
    gt, odo = np.stack(gt), np.stack(odo)
    before = ate(gt, odo)["rmse"]
    fixed = optimise(odo, [(0, len(gt) - 1, np.linalg.inv(gt[0]) @ gt[-1])])
    after = ate(gt, fixed)["rmse"]
    assert before > 0.3 and after < 0.25 * before
    # the end pose is pulled onto the start, as the loop says
    np.testing.assert_allclose(fixed[-1][:2, 3], fixed[0][:2, 3], atol=0.2)


def test_no_loop_leaves_the_odometry_unchanged():
    odo = np.stack([_pose(0.1 * k, k, 0) for k in range(5)])
    np.testing.assert_array_equal(optimise(odo, []), odo)
