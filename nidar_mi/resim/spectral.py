"""A surface's reflectance at another wavelength, predicted from its reflectance at the
sensor's: ``ρ(λ₂) ≈ a + b·ρ(λ₁)``, the least-squares line over the earthlib library (7261
measured soils, vegetation, built materials, minerals; :mod:`nidar_mi.materials.earthlib_data`),
fitted on the library and never on a scene. It carries what one band says about another on
average; a surface whose spectrum turns between the bands (wet or green vegetation darkens
towards 1550 nm) departs from it, which :func:`band_map` reports as the line's rank
correlation over the library.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

__all__ = ["BandMap", "band_map"]


class BandMap(NamedTuple):
    """``ρ(to) ≈ intercept + slope · ρ(from)``, clipped to [0, 1]; ``spearman`` over the
    library."""

    from_nm: float
    to_nm: float
    intercept: float
    slope: float
    spearman: float

    def __call__(self, rho: np.ndarray) -> np.ndarray:
        return np.clip(self.intercept + self.slope * np.asarray(rho, dtype=np.float64), 0.0, 1.0)


@functools.lru_cache(maxsize=4)
def band_map(from_nm: float, to_nm: float) -> BandMap:
    """The library's line from ρ at ``from_nm`` to ρ at ``to_nm`` (both in 400-1700 nm)."""
    from scipy.stats import spearmanr

    from ..materials.earthlib_data import extend_below, load_earthlib

    lib = load_earthlib()
    grid = np.array([from_nm, to_nm], dtype=np.float64)
    rows = []
    for row in lib.data.astype(np.float64):
        ok = np.isfinite(row)
        rows.append(np.clip(extend_below(lib.wavelengths_nm[ok], row[ok], grid), 0.0, 1.0))
    v = np.asarray(rows)
    slope, intercept = np.polyfit(v[:, 0], v[:, 1], 1)
    rho = float(spearmanr(v[:, 0], v[:, 1]).statistic)
    return BandMap(float(from_nm), float(to_nm), float(intercept), float(slope), rho)
