"""The von Mises–Fisher lobe of the ``retroreflector`` BSDF, in closed form (no Mitsuba needed).

``V_kappa(c) = kappa / (2 pi (1 - exp(-2 kappa))) * exp(kappa (c - 1))`` is a density over the
sphere (1/sr) of the cosine ``c`` between a direction and the lobe's axis; the model around it
is described in :mod:`nidar_mi.plugins.retroreflector`.
"""

from __future__ import annotations

import math

__all__ = ["lobe_concentration", "normalisation", "monostatic_gain"]


def lobe_concentration(lobe_width_deg: float) -> float:
    """vMF concentration ``kappa`` whose half width at half maximum is ``lobe_width_deg``.

    Args:
        lobe_width_deg: half width at half maximum of the lobe, degrees, in (0, 90].

    Returns:
        ``kappa = ln 2 / (1 - cos(lobe_width))`` (dimensionless).

    Raises:
        ValueError: ``lobe_width_deg`` outside (0, 90].
    """
    if not 0.0 < lobe_width_deg <= 90.0:
        raise ValueError(f"lobe_width must be in (0, 90] degrees, got {lobe_width_deg}")
    one_minus_cos = 2.0 * math.sin(math.radians(lobe_width_deg) / 2.0) ** 2  # stable 1 - cos
    return math.log(2.0) / one_minus_cos


def normalisation(kappa: float) -> float:
    """``kappa / (2 pi (1 - exp(-2 kappa)))``: the lobe's peak density ``V_kappa(1)``, 1/sr."""
    return kappa / (2.0 * math.pi * -math.expm1(-2.0 * kappa))


def monostatic_gain(lobe_width_deg: float, diffuse_fraction: float = 0.0) -> float:
    """``rho_eff / rho`` seen by a monostatic observer (``wo = wi``).

    ``pi f(wi, wi) / rho = (1 - d) * kappa / (2 (1 - exp(-2 kappa))) + d``: about 570 for
    the default 2 degree lobe and ``d = 0``, against 1 for a Lambertian surface.
    """
    kappa = lobe_concentration(lobe_width_deg)
    return (1.0 - diffuse_fraction) * math.pi * normalisation(kappa) + diffuse_fraction
