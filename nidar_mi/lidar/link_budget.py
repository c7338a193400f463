"""The link budget of the presets' detection numbers: closed forms that reproduce them.

The return model (:mod:`.return_model`, ``raw`` mode, gain 1) reports a beam when the
receiver's output ``E + σ_n·n`` reaches the threshold ``T``, ``E = ρ_eff · cos θ / d²`` and ``n``
standard normal: a return is detected with probability ``P_D = Φ((E - T) / σ_n)``. A range
figure "detected to d" is read as ``P_D >= 0.5`` at d (half the shots or more; P_D is specified
"between 50 % and 99 %" in practice, Allegro MicroSystems, *Relationship Between False-Alarm
Rate and Probability of False Alarm*, 2021). Three published figures fix the HDL-64E's
detection:

* **Threshold.** Velodyne's HDL-64E S2 datasheet gives the range as 50 m for pavement (~10 %
  reflectivity) and 120 m for cars and foliage (~80 %). A 10 % Lambertian target at normal
  incidence returns ``0.10 / d²``; ``P_D = 0.5`` exactly where ``E = T``, so detecting it to
  50 m sets ``T = 0.10 / 50² = 4e-5`` (:func:`threshold_for`). An 80 % target then reaches
  ``sqrt(0.8 / 4e-5) = 141 m`` (> 120 m, where ``range_max`` stops it); at 120 m its
  ``P_D = Φ(k (0.8 / 120² / T - 1)) = 0.93``.
* **Receiver noise.** A threshold ``k σ_n`` above white Gaussian noise crosses on noise alone
  with probability ``P_FA = Q(k)`` per ranging event (Kay, *Fundamentals of Statistical Signal
  Processing, Vol. II: Detection Theory*, 1998, ch. 3). Velodyne publishes no false-alarm
  figure; Ouster specifies the OS1's range at a false positive rate of 1/10,000 (OS1 datasheet,
  "Optical performance"), so ``k = Q⁻¹(1e-4) = 3.72`` and ``σ_n = T / k = 1.08e-5``
  (:func:`noise_for`). A return then fades over ``E = T (1 ± 1.28 / k)`` from ``P_D = 0.9`` to
  ``0.1``: for flat asphalt beyond 40 m, where ``E ∝ 1/d²``, from ~43 m to ~62 m.
* **Road backscatter.** "50 m for pavement" is also how far a real HDL-64E S2 sees the road it
  drives on: flat asphalt at 87-88° incidence. A Lambertian road returns
  ``ρ cos θ / d² = ρ h / d³`` and vanishes by 19 m; a rough surface (``roughdiffuse``:
  Oren–Nayar facets with slope deviation ``σ`` and a Hapke opposition surge ``B0``) keeps
  ``ρ (A cos θ + B sin² θ)(1 + B0)``. With ``B0 = 1`` (Hapke's shadow-hiding amplitude of a dark
  surface whose light is scattered at the particle surfaces; Hapke, *Theory of Reflectance and
  Emittance Spectroscopy*, 2012, ch. 9), :func:`sigma_for_reach` gives the ``σ`` at which
  ``asphalt_old`` (ρ = 0.129 at 905 nm) seen from the KITTI rig's 1.73 m (Geiger et al., IJRR
  2013) returns ``E = T`` at 50 m (``P_D = 0.5``): 35.1°, the catalog's value for road asphalt
  and concrete. :func:`ground_detection_probability` is then ``P_D`` of the road at any range.

Every return and probability is the return model's own (:mod:`.return_model`:
:func:`~.return_model.expected_intensity`, :func:`~.return_model.detection_probability`) and the
road's reflectance the ``roughdiffuse`` closed form's (:mod:`nidar_mi.materials.oren_nayar`);
this module only inverts them for the datasheet's figures (the root finding by
:func:`scipy.optimize.brentq`). Nothing here is fitted to KITTI data: the real frames only check
the result (:mod:`nidar_mi.studies.ground_coverage`, ``docs/SENSORS.md``).
"""

from __future__ import annotations

import math
from statistics import NormalDist

from scipy.optimize import brentq

from ..materials.oren_nayar import oren_nayar_monostatic
from .return_model import detection_probability, expected_intensity

__all__ = [
    "HDL64E_DATASHEET",
    "KITTI_SENSOR_HEIGHT_M",
    "FALSE_ALARM_PROBABILITY",
    "threshold_to_noise",
    "noise_for",
    "ground_detection_probability",
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
#: Probability of a false alarm per ranging event: the false positive rate at which Ouster's OS1
#: datasheet specifies its range (1/10,000); Velodyne's datasheets give none.
FALSE_ALARM_PROBABILITY = 1e-4
#: Largest range (m) searched for the end of the road.
_FAR_M = 1e4


def threshold_to_noise(false_alarm: float = FALSE_ALARM_PROBABILITY) -> float:
    """``k = Q⁻¹(P_FA)``: how many noise deviations above the noise the threshold sits for a
    false-alarm probability ``P_FA`` in (0, 0.5) per ranging event (3.719 at 1e-4)."""
    if not 0.0 < false_alarm < 0.5:
        raise ValueError(f"false-alarm probability must be in (0, 0.5) (got {false_alarm:g})")
    return NormalDist().inv_cdf(1.0 - false_alarm)


def noise_for(threshold: float, false_alarm: float = FALSE_ALARM_PROBABILITY) -> float:
    """The receiver noise ``σ_n = T / Q⁻¹(P_FA)`` under a threshold ``T`` (the unit of ``T``)."""
    return threshold / threshold_to_noise(false_alarm)


def threshold_for(reflectivity: float, range_m: float, gain: float = 1.0) -> float:
    """The ``raw``-mode threshold at which a Lambertian target of ``reflectivity`` at normal
    incidence is detected exactly to ``range_m``: its return ``g ρ / d²`` (1/m²)."""
    return expected_intensity(gain, reflectivity, range_m, 1.0, 0.0, "raw")


def target_reach(reflectivity: float, threshold: float, gain: float = 1.0) -> float:
    """How far (m) a Lambertian target at normal incidence is detected: ``sqrt(g ρ / T)``, where
    its return ``g ρ / d²`` equals ``T`` and ``P_D = 0.5`` whatever the receiver noise."""
    return math.sqrt(gain * reflectivity / threshold)


def ground_return(
    rho: float, sigma_deg: float, amplitude: float, height_m: float, range_m: float
) -> float:
    """The return ``ρ_eff cos θ / d²`` of flat ``roughdiffuse`` ground seen at range ``d`` from
    ``h`` (1/m², gain 1): ``ρ_eff`` the monostatic reflectance ``ρ (A + B sin²θ / cos θ)(1 + B0)``
    at ``cos θ = h / d``. ``range_m`` may be an array (the result has its shape)."""
    c = height_m / range_m
    rho_eff = oren_nayar_monostatic(rho, c, sigma_deg, amplitude)
    return expected_intensity(1.0, rho_eff, range_m, c, 0.0, "raw")


def ground_detection_probability(
    rho: float,
    sigma_deg: float,
    amplitude: float,
    height_m: float,
    range_m: float,
    threshold: float,
    noise: float,
) -> float:
    """``P_D`` of flat ``roughdiffuse`` ground at range ``d`` seen from ``h``
    (:func:`ground_return` through :func:`nidar_mi.lidar.return_model.detection_probability`)."""
    e = ground_return(rho, sigma_deg, amplitude, height_m, range_m)
    return float(detection_probability(e, threshold, noise))


def ground_reach(
    rho: float, sigma_deg: float, amplitude: float, height_m: float, threshold: float
) -> float:
    """The range (m) beyond which flat ground no longer reaches ``threshold`` (the return falls
    monotonically with range): where ``P_D`` falls to 0.5 (with receiver noise), or the end of
    the road (without); ``h`` when even the ground below is too dark, 1e4 m at most."""

    def excess(d: float) -> float:
        return ground_return(rho, sigma_deg, amplitude, height_m, d) - threshold

    near = height_m * (1 + 1e-9)
    if excess(near) < 0:
        return height_m
    if excess(_FAR_M) >= 0:
        return _FAR_M
    return brentq(excess, near, _FAR_M, xtol=1e-9, rtol=1e-12)


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
            f"no roughness reaches {reach_m:g} m "
            f"(at most {ground_reach(rho, hi, amplitude, height_m, threshold):.1f} m)"
        )
    if excess(lo) >= 0:
        return 0.0
    return brentq(excess, lo, hi, xtol=1e-12, rtol=1e-12)
