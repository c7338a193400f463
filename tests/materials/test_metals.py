"""Tests of nidar_mi.materials.metals: published (n, k) tables out to the 1550 nm band."""

import math

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import reflectance
from nidar_mi.materials.metals import METAL_SOURCES, metal_nk, metal_reflectance

METAL_MATERIALS = ["aluminium", "copper", "chromium", "iron", "steel_galvanised"]


@pytest.mark.parametrize("metal", sorted(METAL_SOURCES))
def test_tables_cover_360_to_1700_nm(metal):
    n, k = metal_nk(metal, grid_nm=None)
    assert n.wavelengths_nm[0] <= 360.0 and n.wavelengths_nm[-1] >= 1700.0
    assert np.all(n.values > 0) and np.all(k.values > 0)


@pytest.mark.parametrize("name", METAL_MATERIALS)
def test_metal_materials_are_finite_at_905_and_1550(name):
    r = reflectance(name, [905.0, 1550.0])
    assert np.all(np.isfinite(r)) and np.all((r > 0.3) & (r < 1.0))


def test_published_reflectance_features():
    # Rakic 1995 aluminium: R ~ 0.92 in the visible with the interband dip near 826 nm (1.5 eV)
    r450, r826, r1550 = metal_reflectance("Al", np.array([450.0, 826.0, 1550.0]))
    assert 0.91 < r450 < 0.94 and r826 < r450 - 0.03 and r1550 > 0.97
    # Johnson & Christy copper: the green absorption edge gives its colour
    r500, r905 = metal_reflectance("Cu", np.array([500.0, 905.0]))
    assert r500 < 0.65 and r905 > 0.95
    # iron is a poor reflector in the visible, better in the SWIR
    r550, r1550 = metal_reflectance("Fe", np.array([550.0, 1550.0]))
    assert 0.45 < r550 < 0.6 and r1550 > r550 + 0.1


def test_unknown_metal_is_a_user_error():
    with pytest.raises(NidarError, match="no optical constants"):
        metal_nk("Au")


@pytest.mark.parametrize("metal", ["Al", "Cu", "Cr"])
def test_agrees_with_mitsuba_presets_where_they_are_defined(variant, metal):
    """Mitsuba's own conductor data (up to ~886 nm) is an independent source."""
    import drjit as dr
    import mitsuba as mi

    bsdf = mi.load_dict({"type": "conductor", "material": metal})
    si = dr.zeros(mi.SurfaceInteraction3f, 1)
    si.wi = mi.Vector3f(0, 0, 1)
    for wls in ([400.0, 500.0, 600.0, 700.0], [450.0, 550.0, 650.0, 850.0]):
        si.wavelengths = mi.UnpolarizedSpectrum(wls)
        _, weight = bsdf.sample(mi.BSDFContext(), si, 0.5, mi.Point2f(0.5, 0.5))
        theirs = np.array(weight).ravel()  # smooth mirror at normal incidence: weight = R
        np.testing.assert_allclose(metal_reflectance(metal, np.array(wls)), theirs, atol=0.04)
    assert math.isfinite(float(metal_reflectance(metal, 1550.0)))
