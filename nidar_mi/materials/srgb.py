"""sRGB appearance of a reflectance spectrum under CIE D65, with colour-science.

``XYZ = sum(rho * D65 * cmf) / sum(D65 * y_bar)`` over 360-830 nm at 1 nm with the CIE 1931
2-degree observer (``colour.sd_to_XYZ``), then IEC 61966-2-1 sRGB (its white point is D65, so no
chromatic adaptation happens). A spectrally flat ``rho`` gives linear RGB ``(rho, rho, rho)``.
Linear values are clipped to [0, 1] (out-of-gamut colours are saturated pigments) before the
sRGB transfer curve (:func:`nidar_mi.io.images.linear_to_srgb`) is applied.

colour-science is imported on first use (it takes about a second).
"""

from __future__ import annotations

import functools
import warnings

import numpy as np

from ..io.images import linear_to_srgb
from .spectra import Spectrum

__all__ = [
    "colour_tables",
    "spectrum_to_xyz",
    "spectrum_to_linear_srgb",
    "spectrum_to_srgb",
    "srgb_hex",
]


@functools.lru_cache(maxsize=1)
def colour_tables():
    """``(colour, cmfs, d65)``: colour-science (imported once, its SciPy notice silenced), the
    CIE 1931 2° observer and illuminant D65."""
    with warnings.catch_warnings():
        # colour-science notes at import that optional SciPy features are unavailable.
        warnings.filterwarnings("ignore", message=".*SciPy.*")
        import colour
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    return colour, cmfs, d65


def spectrum_to_xyz(spectrum: Spectrum) -> np.ndarray:
    """CIE 1931 XYZ of a reflectance spectrum under D65, with ``Y = 1`` for a perfect white.

    The spectrum is read as Mitsuba reads an ``irregular`` spectrum: linear between samples and
    zero outside its range. It is sampled every 1 nm from 360 to 830 nm for the integration.

    Args:
        spectrum: reflectance in [0, 1].

    Returns:
        (3,) XYZ.
    """
    colour, cmfs, d65 = colour_tables()
    wl = np.arange(360.0, 831.0, 1.0)
    values = np.interp(wl, spectrum.wavelengths_nm, spectrum.values, left=0.0, right=0.0)
    sd = colour.SpectralDistribution(values, wl)
    with warnings.catch_warnings():
        # colour notes that it aligns D65 to the CMF shape: intended.
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        return np.asarray(colour.sd_to_XYZ(sd, cmfs, d65), dtype=np.float64) / 100.0


def spectrum_to_linear_srgb(spectrum: Spectrum) -> np.ndarray:
    """Linear sRGB (D65 white) of a reflectance spectrum, clipped to [0, 1]. Shape (3,)."""
    colour, _, _ = colour_tables()
    xyz = spectrum_to_xyz(spectrum)
    rgb = colour.XYZ_to_sRGB(xyz, apply_cctf_encoding=False)
    return np.clip(np.asarray(rgb, dtype=np.float64), 0.0, 1.0)


def spectrum_to_srgb(spectrum: Spectrum) -> np.ndarray:
    """Encoded sRGB in [0, 1] of a reflectance spectrum under D65. Shape (3,)."""
    return linear_to_srgb(spectrum_to_linear_srgb(spectrum))


def srgb_hex(encoded: np.ndarray) -> str:
    """``#rrggbb`` of an encoded sRGB triple in [0, 1]."""
    r, g, b = (int(round(float(c) * 255.0)) for c in np.clip(encoded, 0.0, 1.0))
    return f"#{r:02x}{g:02x}{b:02x}"
