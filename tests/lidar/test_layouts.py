"""Per-laser layouts: the shipped tables against their published sources, calibration files, and
the beam geometry against the drivers' point models."""

import json

import numpy as np
import pytest

from nidar_mi.lidar.layouts import preset_table, read_calibration, uniform_table
from nidar_mi.lidar.pattern import BeamPattern


@pytest.mark.parametrize(
    "preset, lasers, top, bottom",
    [
        # published values: ros-drivers/velodyne 64e_s2.1-sztaki.xml, 32db.yaml, VLP16db.yaml,
        # ouster-sdk metadata
        ("hdl64e", 64, 4.9700899, -24.845081),
        ("hdl32e", 32, 10.67, -30.67),
        ("vlp16", 16, 15.0, -15.0),
        ("os1_64", 64, 16.729, -16.679),
        ("os1_128", 128, 20.95, -21.82),
    ],
)
def test_preset_tables(preset, lasers, top, bottom):
    t = preset_table(preset)
    assert t.rings == lasers and sorted(t.laser_id) == list(range(lasers))
    assert t.elevation_deg[0] == pytest.approx(top, abs=1e-5)
    assert t.elevation_deg[-1] == pytest.approx(bottom, abs=1e-5)
    assert np.all(np.diff(t.elevation_deg) < 0)


def test_hdl64e_s2_published_entries():
    """Laser 0 of the S2.1 db.xml: rot -7.1559157 deg, vert -8.7686234 deg, vertOffset 19.548199
    cm, horizOffset 2.5999999 cm; the S2 firing table: laser j of a block at 6·(j//4) +
    [0, 1.26, 2.46, 3.66][j%4] µs, the lower block with the upper."""
    t = preset_table("hdl64e")
    i = t.laser_id.index(0)
    assert t.azimuth_offset_deg[i] == pytest.approx(-7.1559157)
    assert t.elevation_deg[i] == pytest.approx(-8.7686234)
    assert t.vertical_offset_m[i] == pytest.approx(0.19548199)
    assert t.horizontal_offset_m[i] == pytest.approx(0.025999999)
    firing = dict(zip(t.laser_id, t.firing_offset_s))
    assert firing[7] == pytest.approx(9.66e-6) and firing[39] == firing[7]
    assert max(firing.values()) == pytest.approx(45.66e-6)
    upper = [e for lid, e in zip(t.laser_id, t.elevation_deg) if lid < 32]
    lower = [e for lid, e in zip(t.laser_id, t.elevation_deg) if lid >= 32]
    assert min(upper) > -11 and max(lower) < -9  # two blocks


def test_velodyne_manual_timing_and_offsets():
    t32, t16 = preset_table("hdl32e"), preset_table("vlp16")
    f32 = dict(zip(t32.laser_id, t32.firing_offset_s))
    assert f32[31] == pytest.approx(31 * 1.152e-6)  # HDL-32E: 1.152 µs per firing
    f16 = dict(zip(t16.laser_id, t16.firing_offset_s))
    assert f16[15] == pytest.approx(15 * 2.304e-6)  # VLP-16: 2.304 µs per firing
    v16 = dict(zip(t16.laser_id, t16.vertical_offset_m))
    assert v16[0] == pytest.approx(0.0112, abs=1e-4)  # VLP-16 manual Table 9-1: 11.2 mm at -15°
    v32 = dict(zip(t32.laser_id, t32.vertical_offset_m))
    assert v32[0] == pytest.approx(0.01717)  # Velodyne drawing 86-0106


def _db_xml(path, rows, enabled=None):
    items = "".join(
        f"<item><px><id_>{i}</id_><rotCorrection_>{rot}</rotCorrection_>"
        f"<vertCorrection_>{vert}</vertCorrection_><distCorrection_>120</distCorrection_>"
        f"<vertOffsetCorrection_>{vo}</vertOffsetCorrection_>"
        f"<horizOffsetCorrection_>{ho}</horizOffsetCorrection_></px></item>"
        for i, rot, vert, vo, ho in rows
    )
    en = ""
    if enabled is not None:
        items_en = "".join(f"<item>{int(e)}</item>" for e in enabled)
        en = f"<enabled_><count>{len(enabled)}</count>{items_en}</enabled_>"
    path.write_text(
        '<?xml version="1.0"?><boost_serialization><DB>'
        f"{en}<points_><count>{len(rows)}</count>{items}</points_></DB></boost_serialization>"
    )
    return str(path)


def test_calibration_formats_agree(tmp_path):
    """The same table as db.xml (deg, cm), ROS YAML (rad, m) and Ouster JSON reads the same."""
    # (laser id, rot_correction deg, vert_correction deg, vert offset cm, horiz offset cm)
    rows = [(0, -1.5, -8.0, 20.0, 2.6), (1, -3.0, 1.0, 19.0, -2.6), (2, 2.0, 0.5, 21.0, 2.6)]
    xml = read_calibration(_db_xml(tmp_path / "db.xml", rows))
    lasers = [
        {
            "laser_id": i,
            "rot_correction": float(np.radians(rot)),
            "vert_correction": float(np.radians(vert)),
            "vert_offset_correction": vo / 100,
            "horiz_offset_correction": ho / 100,
        }
        for i, rot, vert, vo, ho in rows
    ]
    import yaml

    (tmp_path / "c.yaml").write_text(yaml.safe_dump({"lasers": lasers}))
    ros = read_calibration(tmp_path / "c.yaml")
    for t in (xml, ros):
        assert t.laser_id == (1, 2, 0)  # by elevation, highest first
        assert t.elevation_deg == pytest.approx((1.0, 0.5, -8.0))
        assert t.azimuth_offset_deg == pytest.approx((-3.0, 2.0, -1.5))
        assert t.vertical_offset_m == pytest.approx((0.19, 0.21, 0.20))
        assert t.horizontal_offset_m == pytest.approx((-0.026, 0.026, 0.026))
    (tmp_path / "o.json").write_text(
        json.dumps(
            {
                "beam_altitude_angles": [3.0, -1.0],
                "beam_azimuth_angles": [1.5, -1.5],
                "lidar_origin_to_beam_origin_mm": 12.0,
                "lidar_to_sensor_transform": [-1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 36.18, 0, 0, 0, 1],
            }
        )
    )
    ou = read_calibration(tmp_path / "o.json")
    assert ou.elevation_deg == (3.0, -1.0) and ou.azimuth_offset_deg == (-1.5, 1.5)
    assert ou.radial_offset_m == pytest.approx(0.012) and ou.z_offset_m == pytest.approx(0.03618)


def test_disabled_lasers_are_left_out(tmp_path):
    rows = [(0, 0, -1.0, 0, 0), (1, 0, -2.0, 0, 0), (2, 0, -3.0, 0, 0)]
    t = read_calibration(_db_xml(tmp_path / "db.xml", rows, enabled=[1, 0, 1]))
    assert t.laser_id == (0, 2)


@pytest.mark.parametrize(
    "name, content, needle",
    [
        ("a.txt", "x", "unknown calibration format"),
        ("b.xml", "<a><b>", "cannot be read"),
        ("c.xml", "<a/>", "no <px> laser entries"),
        ("d.yaml", "lasers: 3", "no 'lasers' list"),
        ("e.json", "[]", "not a JSON object"),
        ("f.yaml", "lasers: [{laser_id: 0}]", "malformed laser entry"),
    ],
)
def test_bad_calibration_files_one_line(tmp_path, name, content, needle):
    (tmp_path / name).write_text(content)
    with pytest.raises(ValueError, match=needle) as e:
        read_calibration(tmp_path / name)
    assert "\n" not in str(e.value)


def test_velodyne_point_model():
    """A point at range d of laser (θ, β, v, h): the ROS driver's model, rawdata.cc:
    xy = d cosθ - v sinθ, z = d sinθ + v cosθ, x = xy cos φ - h sin φ, y = xy sin φ + h cos φ,
    with φ the beam azimuth (column azimuth + rot_correction)."""
    t = preset_table("hdl64e")
    p = BeamPattern(t, 16, rotation_rate=10.0)
    d, o = p.beams()
    ring, col = np.divmod(np.arange(p.size), 16)
    th = np.radians(np.asarray(t.elevation_deg)[ring])
    drift = -360.0 * 10.0 * np.asarray(t.firing_offset_s)[ring]
    phi = np.radians(p.column_azimuth_deg()[col] + np.asarray(t.azimuth_offset_deg)[ring] + drift)
    v, h = np.asarray(t.vertical_offset_m)[ring], np.asarray(t.horizontal_offset_m)[ring]
    dist = 7.5
    xy = dist * np.cos(th) - v * np.sin(th)
    expected = np.stack(
        [xy * np.cos(phi) - h * np.sin(phi), xy * np.sin(phi) + h * np.cos(phi),
         dist * np.sin(th) + v * np.cos(th)], -1
    )  # fmt: skip
    np.testing.assert_allclose(o + dist * d, expected, atol=1e-12)


def test_ouster_point_model():
    """ouster-sdk xyzlut.cpp: θe encoder angle, θa = -azimuth, φ altitude; dir = (cos(θe+θa)cosφ,
    sin(θe+θa)cosφ, sinφ); xyz = (r - n)·dir + n·(cos θe, sin θe, 0) (+ the lidar origin's height
    above the sensor frame)."""
    import json as _json

    t = preset_table("os1_64")
    p = BeamPattern(t, 8)
    d, o = p.beams()
    ring, col = np.divmod(np.arange(p.size), 8)
    te = np.radians(p.column_azimuth_deg()[col])
    ta = -np.radians(-np.asarray(t.azimuth_offset_deg)[ring])  # the SDK's beam_azimuth_angles
    phi = np.radians(np.asarray(t.elevation_deg)[ring])
    r, n = 5.0, 0.012163
    direction = np.stack(
        [np.cos(te + ta) * np.cos(phi), np.sin(te + ta) * np.cos(phi), np.sin(phi)], -1
    )
    expected = (r - n) * direction + n * np.stack([np.cos(te), np.sin(te), 0 * te], -1)
    expected[:, 2] += 0.03618
    np.testing.assert_allclose(o + (r - n) * d, expected, atol=1e-12)
    assert _json.dumps(t.source)  # the data file is named


def test_uniform_table_is_the_ideal_pattern():
    from nidar_mi.lidar.pattern import beam_directions, elevation_table

    el = elevation_table("hdl64e")
    d, o = BeamPattern(uniform_table(el), 100).beams()
    assert o is None
    np.testing.assert_array_equal(d.reshape(64, 100, 3), beam_directions(el, 100))
