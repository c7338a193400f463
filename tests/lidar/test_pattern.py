"""Beam patterns: preset channel counts and elevation tables against the datasheets, azimuth grid."""

import numpy as np
import pytest

from nidar_mi.lidar.pattern import (
    PRESETS,
    azimuths_deg,
    beam_directions,
    elevation_table,
    parse_angles,
)


@pytest.mark.parametrize(
    "preset, channels, top, bottom",
    [
        ("vlp16", 16, 15.0, -15.0),  # VLP-16 manual: +-15 deg
        ("hdl32e", 32, 10.67, -30.67),  # HDL-32E manual: +10.67 .. -30.67 deg
        ("hdl64e", 64, 2.0, -24.8),  # HDL-64E S2: +2 .. -24.8 deg (KITTI: 26.8 deg FOV)
        ("os1_64", 64, 16.6, -16.6),  # OS1-64: 33.2 deg vertical FOV
        ("os1_128", 128, 22.5, -22.5),  # OS1: 45 deg vertical FOV
        ("waymo_top", 64, 2.4, -17.6),  # Waymo Open Dataset top LiDAR: [-17.6, +2.4]
    ],
)
def test_preset_tables(preset, channels, top, bottom):
    el = elevation_table(preset)
    assert el.shape == (channels,)
    assert el[0] == pytest.approx(top, abs=1e-3)
    assert el[-1] == pytest.approx(bottom, abs=1e-3)
    assert np.all(np.diff(el) < 0), "ring 0 is the highest beam"


def test_vlp16_is_two_degree_grid():
    np.testing.assert_allclose(elevation_table("vlp16"), np.arange(15, -16, -2), atol=1e-9)


def test_hdl32e_spacing():
    d = -np.diff(elevation_table("hdl32e"))
    np.testing.assert_allclose(d, 4.0 / 3.0, atol=2e-3)


def test_hdl64e_fov_and_spacing():
    el = elevation_table("hdl64e")
    assert el[0] - el[-1] == pytest.approx(26.8, abs=1e-6)
    np.testing.assert_allclose(-np.diff(el), 26.8 / 63, atol=2e-4)


def test_azimuth_grid_half_column_offset():
    az = azimuths_deg(8, 360.0)
    np.testing.assert_allclose(az, [22.5, 67.5, 112.5, 157.5, 202.5, 247.5, 292.5, 337.5])
    np.testing.assert_allclose(azimuths_deg(4, 90.0), [11.25, 33.75, 56.25, 78.75])


def test_beam_directions_angles():
    el = np.array([10.0, -20.0])
    d = beam_directions(el, 6, 360.0)
    assert d.shape == (2, 6, 3)
    np.testing.assert_allclose(np.linalg.norm(d, axis=-1), 1.0, atol=1e-12)
    np.testing.assert_allclose(
        np.rad2deg(np.arcsin(d[..., 2])), np.repeat(el[:, None], 6, 1), atol=1e-9
    )
    az = np.rad2deg(np.arctan2(d[..., 1], d[..., 0])) % 360
    np.testing.assert_allclose(az, np.tile((np.arange(6) + 0.5) * 60.0, (2, 1)), atol=1e-9)
    # column 0 of a 4-column scan points between +x and +y (x forward, y left, CCW azimuth)
    d4 = beam_directions(np.array([0.0]), 4)[0, 0]
    assert d4[0] > 0 and d4[1] > 0


def test_parse_angles():
    np.testing.assert_allclose(parse_angles("-1, 3.5,0"), [3.5, 0.0, -1.0])
    with pytest.raises(ValueError, match="non-numeric"):
        parse_angles("1, x")
    with pytest.raises(ValueError, match="outside"):
        parse_angles("95")
    with pytest.raises(ValueError, match="empty"):
        parse_angles(" , ")


def test_every_preset_has_reference():
    for name, p in PRESETS.items():
        assert p.reference and p.range_max > p.range_min >= 0, name


def test_centred_field_of_view():
    """fov_h 120 centred: columns span -60..+60 deg around +x; not centred: 0..120."""
    from nidar_mi.lidar.config import LidarConfig

    c = LidarConfig.from_mapping(
        "l", {"fov_h": 120, "fov_h_centred": True, "horizontal_resolution": 120}
    )
    az = c.pattern.column_azimuth_deg()
    assert az[0] == pytest.approx(-59.5) and az[-1] == pytest.approx(59.5)
    d, _ = c.pattern.beams()
    assert np.degrees(np.arctan2(d[:, 1], d[:, 0])).min() == pytest.approx(-59.5)
    plain = LidarConfig.from_mapping("l", {"fov_h": 120, "horizontal_resolution": 120})
    assert plain.pattern.column_azimuth_deg()[0] == pytest.approx(0.5)


def test_firing_offsets_delay_and_turn_each_laser():
    """A laser firing τ after its column points s·360°·rate·τ further along the spin."""
    from nidar_mi.lidar.layouts import uniform_table
    from nidar_mi.lidar.pattern import BeamPattern

    table = uniform_table([1.0, -1.0]).with_firing([0.0, 50e-6])
    p = BeamPattern(table, 4, rotation_rate=20.0, spin=-1, scan_start_azimuth=0.0)
    t = p.time_s().reshape(2, 4)
    np.testing.assert_allclose(t[1] - t[0], 50e-6)
    d, o = p.beams()
    assert o is None
    az = np.degrees(np.arctan2(d[:, 1], d[:, 0])).reshape(2, 4)
    np.testing.assert_allclose(az[1] - az[0], -360.0 * 20.0 * 50e-6, atol=1e-9)  # clockwise
    # clockwise from 0 deg: the column at 45 deg fires at (360 - 45) / 360 / 20 s
    np.testing.assert_allclose(t[0, 0], (360.0 - 45.0) / 360.0 / 20.0)
