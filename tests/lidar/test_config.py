"""Parameter validation of the lidar sensor, directly and through scene loading."""

import pytest

from nidar_mi.errors import NidarError
from nidar_mi.lidar.config import LidarConfig


def test_defaults_from_preset():
    c = LidarConfig.from_mapping("l", {"preset": "hdl64e"})
    assert c.rings == 64 and c.horizontal_resolution == 2048
    assert c.wavelength == 905.0 and c.gain == 1.0 and c.intensity_mode == "raw"
    assert c.range_min == 0.9 and c.range_max == 120.0
    # the datasheet's 10 % target at 50 m, in raw units only
    assert c.detection_threshold == pytest.approx(0.10 / 50.0**2)
    # the receiver noise under it: false alarms 1e-4 per ranging event, Q^-1(1e-4) = 3.719
    assert c.receiver_noise_std == pytest.approx(4e-5 / 3.7190164854557, rel=1e-12)
    comp = LidarConfig.from_mapping("l", {"preset": "hdl64e", "intensity_mode": "compensated"})
    assert comp.detection_threshold == 0.0 and comp.receiver_noise_std == 0.0
    vlp = LidarConfig.from_mapping("l", {"preset": "vlp16"})
    assert vlp.detection_threshold == 0.0 and vlp.receiver_noise_std == 0.0
    # a threshold of one's own keeps the preset's receiver
    own = LidarConfig.from_mapping("l", {"preset": "hdl64e", "detection_threshold": 5e-5})
    assert own.receiver_noise_std == c.receiver_noise_std


@pytest.mark.parametrize(
    "values, layout",
    [
        ({}, "per_laser"),  # vlp16
        ({"preset": "hdl64e"}, "per_laser"),
        ({"preset": "os1_128"}, "per_laser"),
        ({"preset": "waymo_top"}, "uniform"),  # no published table
        ({"preset": "hdl64e", "layout": "uniform"}, "uniform"),
        ({"preset": "hdl32e", "elevation_angles": "1, -1"}, "uniform"),
        ({"elevation_angles": "1, -1"}, "uniform"),
    ],
)
def test_default_layout_is_the_published_table(values, layout):
    c = LidarConfig.from_mapping("l", values)
    assert c.layout == layout
    assert (c.table is not None) == (layout == "per_laser")


def test_elevation_angles_imply_channels():
    c = LidarConfig.from_mapping(
        "l", {"elevation_angles": "1, -1, 0.5", "horizontal_resolution": 10}
    )
    assert c.rings == 3 and c.elevations_deg == (1.0, 0.5, -1.0) and c.preset is None


@pytest.mark.parametrize(
    "values, param",
    [
        ({"preset": "hdl128"}, "preset"),
        ({"elevation_angles": "1, abc"}, "elevation_angles"),
        ({"elevation_angles": "91"}, "elevation_angles"),
        ({"horizontal_resolution": 0}, "horizontal_resolution"),
        ({"horizontal_resolution": 10.5}, "horizontal_resolution"),
        ({"fov_h": 400}, "fov_h"),
        ({"range_min": 10, "range_max": 5}, "range_min"),
        ({"noise_intensity_std": -1}, "noise_intensity_std"),
        ({"noise_range_std": -0.1}, "noise_range_std"),
        ({"receiver_noise_std": -1e-6}, "receiver_noise_std"),
        ({"receiver_noise_std": "nan"}, "receiver_noise_std"),
        ({"dropout": 1.5}, "dropout"),
        ({"gain": 0}, "gain"),
        ({"gain": "x"}, "gain"),
        ({"intensity_mode": "linear"}, "intensity_mode"),
        ({"atmospheric_extinction": -0.1}, "atmospheric_extinction"),
        ({"wavelength": 3000}, "wavelength"),
        ({"layout": "grid"}, "layout"),
        ({"preset": "waymo_top", "layout": "per_laser"}, "layout"),
        ({"elevation_angles": "1,2", "layout": "per_laser"}, "elevation_angles"),
        ({"calibration_file": "/nonexistent/db.xml"}, "calibration_file"),
        ({"calibration_file": "x.xml", "layout": "uniform"}, "calibration_file"),
        ({"fov_h_centred": "maybe"}, "fov_h_centred"),
        ({"rotation_rate": 0}, "rotation_rate"),
        ({"rotation_rate": 1000}, "rotation_rate"),
        ({"spin": "left"}, "spin"),
        ({"scan_start_azimuth": 400}, "scan_start_azimuth"),
        ({"beam_divergence": -1}, "beam_divergence"),
        ({"beam_sample_quality": 0}, "beam_sample_quality"),
        ({"beam_sample_quality": 13}, "beam_sample_quality"),
        ({"return_mode": "all"}, "return_mode"),
        ({"return_separation": 0}, "return_separation"),
    ],
)
def test_invalid_values_name_the_parameter(values, param):
    with pytest.raises(NidarError, match=f"parameter '{param}'"):
        LidarConfig.from_mapping("l", values)


@pytest.mark.parametrize(
    "values, message",
    [
        # an interval, one bound or two, open or closed
        ({"gain": 0}, "parameter 'gain' must be > 0 (got 0)"),
        ({"horizontal_resolution": 0}, "parameter 'horizontal_resolution' must be >= 1 (got 0)"),
        ({"dropout": 1.5}, "parameter 'dropout' must lie in [0, 1] (got 1.5)"),
        ({"fov_h": 400}, "parameter 'fov_h' must lie in (0, 360] (got 400)"),
        ({"rotation_rate": 0}, "parameter 'rotation_rate' must lie in (0, 100] (got 0)"),
        (
            {"beam_sample_quality": 13},
            "parameter 'beam_sample_quality' must lie in [1, 12] (got 13)",
        ),
        (
            {"elevation_angles": "-10, -30", "laser_gains": "1, 0"},
            "parameter 'laser_gains' must be > 0 (got 0)",
        ),
        # a choice
        ({"spin": "left"}, "parameter 'spin' must be one of cw, ccw (got 'left')"),
        ({"layout": "grid"}, "parameter 'layout' must be one of uniform, per_laser (got 'grid')"),
        (
            {"intensity_mode": "linear"},
            "parameter 'intensity_mode' must be one of raw, compensated (got 'linear')",
        ),
        (
            {"return_mode": "all"},
            "parameter 'return_mode' must be one of strongest, first, last, dual (got 'all')",
        ),
        # the wrong kind of value
        (
            {"horizontal_resolution": 10.5},
            "parameter 'horizontal_resolution' should be a valid integer (got 10.5)",
        ),
        (
            {"receiver_noise_std": "nan"},
            "parameter 'receiver_noise_std' should be a finite number (got 'nan')",
        ),
        ({"gain": True}, "parameter 'gain' should be a valid number (got True)"),
        (
            {"fov_h_centred": "maybe"},
            "parameter 'fov_h_centred' should be a valid boolean (got 'maybe')",
        ),
    ],
)
def test_a_bad_value_is_one_line_naming_parameter_allowed_values_and_value(values, message):
    with pytest.raises(NidarError) as e:
        LidarConfig.from_mapping("l", values)
    assert str(e.value) == f"lidar 'l': {message}"


def test_xml_spellings_of_choices_and_numbers_are_read():
    c = LidarConfig.from_mapping(
        "l",
        {
            "spin": " CCW ",
            "fov_h_centred": "TRUE",
            "horizontal_resolution": "10.0",
            "preset": "HDL64E",
        },
    )
    assert (c.spin, c.fov_h_centred, c.horizontal_resolution, c.preset) == (
        "ccw",
        True,
        10,
        "hdl64e",
    )


@pytest.mark.parametrize(
    "prop, param",
    [
        ('<string name="preset" value="nope"/>', "preset"),
        ('<string name="elevation_angles" value="1,2,x"/>', "elevation_angles"),
        ('<integer name="horizontal_resolution" value="-4"/>', "horizontal_resolution"),
        ('<float name="range_min" value="50"/><float name="range_max" value="10"/>', "range_min"),
        ('<float name="noise_range_std" value="-1"/>', "noise_range_std"),
    ],
)
def test_invalid_xml_gives_one_line(variant, write_scene, prop, param):
    from nidar_mi.scene import load_scene

    path = write_scene(f'<sensor type="lidar" id="top">{prop}</sensor>')
    with pytest.raises(NidarError) as e:
        load_scene(path)
    msg = str(e.value)
    assert "\n" not in msg and f"parameter '{param}'" in msg and "lidar 'top'" in msg


def test_per_laser_layout_and_derived_counts():
    c = LidarConfig.from_mapping("l", {"preset": "hdl64e", "layout": "per_laser"})
    assert c.rings == 64 and c.laser_table.has_origins and c.subrays == 1 and c.max_returns == 1
    assert (
        c.elevations_deg
        == c.laser_table.elevation_deg
        != LidarConfig.from_mapping("l", {"preset": "hdl64e", "layout": "uniform"}).elevations_deg
    )
    d = LidarConfig.from_mapping(
        "l", {"beam_divergence": 2, "beam_sample_quality": 4, "return_mode": "dual"}
    )
    assert d.subrays == 37 and d.max_returns == 2
    assert d.to_dict()["subrays"] == 37


def test_calibration_file_keeps_the_preset_timing(tmp_path):
    import yaml

    from nidar_mi.lidar.layouts import preset_table

    ref = preset_table("vlp16")
    lasers = [
        {"laser_id": i, "vert_correction": float(v) * 3.14159265 / 180.0}
        for i, v in zip(ref.laser_id, ref.elevation_deg)
    ]
    path = tmp_path / "vlp16.yaml"
    path.write_text(yaml.safe_dump({"lasers": lasers}))
    c = LidarConfig.from_mapping("l", {"preset": "vlp16", "calibration_file": str(path)})
    assert c.layout == "per_laser" and c.laser_table.firing_offset_s == ref.firing_offset_s
    assert not c.laser_table.has_origins  # the file has no offsets
    with pytest.raises(NidarError, match="has 16 lasers .* the preset 32"):
        LidarConfig.from_mapping("l", {"preset": "hdl32e", "calibration_file": str(path)})
    alone = LidarConfig.from_mapping("l", {"calibration_file": str(path)})
    assert alone.preset is None and not any(alone.laser_table.firing_offset_s)


def test_calibration_file_relative_to_the_scene(variant, write_scene, tmp_path):
    from nidar_mi.scene import load_scene

    (tmp_path / "cal.json").write_text(
        '{"beam_altitude_angles": [2.0, 0.0, -2.0], "beam_azimuth_angles": [0, 0, 0]}'
    )
    L = load_scene(
        write_scene(
            '<sensor type="lidar" id="top"><string name="calibration_file" value="cal.json"/>'
            "</sensor>"
        )
    )
    assert L.lidars[0].config.elevations_deg == (2.0, 0.0, -2.0)


def test_unknown_property_is_rejected(variant, write_scene):
    from nidar_mi.scene import load_scene

    path = write_scene(
        '<sensor type="lidar" id="top"><float name="wavelenght" value="905"/></sensor>'
    )
    with pytest.raises(NidarError, match="wavelenght"):
        load_scene(path)
