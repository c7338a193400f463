"""The footprint of a diverging beam: sub-ray directions and their Gaussian weights.

A beam of divergence ``δ`` (full angle at 1/e² irradiance, rad) has a Gaussian irradiance profile
``E(r) ∝ exp(-2 r² / θ_w²)`` over the angle ``r`` from its axis, with ``θ_w = δ / 2``. The footprint
is sampled HELIOS++-style (3dgeo-heidelberg/helios ``FullWaveformPulseRunnable::computeSubrays``:
concentric rings of sub-rays, ring ``k`` holding ``6k`` of them, each weighted by the Gaussian
profile of Carlsson et al. 2001): with sample quality ``q`` the rings ``k = 0 .. q-1`` sit at
angles ``k · Δ`` with ``Δ = θ_w / (q - 1/2)``, so the outermost annulus ends at the 1/e² radius
``θ_w``. Each sub-ray stands for the area of its annulus cell (``π Δ²/4`` for the centre,
``π Δ²/3`` for every other one: equal areas), and its weight is that area times ``E(r)``,
normalised to sum 1 over the footprint (the energy outside ``θ_w``, 13.5 %, is left out, as
HELIOS++ does). ``1 + 3 q (q - 1)`` sub-rays: 1, 7, 19, 37, 61 for ``q = 1 .. 5``.

A surface that covers a fraction ``F`` of the footprint's energy receives ``F`` of the pulse; the
sum ``Σ w_k`` over the sub-rays that hit it estimates ``F`` (midpoint quadrature of the profile).
For a straight edge the estimate is within 0.12, 0.053, 0.038 and 0.026 of the exact fraction
(:func:`footprint_fraction`) at ``q`` = 3, 5, 8 and 12, whatever the edge's position and
orientation.
"""

from __future__ import annotations

import numpy as np

__all__ = ["subray_offsets", "footprint_fraction"]


def subray_offsets(quality: int) -> tuple[np.ndarray, np.ndarray]:
    """Sub-ray offsets from the beam axis and their weights.

    Args:
        quality: sample quality q >= 1 (number of rings, the centre included).

    Returns:
        ``(offsets, weights)``: (N, 2) float64 angular offsets in units of ``θ_w`` (the 1/e²
        half-angle; the second component is the vertical one), and (N,) float64 weights summing
        to 1. The first sub-ray is the axis.
    """
    if quality < 1:
        raise ValueError("quality must be >= 1")
    step = 1.0 / (quality - 0.5)
    offsets = [(0.0, 0.0)]
    areas = [np.pi * step * step / 4.0]
    for k in range(1, quality):
        n = 6 * k
        phase = 0.5 if k % 2 else 0.0  # stagger neighbouring rings
        a = 2.0 * np.pi * (np.arange(n) + phase) / n
        offsets += list(zip(k * step * np.cos(a), k * step * np.sin(a)))
        areas += [np.pi * step * step / 3.0] * n
    off = np.asarray(offsets, dtype=np.float64)
    w = np.asarray(areas) * np.exp(-2.0 * np.sum(off * off, axis=1))
    return off, w / w.sum()


def footprint_fraction(edge: float) -> float:
    """Fraction of the footprint's energy on one side of a straight edge (the exact integral).

    Args:
        edge: signed distance of the edge from the axis in units of ``θ_w``; the covered side is
            ``x < edge`` (so 0 gives one half, -1 nothing, +1 everything).

    Returns:
        ``∫∫_{r<1, x<edge} exp(-2 r²) dA / ∫∫_{r<1} exp(-2 r²) dA``.
    """
    from scipy import integrate

    edge = float(np.clip(edge, -1.0, 1.0))

    def strip(x: float) -> float:  # ∫ exp(-2(x²+y²)) dy over the chord at x
        h = np.sqrt(max(1.0 - x * x, 0.0))
        from scipy.special import erf

        return np.exp(-2.0 * x * x) * np.sqrt(np.pi / 2.0) * erf(np.sqrt(2.0) * h)

    total = np.pi / 2.0 * (1.0 - np.exp(-2.0))
    part, _ = integrate.quad(strip, -1.0, edge, epsabs=1e-12, epsrel=1e-10)
    return float(part / total)
