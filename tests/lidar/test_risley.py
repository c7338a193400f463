"""The Risley-prism (rosette) pattern: the Livox Mid-40 preset against its datasheet, the prisms'
refraction against the thin-prism law, the pattern's non-repetition, and a scan."""

import numpy as np
import pytest

from nidar_mi.lidar.config import LidarConfig
from nidar_mi.lidar.pattern import PRESETS, RisleyPattern
from nidar_mi.lidar.risley import MID40_PRISMS, RisleyPrisms

# Livox wiki, "Livox Point Cloud and Coordinate System", Mid series point cloud specifications:
# FOV 38.4 deg (circular), data rate 100,000 points/s, detection range 90 m @ 10 %, 130 m @ 20 %,
# 260 m @ 80 % reflectivity (100 klx); one laser (the rosette of two Risley prisms)
MID40_FOV_DEG, MID40_POINTS_PER_S, MID40_RANGE_80 = 38.4, 100_000, 260.0
# no minimum range stated: HELIOS++'s livox_mid-40 rangeMin_m (3dgeo-heidelberg/helios@fd94d1f)
MID40_RANGE_MIN = 1.0


def test_livox_mid40_against_its_datasheet():
    cfg = LidarConfig.from_mapping("l", {"preset": "livox_mid40"})
    pattern = cfg.pattern
    assert isinstance(pattern, RisleyPattern) and cfg.rings == 1
    assert cfg.horizontal_resolution * cfg.rotation_rate == MID40_POINTS_PER_S
    assert np.all(np.diff(pattern.column_time_s()) == pytest.approx(1.0 / MID40_POINTS_PER_S))
    # one second of shots: the widest beam is the field of view's edge
    second = RisleyPattern(
        cfg.laser_table, MID40_POINTS_PER_S, rotation_rate=1.0, prisms=MID40_PRISMS
    )
    d, origins = second.beams()
    off_axis = np.degrees(np.arccos(d[:, 0]))
    assert origins is None and np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert 2.0 * off_axis.max() == pytest.approx(MID40_FOV_DEG, abs=0.15)
    assert 2.0 * MID40_PRISMS.half_angle_deg() == pytest.approx(MID40_FOV_DEG, abs=0.1)
    assert off_axis.min() < 0.1  # the rosette's petals pass through the centre
    assert PRESETS["livox_mid40"].fov_h == MID40_FOV_DEG
    assert (cfg.range_min, cfg.range_max) == (MID40_RANGE_MIN, MID40_RANGE_80)
    assert cfg.frame_rate == cfg.rotation_rate


def test_thin_prisms_follow_the_thin_prism_law():
    """Thin wedges deviate a beam by (n - 1)·α each (first order): aligned, by the sum;
    the exact refraction agrees to the second-order term."""
    thin = RisleyPrisms((1.0, 0.5), (1.5, 1.5), (0.0, 0.0), "test")
    assert thin.half_angle_deg() == pytest.approx(0.5 * 1.0 + 0.5 * 0.5, rel=2e-3)
    opposed = RisleyPrisms((1.0, 0.5), (1.5, 1.5), (0.0, 0.5), "test")
    d = opposed.directions(np.array([1.0]))  # second prism half a turn on: 0.5 - 0.25 deg
    assert np.degrees(np.arccos(d[0, 0])) == pytest.approx(0.25, rel=5e-3)


def _coverage(directions: np.ndarray, cell_deg: float = 0.5) -> set:
    """The cells of a cell_deg grid of (y, z) angles that the beams hit."""
    y = np.degrees(np.arctan2(directions[:, 1], directions[:, 0]))
    z = np.degrees(np.arctan2(directions[:, 2], directions[:, 0]))
    return set(zip(np.floor(y / cell_deg).astype(int), np.floor(z / cell_deg).astype(int)))


def test_the_rosette_does_not_repeat():
    """The prisms turn at incommensurable rates: a sweep's shots are not the next sweep's, and
    the area covered keeps growing with the integration time."""
    t = np.arange(100_000) / 100_000.0  # one second
    d = MID40_PRISMS.directions(t)
    first, second = d[:10_000], d[10_000:20_000]
    assert np.degrees(np.arccos(np.sum(first * second, axis=1))).max() > 10.0
    covered = [len(_coverage(d[: int(n)])) for n in (1e3, 1e4, 1e5)]
    assert covered[0] < covered[1] < covered[2]
    assert len(_coverage(second) - _coverage(first)) > 0.2 * len(_coverage(second))


def test_livox_mid40_scans_a_wall(variant, write_scene):
    """Every shot of the 38.4 deg cone meets a wall 10 m ahead (+-40 m) at x = 10 m, along its
    prism direction, at its firing time."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    body = """<sensor type="lidar" id="l"><string name="preset" value="livox_mid40"/>
        <integer name="horizontal_resolution" value="2000"/></sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf>
    <shape type="rectangle" id="wall"><transform name="to_world"><scale value="40"/>
        <rotate y="1" angle="-90"/><translate x="10"/></transform><ref id="grey"/></shape>"""
    loaded = load_scene(write_scene(body))
    cfg = loaded.lidars[0].config
    p = scan(loaded.scene, loaded.lidars[0], to_world=np.eye(4)).points()
    assert len(p["range"]) == 2000 and np.all(p["ring"] == 0)
    want = MID40_PRISMS.directions(p["column"] / (2000 * cfg.rotation_rate))
    np.testing.assert_allclose(p["xyz"], want * (10.0 / want[:, :1]), atol=2e-3)
    np.testing.assert_allclose(p["t"], p["column"] / (2000 * 10.0), atol=1e-7)
