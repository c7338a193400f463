"""Baselines against hand-computed values; the RGB twin on a dome with a red-edge spectrum."""

import warnings

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.eval import baselines as B

# --- CARLA ------------------------------------------------------------------------------------------


def test_carla_at_250_m_is_exp_minus_one():
    np.testing.assert_allclose(B.carla([0.0, 250.0, 500.0]), [1.0, np.exp(-1), np.exp(-2)])


@pytest.mark.parametrize("d", [[-1.0], [np.nan]])
def test_carla_rejects_bad_distances(d):
    with pytest.raises(NidarError, match="distances"):
        B.carla(d)


# --- luminance -----------------------------------------------------------------------------------


def test_luminance_of_linearised_srgb_by_hand():
    img = np.array(
        [[[255, 255, 255], [0, 0, 0], [255, 0, 0]], [[128] * 3, [0, 255, 0], [0, 0, 255]]]
    )
    img = img.astype(np.uint8)
    grey128 = ((128 / 255 + 0.055) / 1.055) ** 2.4  # 0.2158605
    uv = np.array([[0, 0], [2, 0], [0, 1], [1, 1], [2, 1], [0.5, 0], [-3, 0]])
    got = B.luminance_rho(img, uv)
    expected = [1.0, 0.2126, grey128, 0.7152, 0.0722, 0.5]  # white/black midpoint: linear 0.5
    np.testing.assert_allclose(got[:6], expected, rtol=1e-12)
    assert np.isnan(got[6])  # outside the image


def test_luminance_needs_an_8bit_rgb_image():
    with pytest.raises(NidarError, match="uint8"):
        B.luminance_rho(np.zeros((2, 2, 3)), np.zeros((1, 2)))


# --- one constant per class ---------------------------------------------------------------------


def test_class_constant_means_and_unseen_classes():
    fit = B.ClassConstant.fit([0, 0, 1, 2, 2, 2], [0.1, 0.3, 0.5, 0.2, 0.4, 0.6])
    assert fit.global_mean == pytest.approx(2.1 / 6)
    np.testing.assert_array_equal(fit.counts, [2, 1, 3])
    got = fit.predict([2, 0, 7, 1, -1])
    np.testing.assert_allclose(got, [0.4, 0.2, 0.35, 0.5, 0.35])


def test_class_constant_with_material_names():
    fit = B.ClassConstant.fit(["brick", "asphalt", "brick"], [0.5, 0.1, 0.3])
    got = fit.predict(["asphalt", "brick", "zinc", "aaa"])
    np.testing.assert_allclose(got, [0.1, 0.4, 0.3, 0.3])
    with pytest.raises(NidarError, match="labels"):
        fit.predict([1, 2])


@pytest.mark.parametrize("ids, y", [([0, 1], [0.5]), ([], []), ([0], [np.nan])])
def test_class_constant_rejects_bad_training_data(ids, y):
    with pytest.raises(NidarError, match="ClassConstant.fit"):
        B.ClassConstant.fit(ids, y)


# --- RGB-only twin ----------------------------------------------------------------------------------

DOME = """
    <sensor type="lidar" id="b_lidar">
        <string name="preset" value="vlp16"/>
        <integer name="horizontal_resolution" value="24"/>
        <float name="dropout" value="0.3"/>
    </sensor>
    <sensor type="lidar" id="a_lidar">
        <string name="preset" value="vlp16"/>
        <integer name="horizontal_resolution" value="12"/>
    </sensor>
    <bsdf type="twosided" id="leafy"><bsdf type="diffuse">
        <spectrum name="reflectance" value="360:0.1, 780:0.1, 850:0.6, 1700:0.6"/>
    </bsdf></bsdf>
    <shape type="sphere" id="dome"><float name="radius" value="10"/><ref id="leafy"/></shape>
"""


def test_rgb_twin_sees_the_visible_albedo_not_the_nir_one(write_scene, variant):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    path = write_scene(DOME)
    twin = B.rgb_twin_scan(path, variant=variant)
    assert twin.config.name == "a_lidar" and twin.valid.shape == (16, 12) and twin.valid.all()
    np.testing.assert_allclose(twin.range, 10.0, rtol=1e-5)
    # visible plateau 0.1 (grey twin) vs 0.6 at 905 nm; raw intensity rho * cos / d^2, cos = 1
    np.testing.assert_allclose(twin.reflectance, 0.1, atol=0.002)
    np.testing.assert_allclose(twin.intensity, 0.1 / 100, rtol=0.02)
    loaded = load_scene(path, variant=variant)
    spectral = scan(loaded.scene, loaded.lidars[0])
    np.testing.assert_allclose(spectral.reflectance, 0.6, rtol=1e-5)


def test_rgb_twin_keeps_the_dropout_draws_of_the_same_seed(write_scene, variant):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    path = write_scene(DOME)
    loaded = load_scene(path, variant=variant)
    sensor = [s for s in loaded.lidars if s.id() == "b_lidar"][0]
    spectral = scan(loaded.scene, sensor, seed=5)
    twin = B.rgb_twin_scan(path, seed=5, lidar="b_lidar", variant=variant)
    other = B.rgb_twin_scan(path, seed=6, lidar="b_lidar", variant=variant)
    assert 0.5 < twin.valid.mean() < 0.9
    np.testing.assert_array_equal(twin.valid, spectral.valid)
    assert not np.array_equal(twin.valid, other.valid)


def test_rgb_twin_scan_silences_only_the_rgb_material_warning(write_scene, variant, monkeypatch):
    from nidar_mi.lidar import scan as scan_module
    from nidar_mi.scene import load_scene

    path = write_scene(DOME)
    monkeypatch.setattr(scan_module, "_warned_rgb", set())
    loaded = load_scene(path, variant=variant, rgb_twin=True)
    with pytest.warns(RuntimeWarning, match="RGB-only"):
        scan_module.scan(loaded.scene, loaded.lidars[0])
    monkeypatch.setattr(scan_module, "_warned_rgb", set())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        B.rgb_twin_scan(path, variant=variant)


def test_rgb_twin_scan_errors(write_scene, variant):
    path = write_scene(DOME)
    with pytest.raises(NidarError, match="no lidar 'c'.*a_lidar, b_lidar"):
        B.rgb_twin_scan(path, lidar="c", variant=variant)
    bare = write_scene('<shape type="sphere"/>', name="bare.xml")
    with pytest.raises(NidarError, match="no lidar sensor"):
        B.rgb_twin_scan(bare, variant=variant)
    with pytest.raises(NidarError, match="no such scene"):
        B.rgb_twin_scan(path + ".missing", variant=variant)
