"""Tests of nidar_mi.resim.spectral: the band maps against their least-squares definition over
the earthlib library, and the shipped lines without earthlib."""

import importlib.util

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.resim import spectral


@pytest.fixture()
def no_earthlib(monkeypatch):
    """earthlib reported as not installed (as ``find_spec`` reports a missing package)."""
    from nidar_mi.materials.earthlib_data import load_earthlib

    load_earthlib.cache_clear()
    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util, "find_spec", lambda name, *a: None if name == "earthlib" else real(name, *a)
    )
    spectral.band_map.cache_clear()
    yield
    spectral.band_map.cache_clear()
    load_earthlib.cache_clear()


def _library_bands(from_nm: float, to_nm: float) -> np.ndarray:
    """(N, 2) every library spectrum read at the two wavelengths, through numpy's own
    interpolation (the library's grid covers both; no extension needed)."""
    from nidar_mi.materials.earthlib_data import load_earthlib

    lib = load_earthlib()
    rows = []
    for row in lib.data.astype(np.float64):
        ok = np.isfinite(row)
        rows.append(np.interp([from_nm, to_nm], lib.wavelengths_nm[ok], row[ok]))
    return np.clip(np.asarray(rows), 0.0, 1.0)


def test_the_shipped_lines_are_the_librarys_least_squares_lines():
    """Each shipped line equals its recomputation on the installed library (1e-12), and is the
    least-squares line: its residuals sum to zero and are uncorrelated with ρ(from)."""
    pytest.importorskip("earthlib")
    for pair in spectral.SHIPPED_PAIRS:
        shipped = spectral.band_map(*pair)
        np.testing.assert_allclose(shipped, spectral.compute_band_map(*pair), rtol=1e-12)
        v = _library_bands(*pair)
        residual = v[:, 1] - (shipped.intercept + shipped.slope * v[:, 0])
        assert abs(residual.mean()) < 1e-3
        assert abs(np.corrcoef(residual, v[:, 0])[0, 1]) < 1e-2
    near = spectral.band_map(905.0, 865.0)
    assert near.spearman > 0.99 and abs(near.slope - 1.0) < 0.05  # neighbouring bands agree


def test_the_shipped_lines_need_no_earthlib_and_other_pairs_say_what_is_missing(no_earthlib):
    m = spectral.band_map(905.0, 1550.0)
    assert (m.from_nm, m.to_nm) == (905.0, 1550.0)
    np.testing.assert_allclose(
        m([0.0, 0.5, 1.0]), np.clip(m.intercept + m.slope * np.array([0, 0.5, 1]), 0, 1)
    )
    with pytest.raises(NidarError, match="earthlib"):
        spectral.band_map(905.0, 940.0)
