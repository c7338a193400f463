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

from .echoes import RETURN_MODES
from .layouts import TABLE_FILES, LaserTable, preset_table, read_calibration, uniform_table
from .pattern import PRESETS, BeamPattern, parse_angles
from .return_model import INTENSITY_MODES

__all__ = ["LidarConfig", "PARAMETERS", "INTENSITY_MODES", "RETURN_MODES", "LAYOUTS", "SPINS"]

#: Values of ``layout``.
LAYOUTS = ("uniform", "per_laser")
#: Values of ``spin`` (seen from above).
SPINS = ("cw", "ccw")
#: Largest ``beam_sample_quality`` (1 + 3·q·(q-1) sub-rays per beam: 397 at 12).
MAX_SAMPLE_QUALITY = 12

#: XML parameter names a ``lidar`` sensor reads (``to_world`` is read by Mitsuba itself).
PARAMETERS = (
    "preset",
    "layout",
    "calibration_file",
    "elevation_angles",
    "horizontal_resolution",
    "fov_h",
    "fov_h_centred",
    "rotation_rate",
    "spin",
    "scan_start_azimuth",
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
    "beam_divergence",
    "beam_sample_quality",
    "return_mode",
    "return_separation",
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
    layout: str = "uniform"
    calibration_file: str | None = None
    fov_h_centred: bool = False
    rotation_rate: float = 10.0
    spin: str = "cw"
    scan_start_azimuth: float = 180.0
    beam_divergence: float = 0.0
    beam_sample_quality: int = 3
    return_mode: str = "strongest"
    return_separation: float = 0.5
    table: LaserTable | None = None

    @property
    def laser_table(self) -> LaserTable:
        """The per-laser layout (the uniform table unless ``layout`` is ``per_laser``)."""
        return self.table if self.table is not None else uniform_table(self.elevations_deg)

    @property
    def pattern(self) -> BeamPattern:
        """The beams of one sweep (directions, origins, firing times)."""
        return BeamPattern(
            self.laser_table,
            self.horizontal_resolution,
            fov_h=self.fov_h,
            start_deg=-self.fov_h / 2.0 if self.fov_h_centred else 0.0,
            rotation_rate=self.rotation_rate,
            spin=-1 if self.spin == "cw" else 1,
            scan_start_azimuth=self.scan_start_azimuth,
        )

    @property
    def subrays(self) -> int:
        """Sub-rays per beam: 1 without beam divergence, else 1 + 3·q·(q-1)."""
        if self.beam_divergence <= 0.0:
            return 1
        q = self.beam_sample_quality
        return 1 + 3 * q * (q - 1)

    @property
    def max_returns(self) -> int:
        """Returns per beam at most: 2 in ``dual`` mode with beam divergence, else 1."""
        return 2 if self.return_mode == "dual" and self.beam_divergence > 0.0 else 1

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
        d.pop("table")
        d["elevations_deg"] = list(self.elevations_deg)
        d["rings"] = self.rings
        d["subrays"] = self.subrays
        if self.table is not None:
            t = self.table
            d["laser_table"] = {
                "source": t.source,
                "laser_id": list(t.laser_id),
                "azimuth_offset_deg": list(t.azimuth_offset_deg),
                "vertical_offset_m": list(t.vertical_offset_m),
                "horizontal_offset_m": list(t.horizontal_offset_m),
                "firing_offset_s": list(t.firing_offset_s),
                "radial_offset_m": t.radial_offset_m,
                "z_offset_m": t.z_offset_m,
            }
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

        def choice(param: str, default: str, options: tuple[str, ...]) -> str:
            v = str(values.get(param, default)).strip().lower()
            if v not in options:
                raise fail(param, f"must be one of {', '.join(options)} (got '{v}')")
            return v

        def boolean(param: str, default: bool) -> bool:
            raw = values.get(param, default)
            if isinstance(raw, bool):
                return raw
            text = str(raw).strip().lower()
            if text not in ("true", "false"):
                raise fail(param, f"must be true or false (got '{raw}')")
            return text == "true"

        preset = values.get("preset")
        angles = values.get("elevation_angles")
        calib = values.get("calibration_file")
        if preset is None and angles is None and calib is None:
            preset = "vlp16"
        if preset is not None:
            preset = str(preset).strip().lower()
            if preset not in PRESETS:
                raise fail("preset", f"is unknown: '{preset}' (known: {', '.join(PRESETS)})")
        p = PRESETS[preset] if preset is not None else None
        layout = choice("layout", "per_laser" if calib is not None else "uniform", LAYOUTS)
        if angles is not None and (layout == "per_laser" or calib is not None):
            raise fail("elevation_angles", "cannot be combined with a per-laser layout")
        table = None
        if calib is not None:
            if layout != "per_laser":
                raise fail("calibration_file", "needs layout 'per_laser'")
            try:
                table = read_calibration(str(calib))
            except ValueError as e:
                raise fail("calibration_file", str(e)) from None
            if preset in TABLE_FILES:
                table = _with_preset_timing(table, preset_table(preset), fail)
        elif layout == "per_laser":
            if preset not in TABLE_FILES:
                known = ", ".join(TABLE_FILES)
                raise fail("layout", f"'per_laser' needs a preset with a table ({known})")
            table = preset_table(preset)
        if table is not None:
            elevations = table.elevation_deg
        elif angles is not None:
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
        mode = choice("intensity_mode", "raw", INTENSITY_MODES)
        quality = integer("beam_sample_quality", 3, lo=1)
        if quality > MAX_SAMPLE_QUALITY:
            raise fail("beam_sample_quality", f"must be <= {MAX_SAMPLE_QUALITY} (got {quality})")
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
            layout=layout,
            calibration_file=str(calib) if calib is not None else None,
            fov_h_centred=boolean("fov_h_centred", False),
            rotation_rate=number("rotation_rate", 10.0, lo=0.0, lo_open=True, hi=100.0),
            spin=choice("spin", "cw", SPINS),
            scan_start_azimuth=number("scan_start_azimuth", 180.0, lo=-360.0, hi=360.0),
            beam_divergence=number("beam_divergence", 0.0, lo=0.0, hi=100.0),
            beam_sample_quality=quality,
            return_mode=choice("return_mode", "strongest", RETURN_MODES),
            return_separation=number("return_separation", 0.5, lo=0.0, lo_open=True),
            table=table,
        )


def _with_preset_timing(table: LaserTable, preset: LaserTable, fail) -> LaserTable:
    """A calibration file's table with the firing offsets of the preset's lasers (by laser id)."""
    timing = dict(zip(preset.laser_id, preset.firing_offset_s))
    missing = sorted(set(table.laser_id) - set(timing))
    if len(table.laser_id) != len(preset.laser_id) or missing:
        raise fail(
            "calibration_file",
            f"has {len(table.laser_id)} lasers (ids {min(table.laser_id)}..{max(table.laser_id)}), "
            f"the preset {len(preset.laser_id)}: choose the matching preset or none",
        )
    return table.with_firing([timing[i] for i in table.laser_id])
