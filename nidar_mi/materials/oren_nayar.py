"""The ``roughdiffuse`` BRDF in closed form (NumPy or floats; no Mitsuba needed).

Oren–Nayar's qualitative model of a rough diffuse surface (M. Oren and S. K. Nayar,
"Generalization of Lambert's reflectance model", SIGGRAPH 1994, eq. 30): V-cavity facets
whose slope angles are normally distributed with standard deviation ``sigma``::

    f_ON(wi, wo) = rho/pi · [A + B · max(0, cos(phi_i - phi_o)) · sin(alpha) · tan(beta)]
    A = 1 - 0.5 s² / (s² + 0.33),   B = 0.45 s² / (s² + 0.09),   s = sigma in radians
    alpha = max(theta_i, theta_o),  beta = min(theta_i, theta_o)

times a shadow-hiding opposition surge in the phase angle ``g`` between ``wi`` and ``wo``
(B. Hapke, "Theory of Reflectance and Emittance Spectroscopy", 2nd ed., 2012, eq. 9.22)::

    f(wi, wo) = f_ON(wi, wo) · (1 + B_SH(g)),    B_SH(g) = B0 / (1 + tan(g/2) / h)

with amplitude ``B0`` and ``h = tan(w/2)`` for the surge's half width at half maximum ``w``.
``sin(alpha) tan(beta) max(0, cos(phi_i - phi_o))`` equals
``max(0, wi_x wo_x + wi_y wo_y) / max(cos theta_i, cos theta_o)`` in the local frame, which is
how it is evaluated (no division by sin theta).

Seen by a monostatic LiDAR (``wo = wi``, ``g = 0``) the effective reflectance is::

    rho_eff(theta) = pi f(wi, wi) = rho · (A + B sin² theta / cos theta) · (1 + B0)

so the received ``rho_eff · cos theta`` tends to ``rho · B · (1 + B0)`` at grazing incidence
instead of Lambert's ``rho · cos theta → 0``: rough ground keeps returning at shallow angles.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["coefficients", "half_width_h", "oren_nayar_monostatic", "brdf"]


def coefficients(sigma_deg: float) -> tuple[float, float]:
    """Oren–Nayar ``(A, B)`` for the facet slope standard deviation ``sigma_deg`` (degrees)."""
    s2 = math.radians(sigma_deg) ** 2
    return 1.0 - 0.5 * s2 / (s2 + 0.33), 0.45 * s2 / (s2 + 0.09)


def half_width_h(width_deg: float) -> float:
    """Hapke's ``h = tan(w/2)`` for the surge's half width at half maximum ``w`` (degrees)."""
    return math.tan(math.radians(width_deg) / 2.0)


def brdf(wi, wo, rho, sigma_deg: float, amplitude: float = 0.0, width_deg: float = 5.0):
    """``f(wi, wo)`` in 1/sr for local-frame unit vectors (normal +z), (..., 3) arrays.

    Zero where either direction is below the surface.
    """
    wi, wo = np.asarray(wi, dtype=np.float64), np.asarray(wo, dtype=np.float64)
    a, b = coefficients(sigma_deg)
    ci, co = wi[..., 2], wo[..., 2]
    azimuthal = np.maximum(0.0, wi[..., 0] * wo[..., 0] + wi[..., 1] * wo[..., 1])
    on = np.asarray(rho) / math.pi * (a + b * azimuthal / np.maximum(np.maximum(ci, co), 1e-12))
    tan_half = np.linalg.norm(wi - wo, axis=-1) / np.maximum(
        np.linalg.norm(wi + wo, axis=-1), 1e-12
    )
    surge = amplitude / (1.0 + tan_half / half_width_h(width_deg))
    return np.where((ci > 0) & (co > 0), on * (1.0 + surge), 0.0)


def oren_nayar_monostatic(rho, cos_theta, sigma_deg: float, amplitude: float = 0.0):
    """``rho_eff = pi f(wi, wi) = rho (A + B sin²θ / cos θ)(1 + B0)`` (unitless)."""
    a, b = coefficients(sigma_deg)
    c = np.asarray(cos_theta, dtype=np.float64)
    return np.asarray(rho) * (a + b * (1.0 - c * c) / c) * (1.0 + amplitude)
