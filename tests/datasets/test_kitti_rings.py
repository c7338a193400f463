"""Rings from KITTI's storage order (checked by elevation, with the elevation fallback), truncated
scans, and the road plane, on synthetic sweeps built like KITTI's and the real scans."""

import os
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.datasets.kitti_rings import (
    checked_rings,
    elevation_rings,
    ground_plane,
    grow_ground,
    scan_rings,
)
from nidar_mi.io.kitti import read_kitti_bin
from nidar_mi.lidar.pattern import elevation_table
from tests.helpers.synthetic_kitti import kitti_order_scan


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


REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("front_only", [False, True])
def test_scan_order_gives_the_true_rings(front_only):
    xyz, ring, _ = kitti_order_scan(front_only=front_only)
    got = checked_rings(xyz)
    assert got is not None and got.dtype == np.int16
    np.testing.assert_array_equal(got, ring)


def test_a_scan_cut_inside_a_ring_gives_that_ring_its_own_start():
    xyz, ring, _ = kitti_order_scan(cols=720, rings=40)
    cut = np.flatnonzero(ring == 39)[100]  # 100 points into the last ring (azimuth 0 to 50 deg)
    np.testing.assert_array_equal(checked_rings(xyz[:cut]), ring[:cut])
    front, fring, _ = kitti_order_scan(cols=720, rings=40, front_only=True)
    cut = np.flatnonzero(fring == 39)[60]
    np.testing.assert_array_equal(checked_rings(front[:cut]), fring[:cut])


def test_a_short_scan_keeps_its_top_rings():
    xyz, ring, _ = kitti_order_scan(rings=39)
    np.testing.assert_array_equal(checked_rings(xyz), ring)
    assert checked_rings(xyz[:0]).shape == (0,)


def test_an_unordered_cloud_is_refused_and_elevation_is_the_fallback():
    xyz, ring, rng = kitti_order_scan(offset_m=0.03)
    perm = np.random.default_rng(1).permutation(len(xyz))
    assert checked_rings(xyz[perm]) is None
    # order kept, but ring elevations rising: not a scan either
    assert checked_rings(xyz[np.argsort(-ring, kind="stable")]) is None
    est = elevation_rings(xyz[perm], elevation_table("hdl64e"))
    far = rng[perm] > 20.0  # 3 cm of mounting offset moves a 25 m return by < 0.07 deg
    np.testing.assert_array_equal(est[far], ring[perm][far])


def _shared(name: str) -> Path:
    root = Path(os.environ.get("NIDAR_MI_DATA", REPO.parent / "shared" / "data"))
    path = root / name
    if not (path / "velodyne").is_dir():
        pytest.skip(f"real KITTI scans not found at {path} (set NIDAR_MI_DATA)")
    return path


def test_real_scans_have_64_rings_except_the_truncated_one():
    counts = {}
    for name in ("kitti", "kitti_raw_0926"):
        for p in sorted((_shared(name) / "velodyne").glob("*.bin")):
            rings = checked_rings(read_kitti_bin(p)[0])
            assert rings is not None, p
            counts[f"{name}/{p.stem}"] = int(rings.max()) + 1
    short = {k: v for k, v in counts.items() if v != 64}
    assert len(counts) == 84 and short == {"kitti_raw_0926/000077": 39}
