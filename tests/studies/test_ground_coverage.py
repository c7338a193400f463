"""Ground coverage per ring, real KITTI frames (../shared/data/kitti) against the flat-road scan."""

import os
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.studies.ground_coverage import (
    LAMBERTIAN_ASPHALT,
    ROUGH_ASPHALT,
    RingCoverage,
    compare_rings,
    kitti_ground_rings,
    simulate_flat_road,
)

REPO = Path(__file__).resolve().parents[2]


def _kitti_velodyne() -> Path:
    env = os.environ.get("NIDAR_KITTI_DIR")
    path = (Path(env) if env else REPO.parent / "shared" / "data" / "kitti") / "velodyne"
    if not path.is_dir():
        pytest.skip(f"KITTI frames not found at {path} (set NIDAR_KITTI_DIR)")
    return path


def test_compare_rings_on_hand_made_coverage():
    real = RingCoverage(
        [np.array([10.0, 10.2, 9.8]), np.array([5.0] * 300)],
        np.array([190, 300]),
        np.array([10, 0]),
        1,
    )
    sim = RingCoverage(
        [np.array([10.5] * 4), np.array([6.0] * 4)],
        np.array([4, 4]),
        np.array([0, 0]),
        1,
        np.array([10.5, 6.0]),
    )
    rows = compare_rings(real, sim, min_references=100)
    assert [r["ratio"] for r in rows] == pytest.approx([1.05, 1.2])
    assert [r["range_ok"] for r in rows] == [True, False]
    assert [r["real_p"] for r in rows] == pytest.approx([0.95, 1.0])
    assert all(r["p_ok"] for r in rows) and [r["ok"] for r in rows] == [True, False]


def test_real_frames_rings_and_detection(variant):
    real = kitti_ground_rings(_kitti_velodyne())
    assert real.frames == 6  # every frame gives 64 rings from its storage order
    med = real.medians()
    # rings 20-55 meet the road in order, nearer for lower lasers
    assert np.all(np.diff(med[20:56]) < 0)
    assert 15.0 < med[25] < 20.0 and 4.0 < med[63] < 5.0
    p = real.p_detect
    assert np.all(p[(med < 25.0) & (med > 5.0)] > 0.95)  # the road close by is always seen

    before = compare_rings(real, simulate_flat_road("hdl64e", LAMBERTIAN_ASPHALT, threshold=5e-5))
    after = compare_rings(real, simulate_flat_road("hdl64e", ROUGH_ASPHALT))
    ok_before = sum(r["p_at_range_ok"] for r in before)
    ok_after = sum(r["p_at_range_ok"] for r in after)
    # the Lambertian road stops at 16.5 m; the calibrated rough asphalt follows the real
    # detection out to ~40 m, ring by ring at matching range
    assert ok_after >= ok_before + 8
    for row in after:
        if row["compared"] and 17.0 < row["real_median_m"] < 40.0:
            assert row["p_at_range_ok"], row
