"""Sweeps through panel scenes: incidence angle, range, detection range, extinction."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
from scipy.optimize import brentq

from ..errors import NidarError
from .panels import REFERENCE_DISTANCE_M, scan_panels

__all__ = [
    "IncidenceSweep",
    "RangeSweep",
    "incidence_sweep",
    "range_sweep",
    "detection_range",
    "max_detection_range",
    "extinction_from_visibility",
]


class IncidenceSweep(NamedTuple):
    """Result of :func:`incidence_sweep`. Arrays are (N,)."""

    angles_deg: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray


class RangeSweep(NamedTuple):
    """Result of :func:`range_sweep`. Arrays are (N,)."""

    distances_m: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    range_m: np.ndarray
    valid: np.ndarray


def incidence_sweep(
    material: str,
    angles_deg: Sequence[float],
    wavelength_nm: float = 905.0,
    *,
    distance_m: float = 10.0,
    intensity_mode: str = "compensated",
    variant: str | None = None,
    **kwargs,
) -> IncidenceSweep:
    """Intensity of one material against incidence angle, through the LiDAR.

    Every angle is one panel of the same scene at ``distance_m``; one scan reads them all.

    Args:
        material: library material name.
        angles_deg: (N,) incidence angles, degrees, in [0, 90).
        wavelength_nm: laser wavelength, nm.
        distance_m: panel distance, m.
        intensity_mode: ``compensated`` (default: I = g·ρ(θ)·cosθ) or ``raw`` (÷ d²).
        variant: Mitsuba variant.
        **kwargs: further keyword arguments of :func:`panel_scene_xml` (``gain``,
            ``overrides``, ``panel_size_m``, ...).

    Returns:
        (angles_deg, intensity, reflectance ρ(θ), cos_incidence), each (N,).
    """
    s = scan_panels(
        material,
        distance_m=distance_m,
        incidence_deg=np.asarray(angles_deg, dtype=np.float64),
        wavelength_nm=wavelength_nm,
        intensity_mode=intensity_mode,
        variant=variant,
        **kwargs,
    )
    return IncidenceSweep(s.layout.incidences_deg, s.intensity, s.reflectance, s.cos_incidence)


def range_sweep(
    material: str,
    distances_m: Sequence[float],
    alpha_per_m: float = 0.0,
    wavelength_nm: float = 905.0,
    *,
    incidence_deg: float = 0.0,
    variant: str | None = None,
    **kwargs,
) -> RangeSweep:
    """Raw intensity of one material against distance, through the LiDAR.

    Args:
        material: library material name.
        distances_m: (N,) panel distances, m.
        alpha_per_m: atmospheric extinction α, 1/m.
        wavelength_nm: laser wavelength, nm.
        incidence_deg: incidence angle on every panel, degrees.
        variant: Mitsuba variant.
        **kwargs: further keyword arguments of :func:`panel_scene_xml` (``gain``,
            ``detection_threshold``, ...).

    Returns:
        (distances_m, intensity in 1/m², reflectance, range_m, valid), each (N,).
    """
    s = scan_panels(
        material,
        distance_m=np.asarray(distances_m, dtype=np.float64),
        incidence_deg=incidence_deg,
        alpha_per_m=alpha_per_m,
        wavelength_nm=wavelength_nm,
        intensity_mode="raw",
        variant=variant,
        **kwargs,
    )
    return RangeSweep(s.layout.distances_m, s.intensity, s.reflectance, s.range_m, s.valid)


def detection_range(
    rho: float,
    threshold: float,
    *,
    gain: float = 1.0,
    alpha_per_m: float = 0.0,
    cos_incidence: float = 1.0,
    d_max_m: float = 1.0e6,
    rtol: float = 1.0e-12,
) -> float:
    """Largest range at which a return is still detected: ``g·ρ·cosθ·exp(-2αd)/d² = threshold``.

    The left side is the return model's ``raw`` intensity
    (:func:`nidar_mi.lidar.return_model.expected_intensity`, no glass); it falls strictly with
    ``d``, so the root is unique; it is found by :func:`scipy.optimize.brentq` on ``log`` of
    both sides. With ``α = 0`` it is ``sqrt(g·ρ·cosθ / threshold)``.

    Args:
        rho: monostatic reflectance ρ (π × BSDF) at the laser wavelength, > 0.
        threshold: detection threshold on ``g·ρ·a`` (raw units, 1/m²), > 0.
        gain: LiDAR gain g.
        alpha_per_m: atmospheric extinction α, 1/m, >= 0.
        cos_incidence: cosine of the incidence angle, in (0, 1].
        d_max_m: upper end of the search, m.
        rtol: relative tolerance on the range.

    Returns:
        The range in m (``d_max_m`` if the return is still above threshold there).
    """
    if not (rho > 0 and threshold > 0 and gain > 0 and 0 < cos_incidence <= 1):
        raise NidarError("detection_range needs rho, threshold, gain > 0 and cos in (0, 1]")
    if alpha_per_m < 0:
        raise NidarError(f"alpha_per_m must be >= 0, got {alpha_per_m}")
    log_k = math.log(gain * rho * cos_incidence / threshold)

    def excess(d: float) -> float:  # log(signal / threshold), strictly decreasing in d
        return log_k - 2.0 * alpha_per_m * d - 2.0 * math.log(d)

    if excess(d_max_m) >= 0.0:
        return float(d_max_m)
    d_min = 1.0e-9
    if excess(d_min) < 0.0:
        return d_min
    return brentq(excess, d_min, float(d_max_m), xtol=1e-300, rtol=max(rtol, 1e-15))


def max_detection_range(
    material: str,
    threshold: float,
    *,
    wavelength_nm: float = 905.0,
    alpha_per_m: float = 0.0,
    gain: float = 1.0,
    incidence_deg: float = 0.0,
    variant: str | None = None,
    overrides: Mapping[str, float] | None = None,
) -> float:
    """Maximum detection range of a library material, with ρ·cosθ measured through the LiDAR.

    One ``compensated`` scan of a panel at :data:`REFERENCE_DISTANCE_M`, with gain 1 and
    without extinction, measures ``ρ(θ)·cosθ``; :func:`detection_range` then solves the return
    model ``g·ρ(θ)·cosθ·exp(-2αd)/d² = threshold`` for the range.

    Args:
        material: library material name.
        threshold: detection threshold (raw units, 1/m²).
        wavelength_nm: laser wavelength, nm.
        alpha_per_m: atmospheric extinction α, 1/m.
        gain: LiDAR gain g.
        incidence_deg: incidence angle, degrees.
        variant: Mitsuba variant.
        overrides: material overrides.

    Returns:
        Range in m; 0 if the material returns nothing at this wavelength and angle.
    """
    s = scan_panels(
        material,
        distance_m=REFERENCE_DISTANCE_M,
        incidence_deg=incidence_deg,
        wavelength_nm=wavelength_nm,
        intensity_mode="compensated",
        overrides=overrides,
        variant=variant,
    )
    rho_cos = float(s.intensity[0])
    if not (s.valid[0] and rho_cos > 0.0):
        return 0.0
    return detection_range(rho_cos, threshold, gain=gain, alpha_per_m=alpha_per_m)


def extinction_from_visibility(visibility_km: float, wavelength_nm: float) -> float:
    """Atmospheric extinction α (1/m) from the meteorological visibility (Kim model).

    ``α = 3.91 / V · (λ / 550 nm)^(-q)`` (1/km), with ``q`` = 1.6 (V > 50 km), 1.3
    (6 < V <= 50), 0.16 V + 0.34 (1 < V <= 6), V − 0.5 (0.5 < V <= 1), 0 (V <= 0.5):
    I. I. Kim, B. McArthur, E. Korevaar, "Comparison of laser beam propagation at 785 nm and
    1550 nm in fog and haze for optical wireless communications", Proc. SPIE 4214 (2001).
    The 3.91 is Koschmieder's ``-ln(0.02)`` for a 2 % contrast threshold.

    Args:
        visibility_km: meteorological visibility V, km, > 0.
        wavelength_nm: wavelength λ, nm, > 0.

    Returns:
        α in 1/m (the one-way extinction coefficient of the return model).
    """
    v = float(visibility_km)
    if not (v > 0 and wavelength_nm > 0):
        raise NidarError("visibility_km and wavelength_nm must be positive")
    if v > 50.0:
        q = 1.6
    elif v > 6.0:
        q = 1.3
    elif v > 1.0:
        q = 0.16 * v + 0.34
    elif v > 0.5:
        q = v - 0.5
    else:
        q = 0.0
    return 3.91 / v * (wavelength_nm / 550.0) ** (-q) / 1000.0
