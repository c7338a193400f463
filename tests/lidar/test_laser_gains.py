"""Per-laser gains, the range response, the per-laser range response and the intensity offset
against the closed form.

A sensor 1 m above a Lambertian floor (ρ = 0.5), two rings at -10° and -30°: ring r hits the
floor at range ``d_r = 1 / sin(-θ_r)`` with ``cos θ = sin(-θ_r)``, so in ``compensated`` mode the
reported intensity is ``max(g · G_r · ρ · cos θ · r(d_r) - b, 0)``, ``r`` the piecewise-linear
response through the given knots (computed here by hand), times ring r's own factor
``m_r(d_r)`` through the same knots where ``laser_range_response`` gives one.
"""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from tests.helpers.floor_scene import ELEV, floor_scene


def _scene(params: str) -> str:
    return floor_scene(params, gain=2.0)


def test_gains_response_and_offset_match_the_closed_form(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    params = """<string name="laser_gains" value="1.5, 0.6"/>
        <string name="range_response" value="1:2, 3:0.5, 10:1"/>
        <float name="intensity_offset" value="0.05"/>"""
    loaded = load_scene(write_scene(_scene(params)))
    r = scan(loaded.scene, loaded.lidars[0])
    s = np.sin(np.radians(-np.asarray(ELEV)))
    d = 1.0 / s
    response = np.interp(d, [1.0, 3.0, 10.0], [2.0, 0.5, 1.0])  # 5.76 m and 2 m
    expected = np.maximum(2.0 * np.array([1.5, 0.6]) * 0.5 * s * response - 0.05, 0.0)
    assert r.valid.all()
    np.testing.assert_allclose(r.range.mean(axis=1), d, rtol=1e-5)
    np.testing.assert_allclose(r.intensity, np.repeat(expected[:, None], 36, 1), rtol=1e-5)


def test_per_laser_range_response_matches_the_closed_form(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    params = """<string name="laser_gains" value="1.5, 0.6"/>
        <string name="range_response" value="1:2, 3:0.5, 10:1"/>
        <string name="laser_range_response" value="1, 1.2, 0.8; 0.5, 2, 3"/>"""
    loaded = load_scene(write_scene(_scene(params), name="shapes.xml"))
    r = scan(loaded.scene, loaded.lidars[0])
    s = np.sin(np.radians(-np.asarray(ELEV)))
    d = 1.0 / s  # 5.76 m and 2 m
    knots = [1.0, 3.0, 10.0]
    shared = np.interp(d, knots, [2.0, 0.5, 1.0])
    own = np.array([np.interp(d[0], knots, [1, 1.2, 0.8]), np.interp(d[1], knots, [0.5, 2, 3])])
    expected = 2.0 * np.array([1.5, 0.6]) * 0.5 * s * shared * own
    assert r.valid.all()
    np.testing.assert_allclose(r.intensity, np.repeat(expected[:, None], 36, 1), rtol=1e-5)


@pytest.mark.parametrize("divergence", ["0", "1"])
def test_per_laser_offsets_match_the_closed_form(variant, write_scene, divergence):
    """``max(E - b - b_r, 0)`` for each ring, on one ray per beam and on diverging beams (the
    echo path: sub-rays on the flat floor, the same return)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    params = f"""<float name="intensity_offset" value="0.05"/>
        <string name="laser_offsets" value="0.02, 0.2"/>
        <float name="beam_divergence" value="{divergence}"/>"""
    loaded = load_scene(write_scene(_scene(params), name=f"offsets{divergence}.xml"))
    r = scan(loaded.scene, loaded.lidars[0])
    s = np.sin(np.radians(-np.asarray(ELEV)))
    expected = np.maximum(2.0 * 0.5 * s - 0.05 - np.array([0.02, 0.2]), 0.0)
    assert r.valid.all() and expected[1] > 0
    np.testing.assert_allclose(r.intensity, np.repeat(expected[:, None], 36, 1), rtol=2e-3)


def test_without_them_the_scan_is_unchanged(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    plain = scan(*_loaded(load_scene, write_scene, ""))
    ones = scan(
        *_loaded(
            load_scene,
            write_scene,
            '<string name="laser_gains" value="1, 1"/><string name="range_response" value="0:1"/>',
        )
    )
    np.testing.assert_array_equal(plain.intensity, ones.intensity)


def _loaded(load_scene, write_scene, params):
    loaded = load_scene(write_scene(_scene(params), name=f"s{abs(hash(params))}.xml"))
    return loaded.scene, loaded.lidars[0]


@pytest.mark.parametrize(
    "name, value, needle",
    [
        ("laser_gains", "1, 2, 3", "one gain per laser (2, got 3)"),
        ("laser_gains", "1, -1", "> 0"),
        ("laser_gains", "1, x", "comma-separated numbers"),
        ("range_response", "5:1, 2:1", "strictly increasing"),
        ("range_response", "1:1, 2", "range:factor pairs"),
        ("range_response", "1:-1", "factors >= 0"),
        ("laser_offsets", "0, 0, 0", "one offset per laser (2, got 3)"),
        ("laser_offsets", "0, -1", ">= 0"),
        ("laser_offsets", "0, x", "comma-separated numbers"),
        ("laser_range_response", "1, 1; 1, 1", "needs range_response"),
        ("laser_range_response", "1, x", "rows of comma-separated factors"),
        ("laser_range_response", "1, -1; 1, 1", "factors >= 0"),
    ],
)
def test_bad_values_are_refused_in_one_line(name, value, needle):
    from nidar_mi.lidar.config import LidarConfig

    with pytest.raises(NidarError) as e:
        LidarConfig.from_mapping("l", {"elevation_angles": "-10, -30", name: value})
    assert f"parameter '{name}'" in str(e.value) and needle in str(e.value)


@pytest.mark.parametrize(
    "value, needle",
    [
        ("1, 1, 1", "one row per laser (2, got 1)"),
        ("1, 1; 1, 1, 1", "one factor per range_response knot (2) a row"),
    ],
)
def test_per_laser_rows_must_fit_the_lasers_and_the_knots(value, needle):
    from nidar_mi.lidar.config import LidarConfig

    with pytest.raises(NidarError) as e:
        LidarConfig.from_mapping(
            "l",
            {
                "elevation_angles": "-10, -30",
                "range_response": "1:1, 5:1",
                "laser_range_response": value,
            },
        )
    assert "parameter 'laser_range_response'" in str(e.value) and needle in str(e.value)
