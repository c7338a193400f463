"""Rings of KITTI scans: from the stored order, checked by elevation; the elevation fallback;
truncated files."""

from __future__ import annotations

import os
import warnings
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.datasets.kitti import elevation_rings, read_scan, scan_rings
from nidar_mi.lidar.pattern import elevation_table
from tests.helpers.synthetic_kitti import kitti_order_scan

REPO = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("front_only", [False, True])
def test_scan_order_gives_the_true_rings(front_only):
    xyz, ring, _ = kitti_order_scan(front_only=front_only)
    got = scan_rings(xyz)
    assert got is not None and got.dtype == np.int16
    np.testing.assert_array_equal(got, ring)


def test_a_short_scan_keeps_its_top_rings():
    xyz, ring, _ = kitti_order_scan(rings=39)
    np.testing.assert_array_equal(scan_rings(xyz), ring)
    assert scan_rings(xyz[:0]).shape == (0,)


def test_an_unordered_cloud_is_refused_and_elevation_is_the_fallback():
    xyz, ring, rng = kitti_order_scan(offset_m=0.03)
    perm = np.random.default_rng(1).permutation(len(xyz))
    assert scan_rings(xyz[perm]) is None
    # order kept, but ring elevations rising: not a scan either
    assert scan_rings(xyz[np.argsort(-ring, kind="stable")]) is None
    est = elevation_rings(xyz[perm], elevation_table("hdl64e"))
    far = rng[perm] > 20.0  # 3 cm of mounting offset moves a 25 m return by < 0.07 deg
    np.testing.assert_array_equal(est[far], ring[perm][far])


def test_read_scan_drops_a_trailing_partial_point(tmp_path):
    rows = np.arange(32, dtype="<f4").reshape(8, 4)
    path = tmp_path / "cut.bin"
    path.write_bytes(rows.tobytes() + b"\x00" * 7)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        xyz, inten = read_scan(path)
    assert any("truncated scan" in str(x.message) for x in w)
    np.testing.assert_array_equal(xyz, rows[:, :3])
    np.testing.assert_array_equal(inten, rows[:, 3])


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
            rings = scan_rings(read_scan(p)[0])
            assert rings is not None, p
            counts[f"{name}/{p.stem}"] = int(rings.max()) + 1
    short = {k: v for k, v in counts.items() if v != 64}
    assert len(counts) == 84 and short == {"kitti_raw_0926/000077": 39}
