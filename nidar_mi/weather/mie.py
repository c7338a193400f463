"""Mie efficiencies of spheres, with the geometric-optics limit for large ones, and their
integrals over a size distribution.

The Mie series come from **miepython** (Prahl; maintained, pure Python on NumPy, MIT-licensed,
its results checked against Wiscombe's MIEV0 in its own test suite). PyMieScatt, the other
common choice, had its last release in 2020 and pins old SciPy interfaces; miepython 3 takes
arrays of size parameters and complex indices directly, which is all this module needs.

For a sphere of diameter ``D`` at wavelength ``λ`` the size parameter is ``x = π D / λ``.
Up to :data:`X_MIE` the exact series is summed. Beyond it (raindrops and snowflakes are
``x ~ 10³-10⁴`` in the near infrared) the geometric-optics limit applies:

* extinction ``Q_ext = 2 + 1.9924 x^(-2/3)`` (the extinction paradox with the edge term of
  Nussenzveig & Wiscombe, Phys. Rev. Lett. 45, 1490, 1980), 2.020 at x = 1000 where the series
  gives 2.017;
* absorption ``Q_abs = (1 - R̄)(1 - exp(-γ · 2D/3))``, the light refracted into the sphere
  (``R̄`` the Fresnel reflectance averaged over the sphere's face) absorbed along the mean chord
  ``2D/3`` with ``γ = 4πk/λ``;
* backscatter ``Q_back = R0 = |(m-1)/(m+1)|²``, the front face's specular reflection. A
  perfect sphere also sends back the rays focused on its axis by the rear surface (the glory:
  the series' ``Q_back`` of 1.5-2.7 near X_MIE for water at 905 nm), but drops this large
  (> 0.3 mm at 905 nm, > 0.5 mm at 1550 nm) fall flattened and oscillating (Beard & Chuang, J.
  Atmos. Sci. 44, 1509, 1987), which smooths the spheres' backscatter features away
  (Macke & Großklaus, JQSRT 59, 355, 1998; Nousiainen & Muinonen, JQSRT 63, 643, 1999): only
  the face's reflection is kept, a step at X_MIE where the sphere hands over;
* asymmetry parameter ``g`` the series' average at X_MIE.

Efficiencies oscillate with x (interference and resonances); a particle sampled from a
distribution uses :func:`mean_backscatter`, the series averaged over ±25 % in size.

Backscatter efficiency is miepython's (the radar convention): the backscatter cross-section
``σ_b = Q_back π D²/4 = 4π dσ/dΩ(180°)``; a Lambertian disk of reflectance ρ facing the beam
has ``Q_back = 4ρ``.
"""

from __future__ import annotations

from functools import lru_cache
from typing import NamedTuple

import numpy as np

__all__ = [
    "X_MIE",
    "Efficiencies",
    "efficiencies",
    "series_efficiencies",
    "mean_backscatter",
    "BACKSCATTER_ANCHORS",
    "seam_averages",
    "fresnel_normal",
    "phase_function",
]

#: Largest size parameter summed as a series; beyond it, geometric optics.
X_MIE = 1000.0


class Efficiencies(NamedTuple):
    """Efficiencies (unitless) and asymmetry parameter, each the shape of ``x``."""

    qext: np.ndarray
    qsca: np.ndarray
    qback: np.ndarray
    g: np.ndarray


def series_efficiencies(m: complex, x) -> Efficiencies:
    """The exact Mie series (miepython) at size parameters ``x`` (any shape, > 0)."""
    import miepython

    x = np.asarray(x, dtype=np.float64)
    flat = x.reshape(-1)
    if flat.size == 0:
        empty = np.zeros(x.shape)
        return Efficiencies(empty, empty, empty, empty)
    q = np.asarray(miepython.efficiencies_mx(complex(m), flat), dtype=np.float64).reshape(4, -1)
    return Efficiencies(*(v.reshape(x.shape) for v in q))


def fresnel_normal(m: complex) -> float:
    """Fresnel reflectance at normal incidence ``|(m-1)/(m+1)|²``."""
    return float(abs((m - 1.0) / (m + 1.0)) ** 2)


def _fresnel_mean(m: complex) -> float:
    """Fresnel reflectance of unpolarised light averaged over a sphere's face (cosine-weighted
    over incidence angles), for the real part of ``m``."""
    n = float(np.real(m))
    c = np.linspace(1e-6, 1.0, 2001)  # cos θi
    s = np.sqrt(1.0 - c * c)
    ct = np.sqrt(1.0 - (s / n) ** 2)
    rs = ((c - n * ct) / (c + n * ct)) ** 2
    rp = ((n * c - ct) / (n * c + ct)) ** 2
    return float(np.trapezoid(0.5 * (rs + rp) * 2.0 * c, c))


def seam_averages(m: complex) -> tuple[float, float]:
    """The series' ``Q_back`` and ``g`` averaged over x in [0.9, 1.1]·:data:`X_MIE` (41 sizes),
    where geometric optics takes over; cached per index."""
    return _seam_averages(float(np.real(m)), float(np.imag(m)))


@lru_cache(maxsize=64)
def _seam_averages(m_real: float, m_imag: float) -> tuple[float, float]:
    xs = np.linspace(0.9 * X_MIE, 1.1 * X_MIE, 41)
    q = series_efficiencies(complex(m_real, m_imag), xs)
    return float(np.mean(q.qback)), float(np.mean(q.g))


def _geometric(m: complex, x: np.ndarray, wavelength_m: float) -> Efficiencies:
    gamma = 4.0 * np.pi * abs(np.imag(m)) / wavelength_m
    d = x * wavelength_m / np.pi
    qext = 2.0 + 1.9924 * x ** (-2.0 / 3.0)
    qabs = (1.0 - _fresnel_mean(m)) * (1.0 - np.exp(-gamma * 2.0 * d / 3.0))
    g_seam = seam_averages(m)[1]
    return Efficiencies(
        qext, qext - qabs, np.full_like(x, fresnel_normal(m)), np.full_like(x, g_seam)
    )


def efficiencies(m: complex, x, wavelength_nm: float) -> Efficiencies:
    """Efficiencies at size parameters ``x``: the series up to :data:`X_MIE`, geometric optics
    beyond (module docstring).

    Args:
        m: complex refractive index ``n - i k`` relative to air.
        x: (...) size parameters ``π D / λ``, > 0.
        wavelength_nm: λ (the absorption along the path inside large particles needs it).
    """
    x = np.asarray(x, dtype=np.float64)
    small = x <= X_MIE
    out = [np.zeros(x.shape) for _ in range(4)]
    if small.any():
        q = series_efficiencies(m, x[small])
        for o, v in zip(out, q):
            o[small] = v
    if (~small).any():
        q = _geometric(m, x[~small], wavelength_nm * 1e-9)
        for o, v in zip(out, q):
            o[~small] = v
    return Efficiencies(*out)


#: Size parameters where :func:`mean_backscatter` averages the series (the seam last).
BACKSCATTER_ANCHORS = (
    *(0.5, 1.0, 2.0, 3.0, 4.0, 5.5, 7.5, 10.0, 13.0, 17.0, 22.0, 30.0, 40.0, 55.0, 75.0),
    *(100.0, 140.0, 200.0, 300.0, 450.0, 650.0, X_MIE),
)
#: Relative half-width of the size windows of :data:`BACKSCATTER_ANCHORS` (±).
ANCHOR_WINDOW = 0.25


@lru_cache(maxsize=64)
def _anchor_means(m_real: float, m_imag: float) -> np.ndarray:
    """The series' ``Q_back`` averaged over 41 sizes within ±:data:`ANCHOR_WINDOW` of each
    anchor; at the seam, :func:`seam_averages`' (so that geometric optics continues it)."""
    m = complex(m_real, m_imag)
    out = []
    for a in BACKSCATTER_ANCHORS[:-1]:
        xs = a * np.linspace(1.0 - ANCHOR_WINDOW, 1.0 + ANCHOR_WINDOW, 41)
        out.append(float(np.mean(series_efficiencies(m, xs).qback)))
    return np.asarray([*out, seam_averages(m)[0]])


def mean_backscatter(m: complex, x, wavelength_nm: float) -> np.ndarray:
    """``Q_back`` of spheres of size parameters ``x`` without the resonances of one exact
    sphere: up to :data:`X_MIE` the series averaged over ±25 % in size at
    :data:`BACKSCATTER_ANCHORS` (41 sizes each, cached per index; the average still moves by
    tens of % between neighbouring windows below x ~ 60, where interference dominates),
    interpolated in log x between them; geometric optics beyond (module docstring). What a
    drop of a sampled size returns.

    Args:
        m: complex refractive index.
        x: size parameters, any shape.
        wavelength_nm: λ.

    Returns:
        float64, the shape of ``x``.
    """
    x = np.asarray(x, dtype=np.float64)
    anchors = _anchor_means(float(np.real(m)), float(np.imag(m)))
    small = np.interp(np.log(np.maximum(x, 1e-12)), np.log(BACKSCATTER_ANCHORS), anchors)
    large = _geometric(m, np.maximum(x, X_MIE), wavelength_nm * 1e-9).qback
    return np.where(x <= X_MIE, small, large)


def phase_function(m: complex, x, mu) -> np.ndarray:
    """Unpolarised Mie phase functions ``p(μ)`` normalised to ``∫ p dΩ = 1`` (1/sr).

    The coefficients ``a_n, b_n`` are miepython's; the angular sums are formed here, the
    recurrences of π_n and τ_n run over the orders with all angles at once (Bohren & Huffman
    1983, eqs. 4.47 and 4.74): miepython's own angular functions loop over the angles one by
    one in Python without its optional numba compilation, ~100 times slower for the thousands
    of angles a forward-peaked phase function needs. ``p = (|S1|² + |S2|²) / (2π x² Q_sca)``.

    Args:
        m: complex refractive index.
        x: (N,) size parameters (<= :data:`X_MIE`).
        mu: (M,) cosines of the scattering angle (1: forward).

    Returns:
        (N, M) float64.
    """
    import miepython

    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    mu = np.asarray(mu, dtype=np.float64)
    out = np.empty((x.size, mu.size))
    for i, xi in enumerate(x):
        a, b = miepython.coefficients(complex(m), float(xi))
        n = np.arange(1, a.size + 1, dtype=np.float64)
        scale = (2.0 * n + 1.0) / (n * (n + 1.0))
        s1 = np.zeros(mu.size, dtype=np.complex128)
        s2 = np.zeros(mu.size, dtype=np.complex128)
        pi_prev, pi_n = np.zeros(mu.size), np.ones(mu.size)
        for k in range(a.size):
            order = k + 1.0
            tau_n = order * mu * pi_n - (order + 1.0) * pi_prev
            s1 += scale[k] * (a[k] * pi_n + b[k] * tau_n)
            s2 += scale[k] * (a[k] * tau_n + b[k] * pi_n)
            pi_prev, pi_n = (
                pi_n,
                ((2.0 * order + 1.0) * mu * pi_n - (order + 1.0) * pi_prev) / order,
            )
        qsca = float(series_efficiencies(complex(m), [xi]).qsca[0])
        out[i] = (np.abs(s1) ** 2 + np.abs(s2) ** 2) / (2.0 * np.pi * xi * xi * qsca)
    return out
