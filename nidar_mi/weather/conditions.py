"""The weather a scan or a render sees: fog by its visibility, rain and snow by their rate.

:class:`Weather` holds it; :meth:`Weather.from_mapping` reads it from a ``lidar`` sensor's XML
parameters (:data:`PARAMETERS`) and :func:`check_weather` refuses values that cannot be: one
line naming the parameter in backticks (the command line shows it as its flag).

================  =======  =======================================================================
parameter         unit     meaning
================  =======  =======================================================================
``fog``           m        meteorological optical range (MOR, WMO: the distance at which a black
                           object's contrast falls to 5 %, α(550 nm) = ln 20 / MOR), in
                           [:data:`MIN_MOR`, :data:`MAX_MOR`]; absent: no fog
``fog_type``      --       ``advection`` (default) or ``radiation``: the droplet sizes
                           (:mod:`.particles`)
``rain``          mm/h     rain rate, [0, :data:`MAX_RAIN`]; 0: none
``snow``          mm/h     snowfall rate as melted water, [0, :data:`MAX_SNOW`]; 0: none
================  =======  =======================================================================

Rain and snow do not fall together here (one precipitation at a time); either may fall in fog.
The upper rates are beyond the extremes on record, so that a typo is refused rather than
simulated: the world's greatest 1-hour rainfall is 305 mm (Holt, Missouri, 1947; WMO Weather and
Climate Extremes Archive); a snowfall of 50 mm/h of melted water would be ~0.5 m of fresh snow
per hour, several times the heaviest hourly snowfalls reported.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import NidarError
from .particles import FOG_TYPES

__all__ = [
    "PARAMETERS",
    "MIN_MOR",
    "MAX_MOR",
    "MAX_RAIN",
    "MAX_SNOW",
    "Weather",
    "check_weather",
]

#: XML parameter names of a ``lidar`` sensor read here.
PARAMETERS = ("fog", "fog_type", "rain", "snow")
#: Smallest meteorological optical range accepted, m.
MIN_MOR = 5.0
#: Largest meteorological optical range accepted, m (beyond it the air is clear).
MAX_MOR = 100_000.0
#: Largest rain rate accepted, mm/h.
MAX_RAIN = 300.0
#: Largest snowfall rate accepted (melted water), mm/h.
MAX_SNOW = 50.0


@dataclass(frozen=True)
class Weather:
    """Fog, rain and snow; None or 0 where absent (module docstring).

    Attributes:
        fog: meteorological optical range in m, or None.
        fog_type: ``advection`` or ``radiation``.
        rain: rain rate in mm/h, or None.
        snow: melted-equivalent snowfall rate in mm/h, or None.
    """

    fog: float | None = None
    fog_type: str = "advection"
    rain: float | None = None
    snow: float | None = None

    @property
    def clear(self) -> bool:
        """No fog, no rain, no snow."""
        return not (self.fog or self.rain or self.snow)

    @property
    def precipitation(self) -> str | None:
        """``rain``, ``snow`` or None."""
        if self.rain:
            return "rain"
        return "snow" if self.snow else None

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict (what a manifest records)."""
        return {"fog": self.fog, "fog_type": self.fog_type, "rain": self.rain, "snow": self.snow}

    def describe(self) -> str:
        """A short text: ``fog 50 m (advection), rain 10 mm/h``; ``clear``."""
        parts = []
        if self.fog:
            parts.append(f"fog {self.fog:g} m ({self.fog_type})")
        if self.rain:
            parts.append(f"rain {self.rain:g} mm/h")
        if self.snow:
            parts.append(f"snow {self.snow:g} mm/h")
        return ", ".join(parts) or "clear"

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any]) -> Weather | None:
        """The weather of raw parameter values (as read from XML; absent names: none), or None
        when it is clear.

        Raises:
            NidarError: a value that is not a number, out of range, or an unknown fog type.
        """
        fog_type = str(values.get("fog_type", "advection")).strip().lower()
        w = cls(
            fog=_number(values.get("fog"), "fog"),
            fog_type=fog_type,
            rain=_number(values.get("rain"), "rain"),
            snow=_number(values.get("snow"), "snow"),
        )
        check_weather(w)
        return None if w.clear else w


def _number(raw: Any, name: str) -> float | None:
    if raw is None:
        return None
    try:
        value = float(raw)
    except (TypeError, ValueError):
        raise NidarError(f"`{name}` must be a number (got '{raw}')") from None
    if isinstance(raw, bool) or not math.isfinite(value):
        raise NidarError(f"`{name}` must be a finite number (got '{raw}')")
    return value


def check_weather(w: Weather) -> Weather:
    """Refuse impossible weather (module docstring); returns ``w``.

    Raises:
        NidarError: one line naming the parameter in backticks.
    """
    for name, value in (("fog", w.fog), ("rain", w.rain), ("snow", w.snow)):
        if value is not None and (not isinstance(value, int | float) or not math.isfinite(value)):
            raise NidarError(f"`{name}` must be a finite number (got {value!r})")
    if w.fog is not None and not MIN_MOR <= w.fog <= MAX_MOR:
        why = "> 0" if w.fog <= 0 else f"in [{MIN_MOR:g}, {MAX_MOR:g}] m"
        raise NidarError(f"`fog` (meteorological optical range) must be {why} (got {w.fog:g} m)")
    for name, value, top in (("rain", w.rain, MAX_RAIN), ("snow", w.snow, MAX_SNOW)):
        if value is not None and not 0.0 <= value <= top:
            raise NidarError(f"`{name}` must be a rate in [0, {top:g}] mm/h (got {value:g})")
    if w.fog_type not in FOG_TYPES:
        raise NidarError(f"`fog_type` must be one of {', '.join(FOG_TYPES)} (got '{w.fog_type}')")
    if w.rain and w.snow:
        raise NidarError("`rain` and `snow` cannot fall together: give one of them")
    return w
