"""Elevation agreement of the HDL-64E layouts with real KITTI returns, and of a layout with a
cloud it produced itself.

Real frames: ``../shared/data/kitti/velodyne`` (or ``NIDAR_KITTI_DIR``), read at run time;
skipped with a message where absent. Reference values: an independent measurement on the same six
frames (ring-matched median 2.44° for the uniform table, 0.35° for the S2.1 table with its
offsets; nearest-ring 0.113° and 0.077°); tolerance 0.01°.
"""

import os
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def _velodyne_dir() -> Path:
    env = os.environ.get("NIDAR_KITTI_DIR")
    path = (Path(env) if env else REPO.parent / "shared" / "data" / "kitti") / "velodyne"
    if not path.is_dir():
        pytest.skip(f"real KITTI frames not found at {path}")
    return path


def _pattern(**values):
    from nidar_mi.lidar.config import LidarConfig

    return LidarConfig.from_mapping("l", {"preset": "hdl64e", **values}).pattern


@pytest.mark.parametrize(
    "values, ring_matched, nearest",
    [({"layout": "uniform"}, 2.44, 0.113), ({}, 0.35, 0.077)],  # {}: per_laser by default
)
def test_kitti_elevation_agreement(values, ring_matched, nearest):
    from nidar_mi.eval.layout_agreement import elevation_agreement

    a = elevation_agreement(_pattern(**values), _velodyne_dir())
    assert len(a.frames) >= 6 and a.returns > 600_000 and not a.skipped
    assert a.ring_matched_median == pytest.approx(ring_matched, abs=0.01)
    assert a.nearest_median == pytest.approx(nearest, abs=0.01)


def test_a_layout_agrees_with_its_own_scan(variant, write_scene, tmp_path):
    """A per-laser scan of a closed room, stored KITTI-style (ring by ring, each from azimuth 0
    counter-clockwise): the storage order gives back the rings and every return lies on its own
    laser's beam (offsets included)."""
    from nidar_mi.datasets.kitti_rings import scan_rings
    from nidar_mi.eval.layout_agreement import elevation_agreement
    from nidar_mi.io.kitti import write_kitti_bin
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    body = """
    <sensor type="lidar" id="lidar"><string name="preset" value="hdl64e"/>
        <string name="layout" value="per_laser"/><integer name="horizontal_resolution" value="360"/>
        <float name="range_max" value="200"/></sensor>
    <shape type="cube"><transform name="to_world"><scale value="12"/></transform>
        <bsdf type="twosided"><bsdf type="diffuse"/></bsdf></shape>
    """
    L = load_scene(write_scene(body))
    r = scan(L.scene, L.lidars[0])
    p = r.points()
    assert len(p["range"]) == 64 * 360
    az = np.mod(np.degrees(np.arctan2(p["xyz"][:, 1], p["xyz"][:, 0])), 360.0)
    order = np.lexsort((az, p["ring"]))
    velodyne = tmp_path / "velodyne"
    write_kitti_bin(velodyne / "000000.bin", p["xyz"][order], p["intensity"][order])
    np.testing.assert_array_equal(scan_rings(p["xyz"][order].astype(np.float64)), p["ring"][order])
    a = elevation_agreement(L.lidars[0].config.pattern, velodyne)
    assert a.ring_matched_median < 1e-4 and a.ring_matched_p90 < 1e-3
