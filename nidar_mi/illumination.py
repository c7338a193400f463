"""Daylight spectra that carry NIR energy, for scenes and the scene generator.

Source: ASTM G-173-03 reference solar spectra (AM1.5), as shipped by colour-science
(``colour.plotting.datasets.astm_g_173``). The tables are averaged over bins of ``step`` nm (the
raw data has 0.5-5 nm spacing and deep water-vapour bands near 940, 1130, 1400 nm that point
sampling would alias).

* :func:`sun_irradiance`: direct + circumsolar spectral irradiance, W·m⁻²·nm⁻¹ on a plane normal
  to the sun (Mitsuba ``directional`` emitter ``irradiance``).
* :func:`sky_radiance`: (global tilt − direct) / π, W·m⁻²·sr⁻¹·nm⁻¹: the diffuse sky as a uniform
  radiance (Mitsuba ``constant`` emitter ``radiance``).
"""

from __future__ import annotations

import numpy as np

__all__ = ["sun_irradiance", "sky_radiance", "spectrum_string"]


def _table(name: str) -> tuple[np.ndarray, np.ndarray]:
    from colour.plotting.datasets import astm_g_173 as g

    data = getattr(g, name)
    wl = np.fromiter(data.keys(), dtype=np.float64)
    v = np.fromiter(data.values(), dtype=np.float64)
    return wl, v


def _binned(name: str, lo: float, hi: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    wl, v = _table(name)
    centres = np.arange(lo, hi + 0.5 * step, step)
    fine = np.arange(lo - step / 2, hi + step / 2 + 1e-9, 0.5)
    vf = np.interp(fine, wl, v)
    out = np.array([vf[(fine >= c - step / 2) & (fine < c + step / 2)].mean() for c in centres])
    return centres, out


def sun_irradiance(lo: float = 360.0, hi: float = 1700.0, step: float = 10.0, scale: float = 1.0):
    """(wavelengths nm (K,), irradiance W·m⁻²·nm⁻¹ (K,)) of the direct solar beam."""
    wl, v = _binned("DATA_ASTMG173_DIRECT_CIRCUMSOLAR", lo, hi, step)
    return wl, v * scale


def sky_radiance(lo: float = 360.0, hi: float = 1700.0, step: float = 10.0, scale: float = 1.0):
    """(wavelengths nm (K,), radiance W·m⁻²·sr⁻¹·nm⁻¹ (K,)) of a uniform diffuse sky."""
    wl, g = _binned("DATA_ASTMG173_GLOBAL_TILT", lo, hi, step)
    _, d = _binned("DATA_ASTMG173_DIRECT_CIRCUMSOLAR", lo, hi, step)
    return wl, np.maximum(g - d, 0.0) / np.pi * scale


def spectrum_string(wl: np.ndarray, values: np.ndarray, digits: int = 4) -> str:
    """Mitsuba's literal spectrum syntax: ``"360:0.1, 370:0.2, ..."``."""
    return ", ".join(f"{w:g}:{v:.{digits}g}" for w, v in zip(wl, values))
