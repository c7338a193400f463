"""The ``physical`` profile form: the LiDAR equation in closed form, for a sensor not calibrated.

A sensor-profile form (:mod:`nidar_mi.profiles`). A model value ``v`` (reflectance-like, read as
a reflectance ``ρ = clip(v, 0, 1)``) at a return of range ``d`` (m) whose ray meets the surface
at ``c = |cos θ|`` becomes the intensity

    I = clip(k · ρ · c / max(d, d_min)^p, 0, 1)

* ``p = 2`` (``range_exponent``): a **raw** sensor, whose return power falls off as 1/d² for an
  extended target; ``k`` (``gain``, m^p) sets the level, and near, bright targets saturate at 1.
* ``p = 0``: a **range-compensated** sensor (the intensity a sensor reports after removing the
  range term, e.g. the simulator's ``sim-905``): ``I = clip(k · ρ · c, 0, 1)``.
* ``incidence=False`` drops ``c`` (a Lambertian target seen head-on).

``d_min`` (``min_range_m``) bounds the gain of returns closer than it. The form has no learned
part: the named profiles ``generic-raw`` and ``generic-compensated``
(:mod:`nidar_mi.datasets.sensor_profiles`) are closed forms of it. :meth:`PhysicalMap.fit` fits
``k`` (and, unless given, ``p``) on a sensor's returns by least squares on logarithms.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from ..errors import NidarError

__all__ = ["DEFAULT_MIN_RANGE_M", "PhysicalMap"]

#: Ranges below this (m) are read as this: the gain of a raw map stays bounded near the sensor.
DEFAULT_MIN_RANGE_M = 1.0
#: The largest range exponent a map may hold (a raw sensor's is 2).
_MAX_EXPONENT = 4.0


def _positive(name: str, x: Any) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        raise NidarError(f"physical map: '{name}' must be a number (got {x!r})") from None
    if not (np.isfinite(v) and v > 0):
        raise NidarError(f"physical map: '{name}' must be positive and finite (got {x!r})")
    return v


@dataclass(frozen=True)
class PhysicalFitOptions:
    """How a ``physical`` map is fitted (keyword options of :func:`nidar_mi.profiles.fit`).

    Attributes:
        range_exponent: the fall-off exponent ``p`` (None: fitted with the gain).
        min_range_m: ``d_min``, m.
    """

    range_exponent: float | None = None
    min_range_m: float = DEFAULT_MIN_RANGE_M


@dataclass(frozen=True)
class PhysicalMap:
    """``I = clip(gain · clip(v, 0, 1) · |cos θ| / max(d, min_range_m)^range_exponent, 0, 1)``
    (module docstring)."""

    #: The form's name in a profile file.
    form: ClassVar[str] = "physical"
    #: The options :func:`nidar_mi.profiles.fit` passes to :meth:`fit`.
    fit_options: ClassVar[type] = PhysicalFitOptions
    #: Whether the form can read the returns' incidence cosines.
    reads_incidence: ClassVar[bool] = True

    gain: float
    range_exponent: float = 0.0
    incidence: bool = True
    min_range_m: float = DEFAULT_MIN_RANGE_M

    def __post_init__(self) -> None:
        object.__setattr__(self, "gain", _positive("gain", self.gain))
        object.__setattr__(self, "min_range_m", _positive("min_range_m", self.min_range_m))
        p = self.range_exponent
        if isinstance(p, bool) or not isinstance(p, (int, float)) or not 0 <= p <= _MAX_EXPONENT:
            raise NidarError(
                f"physical map: 'range_exponent' must be a number in [0, {_MAX_EXPONENT:g}] "
                f"(got {p!r})"
            )
        object.__setattr__(self, "range_exponent", float(p))
        if not isinstance(self.incidence, bool):
            raise NidarError(
                f"physical map: 'incidence' must be true or false ({self.incidence!r})"
            )

    @property
    def uses_incidence(self) -> bool:
        """Whether calling the map needs the returns' incidence cosines."""
        return self.incidence

    @property
    def uses_geometry(self) -> bool:
        """Whether the map reads the range (a raw map)."""
        return self.range_exponent > 0

    def _response(self, d: np.ndarray, c: np.ndarray | None) -> np.ndarray:
        """(N,) ``gain · c / max(d, d_min)^p``: the intensity of a reflectance-1 target."""
        out = self.gain / np.maximum(d, self.min_range_m) ** self.range_exponent
        return out * c if c is not None else out

    def _cosines(self, cos_incidence: Any, n: int) -> np.ndarray | None:
        if not self.incidence:
            return None
        if cos_incidence is None:
            raise NidarError("this physical profile reads the incidence: give `cos_incidence`")
        c = np.asarray(cos_incidence, dtype=np.float64).reshape(-1)
        if c.shape != (n,) or not np.all(np.isfinite(c)):
            raise NidarError(f"physical map: {c.size} incidence cosines for {n} returns")
        return np.clip(np.abs(c), 0.0, 1.0)

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray:
        """(N,) float64 intensities in [0, 1] of values ``(N,)`` at ranges ``(N,)`` m (rings and
        elevations are not read; ``cos_incidence`` (N,) is required when :attr:`incidence`)."""
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        d = np.asarray(range_m, dtype=np.float64).reshape(-1)
        if v.shape != d.shape:
            raise NidarError(f"physical map: {v.size} values but {d.size} ranges")
        rho = np.clip(v, 0.0, 1.0)
        return np.clip(rho * self._response(d, self._cosines(cos_incidence, v.size)), 0.0, 1.0)

    def to_dict(self) -> dict[str, Any]:
        """The map's parameters (a profile file's ``mapping``)."""
        return {
            "gain": self.gain,
            "range_exponent": self.range_exponent,
            "incidence": self.incidence,
            "min_range_m": self.min_range_m,
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PhysicalMap:
        """Inverse of :meth:`to_dict`; :class:`NidarError` names a missing or bad field."""
        if not isinstance(data, Mapping):
            raise NidarError("physical map: the mapping is a JSON object")
        unknown = sorted(set(data) - {"gain", "range_exponent", "incidence", "min_range_m"})
        if unknown or "gain" not in data:
            what = f"unknown field(s) {', '.join(unknown)}" if unknown else "missing 'gain'"
            raise NidarError(f"physical map: {what}")
        return cls(
            gain=data["gain"],
            range_exponent=data.get("range_exponent", 0.0),
            incidence=data.get("incidence", True),
            min_range_m=data.get("min_range_m", DEFAULT_MIN_RANGE_M),
        )

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
        options: PhysicalFitOptions | None = None,
    ) -> PhysicalMap:
        """Fit ``gain`` (and ``range_exponent`` when None) by least squares of
        ``log I = log k + log(ρ c) - p log d`` on the returns with ``0 < I < 1`` and ``ρ c > 0``
        (saturated and dark returns say nothing of the level). With ``cos_incidence`` the map
        reads the incidence. ``ring``, ``elevation_deg`` and ``input`` are not read.

        Raises:
            NidarError: mismatched inputs, or fewer than 10 usable returns.
        """
        o = options or PhysicalFitOptions()
        range_exponent, min_range_m = o.range_exponent, o.min_range_m
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        d = np.maximum(np.asarray(range_m, dtype=np.float64).reshape(-1), min_range_m)
        y = np.asarray(intensity, dtype=np.float64).reshape(-1)
        if v.shape != d.shape or v.shape != y.shape:
            raise NidarError("physical map: values, ranges and intensities differ in length")
        f = np.clip(v, 0.0, 1.0)
        if cos_incidence is not None:
            f = f * np.clip(np.abs(np.asarray(cos_incidence, dtype=np.float64).reshape(-1)), 0, 1)
        ok = (y > 0) & (y < 1) & (f > 0) & np.isfinite(f) & np.isfinite(d)
        if ok.sum() < 10:
            raise NidarError(f"physical map: {int(ok.sum())} usable returns to fit (need 10)")
        target = np.log(y[ok]) - np.log(f[ok])
        logd = np.log(d[ok])
        if range_exponent is None:
            p = float(np.clip(-np.polyfit(logd, target, 1)[0], 0.0, _MAX_EXPONENT))
        else:
            p = float(range_exponent)
        gain = float(np.exp(np.mean(target + p * logd)))
        return cls(gain, p, cos_incidence is not None, min_range_m)
