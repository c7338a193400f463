"""Fog, rain and snow as scattering media: extinction α(λ), backscatter β(λ), single-scattering
albedo and asymmetry, from their particle size distributions (:mod:`.particles`) through Mie
theory (:mod:`.mie`).

For a distribution ``n(D)`` of particles of cross-section ``σ(D) = π D²/4``:

    α = ∫ Q_ext σ n dD        (extinction, 1/m)
    β = ∫ Q_back σ n dD / 4π  (backscatter, 1/(m sr): the volume's dσ/dΩ at 180°)
    ω = ∫ Q_sca σ n dD / α    (single-scattering albedo)
    g = ∫ g Q_sca σ n dD / ∫ Q_sca σ n dD

integrated on a log-spaced grid of diameters (:data:`GRID_PER_DECADE` nodes per decade, the
efficiencies cached per material and wavelength).

* **Fog**: droplets are water spheres (Mie). The number density is set so that the fog has the
  meteorological optical range asked for: ``α(550 nm) = ln 20 / MOR`` (WMO, 5 % contrast;
  :func:`fog_number_density`). Its α at the LiDAR's wavelength then follows from the droplet
  sizes: for the default advection fog 1.02 × (905 nm) and 1.05 × (1550 nm) the visible one.
* **Rain**: water spheres, geometric optics beyond the series' range (Q_ext → 2).
* **Snow**: flakes in the geometric-optics limit (as LiDAR snowfall simulation does, Hahner et
  al., CVPR 2022): ``Q_ext = 2`` (with the edge term) on the flake's cross-section; the light
  that enters a flake is absorbed along its mean ice thickness ``t = (ρ_w/ρ_ice)(2/3) D_m³/D²``
  (the flake's ice spread over its disk); it backscatters as a Lambertian disk of the
  reflectance of snow, ``Q_back = 4 ρ_snow``, ``ρ_snow = exp(-3.6 sqrt(γ d))`` (the asymptotic
  albedo of a layer of ice grains, Kokhanovsky & Zege, Appl. Opt. 43, 1589, 2004, with
  ``γ = 4πk/λ`` and grains ``d`` = :data:`SNOW_GRAIN` m): 0.88 at 905 nm, 0.05 at 1550 nm where
  ice absorbs (snow is dark at 1550 nm); ``g`` that of large ice spheres
  (:func:`~nidar_mi.weather.mie.seam_averages`).

:func:`medium_optics` combines fog with one precipitation: their α and β add.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import NamedTuple

import numpy as np

from .conditions import Weather
from .mie import Efficiencies, efficiencies, mean_backscatter, seam_averages
from .particles import (
    Exponential,
    SizeDistribution,
    fog_distribution,
    gunn_marshall,
    marshall_palmer,
)
from .refractive_index import absorption_coefficient, ice_index, water_index

__all__ = [
    "GRID_PER_DECADE",
    "VISIBLE_NM",
    "SNOW_GRAIN",
    "ICE_DENSITY",
    "SCATTERERS",
    "BulkOptics",
    "MediumOptics",
    "bulk_optics",
    "sphere_efficiencies",
    "fog_number_density",
    "snow_reflectance",
    "particle_reflectance",
    "medium_optics",
    "precipitation_distribution",
]

#: Diameter-grid nodes per decade of the integrals.
GRID_PER_DECADE = 100
#: The wavelength of the meteorological optical range, nm.
VISIBLE_NM = 550.0
#: Ice grain size of a snowflake's reflectance (:func:`snow_reflectance`), m.
SNOW_GRAIN = 2e-4
#: Density of ice, kg/m³.
ICE_DENSITY = 917.0
#: What a return came from, by code (the points' ``scatterer`` column).
SCATTERERS = ("surface", "fog", "drop", "flake")
_GRID = (1e-8, 2e-2)  # diameters of the grid, m


class BulkOptics(NamedTuple):
    """Bulk optical properties of a population of particles at one wavelength.

    Attributes:
        alpha: extinction coefficient, 1/m.
        scattering: scattering coefficient, 1/m.
        backscatter: backscatter coefficient β, 1/(m sr).
        g: asymmetry parameter.
    """

    alpha: float
    scattering: float
    backscatter: float
    g: float


def _index(material: str, wavelength_nm: float) -> complex:
    return complex(water_index(wavelength_nm) if material == "water" else ice_index(wavelength_nm))


def _diameters() -> np.ndarray:
    """The integrals' log-spaced diameter grid, m."""
    lo, hi = _GRID
    return np.geomspace(lo, hi, int(round(GRID_PER_DECADE * math.log10(hi / lo))) + 1)


@lru_cache(maxsize=32)
def _sphere_grid(material: str, wavelength_nm: float) -> tuple[np.ndarray, Efficiencies]:
    """The diameter grid and the efficiencies of spheres of ``material`` on it."""
    d = _diameters()
    m = _index(material, wavelength_nm)
    return d, efficiencies(m, np.pi * d / (wavelength_nm * 1e-9), wavelength_nm)


def sphere_efficiencies(material: str, wavelength_nm: float) -> tuple[np.ndarray, Efficiencies]:
    """The integrals' diameter grid (m) and the efficiencies of ``water`` or ``ice`` spheres on
    it at ``wavelength_nm`` (cached)."""
    return _sphere_grid(material, float(wavelength_nm))


def snow_reflectance(wavelength_nm: float) -> float:
    """Reflectance of snow made of ice grains :data:`SNOW_GRAIN` (module docstring)."""
    gamma = float(absorption_coefficient(ice_index(wavelength_nm), wavelength_nm))
    return float(math.exp(-3.6 * math.sqrt(gamma * SNOW_GRAIN)))


def _flake_efficiencies(dist: Exponential, d: np.ndarray, wavelength_nm: float) -> Efficiencies:
    """Geometric-optics efficiencies of snowflakes of diameters ``d`` (module docstring)."""
    m = ice_index(wavelength_nm)
    x = np.pi * d / (wavelength_nm * 1e-9)
    qext = 2.0 + 1.9924 * x ** (-2.0 / 3.0)
    melted = d / dist.size_ratio
    thickness = (1000.0 / ICE_DENSITY) * (2.0 / 3.0) * melted**3 / d**2
    qabs = 1.0 - np.exp(-float(absorption_coefficient(m, wavelength_nm)) * thickness)
    g = seam_averages(complex(m))[1]
    qback = np.full_like(d, 4.0 * snow_reflectance(wavelength_nm))
    return Efficiencies(qext, qext - qabs, qback, np.full_like(d, g))


def _grid(dist: SizeDistribution, wavelength_nm: float) -> tuple[np.ndarray, Efficiencies]:
    if dist.material == "ice":
        d = _diameters()
        return d, _flake_efficiencies(dist, d, wavelength_nm)
    return _sphere_grid(dist.material, float(wavelength_nm))


def bulk_optics(dist: SizeDistribution, wavelength_nm: float) -> BulkOptics:
    """α, scattering, β and g of a size distribution at a wavelength (module docstring)."""
    d, q = _grid(dist, wavelength_nm)
    weight = dist.density(d) * (np.pi * d * d / 4.0) * d  # n σ dD per d(ln D)
    lnd = np.log(d)

    def integral(values: np.ndarray) -> float:
        return float(np.trapezoid(values * weight, lnd))

    sca = integral(q.qsca)
    return BulkOptics(
        alpha=integral(q.qext),
        scattering=sca,
        backscatter=integral(q.qback) / (4.0 * np.pi),
        g=integral(q.g * q.qsca) / sca if sca > 0 else 0.0,
    )


@lru_cache(maxsize=64)
def _unit_fog(fog_type: str, wavelength_nm: float) -> BulkOptics:
    return bulk_optics(fog_distribution(fog_type, 1.0), wavelength_nm)


def fog_number_density(fog_type: str, mor_m: float) -> float:
    """Droplets per m³ of a fog of meteorological optical range ``mor_m``: α(550 nm) =
    ln 20 / MOR."""
    return math.log(20.0) / mor_m / _unit_fog(fog_type, VISIBLE_NM).alpha


def precipitation_distribution(weather: Weather) -> Exponential | None:
    """The drop or flake distribution of the weather's precipitation, or None."""
    if weather.rain:
        return marshall_palmer(weather.rain)
    if weather.snow:
        return gunn_marshall(weather.snow)
    return None


def particle_reflectance(dist: SizeDistribution, d, wavelength_nm: float) -> np.ndarray:
    """The reflectance ``ρ = Q_back / 4`` of single particles of diameters ``d`` (m): what a
    LiDAR sees of a drop or flake in its beam, as a Lambertian disk of the particle's
    cross-section facing it; a drop's ``Q_back`` without the resonances of one exact sphere
    (:func:`~nidar_mi.weather.mie.mean_backscatter`).

    Returns:
        float64, the shape of ``d``.
    """
    d = np.asarray(d, dtype=np.float64)
    if dist.material == "ice":
        return np.full(d.shape, snow_reflectance(wavelength_nm))
    x = np.pi * d / (wavelength_nm * 1e-9)
    return mean_backscatter(complex(water_index(wavelength_nm)), x, wavelength_nm) / 4.0


@lru_cache(maxsize=64)
def _precipitation_optics(kind: str, rate: float, wavelength_nm: float) -> BulkOptics:
    dist = marshall_palmer(rate) if kind == "rain" else gunn_marshall(rate)
    return bulk_optics(dist, wavelength_nm)


@dataclass(frozen=True)
class MediumOptics:
    """The medium at one wavelength (module docstring).

    Attributes:
        wavelength: nm.
        alpha: extinction, 1/m (fog and precipitation).
        backscatter: β, 1/(m sr).
        albedo: single-scattering albedo.
        g: asymmetry parameter.
        components: ``fog``, ``rain`` or ``snow`` -> its :class:`BulkOptics`.
    """

    wavelength: float
    alpha: float
    backscatter: float
    albedo: float
    g: float
    components: dict = field(default_factory=dict)

    @property
    def volume_scatterer(self) -> int:
        """Code (:data:`SCATTERERS`) of the component with the most backscatter: what a
        return from the volume itself came from."""
        if not self.components:
            return 0
        kind = max(self.components, key=lambda k: self.components[k].backscatter)
        return {"fog": 1, "rain": 2, "snow": 3}[kind]


def medium_optics(weather: Weather, wavelength_nm: float) -> MediumOptics:
    """The optics of ``weather`` at ``wavelength_nm`` (fog and precipitation add)."""
    comps: dict[str, BulkOptics] = {}
    if weather.fog:
        unit = _unit_fog(weather.fog_type, float(wavelength_nm))
        n = fog_number_density(weather.fog_type, weather.fog)
        comps["fog"] = BulkOptics(unit.alpha * n, unit.scattering * n, unit.backscatter * n, unit.g)
    kind = weather.precipitation
    if kind is not None:
        rate = weather.rain if kind == "rain" else weather.snow
        comps[kind] = _precipitation_optics(kind, float(rate), float(wavelength_nm))
    alpha = sum(c.alpha for c in comps.values())
    sca = sum(c.scattering for c in comps.values())
    return MediumOptics(
        wavelength=float(wavelength_nm),
        alpha=alpha,
        backscatter=sum(c.backscatter for c in comps.values()),
        albedo=sca / alpha if alpha > 0 else 1.0,
        g=sum(c.g * c.scattering for c in comps.values()) / sca if sca > 0 else 0.0,
        components=comps,
    )
