"""The LiDAR return model, as pure functions over NumPy or Dr.Jit arrays.

A beam hitting a surface at path length ``d`` (m) with incidence cosine ``cos θ`` returns

    I = g · ρ(m, λ, θ) · T² · a(d, θ) + η

with ``ρ = π · f_r(ω, ω; λ)`` the hit BSDF evaluated monostatically at the laser wavelength (a
Lambertian surface gives its albedo), ``T²`` the two-way transmittance of the glass the beam
passed through (1 without glass), and

    a(d, θ) = cos θ · exp(-2 α d) / d²      (``raw``)
    a(d, θ) = cos θ · exp(-2 α d)           (``compensated``: range-normalised, as many sensors report)

``α`` is the atmospheric extinction coefficient (1/m); the factor 2 is the two-way path.

A return is reported (:func:`detect`) when the beam hit something, its expected intensity
``g·ρ·T²·a`` is finite, carries energy (> 0) and reaches the detection threshold, its range
lies in ``[range_min, range_max]``, and a uniform draw is not below the dropout probability.
``η`` is zero-mean Gaussian noise added after the detection test (:func:`add_noise`; the
range gets its own), the result clipped at 0. :func:`compensate` turns written intensities
back into the range-compensated ``g·ρ·T²·cos θ·exp(-2αd)`` (+ noise).
:func:`full_scale_intensity` is a sensor's fixed reference for integer or unit-range encodings
(LAS counts, KITTI's [0, 1]): the same for every frame of the sensor.

Every function takes NumPy arrays (or Python floats) or Dr.Jit arrays alike and returns the
same kind; arguments broadcast. :func:`nidar_mi.lidar.scan.scan` calls them on Dr.Jit arrays.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "INTENSITY_MODES",
    "attenuation",
    "expected_intensity",
    "detect",
    "add_noise",
    "box_muller",
    "compensate",
    "full_scale_intensity",
]

#: Values of the sensor's ``intensity_mode``.
INTENSITY_MODES = ("raw", "compensated")


def _is_drjit(x) -> bool:
    return type(x).__module__.startswith("drjit")


def _math(*xs):
    """``drjit`` if any argument is a Dr.Jit array, else ``numpy``."""
    if any(_is_drjit(x) for x in xs):
        import drjit as dr

        return dr
    return np


def _check_mode(mode: str) -> None:
    if mode not in INTENSITY_MODES:
        raise ValueError(f"unknown intensity mode '{mode}'")


def attenuation(d, cos_theta, alpha, mode: str = "raw"):
    """Geometric and atmospheric attenuation ``a(d, θ)``.

    Args:
        d: range (path length) in m, > 0.
        cos_theta: cosine of the incidence angle, in [0, 1].
        alpha: extinction coefficient in 1/m, >= 0.
        mode: ``raw`` (includes 1/d²) or ``compensated``.

    Returns:
        Broadcast shape of the arguments; unitless (``compensated``) or 1/m² (``raw``).
    """
    _check_mode(mode)
    a = cos_theta * _math(d, alpha).exp(-2.0 * alpha * d)
    return a / (d * d) if mode == "raw" else a


def expected_intensity(
    gain, rho, d, cos_theta, alpha, mode: str = "raw", two_way_transmittance=1.0
):
    """Noise-free return ``g · ρ · T² · a(d, θ)``.

    Args:
        gain: sensor gain g, > 0.
        rho: monostatic reflectance ρ at the laser wavelength (unitless, >= 0).
        d: range (path length) in m, > 0.
        cos_theta: cosine of the incidence angle, in [0, 1].
        alpha: extinction coefficient in 1/m.
        mode: ``raw`` or ``compensated`` (see :func:`attenuation`).
        two_way_transmittance: ``T²`` of the glass on the path, in [0, 1].

    Returns:
        Broadcast shape of the arguments; 1/m² (``raw``) or unitless (``compensated``).
    """
    return gain * rho * two_way_transmittance * attenuation(d, cos_theta, alpha, mode)


def detect(
    expected, d, *, hit=True, threshold=0.0, range_min=0.0, range_max=np.inf, dropout=0.0, u=1.0
):
    """Which returns the sensor reports.

    Args:
        expected: expected intensity ``g·ρ·T²·a`` (:func:`expected_intensity`).
        d: range (path length) in m.
        hit: bool, the beam hit a surface.
        threshold: detection threshold on ``expected``, same unit, >= 0.
        range_min, range_max: the range window in m.
        dropout: probability of dropping a return at random, in [0, 1].
        u: uniform draws in [0, 1), one per beam; a return is dropped where ``u < dropout``.

    Returns:
        bool mask, broadcast shape of the arguments: hit, finite, ``expected > 0`` (a return
        carrying no energy is never reported, whatever the threshold), ``expected >= threshold``,
        ``range_min <= d <= range_max`` and ``u >= dropout``.
    """
    xp = _math(expected, d, u)
    return (
        hit
        & xp.isfinite(expected)
        & (expected > 0.0)
        & (expected >= threshold)
        & (d >= range_min)
        & (d <= range_max)
        & (u >= dropout)
    )


def add_noise(value, std, normal):
    """``max(value + std · normal, 0)``: additive Gaussian noise, clipped at 0.

    Args:
        value: noise-free intensity or range.
        std: standard deviation, in the unit of ``value``, >= 0.
        normal: standard normal deviates (:func:`box_muller`), same shape as ``value``.
    """
    return _math(value, std, normal).maximum(value + std * normal, 0.0)


def box_muller(u1, u2):
    """Standard normal deviates from two uniform deviates in [0, 1) (Box–Muller, cosine branch)."""
    xp = _math(u1, u2)
    return xp.sqrt(-2.0 * xp.log(1.0 - u1)) * xp.cos(2.0 * xp.pi * u2)


def compensate(intensity, range_m, mode: str):
    """Range-compensated intensity ``g·ρ·T²·cos θ·exp(-2αd)`` (+ η·d²) of reported returns.

    The inverse of the ``raw`` mode's ``1/d²``: ``raw`` intensities are multiplied by ``d²``,
    ``compensated`` ones are returned as they are.

    Args:
        intensity: (N,) intensities as the sensor reported them (``raw``: 1/m²).
        range_m: (N,) reported ranges in m.
        mode: the sensor's ``intensity_mode``.

    Returns:
        (N,) unitless; float32 for NumPy input (the product is formed in float64).
    """
    _check_mode(mode)
    if _is_drjit(intensity) or _is_drjit(range_m):
        return intensity if mode == "compensated" else intensity * range_m * range_m
    intensity = np.asarray(intensity)
    if mode == "compensated":
        return intensity.astype(np.float32)
    return (intensity * np.asarray(range_m).astype(np.float64) ** 2).astype(np.float32)


def full_scale_intensity(gain: float, mode: str) -> float:
    """The intensity a sensor encodes as full scale: a ρ = 1 Lambertian target at normal
    incidence without extinction, at 1 m in ``raw`` mode (``g`` in 1/m²), at any range in
    ``compensated`` mode (``g``, unitless).

    It depends on the sensor's parameters only, never on a frame's content, so encodings
    scaled by it (LAS counts, KITTI's [0, 1]) compare across frames. Brighter returns
    (retroreflectors, specular lobes with ρ > 1, targets closer than 1 m in ``raw`` mode)
    exceed it and saturate where the encoding is bounded.

    Args:
        gain: the sensor's ``gain`` g (> 0).
        mode: ``raw`` or ``compensated``.
    """
    _check_mode(mode)
    return float(gain) * float(attenuation(1.0, 1.0, 0.0, mode))
