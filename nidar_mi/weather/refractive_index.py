"""Complex refractive indices of liquid water and of ice between 300 and 1800 nm.

Both are tabulated measurements, interpolated as their compilers prescribe: the real part
linearly and the imaginary part linearly in its logarithm, both against the logarithm of the
wavelength.

* **Water**: Segelstein (1981), *The complex refractive index of water* (M.S. thesis, University
  of Missouri-Kansas City), the compilation most Mie codes ship (the rows are miepython's
  ``segelstein81_index.txt``); in the near infrared it follows Hale & Querry (1973, Appl. Opt.
  12, 555). At 905 nm ``m = 1.3235 - 5.1e-7 i``, at 1550 nm ``1.3109 - 1.34e-4 i``: the water
  absorption band at 1450 nm makes a drop ~260 times more absorbing at 1550 than at 905 nm.
* **Ice** (snowflakes): Warren & Brandt (2008), J. Geophys. Res. 113, D14220
  (``IOP_2008_ASCIItable.dat``). At 905 nm ``1.3031 - 4.3e-7 i``, at 1550 nm ``1.2906 - 4.2e-4 i``.

The sign convention is miepython's: ``m = n - i k`` with ``k >= 0``.
"""

from __future__ import annotations

from functools import cache
from importlib import resources

import numpy as np

__all__ = ["WAVELENGTH_RANGE_NM", "water_index", "ice_index", "absorption_coefficient"]

#: Wavelengths (nm) the tables cover.
WAVELENGTH_RANGE_NM = (300.0, 1800.0)


@cache
def _table(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(λ nm, n, k) of a data file, read-only."""
    text = resources.files("nidar_mi.weather.data").joinpath(name).read_text(encoding="utf-8")
    rows = [ln for ln in text.splitlines() if ln and not ln.startswith("#")][1:]
    data = np.array([[float(v) for v in ln.split(",")] for ln in rows], dtype=np.float64)
    out = (data[:, 0] * 1000.0, data[:, 1], data[:, 2])
    for a in out:
        a.setflags(write=False)
    return out


def _interpolate(name: str, wavelength_nm) -> np.ndarray:
    lam, n, k = _table(name)
    w = np.asarray(wavelength_nm, dtype=np.float64)
    lo, hi = WAVELENGTH_RANGE_NM
    if not np.all(np.isfinite(w)) or np.any(w < lo) or np.any(w > hi):
        raise ValueError(f"wavelength must lie in [{lo:g}, {hi:g}] nm (got {w})")
    x = np.log(w)
    re = np.interp(x, np.log(lam), n)
    im = np.exp(np.interp(x, np.log(lam), np.log(k)))
    return re - 1j * im


def water_index(wavelength_nm):
    """Complex refractive index ``n - i k`` of liquid water (Segelstein 1981).

    Args:
        wavelength_nm: scalar or array, in [300, 1800] nm.

    Returns:
        complex128, the shape of ``wavelength_nm``.
    """
    return _interpolate("water_segelstein_1981.csv", wavelength_nm)


def ice_index(wavelength_nm):
    """Complex refractive index ``n - i k`` of ice Ih (Warren & Brandt 2008).

    Args:
        wavelength_nm: scalar or array, in [300, 1800] nm.

    Returns:
        complex128, the shape of ``wavelength_nm``.
    """
    return _interpolate("ice_warren_brandt_2008.csv", wavelength_nm)


def absorption_coefficient(index, wavelength_nm):
    """Bulk absorption coefficient ``4 π k / λ`` of the material, 1/m."""
    return 4.0 * np.pi * np.abs(np.imag(index)) / (np.asarray(wavelength_nm) * 1e-9)
