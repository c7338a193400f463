"""Particle size distributions of fog, rain and snow.

Every distribution is a number density per unit volume and unit diameter, ``n(D)`` in m⁻⁴
(particles per m³ of air per m of diameter), over the diameter ``D`` in m of the particle as
the light sees it (a snowflake's own diameter, not its melted one).

* **Fog** (:class:`GammaFog`): the modified gamma distribution of the droplet radius
  (Deirmendjian 1969), ``n(r) = N γ b^((α+1)/γ) r^α exp(-b r^γ) / Γ((α+1)/γ)`` with
  ``b = α / (γ r_c^γ)`` (``r_c`` the mode radius), as tabled for automotive LiDAR by
  Rasshofer et al. (Adv. Radio Sci. 9, 49, 2011) and used by LISA (Kilic et al. 2021):
  ``advection`` fog (the default) α = 3, γ = 1, r_c = 10 µm (Rasshofer's "strong advection fog",
  Shettle & Fenn's 1979 heavy advection fog, b = 0.3 µm⁻¹); ``radiation`` fog α = 6, γ = 1,
  r_c = 2 µm (Shettle & Fenn's moderate radiation fog, b = 3 µm⁻¹). Only the shape matters here:
  the number density ``N`` is set so that the fog has the meteorological optical range asked
  for (:mod:`.media`).
* **Rain** (:func:`marshall_palmer`): ``N(D) = N0 exp(-Λ D)`` with ``N0 = 8000 m⁻³ mm⁻¹`` and
  ``Λ = 4.1 R^-0.21 mm⁻¹`` for a rain rate ``R`` in mm/h (Marshall & Palmer, J. Meteor. 5, 165,
  1948), drops up to 6 mm (larger ones break up).
* **Snow** (:func:`gunn_marshall`, :func:`sekhon_srivastava`): exponential distributions of the
  *melted* diameter ``D_m`` for a melted-equivalent precipitation rate ``R`` in mm/h:
  Gunn & Marshall (J. Meteor. 15, 452, 1958) ``N0 = 3800 R^-0.87 m⁻³ mm⁻¹``,
  ``Λ = 2.55 R^-0.48 mm⁻¹``; Sekhon & Srivastava (J. Atmos. Sci. 27, 299, 1970)
  ``N0 = 2500 R^-0.94``, ``Λ = 2.29 R^-0.45``; melted diameters up to 5 mm. A flake of density
  ``ρ_s`` has the diameter ``D = D_m (ρ_w / ρ_s)^(1/3)``; ``ρ_s`` = :data:`SNOW_DENSITY` (dry
  aggregates weigh tens to a few hundred kg/m³; the extinction scales as ``ρ_s^(-2/3)``).

Terminal velocities are not needed: both precipitation distributions are parametrised by the
rate itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = [
    "FOG_TYPES",
    "SNOW_DENSITY",
    "WATER_DENSITY",
    "SizeDistribution",
    "GammaFog",
    "Exponential",
    "fog_distribution",
    "marshall_palmer",
    "gunn_marshall",
    "sekhon_srivastava",
    "SNOW_DISTRIBUTIONS",
]

#: Density of liquid water, kg/m³.
WATER_DENSITY = 1000.0
#: Density of a dry aggregate snowflake assumed here, kg/m³.
SNOW_DENSITY = 100.0


@dataclass(frozen=True)
class SizeDistribution:
    """A particle size distribution ``n(D)`` (m⁻⁴) over ``[d_min, d_max]`` (m).

    Attributes:
        name: what it is (for messages and tables).
        material: ``water`` or ``ice``.
        d_min, d_max: the diameters it spans, m.
    """

    name: str
    material: str
    d_min: float
    d_max: float

    def density(self, d: np.ndarray) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def number(self) -> float:
        """Total number density over ``[d_min, d_max]``, m⁻³ (log-spaced quadrature)."""
        d = np.geomspace(self.d_min, self.d_max, 4001)
        return float(np.trapezoid(self.density(d) * d, np.log(d)))


@dataclass(frozen=True)
class GammaFog(SizeDistribution):
    """Modified gamma distribution of the droplet radius (module docstring), ``number`` m⁻³.

    Attributes:
        alpha, gamma: the shape exponents α and γ.
        mode_radius: ``r_c``, m.
        total: the number density N, m⁻³.
    """

    alpha: float = 3.0
    gamma: float = 1.0
    mode_radius: float = 10e-6
    total: float = 1.0

    def density(self, d):
        r_um = np.asarray(d, dtype=np.float64) / 2.0 * 1e6
        a, g, rc = self.alpha, self.gamma, self.mode_radius * 1e6
        b = a / (g * rc**g)
        log_norm = math.log(g) + (a + 1.0) / g * math.log(b) - math.lgamma((a + 1.0) / g)
        with np.errstate(divide="ignore"):
            n_r = np.exp(log_norm + a * np.log(r_um) - b * r_um**g)  # per µm of radius
        inside = (d >= self.d_min) & (d <= self.d_max)
        # per µm of radius -> per m of diameter: x 1e6 / 2
        return np.where(inside, self.total * n_r * 0.5e6, 0.0)


@dataclass(frozen=True)
class Exponential(SizeDistribution):
    """``N0 exp(-Λ D_m)`` over the melted (water-equivalent) diameter ``D_m``.

    Attributes:
        n0: N0, m⁻⁴ (per m³ per m of melted diameter).
        slope: Λ, 1/m.
        particle_density: the particles' density, kg/m³ (water: drops; less: snowflakes).
    """

    n0: float = 8e6
    slope: float = 2000.0
    particle_density: float = WATER_DENSITY

    @property
    def size_ratio(self) -> float:
        """Particle diameter over melted diameter, ``(ρ_w / ρ_s)^(1/3)``."""
        return (WATER_DENSITY / self.particle_density) ** (1.0 / 3.0)

    def density(self, d):
        d = np.asarray(d, dtype=np.float64)
        k = self.size_ratio
        inside = (d >= self.d_min) & (d <= self.d_max)
        return np.where(inside, self.n0 * np.exp(-self.slope * d / k) / k, 0.0)


#: Fog types and their droplet distributions' shape (module docstring); N = 1 m⁻³.
FOG_TYPES = {
    "advection": GammaFog("advection fog", "water", 2e-7, 2e-4, 3.0, 1.0, 10e-6, 1.0),
    "radiation": GammaFog("radiation fog", "water", 4e-8, 4e-5, 6.0, 1.0, 2e-6, 1.0),
}


def fog_distribution(fog_type: str, total: float = 1.0) -> GammaFog:
    """The droplet distribution of a fog type with ``total`` droplets per m³."""
    from dataclasses import replace

    if fog_type not in FOG_TYPES:
        raise ValueError(f"unknown fog type '{fog_type}' (known: {', '.join(FOG_TYPES)})")
    return replace(FOG_TYPES[fog_type], total=float(total))


def marshall_palmer(rate_mm_h: float) -> Exponential:
    """Marshall–Palmer raindrops for a rain rate in mm/h (> 0)."""
    lam = 4.1 * rate_mm_h**-0.21 * 1e3  # 1/mm -> 1/m
    return Exponential("rain (Marshall-Palmer)", "water", 1e-5, 6e-3, 8000.0 * 1e3, lam)


def _snow(name: str, n0_mm: float, slope_mm: float) -> Exponential:
    ratio = (WATER_DENSITY / SNOW_DENSITY) ** (1.0 / 3.0)
    return Exponential(
        name, "ice", 1e-5 * ratio, 5e-3 * ratio, n0_mm * 1e3, slope_mm * 1e3, SNOW_DENSITY
    )


def gunn_marshall(rate_mm_h: float) -> Exponential:
    """Gunn–Marshall snowflakes for a melted-equivalent rate in mm/h (> 0)."""
    return _snow("snow (Gunn-Marshall)", 3800.0 * rate_mm_h**-0.87, 2.55 * rate_mm_h**-0.48)


def sekhon_srivastava(rate_mm_h: float) -> Exponential:
    """Sekhon–Srivastava snowflakes for a melted-equivalent rate in mm/h (> 0)."""
    return _snow("snow (Sekhon-Srivastava)", 2500.0 * rate_mm_h**-0.94, 2.29 * rate_mm_h**-0.45)


#: Snow distributions by name; ``gunn-marshall`` is the default.
SNOW_DISTRIBUTIONS = {"gunn-marshall": gunn_marshall, "sekhon-srivastava": sekhon_srivastava}
