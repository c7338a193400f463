"""A monotone piecewise-linear quantile map, the building block of two profile forms.

``g(i) = clip(interp(i, Q_s, Q_r), 0, 1)``, ``Q_s`` and ``Q_r`` quantiles of a source and a
reference distribution at the same levels ``q_k``: the ``distance_quantile`` form
(:mod:`nidar_mi.profiles.distance_quantile`) applies one to the distance-encoded values, the
``range_ring`` form (:mod:`nidar_mi.profiles.range_ring`) one per range bin. Pure NumPy.
"""

from __future__ import annotations

import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import NidarError

__all__ = ["DEFAULT_K", "QuantileMap", "as_float_array"]

DEFAULT_K = 101
"""Number of quantile levels; default levels are ``linspace(0, 1, K)``."""


def as_float_array(x: Any, name: str) -> np.ndarray:
    """``x`` as a float64 array; :class:`NidarError` naming ``name`` when it is not numeric."""
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise NidarError(f"{name} must be numeric: {exc}") from None
    return arr


def _dedupe_knots(
    q_source: np.ndarray, levels: np.ndarray, reference: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Collapse runs of equal source quantiles into one knot at the run's middle level.

    A run ``Q_s[a] == ... == Q_s[b]`` means a point mass of the source distribution spanning
    levels ``q_a..q_b``; it is mapped to the reference quantile at ``(q_a + q_b) / 2``.
    """
    _, start, counts = np.unique(q_source, return_index=True, return_counts=True)
    first = levels[start]
    last = levels[start + counts - 1]
    mid = 0.5 * (first + last)
    return q_source[start], mid, np.quantile(reference, mid)


@dataclass(frozen=True, eq=False)
class QuantileMap:
    """Piecewise-linear quantile mapping ``g(i) = clip(interp(i, Q_s, Q_r), 0, 1)``.

    Attributes:
        levels: (K,) quantile levels ``q_k`` in [0, 1], strictly increasing.
        q_source: (K,) source quantiles ``Q_s`` (distance-encoded predictions), strictly
            increasing, so ``g`` is well defined.
        q_reference: (K,) reference quantiles ``Q_r`` (source-domain LiDAR intensities),
            non-decreasing, so ``g`` is monotone (non-decreasing).

    ``g(Q_s[k]) == clip(Q_r[k], 0, 1)`` exactly; inputs below ``Q_s[0]`` (above ``Q_s[-1]``)
    map to ``Q_r[0]`` (``Q_r[-1]``).
    """

    levels: np.ndarray
    q_source: np.ndarray
    q_reference: np.ndarray

    def __post_init__(self) -> None:
        arrays = {}
        for name in ("levels", "q_source", "q_reference"):
            arr = np.array(getattr(self, name), dtype=np.float64).reshape(-1)
            if arr.size == 0 or not np.all(np.isfinite(arr)):
                raise NidarError(f"QuantileMap: {name} must be a non-empty finite 1-D array")
            arr.setflags(write=False)
            arrays[name] = arr
        if not arrays["levels"].size == arrays["q_source"].size == arrays["q_reference"].size:
            raise NidarError("QuantileMap: levels, q_source and q_reference differ in length")
        if np.any(np.diff(arrays["levels"]) <= 0) or not (
            0.0 <= arrays["levels"][0] and arrays["levels"][-1] <= 1.0
        ):
            raise NidarError("QuantileMap: levels must be strictly increasing in [0, 1]")
        if np.any(np.diff(arrays["q_source"]) <= 0):
            raise NidarError("QuantileMap: q_source must be strictly increasing")
        if np.any(np.diff(arrays["q_reference"]) < 0):
            raise NidarError("QuantileMap: q_reference must be non-decreasing")
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)

    @classmethod
    def fit(
        cls,
        source_values: Any,
        reference_values: Any,
        K: int = DEFAULT_K,
        levels: Any = None,
    ) -> QuantileMap:
        """Fit the map from samples of the source and reference distributions.

        Quantiles use numpy's default (linear) estimator. Where several levels give the same
        source quantile (a point mass, e.g. many predictions clipped to 0), the tied knots
        are merged into one at the middle level of the run, whose reference quantile is
        recomputed, so the stored knots are strictly increasing and still exact.

        Args:
            source_values: (N,) distance-encoded predictions ``i_d``.
            reference_values: (M,) source-domain LiDAR intensities ``r_n`` on the [0, 1] scale.
            K: number of levels when ``levels`` is None (``linspace(0, 1, K)``), K >= 2.
            levels: optional (K,) strictly increasing levels in [0, 1].

        Returns:
            The fitted map (possibly fewer than K knots after merging ties).

        Raises:
            NidarError: on empty or non-finite inputs or invalid levels.
        """
        src = as_float_array(source_values, "source_values").reshape(-1)
        ref = as_float_array(reference_values, "reference_values").reshape(-1)
        for name, arr in (("source_values", src), ("reference_values", ref)):
            if arr.size == 0:
                raise NidarError(f"QuantileMap.fit: {name} is empty")
            if not np.all(np.isfinite(arr)):
                raise NidarError(f"QuantileMap.fit: {name} contains NaN or inf")
        if levels is None:
            if int(K) < 2:
                raise NidarError(f"QuantileMap.fit: K must be >= 2, got {K!r}")
            lv = np.linspace(0.0, 1.0, int(K))
        else:
            lv = as_float_array(levels, "levels").reshape(-1)
            if lv.size < 1 or np.any(np.diff(lv) <= 0) or lv[0] < 0.0 or lv[-1] > 1.0:
                raise NidarError("QuantileMap.fit: levels must be strictly increasing in [0, 1]")
        # np.quantile is monotone in the level up to rounding; make it exactly so.
        q_s = np.maximum.accumulate(np.quantile(src, lv))
        q_s, lv, q_r = _dedupe_knots(q_s, lv, ref)
        if q_s.size < 2:
            warnings.warn(
                "QuantileMap.fit: the source values are constant; the map is constant",
                stacklevel=2,
            )
        return cls(levels=lv, q_source=q_s, q_reference=q_r)

    def __call__(self, i: Any) -> np.ndarray:
        """Apply ``clip(interp(i, Q_s, Q_r), 0, 1)``.

        Args:
            i: values, any shape.

        Returns:
            float64 array of the same shape, in [0, 1] (NaN stays NaN).
        """
        x = as_float_array(i, "i")
        return np.clip(np.interp(x, self.q_source, self.q_reference), 0.0, 1.0)

    def to_dict(self) -> dict[str, list[float]]:
        """JSON-safe representation (plain lists of Python floats)."""
        return {
            "levels": self.levels.tolist(),
            "q_source": self.q_source.tolist(),
            "q_reference": self.q_reference.tolist(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> QuantileMap:
        """Inverse of :meth:`to_dict`; raises :class:`NidarError` on malformed input."""
        if not isinstance(data, Mapping):
            raise NidarError("QuantileMap: expected a mapping with levels/q_source/q_reference")
        missing = [k for k in ("levels", "q_source", "q_reference") if k not in data]
        if missing:
            raise NidarError(f"QuantileMap: missing key(s) {', '.join(missing)}")
        return cls(
            levels=as_float_array(data["levels"], "levels"),
            q_source=as_float_array(data["q_source"], "q_source"),
            q_reference=as_float_array(data["q_reference"], "q_reference"),
        )
