"""Range compensation of the intensity a LiDAR reports (:func:`compensate`)."""

from __future__ import annotations

import numpy as np

__all__ = ["compensate"]


def compensate(intensity: np.ndarray, range_m: np.ndarray, mode: str) -> np.ndarray:
    """Range-compensated intensity ``g·ρ·cosθ·exp(-2αd) (+η·d²)``.

    Args:
        intensity: (N,) intensity as the sensor reported it.
        range_m: (N,) ranges in m.
        mode: the sensor's ``intensity_mode`` (``raw`` intensities are multiplied by d²).
    """
    if mode == "compensated":
        return intensity.astype(np.float32)
    if mode == "raw":
        return (intensity * range_m.astype(np.float64) ** 2).astype(np.float32)
    raise ValueError(f"unknown intensity mode '{mode}'")
