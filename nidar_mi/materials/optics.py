"""Normal-incidence Fresnel reflectance and the refractive index of soda-lime glass.

Pure functions of numpy arrays; wavelengths in nm.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "fresnel_conductor_normal",
    "fresnel_dielectric_normal",
    "soda_lime_ior",
    "SODA_LIME_SOURCE",
]

SODA_LIME_SOURCE = (
    "M. Rubin, Optical properties of soda lime silica glasses, Sol. Energy Mater. 12, 275-288 "
    "(1985), doi:10.1016/0165-1633(85)90052-8: n = 1.5130 - 0.003169 l^2 + 0.003962 / l^2, "
    "l in um, valid 0.31-4.6 um"
)


def fresnel_conductor_normal(n: np.ndarray, k: np.ndarray, n_ext: float = 1.0) -> np.ndarray:
    """Reflectance at normal incidence of a conductor with complex index ``n + ik``.

    ``R = ((n - n_ext)^2 + k^2) / ((n + n_ext)^2 + k^2)`` (Born & Wolf, Principles of Optics).

    Args:
        n, k: real and imaginary parts of the refractive index (same shape).
        n_ext: refractive index of the outside medium.

    Returns:
        R in [0, 1], shape of ``n``.
    """
    n = np.asarray(n, dtype=np.float64)
    k = np.asarray(k, dtype=np.float64)
    return ((n - n_ext) ** 2 + k**2) / ((n + n_ext) ** 2 + k**2)


def fresnel_dielectric_normal(n: np.ndarray, n_ext: float = 1.0) -> np.ndarray:
    """Single-surface reflectance at normal incidence, ``((n - n_ext) / (n + n_ext))^2``."""
    n = np.asarray(n, dtype=np.float64)
    return ((n - n_ext) / (n + n_ext)) ** 2


def soda_lime_ior(wavelengths_nm: np.ndarray) -> np.ndarray:
    """Refractive index of clear soda-lime float glass (Rubin 1985, see :data:`SODA_LIME_SOURCE`).

    Args:
        wavelengths_nm: any shape, nm (the fit holds for 310-4600 nm).

    Returns:
        n, same shape (1.5373 at 400 nm, 1.5233 at 589 nm, 1.5070 at 1550 nm).
    """
    l_um = np.asarray(wavelengths_nm, dtype=np.float64) / 1000.0
    return 1.5130 - 0.003169 * l_um**2 + 0.003962 / l_um**2
