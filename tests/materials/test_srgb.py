"""Tests of the sRGB appearance: colour-science pipeline, published ColorChecker values."""

import numpy as np
import pytest

from nidar_mi.materials import linear_rgb, srgb
from nidar_mi.materials.spectra import Spectrum, flat
from nidar_mi.materials.srgb import spectrum_to_srgb, srgb_hex

# BabelColor "ColorChecker RGB and spectra" (D. Pascale, 2006): sRGB of the average 2005 chart.
BABELCOLOR_SRGB = {
    "dark skin": (115, 82, 68),
    "light skin": (194, 150, 130),
    "blue sky": (98, 122, 157),
    "foliage": (87, 108, 67),
    "red": (175, 54, 60),
    "green": (70, 148, 73),
}


def test_grey_panel_stays_grey():
    np.testing.assert_allclose(linear_rgb("grey_panel_50"), [0.5, 0.5, 0.5], atol=2e-4)
    np.testing.assert_allclose(srgb("grey_panel_50"), [0.735357] * 3, atol=5e-4)
    np.testing.assert_allclose(linear_rgb("white_panel_95"), [0.95] * 3, atol=2e-4)
    assert srgb_hex(srgb("white_panel_95")) == "#f9f9f9"


def test_nir_does_not_change_colour():
    a = Spectrum([360.0, 830.0, 1700.0], [0.3, 0.3, 0.3])
    b = Spectrum([360.0, 830.0, 1700.0], [0.3, 0.3, 0.9])
    np.testing.assert_allclose(spectrum_to_srgb(a), spectrum_to_srgb(b), atol=1e-3)
    np.testing.assert_allclose(spectrum_to_srgb(a), spectrum_to_srgb(flat(0.3)), atol=1e-6)


@pytest.mark.parametrize("patch", sorted(BABELCOLOR_SRGB))
def test_colorchecker_matches_published_srgb(patch):
    colour = pytest.importorskip("colour")
    sd = colour.SDS_COLOURCHECKERS["ISO 17321-1"][patch]
    s = Spectrum(sd.wavelengths, sd.values)
    got = spectrum_to_srgb(s) * 255.0
    np.testing.assert_allclose(got, BABELCOLOR_SRGB[patch], atol=9.0)


def test_material_colours_are_plausible():
    r, g, b = srgb("grass")
    assert g > r and g > b
    r, g, b = srgb("car_paint_red")
    assert r > 1.5 * g and r > 1.5 * b
    r, g, b = srgb("lane_paint_yellow")
    assert r > g > b and b < 0.6 * g
    r, g, b = srgb("marking_paint_blue")
    assert b > r
    asphalt = srgb("asphalt_new")
    assert asphalt.max() - asphalt.min() < 0.06 and asphalt.mean() < 0.35
    copper = srgb("copper")
    assert copper[0] > copper[1] > copper[2]
    np.testing.assert_allclose(srgb("glass_clear"), [1.0, 1.0, 1.0], atol=1e-3)
    r, g, b = srgb("glass_blue")
    assert b > r
