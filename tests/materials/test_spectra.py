"""Tests of nidar_mi.materials.spectra: the Spectrum type, the grid and the model shapes."""

import dataclasses

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials.spectra import (
    GRID_NM,
    Spectrum,
    absorption_band,
    check_wavelengths,
    flat,
    logistic,
)


def test_grid_covers_360_to_1700_every_10_nm():
    assert GRID_NM[0] == 360.0 and GRID_NM[-1] == 1700.0
    assert GRID_NM.size == 135
    assert np.all(np.diff(GRID_NM) == 10.0)


def test_linear_interpolation_keeps_shape():
    s = Spectrum([400.0, 500.0, 600.0], [0.2, 0.4, 0.1])
    np.testing.assert_allclose(s(450.0), 0.3)
    np.testing.assert_allclose(
        s(np.array([[400.0, 550.0], [575.0, 600.0]])), [[0.2, 0.25], [0.175, 0.1]]
    )


def test_out_of_range_wavelength_is_a_user_error():
    s = Spectrum([400.0, 500.0], [0.2, 0.4])
    with pytest.raises(NidarError, match="outside 400-500 nm"):
        s(399.0)
    with pytest.raises(NidarError):
        check_wavelengths([905.0, 1800.0])
    with pytest.raises(NidarError):
        check_wavelengths(np.nan)


@pytest.mark.parametrize(
    "wl, v",
    [([500.0, 400.0], [0.1, 0.2]), ([400.0], [0.1]), ([400.0, 500.0], [0.1, np.nan])],
)
def test_invalid_spectra_are_rejected(wl, v):
    with pytest.raises(ValueError):
        Spectrum(wl, v)


def test_spectrum_is_immutable():
    s = flat(0.5)
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.values = np.zeros(3)
    with pytest.raises(ValueError):
        s.values[0] = 1.0


def test_xml_value_round_trip_and_mitsuba_dict():
    s = Spectrum([360.0, 905.0, 1550.0], [0.125, 0.5, 0.75])
    assert s.xml_value() == "360:0.125, 905:0.5, 1550:0.75"
    back = Spectrum.parse_xml_value(s.xml_value())
    np.testing.assert_array_equal(back.wavelengths_nm, s.wavelengths_nm)
    np.testing.assert_array_equal(back.values, s.values)
    d = s.mitsuba_dict()
    assert d == {"type": "irregular", "wavelengths": "360, 905, 1550", "values": "0.125, 0.5, 0.75"}
    with pytest.raises(ValueError):
        Spectrum.parse_xml_value("0.5")


def test_logistic_edge_values():
    s = logistic(0.1, 0.9, 600.0, 10.0)
    np.testing.assert_allclose(s(600.0), 0.5)
    # 1 / (1 + e^1) of the way at one width below the centre
    np.testing.assert_allclose(s(590.0), 0.1 + 0.8 / (1.0 + np.e))
    np.testing.assert_allclose(s(360.0), 0.1, atol=1e-9)
    np.testing.assert_allclose(s(1700.0), 0.9, atol=1e-9)


def test_absorption_band_depth_and_half_width():
    base = flat(0.6)
    s = absorption_band(base, 1200.0, 40.0, 0.25)
    np.testing.assert_allclose(s(1200.0), 0.6 * 0.75)
    np.testing.assert_allclose(s(1220.0), 0.6 * (1.0 - 0.125))  # half depth at FWHM / 2
    np.testing.assert_allclose(s(400.0), 0.6)
