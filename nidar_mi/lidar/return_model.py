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
``E = g·ρ·T²·a`` is finite and carries energy (> 0), the receiver's output ``E + σ_n·n`` reaches
the detection threshold ``T`` (``n`` standard normal: the receiver noise, ``σ_n`` the sensor's
``receiver_noise_std``), its range lies in ``[range_min, range_max]``, and a uniform draw is not
below the dropout probability. The threshold test in white Gaussian noise gives the detection
probability (:func:`detection_probability`)

    P_D = Φ((E - T) / σ_n),   P_FA = Q(T / σ_n)

(a known level in white Gaussian noise: S. M. Kay, *Fundamentals of Statistical Signal
Processing, Vol. II: Detection Theory*, 1998, ch. 3): a return fades out over a few ``σ_n``
around the threshold instead of stopping at a step (``σ_n = 0``), and a return exactly at the
threshold is detected half the time. The sensor reports the receiver's output ``E + σ_n·n``;
``η`` is further zero-mean Gaussian noise added after the detection test (:func:`add_noise`;
the range gets its own), the result clipped at 0. :func:`compensate` turns written intensities
back into the range-compensated ``g·ρ·T²·cos θ·exp(-2αd)`` (+ noise).
A sensor may add per-laser gains (``laser_gains``: ``g`` becomes ``g·G_r`` for ring ``r``), a
range response ``r(d)`` multiplying ``E`` (:func:`range_response`, piecewise linear) and an
intensity offset ``b`` (the reported intensity is ``max(E + σ_n·n - b + η, 0)``); detection
is on ``E`` itself. :func:`full_scale_intensity` is a sensor's fixed reference for integer or unit-range encodings
(LAS counts, KITTI's [0, 1]): the same for every frame of the sensor.

Every function takes NumPy arrays (or Python floats) or Dr.Jit arrays alike and returns the
same kind; arguments broadcast. :func:`nidar_mi.lidar.scan.scan` calls them on Dr.Jit arrays.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "array_module",
    "INTENSITY_MODES",
    "attenuation",
    "expected_intensity",
    "detect",
    "detection_probability",
    "received",
    "add_noise",
    "box_muller",
    "compensate",
    "full_scale_intensity",
    "range_response",
]

#: Values of the sensor's ``intensity_mode``.
INTENSITY_MODES = ("raw", "compensated")


def _is_drjit(x) -> bool:
    return type(x).__module__.startswith("drjit")


def array_module(*xs):
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
    a = cos_theta * array_module(d, alpha).exp(-2.0 * alpha * d)
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
    expected,
    d,
    *,
    hit=True,
    threshold=0.0,
    range_min=0.0,
    range_max=np.inf,
    dropout=0.0,
    u=1.0,
    noise=0.0,
    normal=0.0,
):
    """Which returns the sensor reports.

    Args:
        expected: expected intensity ``E = g·ρ·T²·a`` (:func:`expected_intensity`).
        d: range (path length) in m.
        hit: bool, the beam hit a surface.
        threshold: detection threshold ``T`` on the receiver's output, the unit of ``expected``,
            >= 0.
        range_min, range_max: the range window in m.
        dropout: probability of dropping a return at random, in [0, 1].
        u: uniform draws in [0, 1), one per beam; a return is dropped where ``u < dropout``.
        noise: ``σ_n``, standard deviation of the receiver noise, the unit of ``expected``, >= 0.
        normal: standard normal draws, one per beam: the receiver's output is
            ``E + σ_n · normal`` (:func:`received`).

    Returns:
        bool mask, broadcast shape of the arguments: hit, finite, ``E > 0`` (a return carrying
        no energy is never reported, whatever the threshold and the noise),
        ``E + σ_n·normal >= T``, ``range_min <= d <= range_max`` and ``u >= dropout``.
    """
    xp = array_module(expected, d, u, normal)
    return (
        hit
        & xp.isfinite(expected)
        & (expected > 0.0)
        & (received(expected, noise, normal) >= threshold)
        & (d >= range_min)
        & (d <= range_max)
        & (u >= dropout)
    )


def received(expected, noise, normal):
    """The receiver's output ``E + σ_n · n``: the expected intensity and the receiver noise.

    Args:
        expected: expected intensity ``E``.
        noise: ``σ_n``, >= 0, the unit of ``expected``.
        normal: standard normal draws (:func:`box_muller`), broadcast with ``expected``.
    """
    return expected + noise * normal


def detection_probability(expected, threshold, noise):
    """``P_D = Φ((E - T) / σ_n)``: the probability that a return of expected intensity ``E``
    passes the threshold ``T`` in white Gaussian receiver noise of deviation ``σ_n`` (a step
    ``E >= T`` where ``σ_n = 0``). The range window, dropout and the ``E > 0`` rule of
    :func:`detect` come on top.

    Args:
        expected: (...) expected intensity ``E``.
        threshold: ``T``, the unit of ``E``.
        noise: ``σ_n`` >= 0, the unit of ``E``.

    Returns:
        (...) float64 probabilities in [0, 1]; for Dr.Jit arguments a Dr.Jit array (there
        ``σ_n`` must be > 0), differentiable in ``E``, ``T`` and ``σ_n``.
    """
    if _is_drjit(expected) or _is_drjit(threshold) or _is_drjit(noise):
        import drjit as dr

        return 0.5 * (1.0 + dr.erf((expected - threshold) / (noise * np.sqrt(2.0))))
    from scipy.special import ndtr

    e = np.asarray(expected, dtype=np.float64)
    t = np.asarray(threshold, dtype=np.float64)
    s = np.asarray(noise, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        z = (e - t) / s
    step = (e >= t).astype(np.float64)
    return np.where(s > 0, ndtr(np.where(s > 0, z, 0.0)), step)


def add_noise(value, std, normal):
    """``max(value + std · normal, 0)``: additive Gaussian noise, clipped at 0.

    Args:
        value: noise-free intensity or range.
        std: standard deviation, in the unit of ``value``, >= 0.
        normal: standard normal deviates (:func:`box_muller`), same shape as ``value``.
    """
    return array_module(value, std, normal).maximum(value + std * normal, 0.0)


def box_muller(u1, u2):
    """Standard normal deviates from two uniform deviates in [0, 1) (Box–Muller, cosine branch)."""
    xp = array_module(u1, u2)
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


def range_response(d, knots_m, values):
    """A sensor's range response ``r(d)``: piecewise linear through ``(knots_m[i], values[i])``,
    constant before the first knot and after the last.

    Written as ``values[0] + Σ_i (values[i+1] - values[i]) · clip((d - k_i) / (k_{i+1} - k_i),
    0, 1)`` so that it runs on NumPy and Dr.Jit alike and is differentiable in ``values``.

    Args:
        d: range in m.
        knots_m: (K,) strictly increasing ranges, m (Python floats).
        values: (K,) the response at the knots (floats, or Dr.Jit scalars).

    Returns:
        Shape of ``d``; unitless.
    """
    xp = array_module(d, *values)
    out = values[0] + 0.0 * d
    for i in range(len(knots_m) - 1):
        width = float(knots_m[i + 1]) - float(knots_m[i])
        t = xp.clip((d - float(knots_m[i])) / width, 0.0, 1.0)
        out = out + (values[i + 1] - values[i]) * t
    return out
