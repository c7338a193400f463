"""Complex refractive index ``n + ik`` of metals from 340 to 1720 nm, from published tables.

Mitsuba's built-in conductor presets (``material="Al"`` ...) stop near 886 nm and give NaN past
it; these tables reach the 1550 nm LiDAR band. ``data/metals_nk.csv`` holds the authors' own
samples (kept as published, no resampling), copied from the refractiveindex.info database (CC0):

=====  ==========================================================================================
Metal  Source
=====  ==========================================================================================
Al     A. D. Rakic, Appl. Opt. 34, 4755 (1995): evaporated films, KK + semiquantum-model analysis
Cr     A. D. Rakic et al., Appl. Opt. 37, 5271 (1998): Brendel-Bormann fit to several data sets
Cu     P. B. Johnson, R. W. Christy, Phys. Rev. B 6, 4370 (1972): evaporated films, room temp.
Fe     P. B. Johnson, R. W. Christy, Phys. Rev. B 9, 5056 (1974): evaporated films, room temp.
Zn     W. S. M. Werner, K. Glantschnig, C. Ambrosch-Draxl, J. Phys. Chem. Ref. Data 38, 1013
       (2009): from reflection electron energy-loss spectra (used for galvanised steel)
=====  ==========================================================================================

Between samples ``n`` and ``k`` are interpolated linearly (the database's convention). For
chromium the Rakic 1998 fit is used rather than Johnson & Christy 1974, whose evaporated films
reflect about 0.1 less than bulk chromium plating in the visible (0.55 against 0.65 at 550 nm).
"""

from __future__ import annotations

import functools
from importlib import resources

import numpy as np

from ..errors import NidarError
from .optics import fresnel_conductor_normal
from .spectra import GRID_NM, Spectrum

__all__ = ["METAL_SOURCES", "METALS_LICENSE", "metal_nk", "metal_reflectance"]

METALS_LICENSE = "CC0 1.0 (refractiveindex.info database); data from the cited publications"

#: Citation of the optical constants of each metal in ``data/metals_nk.csv``.
METAL_SOURCES = {
    "Al": "A. D. Rakic, Appl. Opt. 34, 4755-4767 (1995), doi:10.1364/AO.34.004755",
    "Cr": (
        "A. D. Rakic, A. B. Djurisic, J. M. Elazar and M. L. Majewski, Appl. Opt. 37, 5271-5283 "
        "(1998), doi:10.1364/AO.37.005271 (Brendel-Bormann model)"
    ),
    "Cu": "P. B. Johnson and R. W. Christy, Phys. Rev. B 6, 4370-4379 (1972), doi:10.1103/PhysRevB.6.4370",
    "Fe": "P. B. Johnson and R. W. Christy, Phys. Rev. B 9, 5056-5070 (1974), doi:10.1103/PhysRevB.9.5056",
    "Zn": (
        "W. S. M. Werner, K. Glantschnig and C. Ambrosch-Draxl, J. Phys. Chem. Ref. Data 38, "
        "1013-1092 (2009), doi:10.1063/1.3243762"
    ),
}


@functools.lru_cache(maxsize=1)
def _table() -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """metal -> (wavelengths_nm, n, k) from ``data/metals_nk.csv``."""
    text = resources.files("nidar_mi.materials").joinpath("data/metals_nk.csv").read_text("utf-8")
    rows: dict[str, list[tuple[float, float, float]]] = {}
    for line in text.splitlines():
        if not line.strip() or line.startswith("#") or line.startswith("metal,"):
            continue
        metal, wl, n, k = line.split(",")
        rows.setdefault(metal, []).append((float(wl), float(n), float(k)))
    out = {}
    for metal, r in rows.items():
        a = np.array(sorted(r))
        out[metal] = (a[:, 0], a[:, 1], a[:, 2])
    return out


def metal_nk(metal: str, grid_nm: np.ndarray | None = GRID_NM) -> tuple[Spectrum, Spectrum]:
    """Real and imaginary refractive index of ``metal`` (``"Al"``, ``"Cr"``, ``"Cu"``, ``"Fe"``, ``"Zn"``).

    Args:
        metal: chemical symbol, a key of :data:`METAL_SOURCES`.
        grid_nm: wavelengths to interpolate onto, nm; None returns the published samples.

    Returns:
        ``(n, k)`` spectra.

    Raises:
        NidarError: unknown metal.
    """
    table = _table()
    if metal not in table:
        raise NidarError(
            f"no optical constants for metal '{metal}' (have: {', '.join(sorted(table))})"
        )
    wl, n, k = table[metal]
    n_s, k_s = Spectrum(wl, n), Spectrum(wl, k)
    if grid_nm is None:
        return n_s, k_s
    return n_s.resample(grid_nm), k_s.resample(grid_nm)


def metal_reflectance(metal: str, wavelengths_nm: np.ndarray) -> np.ndarray:
    """Normal-incidence reflectance of a smooth ``metal`` surface in air at ``wavelengths_nm``."""
    n, k = metal_nk(metal, grid_nm=None)
    return fresnel_conductor_normal(n(wavelengths_nm), k(wavelengths_nm))
