"""Validated parameters of a ``lidar`` sensor (the public scene-XML interface).

The parameters, their types, meanings, ranges and defaults are tabled in the docstring of the
plugin class, :class:`nidar_mi.plugins.lidar.LidarSensor`; :meth:`LidarConfig.from_mapping`
enforces them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from .pattern import PRESETS, parse_angles
from .return_model import INTENSITY_MODES

__all__ = ["LidarConfig", "PARAMETERS", "INTENSITY_MODES"]

#: XML parameter names a ``lidar`` sensor reads (``to_world`` is read by Mitsuba itself).
PARAMETERS = (
    "preset",
    "elevation_angles",
    "horizontal_resolution",
    "fov_h",
    "wavelength",
    "gain",
    "range_min",
    "range_max",
    "atmospheric_extinction",
    "intensity_mode",
    "noise_intensity_std",
    "noise_range_std",
    "detection_threshold",
    "dropout",
    "seed",
)


@dataclass(frozen=True)
class LidarConfig:
    """Resolved parameters of one LiDAR.

    Meanings, units and ranges: :class:`nidar_mi.plugins.lidar.LidarSensor`.
    """

    name: str
    preset: str | None
    elevations_deg: tuple[float, ...]
    horizontal_resolution: int
    fov_h: float
    wavelength: float
    gain: float
    range_min: float
    range_max: float
    atmospheric_extinction: float
    intensity_mode: str
    noise_intensity_std: float
    noise_range_std: float
    detection_threshold: float
    dropout: float
    seed: int

    @property
    def rings(self) -> int:
        """Number of channels (rows of the range image)."""
        return len(self.elevations_deg)

    @property
    def elevations(self) -> np.ndarray:
        """(R,) float64 ring elevations in degrees, ring 0 highest."""
        return np.asarray(self.elevations_deg, dtype=np.float64)

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dict of every parameter as resolved."""
        d = asdict(self)
        d["elevations_deg"] = list(self.elevations_deg)
        d["rings"] = self.rings
        return d

    @classmethod
    def from_mapping(cls, name: str, values: Mapping[str, Any]) -> LidarConfig:
        """Validate raw parameter values (as read from XML) and fill in defaults.

        Args:
            name: the sensor id, used in error messages.
            values: parameter name -> value; missing names take their defaults.

        Raises:
            ValueError: one line naming the sensor and the offending parameter.
        """

        def fail(param: str, why: str) -> ValueError:
            return ValueError(f"lidar '{name}': parameter '{param}' {why}")

        def number(param: str, default: float, *, lo=None, lo_open=False, hi=None) -> float:
            raw = values.get(param, default)
            try:
                v = float(raw)
            except (TypeError, ValueError):
                raise fail(param, f"must be a number (got '{raw}')") from None
            if isinstance(raw, bool) or not math.isfinite(v):
                raise fail(param, f"must be a finite number (got '{raw}')")
            if lo is not None and (v <= lo if lo_open else v < lo):
                raise fail(param, f"must be {'>' if lo_open else '>='} {lo:g} (got {v:g})")
            if hi is not None and v > hi:
                raise fail(param, f"must be <= {hi:g} (got {v:g})")
            return v

        def integer(param: str, default: int, *, lo: int) -> int:
            raw = values.get(param, default)
            try:
                f = float(raw)
            except (TypeError, ValueError):
                raise fail(param, f"must be an integer (got '{raw}')") from None
            if not math.isfinite(f) or f != int(f):
                raise fail(param, f"must be an integer (got '{raw}')")
            if int(f) < lo:
                raise fail(param, f"must be >= {lo} (got {int(f)})")
            return int(f)

        preset = values.get("preset")
        angles = values.get("elevation_angles")
        if preset is None and angles is None:
            preset = "vlp16"
        if preset is not None:
            preset = str(preset).strip().lower()
            if preset not in PRESETS:
                raise fail("preset", f"is unknown: '{preset}' (known: {', '.join(PRESETS)})")
        p = PRESETS[preset] if preset is not None else None
        if angles is not None:
            try:
                elevations = tuple(float(a) for a in parse_angles(str(angles)))
            except ValueError as e:
                raise fail("elevation_angles", str(e)) from None
        else:
            elevations = p.elevations_deg
        cols = integer("horizontal_resolution", p.horizontal_resolution if p else 1800, lo=1)
        fov_h = number("fov_h", 360.0, lo=0.0, lo_open=True, hi=360.0)
        wavelength = number("wavelength", 905.0, lo=360.0, hi=1700.0)
        gain = number("gain", 1.0, lo=0.0, lo_open=True)
        range_min = number("range_min", p.range_min if p else 0.5, lo=0.0)
        range_max = number("range_max", p.range_max if p else 100.0, lo=0.0, lo_open=True)
        if range_min >= range_max:
            raise fail("range_min", f"must be < range_max (got {range_min:g} >= {range_max:g})")
        alpha = number("atmospheric_extinction", 0.0, lo=0.0)
        mode = str(values.get("intensity_mode", "raw")).strip().lower()
        if mode not in INTENSITY_MODES:
            raise fail(
                "intensity_mode", f"must be one of {', '.join(INTENSITY_MODES)} (got '{mode}')"
            )
        return cls(
            name=name,
            preset=preset if angles is None else None,
            elevations_deg=tuple(elevations),
            horizontal_resolution=cols,
            fov_h=fov_h,
            wavelength=wavelength,
            gain=gain,
            range_min=range_min,
            range_max=range_max,
            atmospheric_extinction=alpha,
            intensity_mode=mode,
            noise_intensity_std=number("noise_intensity_std", 0.0, lo=0.0),
            noise_range_std=number("noise_range_std", 0.0, lo=0.0),
            # the preset's threshold is in raw units (1/m²): it is the default in raw mode only
            detection_threshold=number(
                "detection_threshold",
                p.detection_threshold if p and mode == "raw" else 0.0,
                lo=0.0,
            ),
            dropout=number("dropout", 0.0, lo=0.0, hi=1.0),
            seed=integer("seed", 0, lo=0),
        )
