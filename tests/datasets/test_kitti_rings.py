"""Rings from KITTI's storage order and the road plane, on synthetic sweeps built like KITTI's."""

import numpy as np
import pytest

from nidar_mi.datasets.kitti_rings import ground_plane, grow_ground, scan_rings


def _sweep(rings=8, cols=400, half=False, seed=0, height=1.73, slope_deg=0.0):
    """A KITTI-ordered sweep: ring by ring (highest first), each starting near azimuth 0 and
    turning counter-clockwise once; points on a road plane (rising ``slope_deg`` beyond 20 m)."""
    rng = np.random.default_rng(seed)
    span = 180.0 if half else 360.0
    out, truth = [], []
    elevations = np.linspace(-3.0, -20.0, rings)
    for r, el in enumerate(elevations):
        az = (np.arange(cols) + 0.5) * span / cols + rng.normal(0, 0.05, cols)
        az = az if not half else az - 90.0
        az = np.where(az > 180.0, az - 360.0, az) if not half else az
        # storage starts at azimuth 0: rotate the sequence so the first point is just above 0
        start = int(np.argmin(np.where(az >= 0, az, 999.0)))
        az = np.roll(az, -start)
        d = height / np.sin(np.radians(-el))
        rho = d * np.cos(np.radians(el))
        z = -height + np.maximum(rho - 20.0, 0.0) * np.tan(np.radians(slope_deg))
        a = np.radians(az)
        out.append(np.stack([rho * np.cos(a), rho * np.sin(a), np.full(cols, z)], 1))
        truth.append(np.full(cols, r))
    return np.concatenate(out), np.concatenate(truth)


@pytest.mark.parametrize("half", [False, True])
def test_rings_from_storage_order(half):
    xyz, truth = _sweep(half=half)
    np.testing.assert_array_equal(scan_rings(xyz), truth)


def test_ground_plane_and_growing_over_a_rise():
    xyz, ring = _sweep(rings=24, cols=720, slope_deg=1.0)
    rng = np.random.default_rng(1)
    noisy = xyz + rng.normal(0, 0.01, xyz.shape)
    wall = np.stack([np.full(200, 6.0), np.linspace(-2, 2, 200), np.linspace(-1.7, 1.0, 200)], 1)
    n, c = ground_plane(np.concatenate([noisy, wall]), np.random.default_rng(2))
    np.testing.assert_allclose(n, [0, 0, 1], atol=2e-3)
    assert c == pytest.approx(1.73, abs=0.01)
    step = 0.5
    flat_only = np.abs(noisy @ n + c) < 0.2
    grown = grow_ground(noisy, ring, (n, c), step)
    rho = np.hypot(noisy[:, 0], noisy[:, 1])
    # the road rises 1 degree beyond 20 m: the plane loses it past ~31 m, growing keeps it
    assert not flat_only[rho > 40].any() and grown.all()
