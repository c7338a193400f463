"""The LiDAR return model, as pure functions over NumPy or Dr.Jit arrays.

A return of a beam hitting a surface at range ``d`` (m) with incidence cosine ``cos θ`` is

    I = g · ρ(m, λ, θ) · a(d, θ) + η

with ``ρ = π · f_r(ω, ω; λ)`` the hit BSDF evaluated monostatically at the laser wavelength (a
Lambertian surface gives its albedo), and

    a(d, θ) = cos θ · exp(-2 α d) / d²      (``raw``)
    a(d, θ) = cos θ · exp(-2 α d)           (``compensated``: range-normalised, as many sensors report)

``α`` is the atmospheric extinction coefficient (1/m); the factor 2 is the two-way path.
``η`` is zero-mean Gaussian noise added after the detection test.
"""

from __future__ import annotations

import numpy as np

__all__ = ["attenuation", "expected_intensity", "box_muller"]


def _exp(x):
    if type(x).__module__.startswith("drjit"):
        import drjit as dr

        return dr.exp(x)
    return np.exp(x)


def attenuation(d, cos_theta, alpha: float, mode: str = "raw"):
    """Geometric and atmospheric attenuation ``a(d, θ)``.

    Args:
        d: range in m (> 0).
        cos_theta: cosine of the incidence angle, in [0, 1].
        alpha: extinction coefficient in 1/m.
        mode: ``raw`` (includes 1/d²) or ``compensated``.

    Returns:
        Same shape/type as ``d``; unitless (``compensated``) or 1/m² (``raw``).
    """
    a = cos_theta * _exp(-2.0 * alpha * d)
    if mode == "raw":
        return a / (d * d)
    if mode == "compensated":
        return a
    raise ValueError(f"unknown intensity mode '{mode}'")


def expected_intensity(gain: float, rho, d, cos_theta, alpha: float, mode: str = "raw"):
    """Noise-free return ``g · ρ · a(d, θ)``."""
    return gain * rho * attenuation(d, cos_theta, alpha, mode)


def box_muller(u1, u2):
    """Standard normal deviates from two uniform deviates in [0, 1) (NumPy or Dr.Jit)."""
    if type(u1).__module__.startswith("drjit"):
        import drjit as dr

        return dr.sqrt(-2.0 * dr.log(1.0 - u1)) * dr.cos(2.0 * dr.pi * u2)
    return np.sqrt(-2.0 * np.log(1.0 - u1)) * np.cos(2.0 * np.pi * u2)
