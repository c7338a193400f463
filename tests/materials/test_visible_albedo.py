"""Albedo colour weights against colour-science's integration; the earthlib colour -> ρ(λ) map."""

import numpy as np
import pytest
from scipy.stats import spearmanr

from nidar_mi.errors import NidarError
from nidar_mi.materials.spectra import Spectrum
from nidar_mi.materials.srgb import spectrum_to_linear_srgb
from nidar_mi.materials.visible_albedo import (
    ALBEDO_WAVELENGTHS_NM,
    colour_reflectance_map,
    srgb_weights,
)


def test_weights_give_the_colour_science_srgb_of_a_sampled_spectrum():
    """A spectrum read linearly between the 10 nm samples: ``rho @ W`` equals
    :func:`spectrum_to_linear_srgb` (which integrates it every 1 nm with colour-science)."""
    rng = np.random.default_rng(0)
    wl = ALBEDO_WAVELENGTHS_NM
    for _ in range(5):
        rho = np.clip(0.4 + 0.25 * np.sin(wl / rng.uniform(20, 80) + rng.uniform(0, 6)), 0, 1)
        # padded by one zero sample each side: the reading of the weights' outermost hats
        spectrum = Spectrum(np.r_[wl[0] - 10, wl, wl[-1] + 10], np.r_[0.0, rho, 0.0])
        expected = spectrum_to_linear_srgb(spectrum)
        if np.all((expected > 0) & (expected < 1)):  # not clipped
            np.testing.assert_allclose(rho @ srgb_weights(), expected, atol=1e-9)
    # a flat grey is grey of its own value (the 1 nm integration of the D65 white)
    np.testing.assert_allclose(np.full(len(wl), 0.5) @ srgb_weights(), 0.5, atol=2e-4)


def test_the_earthlib_map_ranks_the_library_and_predicts_its_spectra():
    """The map's own score is what colour-science's colours of the library's spectra give."""
    from nidar_mi.materials.earthlib_data import earthlib_spectrum, extend_below, load_earthlib
    from nidar_mi.materials.spectra import GRID_NM

    m = colour_reflectance_map(905.0)
    lib = load_earthlib()
    assert m.wavelength_nm == 905.0 and m.spectra == len(lib.names) > 7000
    assert 0.6 < m.spearman < 0.95
    rows = np.random.default_rng(1).choice(len(lib.names), 400, replace=False)
    truth, pred = [], []
    for i in rows:
        row = lib.data[i].astype(np.float64)
        ok = np.isfinite(row)
        values = np.clip(extend_below(lib.wavelengths_nm[ok], row[ok], GRID_NM), 0.0, 1.0)
        s = Spectrum(GRID_NM, values)
        truth.append(np.interp(905.0, s.wavelengths_nm, s.values))
        pred.append(float(m(spectrum_to_linear_srgb(s))))
    assert spearmanr(pred, truth).statistic == pytest.approx(m.spearman, abs=0.06)
    assert np.all((np.asarray(pred) >= 0) & (np.asarray(pred) <= 1))
    # a green canopy reflects more at 905 nm than a grey of the same luminance: the red edge
    canopy = spectrum_to_linear_srgb(
        earthlib_spectrum("vegetation", "canopy", "v-LAI-3.0-LMA-0.008-CHL-40.7-N-1.6")
    )
    grey = np.full(3, canopy @ [0.2126, 0.7152, 0.0722])
    assert m(canopy) > m(grey)


def test_bad_inputs_of_the_map():
    with pytest.raises(NidarError, match="`wavelength_nm` must lie in"):
        colour_reflectance_map(300.0)
    with pytest.raises(NidarError, match="`rgb` must end in 3 colour channels"):
        colour_reflectance_map(905.0)(np.zeros((4, 2)))


def test_the_shipped_weights_are_the_computed_ones():
    """To float64 rounding: the table was written on one CPU; another sums in another order
    (measured: 8e-15 relative, 9e-17 absolute at most)."""
    from nidar_mi.materials.visible_albedo import compute_srgb_weights

    np.testing.assert_allclose(srgb_weights(), compute_srgb_weights(), rtol=1e-12, atol=1e-15)
