"""Source-domain distribution calibration: distance encoding and quantile remapping.

This is §III.D of the NIDAR paper. A per-point branch value ``i`` (the reflectance-like ``R``
branch sampled at the point; see :mod:`nidar_mi.geometry.fusion`) is turned into an
intensity in two steps, both fitted offline on the training split and then held fixed:

1. **Distance encoding** (paper Eq. dist_encode), a first-order range attenuation::

       t   = clip((d - d_min) / (d_max - d_min), 0, 1)
       i_d = clip(i + (R_min - i) * t, 0, 1),   R_min = 0 if i <= tau else r_retro

   ``d`` is the Euclidean distance of the point from the LiDAR origin in metres. The paper
   states ``t`` is "in [0, 1]"; points closer than ``d_min`` or farther than ``d_max`` are
   therefore clamped to ``t = 0`` and ``t = 1`` (no extrapolation).

2. **Quantile remapping** (paper Eq. quantile), ``i' = clip(interp(i_d, Q_s, Q_r), 0, 1)``,
   where ``Q_s`` and ``Q_r`` are quantiles of the distance-encoded predictions and of the
   source-domain LiDAR intensities at fixed levels ``q_k``.

The calibration is meant for the ``R`` branch; the direct dense head ``Î`` is reported raw
unless a result is explicitly labelled as a post-hoc diagnostic. Points that no camera
observed receive intensity 0 and ``observed = False``.

The paper publishes neither ``tau`` and ``r_retro`` nor ``K``. The defaults here are
:data:`DEFAULT_TAU` = 0.8, :data:`DEFAULT_R_RETRO` = 0.8 (equal to ``tau``, so a value
classified retro-reflective never decays below the diffuse/retro threshold at any
distance, whereas diffuse values decay to 0 at ``d_max``) and :data:`DEFAULT_K` = 101
levels ``q_k = 0, 0.01, ..., 1`` (percentiles). ``d_min``/``d_max`` are fitted as the
:data:`DEFAULT_RANGE_QUANTILES` (1 % and 99 %) of the training distances.
"""

from __future__ import annotations

import json
import os
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from nidar_mi.errors import NidarError
from nidar_mi.io.atomic import atomic_write_json

__all__ = [
    "DEFAULT_K",
    "DEFAULT_RANGE_QUANTILES",
    "DEFAULT_R_RETRO",
    "DEFAULT_TAU",
    "Calibration",
    "QuantileMap",
    "distance_encode",
    "fit_calibration",
]

DEFAULT_TAU = 0.8
"""Diffuse / retro-reflective threshold on the branch value (not given in the paper)."""
DEFAULT_R_RETRO = 0.8
"""Far-range floor ``R_min`` of retro-reflective values (not given in the paper)."""
DEFAULT_K = 101
"""Number of quantile levels; default levels are ``linspace(0, 1, K)``."""
DEFAULT_RANGE_QUANTILES = (0.01, 0.99)
"""Quantiles of the training distances that define ``(d_min, d_max)``."""

_SCHEMA = "nidar_mi.calibration/1"


def _as_float_array(x: Any, name: str) -> np.ndarray:
    try:
        arr = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise NidarError(f"{name} must be numeric: {exc}") from None
    return arr


def distance_encode(
    i: Any, d: Any, *, d_min: float, d_max: float, tau: float, r_retro: float
) -> np.ndarray:
    """Distance-dependent linear modulation of branch values (paper Eq. dist_encode).

    ``i_d = clip(i + (R_min - i) * t, 0, 1)`` with ``t = clip((d - d_min) / (d_max - d_min), 0, 1)``
    and ``R_min = 0`` where ``i <= tau`` (diffuse), ``r_retro`` elsewhere (retro-reflective).

    Args:
        i: branch values, any shape, nominally in [0, 1].
        d: point distances from the LiDAR origin in metres, broadcastable to ``i``.
        d_min: distance (m) at which the modulation starts (``t = 0``).
        d_max: distance (m) at which ``i_d = R_min`` (``t = 1``); must exceed ``d_min``.
        tau: diffuse / retro-reflective threshold on ``i``.
        r_retro: ``R_min`` for retro-reflective values.

    Returns:
        ``i_d`` as float64 with the broadcast shape of ``i`` and ``d``, in [0, 1]
        (NaN inputs stay NaN).

    Raises:
        NidarError: if ``d_max <= d_min`` or a parameter is not finite.
    """
    params = {"d_min": d_min, "d_max": d_max, "tau": tau, "r_retro": r_retro}
    for name, value in params.items():
        if not np.isfinite(value):
            raise NidarError(f"distance_encode: {name} must be finite, got {value!r}")
    if not d_max > d_min:
        raise NidarError(f"distance_encode: need d_max > d_min, got {d_min!r}, {d_max!r}")
    i = _as_float_array(i, "i")
    d = _as_float_array(d, "d")
    t = np.clip((d - d_min) / (d_max - d_min), 0.0, 1.0)
    r_min = np.where(i <= tau, 0.0, float(r_retro))
    return np.clip(i + (r_min - i) * t, 0.0, 1.0)


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
        src = _as_float_array(source_values, "source_values").reshape(-1)
        ref = _as_float_array(reference_values, "reference_values").reshape(-1)
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
            lv = _as_float_array(levels, "levels").reshape(-1)
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
        x = _as_float_array(i, "i")
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
            levels=_as_float_array(data["levels"], "levels"),
            q_source=_as_float_array(data["q_source"], "q_source"),
            q_reference=_as_float_array(data["q_reference"], "q_reference"),
        )


@dataclass(frozen=True, eq=False)
class Calibration:
    """Fitted distance encoding plus quantile map, applied to per-point branch values.

    Attributes:
        d_min: start of the distance modulation in metres.
        d_max: end of the distance modulation in metres (> ``d_min``).
        tau: diffuse / retro-reflective threshold on the branch value.
        r_retro: far-range floor of retro-reflective values.
        quantile_map: the fitted :class:`QuantileMap`.
        branch: which network output the calibration was fitted for (``"R"`` in the paper).
    """

    d_min: float
    d_max: float
    tau: float
    r_retro: float
    quantile_map: QuantileMap
    branch: str = field(default="R")

    def __post_init__(self) -> None:
        for name in ("d_min", "d_max", "tau", "r_retro"):
            try:
                value = float(getattr(self, name))
            except (TypeError, ValueError):
                raise NidarError(f"Calibration: {name} must be a number") from None
            if not np.isfinite(value):
                raise NidarError(f"Calibration: {name} must be finite")
            object.__setattr__(self, name, value)
        if not self.d_max > self.d_min:
            raise NidarError(f"Calibration: need d_max > d_min, got {self.d_min}, {self.d_max}")
        if not isinstance(self.quantile_map, QuantileMap):
            raise NidarError("Calibration: quantile_map must be a QuantileMap")

    def encode(self, values: Any, distances: Any) -> np.ndarray:
        """:func:`distance_encode` with this calibration's parameters."""
        return distance_encode(
            values,
            distances,
            d_min=self.d_min,
            d_max=self.d_max,
            tau=self.tau,
            r_retro=self.r_retro,
        )

    def apply(
        self, values: Any, distances: Any, observed: Any = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """Distance-encode and remap the observed points.

        Args:
            values: (N,) branch values sampled at the points.
            distances: (N,) distances of the points from the LiDAR origin in metres.
            observed: (N,) bool, points that a camera observed; None means all.

        Returns:
            ``(intensity, observed)``: (N,) float32 in [0, 1], 0 where not observed, and the
            (N,) bool mask actually used: the input mask minus points whose value or
            distance is not finite.
        """
        v = _as_float_array(values, "values").reshape(-1)
        d = _as_float_array(distances, "distances").reshape(-1)
        if d.shape != v.shape:
            raise NidarError(f"Calibration.apply: {v.size} values but {d.size} distances")
        if observed is None:
            obs = np.ones(v.shape, dtype=bool)
        else:
            obs = np.asarray(observed, dtype=bool).reshape(-1)
            if obs.shape != v.shape:
                raise NidarError(f"Calibration.apply: {v.size} values but {obs.size} flags")
        obs = obs & np.isfinite(v) & np.isfinite(d)
        out = np.zeros(v.shape, dtype=np.float32)
        out[obs] = self.quantile_map(self.encode(v[obs], d[obs])).astype(np.float32)
        return out, obs

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation, including a schema tag."""
        return {
            "schema": _SCHEMA,
            "branch": self.branch,
            "distance_encoding": {
                "d_min": self.d_min,
                "d_max": self.d_max,
                "tau": self.tau,
                "r_retro": self.r_retro,
            },
            "quantile_map": self.quantile_map.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Calibration:
        """Inverse of :meth:`to_dict`; raises :class:`NidarError` on malformed input."""
        if not isinstance(data, Mapping) or data.get("schema") != _SCHEMA:
            raise NidarError(f"calibration: expected a mapping with schema {_SCHEMA!r}")
        enc = data.get("distance_encoding")
        if not isinstance(enc, Mapping):
            raise NidarError("calibration: missing 'distance_encoding'")
        try:
            params = {k: enc[k] for k in ("d_min", "d_max", "tau", "r_retro")}
        except KeyError as exc:
            raise NidarError(f"calibration: distance_encoding lacks {exc.args[0]!r}") from None
        return cls(
            **params,
            quantile_map=QuantileMap.from_dict(data.get("quantile_map")),
            branch=str(data.get("branch", "R")),
        )

    def save_json(self, path: str | os.PathLike[str]) -> None:
        """Write the calibration as JSON, atomically (temp file then ``os.replace``)."""
        atomic_write_json(path, self.to_dict())

    @classmethod
    def load_json(cls, path: str | os.PathLike[str]) -> Calibration:
        """Read a file written by :meth:`save_json`; raises :class:`NidarError` if invalid."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except OSError as exc:
            raise NidarError(f"{path}: cannot read calibration: {exc.strerror}") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise NidarError(f"{path}: not valid JSON: {exc}") from None
        try:
            return cls.from_dict(data)
        except NidarError as exc:
            raise NidarError(f"{path}: {exc}") from None


def fit_calibration(
    pred_values: Any,
    distances: Any,
    lidar_intensity: Any,
    *,
    tau: float = DEFAULT_TAU,
    r_retro: float = DEFAULT_R_RETRO,
    range_quantiles: tuple[float, float] = DEFAULT_RANGE_QUANTILES,
    K: int = DEFAULT_K,
    levels: Any = None,
    branch: str = "R",
) -> Calibration:
    """Fit a :class:`Calibration` on training points.

    ``d_min, d_max`` are the ``range_quantiles`` of ``distances``; the predictions are
    distance-encoded with them and the quantile map is fitted from the encoded predictions
    to the LiDAR intensities. Only observed training points should be passed.

    Args:
        pred_values: (N,) branch values sampled at training points.
        distances: (N,) their distances from the LiDAR origin in metres.
        lidar_intensity: (M,) source-domain LiDAR intensities on the [0, 1] scale (usually the
            same N points, but the pairing is not used: only the distribution matters).
        tau: diffuse / retro-reflective threshold.
        r_retro: far-range floor of retro-reflective values.
        range_quantiles: ``(lo, hi)`` quantile levels of ``distances``, ``0 <= lo < hi <= 1``.
        K: number of quantile levels when ``levels`` is None.
        levels: optional explicit quantile levels.
        branch: label stored with the calibration.

    Returns:
        The fitted calibration.

    Raises:
        NidarError: on mismatched, empty or non-finite inputs, or a degenerate range.
    """
    pred = _as_float_array(pred_values, "pred_values").reshape(-1)
    dist = _as_float_array(distances, "distances").reshape(-1)
    ref = _as_float_array(lidar_intensity, "lidar_intensity").reshape(-1)
    if pred.shape != dist.shape:
        raise NidarError(f"fit_calibration: {pred.size} predictions but {dist.size} distances")
    if pred.size == 0:
        raise NidarError("fit_calibration: no training points")
    if not (np.all(np.isfinite(pred)) and np.all(np.isfinite(dist))):
        raise NidarError("fit_calibration: predictions or distances contain NaN or inf")
    lo, hi = (float(q) for q in range_quantiles)
    if not 0.0 <= lo < hi <= 1.0:
        raise NidarError(f"fit_calibration: bad range_quantiles {range_quantiles!r}")
    if ref.size and (np.nanmin(ref) < 0.0 or np.nanmax(ref) > 1.0):
        warnings.warn(
            "fit_calibration: LiDAR intensities outside [0, 1]; the calibrated output is "
            "clipped to [0, 1]",
            stacklevel=2,
        )
    d_min, d_max = (float(x) for x in np.quantile(dist, [lo, hi]))
    if not d_max > d_min:
        raise NidarError(
            f"fit_calibration: training distances span no range ({d_min} m to {d_max} m)"
        )
    encoded = distance_encode(pred, dist, d_min=d_min, d_max=d_max, tau=tau, r_retro=r_retro)
    qmap = QuantileMap.fit(encoded, ref, K=K, levels=levels)
    return Calibration(
        d_min=d_min, d_max=d_max, tau=tau, r_retro=r_retro, quantile_map=qmap, branch=branch
    )
