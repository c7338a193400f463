"""``laser_shadow``: the beams a mounting blocks (the vehicle's body, a roof rack) return
nothing, every other beam exactly what it returns without the shadow.

A floor 1 m below the sensor (as in ``test_laser_gains.py``): two rings at -10° and -30°, 36 columns 10° apart, every
beam returns. The shadow names azimuth intervals of the beams' sensor-frame directions
(``atan2(y, x)``, degrees, [from, to)).
"""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from tests.helpers.floor_scene import floor_scene as _scene

SHADOW = "0:-90:-30, 1:100:180, 1:-180:-170"


def _shadowed(directions: np.ndarray) -> np.ndarray:
    az = np.degrees(np.arctan2(directions[..., 1], directions[..., 0]))
    out = np.zeros(az.shape, bool)
    out[0] = (az[0] >= -90) & (az[0] < -30)
    out[1] = ((az[1] >= 100) & (az[1] < 180)) | ((az[1] >= -180) & (az[1] < -170))
    return out


@pytest.mark.parametrize("divergence", ["0", "1"])
def test_the_shadowed_beams_return_nothing_and_the_others_are_unchanged(
    variant, write_scene, divergence
):
    """On one ray per beam and on diverging beams (the echo path)."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    div = f'<float name="beam_divergence" value="{divergence}"/>'
    plain = load_scene(write_scene(_scene(div), name=f"plain{divergence}.xml"))
    shaded = load_scene(
        write_scene(
            _scene(div + f'<string name="laser_shadow" value="{SHADOW}"/>'),
            name=f"shadow{divergence}.xml",
        )
    )
    a = scan(plain.scene, plain.lidars[0])
    b = scan(shaded.scene, shaded.lidars[0])
    mask = _shadowed(b.directions)
    assert a.valid.all() and 6 <= mask[0].sum() <= 7 and 9 <= mask[1].sum() <= 10
    np.testing.assert_array_equal(b.valid, ~mask)
    assert (b.range[mask] == 0).all() and (b.intensity[mask] == 0).all()
    np.testing.assert_array_equal(b.range[~mask], a.range[~mask])
    np.testing.assert_array_equal(b.intensity[~mask], a.intensity[~mask])


def test_a_shadow_holds_in_fog(variant, write_scene):
    """Weather scans (their own path): no return of a shadowed beam, in any layer."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene
    from nidar_mi.weather import Weather

    shaded = load_scene(
        write_scene(_scene(f'<string name="laser_shadow" value="{SHADOW}"/>'), name="fog.xml")
    )
    r = scan(shaded.scene, shaded.lidars[0], weather=Weather(fog=30.0))
    mask = _shadowed(r.directions)
    assert not r.valid[mask].any() and r.valid[~mask].any()
    for layer in r.further:
        assert not layer.valid[mask].any()


@pytest.mark.parametrize(
    "value, needle",
    [
        ("0:10", "'laser:from:to' triples"),
        ("0:20:10", "from < to"),
        ("0:-200:10", "-180 <= from"),
        ("x:1:2", "'laser:from:to' triples"),
        ("2:0:10", "names a laser past the last (1)"),
        (" ", "at least one"),
    ],
)
def test_bad_shadows_are_refused_in_one_line(value, needle):
    from nidar_mi.lidar.config import LidarConfig

    with pytest.raises(NidarError) as e:
        LidarConfig.from_mapping("l", {"elevation_angles": "-10, -30", "laser_shadow": value})
    assert "parameter 'laser_shadow'" in str(e.value) and needle in str(e.value)
