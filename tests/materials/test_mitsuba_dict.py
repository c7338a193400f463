"""Tests of nidar_mi.materials.mitsuba_dict: the BSDFs load and evaluate in a spectral variant."""

import math

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import bsdf_dict, get_material, linear_rgb, list_materials, reflectance

WAVELENGTH_SETS = ([360.0, 550.0, 660.0, 830.0], [905.0, 1064.0, 1550.0, 1700.0])


@pytest.fixture(scope="module")
def mi(variant):
    import mitsuba

    return mitsuba  # the variant fixture registered the plugins (retroreflector)


def monostatic_rho(mi, bsdf, theta_deg: float = 20.0) -> np.ndarray:
    """pi * f(wi, wi) at the 8 wavelengths of WAVELENGTH_SETS (what the LiDAR return model uses)."""
    import drjit as dr

    th = math.radians(theta_deg)
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(math.sin(th), 0.0, math.cos(th))
    out = []
    for wls in WAVELENGTH_SETS:
        si.wavelengths = mi.UnpolarizedSpectrum(wls)
        value = bsdf.eval(mi.BSDFContext(), si, si.wi)
        out.append(np.array(value).ravel() * math.pi / math.cos(th))
    return np.concatenate(out)


def test_every_material_loads_and_is_finite_from_360_to_1700_nm(mi):
    for name in list_materials():
        for twin in (False, True):
            rho = monostatic_rho(mi, mi.load_dict(bsdf_dict(name, rgb_twin=twin)))
            assert np.all(np.isfinite(rho)) and np.all(rho >= 0.0), (name, twin, rho)


@pytest.mark.parametrize("name", ["gravel", "grass", "white_panel_95", "fabric"])
def test_diffuse_monostatic_reflectance_equals_the_library(mi, name):
    rho = monostatic_rho(mi, mi.load_dict(bsdf_dict(name)))
    want = reflectance(name, np.concatenate(WAVELENGTH_SETS))
    np.testing.assert_allclose(rho, want, rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", ["asphalt_old", "asphalt_new", "concrete"])
@pytest.mark.parametrize("theta", [20.0, 85.0])
def test_road_surfaces_are_rough_diffuse(mi, name, theta):
    """rho_eff = rho (A + B sin²θ / cos θ)(1 + B0) (Oren–Nayar facets with the opposition surge)."""
    from nidar_mi.materials.oren_nayar import coefficients

    m = get_material(name)
    assert m.kind == "rough_diffuse" and bsdf_dict(name)["type"] == "roughdiffuse"
    a, b = coefficients(m.params["sigma"])
    c = math.cos(math.radians(theta))
    gain = (a + b * (1 - c * c) / c) * (1 + m.params["opposition_amplitude"])
    rho = monostatic_rho(mi, mi.load_dict(bsdf_dict(name)), theta)
    want = reflectance(name, np.concatenate(WAVELENGTH_SETS)) * gain
    np.testing.assert_allclose(rho, want, rtol=1e-4)
    twin = bsdf_dict(name, rgb_twin=True)
    assert twin["type"] == "roughdiffuse" and twin["reflectance"]["type"] == "rgb"
    with pytest.raises(NidarError, match=r"'sigma' = 90 is outside \[0, 90\)"):
        bsdf_dict(name, overrides={"sigma": 90})
    assert bsdf_dict(name, overrides={"sigma": 10})["sigma"] == 10.0


def test_retro_sheeting_returns_far_more_than_a_white_panel(mi):
    retro = monostatic_rho(mi, mi.load_dict(bsdf_dict("retro_sheeting_white")))
    panel = monostatic_rho(mi, mi.load_dict(bsdf_dict("white_panel_95")))
    assert np.all(retro[4:] > 100.0 * panel[4:])


def test_rgb_twin_carries_the_srgb_appearance(mi):
    d = bsdf_dict("grass", rgb_twin=True)
    assert d["reflectance"]["type"] == "rgb"
    np.testing.assert_allclose(d["reflectance"]["value"], linear_rgb("grass"))
    # the upsampled RGB knows nothing of the red edge: the NIR return is lost
    spectral = monostatic_rho(mi, mi.load_dict(bsdf_dict("grass")))
    twin = monostatic_rho(mi, mi.load_dict(d))
    assert spectral[4] > 0.4 and twin[4] < 0.1
    np.testing.assert_allclose(twin[1], spectral[1], atol=0.02)  # same green at 550 nm


def test_conductor_twin_is_a_tinted_mirror():
    d = bsdf_dict("copper", rgb_twin=True)
    assert d["material"] == "none" and "eta" not in d
    np.testing.assert_allclose(d["specular_reflectance"]["value"], linear_rgb("copper"))
    spectral = bsdf_dict("copper")
    assert spectral["eta"]["type"] == "irregular" and spectral["k"]["type"] == "irregular"


def test_glass_twin_keeps_clear_glass_and_tints_blue_glass():
    assert bsdf_dict("glass_clear", rgb_twin=True) == bsdf_dict("glass_clear")
    d = bsdf_dict("glass_blue", rgb_twin=True)
    np.testing.assert_allclose(d["specular_transmittance"]["value"], linear_rgb("glass_blue"))


def test_overrides_apply_and_are_checked():
    d = bsdf_dict("car_paint_red", overrides={"roughness": 0.3, "int_ior": 1.6})
    assert d["alpha"] == 0.3 and d["int_ior"] == 1.6
    assert bsdf_dict("retro_sheeting_red", overrides={"lobe_width": 1.0})["lobe_width"] == 1.0
    assert (
        bsdf_dict("retro_sheeting_red", overrides={"diffuse_fraction": 0})["diffuse_fraction"] == 0
    )
    assert get_material("car_paint_red").params["alpha"] == 0.1  # the registry is unchanged
    with pytest.raises(NidarError, match="cannot be set on a diffuse material"):
        bsdf_dict("grass", overrides={"roughness": 0.2})
    with pytest.raises(NidarError, match="outside"):
        bsdf_dict("aluminium", overrides={"roughness": 0.0})
    with pytest.raises(NidarError, match="must be a number"):
        bsdf_dict("aluminium", overrides={"roughness": "rough"})
