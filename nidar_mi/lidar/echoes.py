"""Multiple returns: the sub-ray contributions of each beam grouped into echoes, and the
returns a sensor reports from them.

Each beam carries ``K`` contributions (its sub-rays' surface hits, and the specular echoes of the
first glass pane they met), each a range ``d`` (m) and an energy ``e`` (the sub-ray's weight
times its expected intensity ``g·ρ·T²·a``). Sorted by range, contributions closer than
``separation`` (m) to the previous one belong to the same echo (the pulses overlap and the
detector sees one peak): its energy is the sum ``Σ e`` and its range the energy-weighted mean
``Σ e·d / Σ e``; its attributes (reflectance, incidence, material, shape) are those of its
strongest contribution.

An echo is a candidate when it passes the detection test of :func:`.return_model.detect`
(energy > 0, >= threshold, range inside the window). The reported returns, per ``return_mode``:

=============  ==============================================================================
``strongest``  the candidate with the most energy (ties: the nearest)
``first``      the nearest candidate
``last``       the farthest candidate
``dual``       the strongest, and the last; when the strongest is also the last, the second
               strongest (the "last and strongest" dual mode of Velodyne and Hesai sensors,
               e.g. the Hesai PandarXT-16 user manual, section 3.1.2.3)
=============  ==============================================================================

Everything here is NumPy over a block of beams (``(n, K)`` arrays): no Python loop over beams.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = ["RETURN_MODES", "Echoes", "group_echoes", "select_returns"]

#: Values of the sensor's ``return_mode``.
RETURN_MODES = ("strongest", "first", "last", "dual")


class Echoes(NamedTuple):
    """The echoes of ``n`` beams in range order, padded to ``E`` slots (the most echoes a beam has).

    Attributes:
        range_m: (n, E) float64 energy-weighted range; inf in empty slots.
        energy: (n, E) float64 summed energy; 0 in empty slots.
        source: (n, E) int64 index (into the K contributions) of the strongest contribution;
            -1 in empty slots.
    """

    range_m: np.ndarray
    energy: np.ndarray
    source: np.ndarray


def group_echoes(range_m: np.ndarray, energy: np.ndarray, separation: float) -> Echoes:
    """Group each beam's contributions into echoes.

    Args:
        range_m: (n, K) range of every contribution, m; inf (or NaN) where there is none.
        energy: (n, K) energy of every contribution, >= 0 (non-finite counts as none).
        separation: minimum range difference between two echoes, m, > 0.

    Returns:
        The echoes, slot 0 the nearest.
    """
    range_m = np.asarray(range_m, dtype=np.float64)
    energy = np.asarray(energy, dtype=np.float64)
    n, k = range_m.shape
    present = np.isfinite(range_m) & np.isfinite(energy)
    d = np.where(present, range_m, np.inf)
    order = np.argsort(d, axis=1, kind="stable")
    ds = np.take_along_axis(d, order, axis=1)
    es = np.take_along_axis(np.where(present, energy, 0.0), order, axis=1)
    valid = np.isfinite(ds)  # present entries come first in each row
    with np.errstate(invalid="ignore"):  # inf - inf between empty contributions
        gap = np.diff(ds, axis=1, prepend=-np.inf) > separation
    slot = np.cumsum(gap & valid, axis=1) - 1  # echo slot of each contribution
    # present contributions, flattened row by row: each echo is a contiguous run
    pos = np.flatnonzero(valid)
    slot_v = slot.ravel()[pos]
    width = int(slot_v.max()) + 1 if pos.size else 1  # echo slots needed
    seg = (pos // k) * width + slot_v
    e_v, d_v, src_v = es.ravel()[pos], ds.ravel()[pos], order.ravel()[pos]
    rng = np.full(n * width, np.inf)
    total = np.zeros(n * width)
    source = np.full(n * width, -1, dtype=np.int64)
    if pos.size:
        starts = np.flatnonzero(np.diff(seg, prepend=-1))
        count = np.diff(starts, append=pos.size)
        tot = np.add.reduceat(e_v, starts)
        with np.errstate(invalid="ignore", divide="ignore"):
            weighted = np.add.reduceat(e_v * d_v, starts) / tot
        mean = np.add.reduceat(d_v, starts) / count
        peak = np.maximum.reduceat(e_v, starts)
        run = np.repeat(np.arange(starts.size), count)
        is_peak = np.flatnonzero(e_v == peak[run])
        first_peak = is_peak[np.flatnonzero(np.diff(run[is_peak], prepend=-1))]
        where = seg[starts]
        total[where] = tot
        rng[where] = np.where(tot > 0, weighted, mean)
        source[where] = src_v[first_peak]
    return Echoes(rng.reshape(n, width), total.reshape(n, width), source.reshape(n, width))


def select_returns(echoes: Echoes, candidate: np.ndarray, mode: str) -> np.ndarray:
    """The echo slots each beam reports.

    Args:
        echoes: the grouped echoes.
        candidate: (n, K) bool, the echo passes the detection test.
        mode: one of :data:`RETURN_MODES`.

    Returns:
        (n, M) int64 slot per reported return (M = 2 for ``dual``, else 1); -1 where a beam has
        no (second) return. Column 0 is the strongest for ``strongest`` and ``dual``.
    """
    if mode not in RETURN_MODES:
        raise ValueError(f"unknown return mode '{mode}'")
    n, k = candidate.shape
    any_c = candidate.any(axis=1)
    power = np.where(candidate, echoes.energy, -np.inf)
    strongest = np.argmax(power, axis=1)
    first = np.argmax(candidate, axis=1)
    last = k - 1 - np.argmax(candidate[:, ::-1], axis=1)
    pick = {"strongest": strongest, "first": first, "last": last, "dual": strongest}[mode]
    out = [np.where(any_c, pick, -1)]
    if mode == "dual":
        second_power = power.copy()
        second_power[np.arange(n), strongest] = -np.inf
        second = np.argmax(second_power, axis=1)
        has_second = np.isfinite(second_power[np.arange(n), second])
        other = np.where(last != strongest, last, np.where(has_second, second, -1))
        out.append(np.where(any_c, other, -1))
    return np.stack(out, axis=1).astype(np.int64)
