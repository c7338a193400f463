"""The ``distance_quantile`` profile form: the paper's distance encoding and quantile remapping.

This is §III.E of the NIDAR paper (the source-domain distribution calibration). A per-point
branch value ``i`` (the reflectance-like ``R`` branch sampled at the point; see
:mod:`nidar_mi.geometry.fusion`) is turned into an intensity in two steps, both fitted offline
on the training split and then held fixed:

1. **Distance encoding** (paper Eq. dist_encode), a first-order range attenuation::

       t   = clip((d - d_min) / (d_max - d_min), 0, 1)
       i_d = clip(i + (R_min - i) * t, 0, 1),   R_min = 0 if i <= tau else r_retro

   ``d`` is the Euclidean distance of the point from the LiDAR origin in metres. The paper
   states ``t`` is "in [0, 1]"; points closer than ``d_min`` or farther than ``d_max`` are
   therefore clamped to ``t = 0`` and ``t = 1`` (no extrapolation).

2. **Quantile remapping** (paper Eq. quantile), ``i' = clip(interp(i_d, Q_s, Q_r), 0, 1)``,
   where ``Q_s`` and ``Q_r`` are quantiles of the distance-encoded predictions and of the
   source-domain LiDAR intensities at fixed levels ``q_k``.

The map is meant for the ``R`` branch; the direct dense head ``Î`` is reported raw unless a
result is explicitly labelled as a post-hoc diagnostic. It reads the value and the range only
(no ring, elevation or incidence).

A weights folder keeps the map fitted on its training split as ``calibration.json``
(:meth:`DistanceQuantileMap.save_json`, schema ``nidar_mi.calibration/1``); in a sensor-profile
file the same fields, less the schema, are the ``mapping``.

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
from typing import Any, ClassVar

import numpy as np

from ..errors import NidarError
from ..io.atomic import atomic_write_json
from .quantile_map import DEFAULT_K, QuantileMap, as_float_array

__all__ = [
    "CALIBRATION_SCHEMA",
    "DEFAULT_K",
    "DEFAULT_RANGE_QUANTILES",
    "DEFAULT_R_RETRO",
    "DEFAULT_TAU",
    "DistanceQuantileFitOptions",
    "DistanceQuantileMap",
    "distance_encode",
]

DEFAULT_TAU = 0.8
"""Diffuse / retro-reflective threshold on the branch value (not given in the paper)."""
DEFAULT_R_RETRO = 0.8
"""Far-range floor ``R_min`` of retro-reflective values (not given in the paper)."""
DEFAULT_RANGE_QUANTILES = (0.01, 0.99)
"""Quantiles of the training distances that define ``(d_min, d_max)``."""

#: Schema of a weights folder's ``calibration.json``.
CALIBRATION_SCHEMA = "nidar_mi.calibration/1"


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
    i = as_float_array(i, "i")
    d = as_float_array(d, "d")
    t = np.clip((d - d_min) / (d_max - d_min), 0.0, 1.0)
    r_min = np.where(i <= tau, 0.0, float(r_retro))
    return np.clip(i + (r_min - i) * t, 0.0, 1.0)


@dataclass(frozen=True)
class DistanceQuantileFitOptions:
    """How a ``distance_quantile`` map is fitted (keyword options of
    :func:`nidar_mi.profiles.fit`).

    Attributes:
        tau: diffuse / retro-reflective threshold.
        r_retro: far-range floor of retro-reflective values.
        range_quantiles: ``(lo, hi)`` quantile levels of ``range_m`` giving ``d_min, d_max``,
            ``0 <= lo < hi <= 1``.
        K: number of quantile levels when ``levels`` is None.
        levels: optional explicit quantile levels.
    """

    tau: float = DEFAULT_TAU
    r_retro: float = DEFAULT_R_RETRO
    range_quantiles: tuple[float, float] = DEFAULT_RANGE_QUANTILES
    K: int = DEFAULT_K
    levels: Any = None


@dataclass(frozen=True, eq=False)
class DistanceQuantileMap:
    """Fitted distance encoding plus quantile map, applied to per-point branch values.

    Attributes:
        d_min: start of the distance modulation in metres.
        d_max: end of the distance modulation in metres (> ``d_min``).
        tau: diffuse / retro-reflective threshold on the branch value.
        r_retro: far-range floor of retro-reflective values.
        quantile_map: the fitted :class:`~nidar_mi.profiles.quantile_map.QuantileMap`.
        branch: the value the map was fitted on (``"R"`` in the paper; a profile's ``input``).
    """

    #: The form's name in a profile file.
    form: ClassVar[str] = "distance_quantile"
    #: Whether the form can read the returns' incidence cosines.
    reads_incidence: ClassVar[bool] = False
    #: The keyword options of its :meth:`fit`.
    fit_options: ClassVar[type] = DistanceQuantileFitOptions

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
                raise NidarError(f"distance_quantile: {name} must be a number") from None
            if not np.isfinite(value):
                raise NidarError(f"distance_quantile: {name} must be finite")
            object.__setattr__(self, name, value)
        if not self.d_max > self.d_min:
            raise NidarError(
                f"distance_quantile: need d_max > d_min, got {self.d_min}, {self.d_max}"
            )
        if not isinstance(self.quantile_map, QuantileMap):
            raise NidarError("distance_quantile: quantile_map must be a QuantileMap")

    @property
    def uses_incidence(self) -> bool:
        """False: the map reads the value and the range only."""
        return False

    def encode(self, values: Any, distances: Any) -> np.ndarray:
        """:func:`distance_encode` with this map's parameters."""
        return distance_encode(
            values,
            distances,
            d_min=self.d_min,
            d_max=self.d_max,
            tau=self.tau,
            r_retro=self.r_retro,
        )

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray:
        """Intensities of returns: the quantile map of the distance-encoded values.

        Args:
            values: (N,) branch values at the returns.
            range_m: (N,) their distances from the LiDAR origin, m.
            ring, elevation_deg, cos_incidence: ignored (the form reads value and range only).

        Returns:
            (N,) float64 in [0, 1] (NaN stays NaN).

        Raises:
            NidarError: mismatched lengths.
        """
        v = as_float_array(values, "values").reshape(-1)
        d = as_float_array(range_m, "range_m").reshape(-1)
        if d.shape != v.shape:
            raise NidarError(f"distance_quantile: {v.size} values but {d.size} distances")
        return self.quantile_map(self.encode(v, d))

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe representation: a profile's ``mapping`` (``calibration.json`` less its
        schema)."""
        return {
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
    def from_dict(cls, data: Mapping[str, Any]) -> DistanceQuantileMap:
        """Inverse of :meth:`to_dict` (a ``schema`` key, when present, must be
        :data:`CALIBRATION_SCHEMA`); raises :class:`NidarError` on malformed input."""
        if not isinstance(data, Mapping):
            raise NidarError("expected an object")
        if data.get("schema", CALIBRATION_SCHEMA) != CALIBRATION_SCHEMA:
            raise NidarError(f"calibration: expected a mapping with schema {CALIBRATION_SCHEMA!r}")
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
        """Write the map as a ``calibration.json`` (with its schema), atomically."""
        atomic_write_json(path, {"schema": CALIBRATION_SCHEMA} | self.to_dict())

    @classmethod
    def load_json(cls, path: str | os.PathLike[str]) -> DistanceQuantileMap:
        """Read a ``calibration.json`` (:meth:`save_json`); :class:`NidarError` if invalid."""
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except OSError as exc:
            raise NidarError(f"{path}: cannot read calibration: {exc.strerror}") from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise NidarError(f"{path}: not valid JSON: {exc}") from None
        try:
            if not isinstance(data, Mapping) or data.get("schema") != CALIBRATION_SCHEMA:
                raise NidarError(
                    f"calibration: expected a mapping with schema {CALIBRATION_SCHEMA!r}"
                )
            return cls.from_dict(data)
        except NidarError as exc:
            raise NidarError(f"{path}: {exc}") from None

    @classmethod
    def fit(
        cls,
        values: Any,
        range_m: Any,
        intensity: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
        input: str = "R",
        options: DistanceQuantileFitOptions | None = None,
    ) -> DistanceQuantileMap:
        """Fit the map on training points (:func:`nidar_mi.profiles.fit` is the entry point).

        ``d_min, d_max`` are the ``range_quantiles`` of ``range_m``; the values are
        distance-encoded with them and the quantile map is fitted from the encoded values to
        the LiDAR intensities. Only observed training points should be passed.

        Args:
            values: (N,) branch values sampled at training points.
            range_m: (N,) their distances from the LiDAR origin in metres.
            intensity: (M,) source-domain LiDAR intensities on the [0, 1] scale (usually the
                same N points, but the pairing is not used: only the distribution matters).
            ring, elevation_deg, cos_incidence: not read by this form.
            input: the value the map is fitted on, stored as its ``branch``.
            options: the fitting options (:class:`DistanceQuantileFitOptions`; default its
                defaults).

        Raises:
            NidarError: on mismatched, empty or non-finite inputs, or a degenerate range.
        """
        o = options or DistanceQuantileFitOptions()
        tau, r_retro, range_quantiles = o.tau, o.r_retro, o.range_quantiles
        pred = as_float_array(values, "values").reshape(-1)
        dist = as_float_array(range_m, "range_m").reshape(-1)
        ref = as_float_array(intensity, "intensity").reshape(-1)
        if pred.shape != dist.shape:
            raise NidarError(f"fit distance_quantile: {pred.size} values but {dist.size} distances")
        if pred.size == 0:
            raise NidarError("fit distance_quantile: no training points")
        if not (np.all(np.isfinite(pred)) and np.all(np.isfinite(dist))):
            raise NidarError("fit distance_quantile: values or distances contain NaN or inf")
        lo, hi = (float(q) for q in range_quantiles)
        if not 0.0 <= lo < hi <= 1.0:
            raise NidarError(f"fit distance_quantile: bad range_quantiles {range_quantiles!r}")
        if ref.size and (np.nanmin(ref) < 0.0 or np.nanmax(ref) > 1.0):
            warnings.warn(
                "fit distance_quantile: LiDAR intensities outside [0, 1]; the output is "
                "clipped to [0, 1]",
                stacklevel=2,
            )
        d_min, d_max = (float(x) for x in np.quantile(dist, [lo, hi]))
        if not d_max > d_min:
            raise NidarError(
                f"fit distance_quantile: training distances span no range ({d_min} m to {d_max} m)"
            )
        encoded = distance_encode(pred, dist, d_min=d_min, d_max=d_max, tau=tau, r_retro=r_retro)
        qmap = QuantileMap.fit(encoded, ref, K=o.K, levels=o.levels)
        return cls(
            d_min=d_min, d_max=d_max, tau=tau, r_retro=r_retro, quantile_map=qmap, branch=input
        )
