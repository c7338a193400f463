"""Tests of nidar_mi.materials.optics: Fresnel at normal incidence and soda-lime dispersion."""

import numpy as np

from nidar_mi.materials.optics import (
    fresnel_conductor_normal,
    fresnel_dielectric_normal,
    soda_lime_ior,
)


def test_dielectric_normal_reflectance_of_glass_is_4_percent():
    np.testing.assert_allclose(fresnel_dielectric_normal(1.5), 0.04)
    np.testing.assert_allclose(fresnel_dielectric_normal(1.0), 0.0)
    np.testing.assert_allclose(fresnel_dielectric_normal(1.5, n_ext=1.5), 0.0)


def test_conductor_normal_reflectance_hand_values():
    # ((0.5 - 1)^2 + 3^2) / ((0.5 + 1)^2 + 3^2) = 9.25 / 11.25
    np.testing.assert_allclose(fresnel_conductor_normal(0.5, 3.0), 9.25 / 11.25)
    # k = 0 reduces to the dielectric formula
    np.testing.assert_allclose(fresnel_conductor_normal(1.5, 0.0), 0.04)
    # large k -> perfect mirror
    assert fresnel_conductor_normal(1.0, 1e4) > 0.9999


def test_soda_lime_index_matches_rubin_1985():
    # n = 1.5130 - 0.003169 l^2 + 0.003962 / l^2, l in um (hand-evaluated at 0.5893 and 1.55 um)
    np.testing.assert_allclose(soda_lime_ior(589.3), 1.523310, atol=2e-6)
    np.testing.assert_allclose(soda_lime_ior(1550.0), 1.507036, atol=2e-6)
    n = soda_lime_ior(np.array([400.0, 905.0, 1700.0]))
    assert np.all(np.diff(n) < 0)  # normal dispersion
