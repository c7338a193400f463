"""SE(3) exponential, logarithm and pose interpolation against closed forms."""

import numpy as np
import pytest

from nidar_mi.geometry.se3 import interpolate_poses, se3_exp, se3_log


def _arc_pose(t, v=10.0, omega=0.5):
    """A vehicle driving at v (m/s) along its x axis while yawing at ω (rad/s), from the origin:
    position (v/ω · sin ωt, v/ω · (1 - cos ωt)), heading ωt."""
    c, s = np.cos(omega * t), np.sin(omega * t)
    T = np.eye(4)
    T[:2, :2] = [[c, -s], [s, c]]
    T[0, 3], T[1, 3] = v / omega * s, v / omega * (1 - c)
    return T


def test_exp_log_round_trip():
    rng = np.random.default_rng(0)
    xi = rng.normal(size=(50, 6)) * [2, 2, 2, 0.8, 0.8, 0.8]
    np.testing.assert_allclose(se3_log(se3_exp(xi)), xi, atol=1e-10)
    np.testing.assert_allclose(se3_exp(np.zeros(6)), np.eye(4), atol=1e-15)
    small = np.array([0.1, 0, 0, 0, 0, 1e-9])
    # V ≈ I + W/2 for a tiny rotation: t = (0.1, 0.1 · 1e-9 / 2, 0)
    np.testing.assert_allclose(se3_exp(small)[:3, 3], [0.1, 5e-11, 0], rtol=1e-9, atol=1e-18)


def test_constant_twist_follows_the_arc_not_the_chord():
    times = np.array([0.0, 1.0])
    poses = np.stack([_arc_pose(0.0), _arc_pose(1.0)])
    q = np.linspace(0.0, 1.0, 11)
    out = interpolate_poses(times, poses, q)
    for t, T in zip(q, out):
        np.testing.assert_allclose(T, _arc_pose(t), atol=1e-12)
    chord_mid = 0.5 * (poses[0, :3, 3] + poses[1, :3, 3])
    assert np.linalg.norm(out[5, :3, 3] - chord_mid) > 0.1  # slerp + lerp would sit on the chord


def test_samples_exact_and_outside_refused():
    times = np.array([0.0, 0.5, 1.5])
    poses = np.stack([_arc_pose(t) for t in times])
    np.testing.assert_array_equal(interpolate_poses(times, poses, times), poses)
    with pytest.raises(ValueError, match="outside the trajectory"):
        interpolate_poses(times, poses, [1.6])
