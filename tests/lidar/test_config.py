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
    comp = LidarConfig.from_mapping("l", {"preset": "hdl64e", "intensity_mode": "compensated"})
    assert comp.detection_threshold == 0.0
    assert LidarConfig.from_mapping("l", {"preset": "vlp16"}).detection_threshold == 0.0


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
        ({"dropout": 1.5}, "dropout"),
        ({"gain": 0}, "gain"),
        ({"gain": "x"}, "gain"),
        ({"intensity_mode": "linear"}, "intensity_mode"),
        ({"atmospheric_extinction": -0.1}, "atmospheric_extinction"),
        ({"wavelength": 3000}, "wavelength"),
    ],
)
def test_invalid_values_name_the_parameter(values, param):
    with pytest.raises(ValueError, match=f"parameter '{param}'"):
        LidarConfig.from_mapping("l", values)


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


def test_unknown_property_is_rejected(variant, write_scene):
    from nidar_mi.scene import load_scene

    path = write_scene(
        '<sensor type="lidar" id="top"><float name="wavelenght" value="905"/></sensor>'
    )
    with pytest.raises(NidarError, match="wavelenght"):
        load_scene(path)
