"""A surface's reflectance at another wavelength, predicted from its reflectance at the
sensor's: ``ρ(λ₂) ≈ a + b·ρ(λ₁)``, the least-squares line over the earthlib library (7261
measured soils, vegetation, built materials, minerals; :mod:`nidar_mi.materials.earthlib_data`),
fitted on the library and never on a scene. It carries what one band says about another on
average; a surface whose spectrum turns between the bands (wet or green vegetation darkens
towards 1550 nm) departs from it, which :func:`band_map` reports as the line's rank
correlation over the library.

The lines from 905 nm (the KITTI sensor's band, which ``reconstruct`` recovers ρ in) to 865,
1064 and 1550 nm ship in ``materials/data/earthlib_band_maps.csv`` (:func:`write_band_maps`;
``tests/resim/test_spectral.py`` checks the file against the library), so ``reconstruct``
needs no optional dependency; any other pair is fitted on the installed earthlib library.
"""

from __future__ import annotations

import csv
import functools
import os
from typing import NamedTuple

import numpy as np

from ..errors import NidarError

__all__ = ["BandMap", "SHIPPED_PAIRS", "band_map", "compute_band_map", "write_band_maps"]

#: The (from_nm, to_nm) pairs whose lines ship with the package.
SHIPPED_PAIRS = ((905.0, 865.0), (905.0, 1064.0), (905.0, 1550.0))
#: :func:`compute_band_map` of :data:`SHIPPED_PAIRS`, as shipped.
BAND_MAPS_FILE = os.path.join(
    os.path.dirname(os.path.dirname(__file__)), "materials", "data", "earthlib_band_maps.csv"
)


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


@functools.lru_cache(maxsize=8)
def band_map(from_nm: float, to_nm: float) -> BandMap:
    """The library's line from ρ at ``from_nm`` to ρ at ``to_nm`` (both in 400-1700 nm): the
    shipped one for :data:`SHIPPED_PAIRS`, else :func:`compute_band_map`.

    Raises:
        NidarError: the shipped file is unreadable, or (another pair) earthlib is not installed.
    """
    pair = (float(from_nm), float(to_nm))
    if pair in SHIPPED_PAIRS:
        return _shipped()[pair]
    return compute_band_map(*pair)


@functools.lru_cache(maxsize=1)
def _shipped() -> dict[tuple[float, float], BandMap]:
    try:
        with open(BAND_MAPS_FILE, newline="", encoding="utf-8") as f:
            rows = [BandMap(*(float(r[k]) for k in BandMap._fields)) for r in csv.DictReader(f)]
    except (OSError, KeyError, ValueError, TypeError) as e:
        raise NidarError(f"cannot read the band maps {BAND_MAPS_FILE}: {e}") from e
    maps = {(m.from_nm, m.to_nm): m for m in rows}
    if set(maps) != set(SHIPPED_PAIRS):
        raise NidarError(f"{BAND_MAPS_FILE}: expected the pairs {SHIPPED_PAIRS}")
    return maps


def write_band_maps(path: str = BAND_MAPS_FILE) -> None:
    """Write :func:`compute_band_map` of :data:`SHIPPED_PAIRS` (full precision; needs earthlib)."""
    lines = [",".join(BandMap._fields)]
    for pair in SHIPPED_PAIRS:
        lines.append(",".join(repr(float(v)) for v in compute_band_map(*pair)))
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")


def compute_band_map(from_nm: float, to_nm: float) -> BandMap:
    """The least-squares line fitted on the installed earthlib library (module docstring).

    Raises:
        NidarError: earthlib is not installed, or its files are unreadable.
    """
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
