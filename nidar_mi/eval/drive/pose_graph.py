"""Pose-graph correction of an odometry trajectory with loop closures (GTSAM).

The graph has one ``Pose3`` per frame, a prior holding the first pose, a between factor per
odometry step (the relative pose of consecutive odometry poses; sigmas
:data:`ODOMETRY_SIGMAS`) and a between factor per loop (the registered relative pose; sigmas
:data:`LOOP_SIGMAS`; loops reach the graph only after their registration passed the overlap
check, so no robust kernel, which would also discount the large corrections a loop exists to
make), solved with Levenberg-Marquardt (Dellaert and Kaess, "Factor Graphs for Robot
Perception", 2017).
"""

from __future__ import annotations

import numpy as np

__all__ = ["ODOMETRY_SIGMAS", "LOOP_SIGMAS", "optimise"]

#: (roll, pitch, yaw in rad; x, y, z in m) standard deviations of one odometry step.
ODOMETRY_SIGMAS = (0.002, 0.002, 0.005, 0.05, 0.05, 0.05)
#: The same for one loop constraint.
LOOP_SIGMAS = (0.01, 0.01, 0.02, 0.2, 0.2, 0.2)


def optimise(odometry: np.ndarray, loops: list[tuple[int, int, np.ndarray]]) -> np.ndarray:
    """Poses after adding ``loops`` to the odometry chain.

    Args:
        odometry: (N, 4, 4) odometry poses ``T_{0 <- k}``.
        loops: (i, j, T_ij) with T_ij the pose of frame j in frame i (``inv(T_0i) T_0j``).

    Returns:
        (N, 4, 4) optimised poses (the odometry itself when there is no loop).
    """
    import gtsam

    odometry = np.asarray(odometry, dtype=np.float64)
    if not loops:
        return odometry.copy()
    graph = gtsam.NonlinearFactorGraph()
    values = gtsam.Values()
    odo_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(ODOMETRY_SIGMAS))
    loop_noise = gtsam.noiseModel.Diagonal.Sigmas(np.array(LOOP_SIGMAS))
    graph.add(
        gtsam.PriorFactorPose3(
            0, gtsam.Pose3(odometry[0]), gtsam.noiseModel.Isotropic.Sigma(6, 1e-6)
        )
    )
    for k in range(len(odometry)):
        values.insert(k, gtsam.Pose3(odometry[k]))
        if k:
            rel = np.linalg.inv(odometry[k - 1]) @ odometry[k]
            graph.add(gtsam.BetweenFactorPose3(k - 1, k, gtsam.Pose3(rel), odo_noise))
    for i, j, T in loops:
        graph.add(gtsam.BetweenFactorPose3(int(i), int(j), gtsam.Pose3(np.asarray(T)), loop_noise))
    result = gtsam.LevenbergMarquardtOptimizer(graph, values).optimize()
    return np.stack([result.atPose3(k).matrix() for k in range(len(odometry))])
