"""Tests of nidar_mi.materials.library: the registry, provenance and reflectance lookups."""

import dataclasses

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import GRID_NM, KINDS, get_material, list_materials, reflectance
from nidar_mi.materials.metals import metal_reflectance

REQUIRED = [
    "asphalt_old", "asphalt_new", "concrete", "brick_red", "lane_paint_white", "lane_paint_yellow",
    "grass", "tree_canopy", "bark", "soil_dry", "sand", "wood_pallet", "shingle",
    "steel_galvanised", "aluminium", "copper", "chromium", "iron", "car_paint_red",
    "car_paint_blue", "car_paint_black", "car_paint_white", "car_paint_silver", "glass_clear",
    "glass_blue", "rubber_tyre", "plastic_wrap", "fabric", "retro_sheeting_white",
    "retro_sheeting_red", "white_panel_95", "grey_panel_50", "black_panel_5",
]  # fmt: skip


def test_required_materials_are_present_and_sorted():
    names = list_materials()
    assert names == sorted(names)
    missing = set(REQUIRED) - set(names)
    assert not missing


@pytest.mark.parametrize("name", list_materials())
def test_every_material_has_provenance_and_a_valid_spectrum(name):
    m = get_material(name)
    assert m.name == name and m.kind in KINDS
    assert m.source.startswith(("earthlib:", "model:"))
    assert m.license and m.description
    r = reflectance(name, GRID_NM)
    assert r.shape == GRID_NM.shape
    assert np.all(np.isfinite(r)) and np.all((r >= 0.0) & (r <= 1.0))


def test_earthlib_materials_carry_the_mit_licence():
    m = get_material("asphalt_old")
    assert m.source == "earthlib:built/road/rpaeof.001-"
    assert m.license.startswith("MIT")


def test_calibration_panels_are_flat():
    for name, rho in (("white_panel_95", 0.95), ("grey_panel_50", 0.5), ("black_panel_5", 0.05)):
        np.testing.assert_allclose(reflectance(name, GRID_NM), rho)


def test_conductor_reflectance_is_normal_incidence_fresnel():
    np.testing.assert_allclose(
        reflectance("aluminium", [550.0, 905.0, 1550.0]),
        metal_reflectance("Al", np.array([550.0, 905.0, 1550.0])),
        rtol=1e-3,  # grid interpolation of n and k vs. interpolation of the published samples
    )


def test_glass_reflectance_is_one_surface_fresnel():
    # Rubin 1985 at 550 nm: n = 1.5130 - 0.003169 * 0.3025 + 0.003962 / 0.3025 = 1.525138
    n = 1.5130 - 0.003169 * 0.55**2 + 0.003962 / 0.55**2
    np.testing.assert_allclose(reflectance("glass_clear", 550.0), ((n - 1) / (n + 1)) ** 2)
    np.testing.assert_allclose(reflectance("glass_blue", 550.0), 0.043250, atol=1e-5)


def test_unknown_name_suggests_close_ones():
    with pytest.raises(NidarError, match="did you mean asphalt_old"):
        get_material("asphalt_olde")


def test_out_of_range_wavelength_is_a_user_error():
    with pytest.raises(NidarError):
        reflectance("grass", 2000.0)
    with pytest.raises(NidarError):
        reflectance("glass_clear", 300.0)


def test_materials_are_frozen():
    m = get_material("grass")
    with pytest.raises(dataclasses.FrozenInstanceError):
        m.kind = "plastic"
    with pytest.raises(TypeError):
        m.params["reflectance"] = None
