"""Tests of nidar_mi.materials.earthlib_data against earthlib's own reader."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.materials import get_material, reflectance
from nidar_mi.materials.earthlib_data import earthlib_spectrum, extend_below, load_earthlib

MEASURED = ["asphalt_old", "asphalt_new", "lane_paint_white", "grass", "soil_dry", "wood_pallet"]


@pytest.fixture(scope="module")
def earthlib_ref():
    """earthlib's full library through its own API (pandas + spectral readers)."""
    earthlib = pytest.importorskip("earthlib")
    lib = earthlib.full_library
    wl = np.asarray(lib.sensor.band_centers, dtype=float)
    if lib.sensor.wavelength_unit.lower().startswith("micro"):
        wl = wl * 1000.0
    return lib, np.round(wl, 3)  # band centres are stored as float32 micrometres


def _row(earthlib_ref, source: str) -> np.ndarray:
    lib, _ = earthlib_ref
    level_2, level_3, name = source.removeprefix("earthlib:").split("/")
    md = lib.metadata
    hit = np.nonzero(
        ((md.LEVEL_2 == level_2) & (md.LEVEL_3 == level_3) & (md.NAME == name)).values
    )[0]
    assert hit.size == 1, source
    return np.asarray(lib.data[hit[0]], dtype=float)


@pytest.mark.parametrize("name", MEASURED)
def test_lookups_match_earthlib_at_550_905_1550(earthlib_ref, name):
    _, wl = earthlib_ref
    row = _row(earthlib_ref, get_material(name).source)
    want = np.interp([550.0, 905.0, 1550.0], wl, row)
    np.testing.assert_allclose(reflectance(name, [550.0, 905.0, 1550.0]), want, rtol=1e-6)


def test_water_band_is_bridged_linearly(earthlib_ref):
    _, wl = earthlib_ref
    assert 1400.0 not in wl and 1350.0 in wl and 1460.0 in wl  # the removed band
    row = _row(earthlib_ref, get_material("grass").source)
    v1350, v1460 = row[wl == 1350.0][0], row[wl == 1460.0][0]
    want = v1350 + (1400.0 - 1350.0) / 110.0 * (v1460 - v1350)
    np.testing.assert_allclose(reflectance("grass", 1400.0), want, rtol=1e-6)


@pytest.mark.parametrize("name", ["grass", "tree_canopy"])
def test_vegetation_red_edge(name):
    r660, r905 = reflectance(name, [660.0, 905.0])
    assert r905 > 3.0 * r660


def test_extension_below_400_follows_the_initial_slope():
    wl = np.arange(400.0, 460.0, 10.0)
    grid = np.array([360.0, 380.0, 400.0, 420.0])
    # gentle rise of 0.001 / nm: extrapolated straight back
    out = extend_below(wl, 0.3 + 0.001 * (wl - 400.0), grid)
    np.testing.assert_allclose(out, [0.26, 0.28, 0.30, 0.32])
    # steep UV edge (0.01 / nm): floored at half the 400 nm value
    out = extend_below(wl, 0.3 + 0.01 * (wl - 400.0), grid)
    np.testing.assert_allclose(out[:2], [0.15, 0.15])
    # brighter towards the UV: held at the 400 nm value, never raised
    out = extend_below(wl, 0.5 - 0.002 * (wl - 400.0), grid)
    np.testing.assert_allclose(out[:2], [0.5, 0.5])


def test_extension_of_a_real_spectrum_stays_in_bounds():
    s = earthlib_spectrum("built", "paint", "trawyg.001-")
    v400 = s(400.0)
    below = s(np.array([360.0, 370.0, 380.0, 390.0]))
    assert np.all(below <= v400 + 1e-12) and np.all(below >= 0.5 * v400 - 1e-12)


def test_unknown_spectrum_is_a_user_error():
    with pytest.raises(NidarError, match="no spectrum"):
        earthlib_spectrum("built", "road", "no-such-spectrum")


def test_library_shape_and_bands():
    lib = load_earthlib()
    assert lib.data.shape == (7261, 180)
    assert lib.wavelengths_nm[0] == 400.0 and lib.wavelengths_nm[-1] == 2450.0
    assert len(lib.names) == 7261


def test_missing_library_folder_is_a_user_error(tmp_path):
    with pytest.raises(NidarError, match="cannot read"):
        load_earthlib.__wrapped__(str(tmp_path))


def test_shipped_catalog_spectra_are_earthlibs(earthlib_ref):
    """materials/data/earthlib_catalog.json holds exactly the catalogue's spectra, each the
    installed library's float32 row and metadata (what renders use without earthlib)."""
    from nidar_mi.materials.catalog import catalog_spectra
    from nidar_mi.materials.earthlib_data import catalog_library

    shipped, lib = catalog_library(), load_earthlib()
    assert list(zip(shipped.level_2, shipped.level_3, shipped.names)) == catalog_spectra()
    np.testing.assert_array_equal(shipped.wavelengths_nm, lib.wavelengths_nm)
    for i, key in enumerate(catalog_spectra()):
        j = lib.index(*key)
        np.testing.assert_array_equal(shipped.data[i], lib.data[j], err_msg=str(key))
        assert (shipped.level_4[i], shipped.sources[i], shipped.notes[i]) == (
            lib.level_4[j],
            lib.sources[j],
            lib.notes[j],
        )
