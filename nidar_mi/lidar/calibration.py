"""Where the presets' detection numbers come from, as closed forms that reproduce them.

The return model (:mod:`.return_model`, ``raw`` mode, gain 1) reports a beam when
``ρ_eff · cos θ / d² >= threshold``. Two published figures fix the HDL-64E's detection:

* **Threshold.** Velodyne's HDL-64E S2 datasheet gives the range as 50 m for pavement (~10 %
  reflectivity) and 120 m for cars and foliage (~80 %). A 10 % Lambertian target at normal
  incidence returns ``0.10 / d²``; detecting it to 50 m sets ``threshold = 0.10 / 50² = 4e-5``
  (:func:`threshold_for`). An 80 % target then reaches ``sqrt(0.8 / 4e-5) = 141 m`` (> 120 m,
  where ``range_max`` stops it).
* **Road backscatter.** "50 m for pavement" is also how far a real HDL-64E S2 sees the road it
  drives on: flat asphalt at 87-88° incidence (KITTI frames give P(detect) 0.8-0.97 at 50 m). A
  Lambertian road returns ``ρ cos θ / d² = ρ h / d³`` and vanishes by 19 m; a rough surface
  (``roughdiffuse``: Oren–Nayar facets with slope deviation ``σ`` and a Hapke opposition surge
  ``B0``) keeps ``ρ (A cos θ + B sin² θ)(1 + B0)``. With ``B0 = 1`` (Hapke's shadow-hiding
  amplitude of a dark surface whose light is scattered at the particle surfaces; Hapke,
  *Theory of Reflectance and Emittance Spectroscopy*, 2012, ch. 9), :func:`sigma_for_reach`
  gives the ``σ`` at which ``asphalt_old`` (ρ = 0.129 at 905 nm) seen from the KITTI rig's
  1.73 m (Geiger et al., IJRR 2013) is detected to 50 m: 35.4°, the catalog's value for road
  asphalt and concrete.

Nothing here is fitted to KITTI data: the real frames only check the result
(:mod:`nidar_mi.studies.ground_coverage`).
"""

from __future__ import annotations

import math

from ..plugins.oren_nayar import coefficients

__all__ = [
    "HDL64E_DATASHEET",
    "KITTI_SENSOR_HEIGHT_M",
    "ground_return",
    "ground_reach",
    "sigma_for_reach",
    "threshold_for",
    "target_reach",
]

#: Velodyne HDL-64E S2 datasheet: (reflectivity, range in m) pairs.
HDL64E_DATASHEET = {"pavement": (0.10, 50.0), "cars_and_foliage": (0.80, 120.0)}
#: Height of the Velodyne above the road on the KITTI car (Geiger et al., IJRR 2013), m.
KITTI_SENSOR_HEIGHT_M = 1.73


def threshold_for(reflectivity: float, range_m: float, gain: float = 1.0) -> float:
    """The ``raw``-mode threshold at which a Lambertian target of ``reflectivity`` at normal
    incidence is detected exactly to ``range_m``: ``g ρ / d²`` (1/m²)."""
    return gain * reflectivity / range_m**2


def target_reach(reflectivity: float, threshold: float, gain: float = 1.0) -> float:
    """How far (m) a Lambertian target at normal incidence is detected: ``sqrt(g ρ / T)``."""
    return math.sqrt(gain * reflectivity / threshold)


def ground_return(
    rho: float, sigma_deg: float, amplitude: float, height_m: float, range_m: float
) -> float:
    """``ρ_eff cos θ / d²`` of flat ``roughdiffuse`` ground seen at range ``d`` from ``h``:
    ``ρ (A c + B (1 - c²))(1 + B0) / d²`` with ``c = cos θ = h / d`` (1/m², gain 1)."""
    a, b = coefficients(sigma_deg)
    c = height_m / range_m
    return rho * (a * c + b * (1.0 - c * c)) * (1.0 + amplitude) / range_m**2


def ground_reach(
    rho: float, sigma_deg: float, amplitude: float, height_m: float, threshold: float
) -> float:
    """The range (m) beyond which flat ground no longer reaches ``threshold`` (bisection; the
    return falls monotonically with range)."""
    lo, hi = height_m, 1e4
    if ground_return(rho, sigma_deg, amplitude, height_m, lo * (1 + 1e-9)) < threshold:
        return height_m
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if ground_return(rho, sigma_deg, amplitude, height_m, mid) >= threshold:
            lo = mid
        else:
            hi = mid
    return lo


def sigma_for_reach(
    rho: float, amplitude: float, height_m: float, reach_m: float, threshold: float
) -> float:
    """The facet slope deviation ``σ`` (degrees) at which flat ground is detected to ``reach_m``.

    Raises:
        ValueError: no ``σ`` in [0, 89] reaches that far.
    """

    def excess(sigma: float) -> float:
        return ground_return(rho, sigma, amplitude, height_m, reach_m) - threshold

    lo, hi = 0.0, 89.0
    if excess(hi) < 0:
        raise ValueError(
            f"no roughness reaches {reach_m:g} m (at most {ground_reach(rho, hi, amplitude, height_m, threshold):.1f} m)"
        )
    if excess(lo) >= 0:
        return 0.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if excess(mid) >= 0:
            hi = mid
        else:
            lo = mid
    return hi
