"""``laser_range_offsets``: each laser reports its range as ``d + o_r``; whether it returns, and
what intensity, are unchanged.

A floor 1 m below the sensor (``tests/helpers/floor_scene.py``): two rings at -10° and -30°,
every beam returns at ``d_r = 1 / sin(-θ_r)`` (5.759 m and 2 m).
"""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from tests.helpers.floor_scene import ELEV
from tests.helpers.floor_scene import floor_scene as _scene

OFFSETS = (0.035, -0.02)


@pytest.mark.parametrize("divergence", ["0", "1"])
def test_each_laser_reports_its_range_plus_its_offset(variant, write_scene, divergence):
    """On one ray per beam and on diverging beams (the echo path): the closed-form range plus
    the ring's offset (float32), every other output identical."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    div = f'<float name="beam_divergence" value="{divergence}"/>'
    value = ", ".join(map(str, OFFSETS))
    plain = load_scene(write_scene(_scene(div), name=f"plain{divergence}.xml"))
    moved = load_scene(
        write_scene(
            _scene(div + f'<string name="laser_range_offsets" value="{value}"/>'),
            name=f"moved{divergence}.xml",
        )
    )
    a = scan(plain.scene, plain.lidars[0])
    b = scan(moved.scene, moved.lidars[0])
    assert a.valid.all() and b.valid.all()
    d = 1.0 / np.sin(-np.radians(np.asarray(ELEV)))  # 5.759 m, 2 m
    tol = 1e-3 if divergence == "1" else 1e-5  # a diverging beam's return: its sub-rays' mean
    np.testing.assert_allclose(a.range, np.broadcast_to(d[:, None], a.range.shape), atol=tol)
    np.testing.assert_allclose(
        b.range - a.range, np.broadcast_to(np.array(OFFSETS)[:, None], a.range.shape), atol=1e-6
    )
    np.testing.assert_array_equal(b.intensity, a.intensity)
    np.testing.assert_array_equal(b.cos_incidence, a.cos_incidence)


def test_offsets_hold_in_fog(variant, write_scene):
    """Weather scans: every layer's returns carry their laser's offset (the floor's returns
    and the fog's alike: the sensor's timing, not the scene)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene
    from nidar_mi.weather import Weather

    value = ", ".join(map(str, OFFSETS))
    plain = load_scene(write_scene(_scene(""), name="fog0.xml"))
    moved = load_scene(
        write_scene(
            _scene(f'<string name="laser_range_offsets" value="{value}"/>'), name="fog1.xml"
        )
    )
    a = scan(plain.scene, plain.lidars[0], weather=Weather(fog=30.0), seed=3)
    b = scan(moved.scene, moved.lidars[0], weather=Weather(fog=30.0), seed=3)
    for la, lb in zip([a, *a.further], [b, *b.further]):
        np.testing.assert_array_equal(lb.valid, la.valid)
        ok = la.valid
        off = np.broadcast_to(np.array(OFFSETS)[:, None], ok.shape)
        np.testing.assert_allclose(lb.range[ok] - la.range[ok], off[ok], atol=1e-5)


@pytest.mark.parametrize(
    "value, needle",
    [
        ("0.01", "needs one offset per laser (2, got 1)"),
        ("0.01, 1.5", "must lie in [-1, 1] (got 1.5)"),
        ("0.01, nan", "should be a finite number (got nan)"),
        ("a, b", "comma-separated numbers"),
    ],
)
def test_bad_offsets_are_refused_in_one_line(value, needle):
    from nidar_mi.lidar.config import LidarConfig

    with pytest.raises(NidarError) as e:
        LidarConfig.from_mapping(
            "l", {"elevation_angles": "-10, -30", "laser_range_offsets": value}
        )
    msg = str(e.value)
    assert "parameter 'laser_range_offsets'" in msg and needle in msg and "\n" not in msg
