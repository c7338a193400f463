"""Scan Context descriptors of a LiDAR scan and their matching under rotation.

A descriptor is a (rings, sectors) polar grid around the sensor, in the horizontal plane: ring
``r`` holds ranges ``[r, r + 1) · max_range / rings``, sector ``s`` holds azimuths
``[s, s + 1) · 2π / sectors`` counted from -x (``atan2(y, x) + π``, as the reference code of
Intensity Scan Context does). Each bin keeps the largest value of the points that fall in it:

* Intensity Scan Context (Wang, Wang and Xie, "Intensity Scan Context: Coding Intensity and
  Geometry Relations for Loop Closure Detection", ICRA 2020): the value is the point's intensity
  in [0, 1];
* Scan Context (Kim and Kim, IROS 2018): the value is the point's height above the ground (the
  "none" source of the drive study: geometry only).

Matching follows the two stages of Intensity Scan Context: :func:`geometry_similarity` compares
the occupancy of two descriptors (the fraction of bins that are both occupied or both empty)
under every column shift and keeps the best shift; :func:`value_similarity` compares the values,
``1 - mean |a - b|`` over all bins, at the shifts within ``window`` sectors of that one.
:func:`ring_key` (each ring's mean over sectors) is invariant to the heading and serves to pick
candidates before the full match. Values are expected in [0, 1] (:func:`normalise`).
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "RINGS",
    "SECTORS",
    "MAX_RANGE_M",
    "descriptor",
    "ring_key",
    "geometry_similarity",
    "value_similarity",
    "normalise",
]

#: Rings, sectors and radius of the reference implementation's KITTI set-up.
RINGS, SECTORS, MAX_RANGE_M = 20, 60, 40.0


def descriptor(
    xyz: np.ndarray,
    values: np.ndarray,
    *,
    rings: int = RINGS,
    sectors: int = SECTORS,
    max_range: float = MAX_RANGE_M,
) -> tuple[np.ndarray, np.ndarray]:
    """The (rings, sectors) max-value grid of a scan and its occupancy.

    Args:
        xyz: (N, 3) points in the sensor frame, m.
        values: (N,) values in [0, 1] (intensity, or normalised height).
        rings, sectors: grid size.
        max_range: radius of the outer ring, m (points beyond it are left out).

    Returns:
        ``(grid, occupied)``: (rings, sectors) float32 largest value per bin (0 where empty) and
        bool, a point fell in the bin.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    values = np.asarray(values, dtype=np.float32)
    if xyz.ndim != 2 or xyz.shape[1] != 3 or values.shape != (len(xyz),):
        raise ValueError(f"expected (N, 3) points and (N,) values, got {xyz.shape}, {values.shape}")
    d = np.hypot(xyz[:, 0], xyz[:, 1])
    ring = np.floor(d / (max_range / rings)).astype(np.int64)
    angle = np.arctan2(xyz[:, 1], xyz[:, 0]) + np.pi
    sector = np.minimum(np.floor(angle / (2 * np.pi / sectors)).astype(np.int64), sectors - 1)
    keep = (d < max_range) & (ring < rings) & np.isfinite(values)
    flat = ring[keep] * sectors + sector[keep]
    grid = np.zeros(rings * sectors, dtype=np.float32)
    np.maximum.at(grid, flat, np.clip(values[keep], 0.0, 1.0))
    occupied = np.zeros(rings * sectors, dtype=bool)
    occupied[flat] = True
    return grid.reshape(rings, sectors), occupied.reshape(rings, sectors)


def ring_key(grid: np.ndarray) -> np.ndarray:
    """(rings,) the mean of each ring over its sectors (unchanged by a rotation of the scan)."""
    return np.asarray(grid, dtype=np.float32).mean(axis=-1)


def geometry_similarity(occ_a: np.ndarray, occ_b: np.ndarray) -> tuple[float, int]:
    """Best occupancy agreement of two descriptors over column shifts.

    Args:
        occ_a, occ_b: (rings, sectors) bool occupancy.

    Returns:
        ``(similarity, shift)``: the largest fraction of bins on which ``occ_a`` and
        ``np.roll(occ_b, -shift, axis=1)`` agree, and that shift (sectors).
    """
    a = np.asarray(occ_a, dtype=bool)
    b = np.asarray(occ_b, dtype=bool)
    S = a.shape[1]
    # every shift at once: (S, rings, sectors) rolled copies of b
    idx = (np.arange(S)[:, None] + np.arange(S)[None, :]) % S
    rolled = b[:, idx].transpose(1, 0, 2)
    agree = (rolled == a[None]).mean(axis=(1, 2))
    shift = int(np.argmax(agree))
    return float(agree[shift]), shift


def value_similarity(a: np.ndarray, b: np.ndarray, shift: int, window: int = 10) -> float:
    """``1 - mean |a - roll(b, -k)|`` at the best k within ``window`` sectors of ``shift``.

    Args:
        a, b: (rings, sectors) descriptors with values in [0, 1].
        shift: the geometric best shift (:func:`geometry_similarity`).
        window: the reference implementation's search half-width (10 sectors).
    """
    a = np.asarray(a, dtype=np.float32)
    b = np.asarray(b, dtype=np.float32)
    S = a.shape[1]
    ks = (shift + np.arange(-window, window)) % S
    idx = (ks[:, None] + np.arange(S)[None, :]) % S
    rolled = b[:, idx].transpose(1, 0, 2)
    diff = np.abs(rolled - a[None]).mean(axis=(1, 2))
    return float(1.0 - diff.min())


def normalise(values: np.ndarray, scale: float) -> np.ndarray:
    """``values / scale`` clipped to [0, 1] (a fixed gain for the whole drive, like a sensor's
    8-bit intensity); NaN becomes 0."""
    v = np.nan_to_num(np.asarray(values, dtype=np.float64) / scale, nan=0.0)
    return np.clip(v, 0.0, 1.0).astype(np.float32)
