"""Validated parameters of a ``lidar`` sensor (the public scene-XML interface).

The parameters, their types, meanings, ranges and defaults are tabled in the docstring of the
plugin class, :class:`nidar_mi.plugins.lidar.LidarSensor`. Two pydantic
models enforce them: :class:`LayoutParameters` which lasers (preset, layout, angles, calibration
file, checked together), then :class:`SensorParameters` every other value, one by one, with the
preset's defaults. Ranges and choices are constraints of the fields' type hints (an
``Annotated`` pydantic ``Field``, a ``Literal``); validators remain only for what pydantic does
not parse (the comma-separated lists of the XML strings) and for rules between parameters.
:meth:`LidarConfig.from_mapping` turns the first error into the plugin's one-line message
(``lidar '<id>': parameter '<name>' <why>``, worded by :func:`nidar_mi.errors.validation_problem`)
and reads the laser table.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import asdict, dataclass
from typing import Annotated, Any, Literal

import numpy as np
from pydantic import (
    AfterValidator,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    ValidationInfo,
    model_validator,
)

from ..errors import NidarError, validation_problem
from .echoes import RETURN_MODES
from .layouts import TABLE_FILES, LaserTable, preset_table, read_calibration, uniform_table
from .pattern import PRESETS, BeamPattern, RisleyPattern, parse_angles
from .return_model import INTENSITY_MODES

__all__ = [
    "LidarConfig",
    "LayoutParameters",
    "SensorParameters",
    "PARAMETERS",
    "INTENSITY_MODES",
    "RETURN_MODES",
    "LAYOUTS",
    "SPINS",
]

#: Values of ``layout``.
LAYOUTS = ("uniform", "per_laser")
#: Values of ``spin`` (seen from above).
SPINS = ("cw", "ccw")
#: Largest ``beam_sample_quality`` (1 + 3·q·(q-1) sub-rays per beam: 397 at 12).
MAX_SAMPLE_QUALITY = 12
#: Largest per-laser range offset (``laser_range_offsets``), m.
MAX_RANGE_OFFSET_M = 1.0

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
    "laser_gains",
    "range_response",
    "laser_range_response",
    "intensity_offset",
    "laser_offsets",
    "laser_shadow",
    "laser_range_offsets",
    "range_min",
    "range_max",
    "atmospheric_extinction",
    "intensity_mode",
    "noise_intensity_std",
    "noise_range_std",
    "detection_threshold",
    "receiver_noise_std",
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
    receiver_noise_std: float = 0.0
    calibration_file: str | None = None
    fov_h_centred: bool = False
    rotation_rate: float = 10.0
    spin: str = "cw"
    scan_start_azimuth: float = 180.0
    beam_divergence: float = 0.0
    beam_sample_quality: int = 3
    return_mode: str = "strongest"
    return_separation: float = 0.5
    laser_gains: tuple[float, ...] | None = None
    range_response: tuple[tuple[float, float], ...] | None = None
    laser_range_response: tuple[tuple[float, ...], ...] | None = None
    intensity_offset: float = 0.0
    laser_offsets: tuple[float, ...] | None = None
    laser_shadow: tuple[tuple[int, float, float], ...] | None = None
    laser_range_offsets: tuple[float, ...] | None = None
    table: LaserTable | None = None

    @property
    def laser_table(self) -> LaserTable:
        """The per-laser layout (the uniform table unless ``layout`` is ``per_laser``)."""
        return self.table if self.table is not None else uniform_table(self.elevations_deg)

    @property
    def pattern(self) -> BeamPattern:
        """The beams of one sweep (directions, origins, firing times)."""
        prisms = PRESETS[self.preset].risley if self.preset is not None else None
        if prisms is not None and self.table is None:
            return RisleyPattern(
                self.laser_table,
                self.horizontal_resolution,
                rotation_rate=self.rotation_rate,
                prisms=prisms,
            )
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
    def frame_rate(self) -> float:
        """Frames per second, Hz: ``rotation_rate`` for a spinning head (one frame per turn) and
        a Risley sweep; ``rotation_rate · 360° / frame_sweep_deg`` for a preset whose frame is
        part of a beam turn (the ``at128``'s mirror facet: 6.67 Hz · 360 / 240 = 10 Hz)."""
        sweep = PRESETS[self.preset].frame_sweep_deg if self.preset is not None else 360.0
        return self.rotation_rate * 360.0 / sweep

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
            values: parameter name -> value; missing names take their defaults (unknown names
                are ignored).

        Raises:
            NidarError: one line naming the sensor and the offending parameter.
        """

        def fail(param: str, why: str) -> NidarError:
            return NidarError(f"lidar '{name}': parameter '{param}' {why}")

        try:
            lasers = LayoutParameters.model_validate(dict(values))
        except ValidationError as e:
            raise _first_error(e, fail, LayoutParameters) from None
        table = _laser_table(lasers, fail)
        try:
            given = lasers.defaults(values.get("intensity_mode", "raw")) | dict(values)
            v = SensorParameters.model_validate(given)
        except ValidationError as e:
            raise _first_error(e, fail, SensorParameters) from None
        # checked here, not in a model: the number of lasers is known once the table is read
        if table is not None:
            elevations = table.elevation_deg
        elif v.elevation_angles is not None:
            elevations = v.elevation_angles
        else:
            elevations = PRESETS[lasers.preset].elevations_deg
        if v.laser_gains is not None and len(v.laser_gains) != len(elevations):
            why = f"needs one gain per laser ({len(elevations)}, got {len(v.laser_gains)})"
            raise fail("laser_gains", why)
        if v.laser_offsets is not None and len(v.laser_offsets) != len(elevations):
            why = f"needs one offset per laser ({len(elevations)}, got {len(v.laser_offsets)})"
            raise fail("laser_offsets", why)
        if v.laser_shadow is not None and max(r for r, _, _ in v.laser_shadow) >= len(elevations):
            why = f"names a laser past the last ({len(elevations) - 1})"
            raise fail("laser_shadow", why)
        offsets = v.laser_range_offsets
        if offsets is not None and len(offsets) != len(elevations):
            why = f"needs one offset per laser ({len(elevations)}, got {len(offsets)})"
            raise fail("laser_range_offsets", why)
        shapes = v.laser_range_response
        if shapes is not None:
            if v.range_response is None:
                raise fail("laser_range_response", "needs range_response (its knots)")
            if len(shapes) != len(elevations):
                why = f"needs one row per laser ({len(elevations)}, got {len(shapes)})"
                raise fail("laser_range_response", why)
            if any(len(row) != len(v.range_response) for row in shapes):
                why = f"needs one factor per range_response knot ({len(v.range_response)}) a row"
                raise fail("laser_range_response", why)
        return cls(
            name=name,
            preset=lasers.preset if lasers.elevation_angles is None else None,
            elevations_deg=tuple(elevations),
            layout=lasers.layout,
            calibration_file=lasers.calibration_file,
            table=table,
            **v.model_dump(exclude={"elevation_angles"}),
        )


# --------------------------------------------------------------------------- one value each


class _Problem(ValueError):
    """A value refused by a validator: ``why`` in the plugin's words; ``param``, the parameter
    it names when not the field that raised it."""

    def __init__(self, why: str, param: str | None = None) -> None:
        super().__init__(why)
        self.why, self.param = why, param


def _not_bool(raw: Any) -> Any:
    """``raw``, unless a boolean (pydantic's lax mode reads ``true`` as the number 1)."""
    if isinstance(raw, bool):
        raise _Problem(f"should be a valid number (got {raw!r})")
    return raw


def _word(raw: Any) -> Any:
    """``raw`` in lower case without surrounding blanks when text (pydantic matches a
    ``Literal`` or a boolean's words as written; XML values are matched ignoring both)."""
    return raw.strip().lower() if isinstance(raw, str) else raw


#: A number parameter (finite: the models refuse inf and NaN; its interval: a ``Field``).
_Number = Annotated[float, BeforeValidator(_not_bool)]
#: A whole-number parameter (``10.0`` is 10, ``10.5`` is refused; its interval: a ``Field``).
_Whole = Annotated[int, BeforeValidator(_not_bool)]


# The three list parameters are comma-separated text in XML, which pydantic does not split:
# read by hand (their items' ranges, where a type can say them, stay in the field's type).


def _angles(raw: Any) -> tuple[float, ...] | None:
    if raw is None:
        return None
    try:
        return tuple(float(a) for a in parse_angles(str(raw)))
    except ValueError as e:
        raise _Problem(str(e)) from None


def _per_laser(bound: str):
    """A reader of comma-separated per-laser numbers (the field's type bounds each one;
    ``bound`` says how in the message)."""

    def read(raw: Any) -> tuple[float, ...] | None:
        if raw is None:
            return None
        try:
            values = tuple(float(g) for g in str(raw).replace(",", " ").split())
        except ValueError:
            values = ()
        if not values:
            raise _Problem(f"must be comma-separated numbers {bound}, one per laser (got '{raw}')")
        return values

    return read


def _shapes(raw: Any) -> tuple[tuple[float, ...], ...] | None:
    """Rows separated by ``;``, each comma-separated factors, finite and >= 0."""
    if raw is None:
        return None
    try:
        rows = tuple(
            tuple(float(f) for f in row.replace(",", " ").split())
            for row in str(raw).split(";")
            if row.strip()
        )
    except ValueError:
        rows = ()
    if not rows or not all(row and all(math.isfinite(f) and f >= 0 for f in row) for row in rows):
        raise _Problem(
            f"must be ';'-separated rows of comma-separated factors >= 0, one row per laser "
            f"(got '{str(raw)[:60]}')"
        )
    return rows


def _shadow(raw: Any) -> tuple[tuple[int, float, float], ...] | None:
    """``r:a0:a1`` triples, comma-separated: laser index r >= 0, azimuths -180 <= a0 < a1 <= 180
    (degrees)."""
    if raw is None:
        return None
    out = []
    for item in str(raw).replace(",", " ").split():
        parts = item.split(":")
        try:
            r, a0, a1 = int(parts[0]), float(parts[1]), float(parts[2])
        except (ValueError, IndexError):
            r, a0, a1 = -1, 0.0, 0.0
        if len(parts) != 3 or r < 0 or not -180.0 <= a0 < a1 <= 180.0:
            raise _Problem(
                "must be comma-separated 'laser:from:to' triples (laser index >= 0, azimuths "
                f"in degrees, -180 <= from < to <= 180; got '{item[:40]}')"
            )
        out.append((r, a0, a1))
    if not out:
        raise _Problem("must name at least one 'laser:from:to' interval")
    return tuple(out)


def _response(raw: Any) -> tuple[tuple[float, float], ...] | None:
    """``d:f`` pairs, comma-separated: ranges >= 0 strictly increasing, factors finite >= 0."""
    if raw is None:
        return None
    try:
        pairs = tuple(
            (float(a), float(b))
            for a, b in (p.split(":") for p in str(raw).replace(" ", "").split(",") if p)
        )
    except ValueError:
        raise _Problem(f"must be comma-separated range:factor pairs (got '{raw}')") from None
    d = [a for a, _ in pairs]
    if not pairs or not all(math.isfinite(a) and math.isfinite(b) and b >= 0 for a, b in pairs):
        raise _Problem("must hold finite range:factor pairs, factors >= 0")
    if d[0] < 0 or any(b <= a for a, b in zip(d, d[1:])):
        raise _Problem("needs ranges >= 0 in strictly increasing order")
    return pairs


#: A choice given in XML: case and surrounding blanks ignored.
_CHOICE = BeforeValidator(_word)


class LayoutParameters(BaseModel):
    """Which lasers a ``lidar`` sensor has: the preset, the layout, the elevation angles or the
    calibration file (meanings: :class:`nidar_mi.plugins.lidar.LidarSensor`).

    Each field takes the raw XML value; the model then fills in the preset (``vlp16`` when
    nothing names the lasers) and the layout (``per_laser`` for a preset with a published table
    or a calibration file), and checks that they go together.
    """

    model_config = ConfigDict(extra="ignore", coerce_numbers_to_str=True)

    preset: Annotated[Literal[tuple(PRESETS)] | None, _CHOICE] = None
    layout: Annotated[Literal[LAYOUTS] | None, _CHOICE] = None
    elevation_angles: str | None = None
    calibration_file: str | None = None

    @model_validator(mode="after")
    def _together(self) -> LayoutParameters:
        angles, calib = self.elevation_angles, self.calibration_file
        if self.preset is None and angles is None and calib is None:
            self.preset = "vlp16"
        # a preset with a published table casts it unless its uniform table is asked for (or
        # replaced by elevation_angles)
        real = calib is not None or (self.preset in TABLE_FILES and angles is None)
        if self.layout is None:
            self.layout = "per_laser" if real else "uniform"
        if angles is not None and (self.layout == "per_laser" or calib is not None):
            raise _Problem("cannot be combined with a per-laser layout", "elevation_angles")
        if calib is not None and self.layout != "per_laser":
            raise _Problem("needs layout 'per_laser'", "calibration_file")
        if calib is None and self.layout == "per_laser" and self.preset not in TABLE_FILES:
            known = ", ".join(TABLE_FILES)
            raise _Problem(f"'per_laser' needs a preset with a table ({known})", "layout")
        return self

    def defaults(self, intensity_mode: Any) -> dict[str, Any]:
        """The defaults of :class:`SensorParameters` that come from the preset (or the generic
        sensor without one), given the raw ``intensity_mode``."""
        p = PRESETS[self.preset] if self.preset is not None else None
        raw = str(intensity_mode).strip().lower() == "raw"
        return {
            "horizontal_resolution": p.horizontal_resolution if p else 1800,
            "range_min": p.range_min if p else 0.5,
            "range_max": p.range_max if p else 100.0,
            # the preset's threshold is in raw units (1/m²): it is the default in raw mode only
            "detection_threshold": p.detection_threshold if p and raw else 0.0,
            # the receiver noise belongs to the preset's receiver: kept when the threshold is set
            "receiver_noise_std": p.receiver_noise_std if p and raw else 0.0,
            "fov_h": p.fov_h if p else 360.0,
            "fov_h_centred": p.fov_h_centred if p else False,
            "rotation_rate": p.rotation_rate if p else 10.0,
            "scan_start_azimuth": p.scan_start_azimuth if p else 180.0,
        }


def _below_range_max(range_max: float, info: ValidationInfo) -> float:
    range_min = info.data.get("range_min")
    if range_min is not None and range_min >= range_max:
        why = f"must be < range_max (got {range_min:g} >= {range_max:g})"
        raise _Problem(why, "range_min")
    return range_max


class SensorParameters(BaseModel):
    """Every other parameter of a ``lidar`` sensor (meanings, units, ranges, defaults:
    :class:`nidar_mi.plugins.lidar.LidarSensor`), each checked alone from its raw XML value,
    in this order; ``range_min < range_max`` with ``range_max``, and a ``dual`` return mode
    with a beam divergence after all. The preset-dependent values have no default here:
    :meth:`LayoutParameters.defaults` gives them.
    """

    model_config = ConfigDict(extra="ignore", validate_default=True, allow_inf_nan=False)

    elevation_angles: Annotated[tuple[float, ...] | None, BeforeValidator(_angles)] = None
    horizontal_resolution: Annotated[_Whole, Field(ge=1)]
    fov_h: Annotated[_Number, Field(gt=0.0, le=360.0)] = 360.0
    wavelength: Annotated[_Number, Field(ge=360.0, le=1700.0)] = 905.0
    gain: Annotated[_Number, Field(gt=0.0)] = 1.0
    laser_gains: Annotated[
        tuple[Annotated[float, Field(gt=0.0)], ...] | None, BeforeValidator(_per_laser("> 0"))
    ] = None
    range_response: Annotated[
        tuple[tuple[float, float], ...] | None, BeforeValidator(_response)
    ] = None
    laser_range_response: Annotated[
        tuple[tuple[float, ...], ...] | None, BeforeValidator(_shapes)
    ] = None
    intensity_offset: Annotated[_Number, Field(ge=0.0)] = 0.0
    laser_offsets: Annotated[
        tuple[Annotated[float, Field(ge=0.0)], ...] | None, BeforeValidator(_per_laser(">= 0"))
    ] = None
    laser_shadow: Annotated[
        tuple[tuple[int, float, float], ...] | None, BeforeValidator(_shadow)
    ] = None
    laser_range_offsets: Annotated[
        tuple[Annotated[float, Field(ge=-MAX_RANGE_OFFSET_M, le=MAX_RANGE_OFFSET_M)], ...] | None,
        BeforeValidator(_per_laser(f"in [-{MAX_RANGE_OFFSET_M:g}, {MAX_RANGE_OFFSET_M:g}] m")),
    ] = None
    range_min: Annotated[_Number, Field(ge=0.0)]
    range_max: Annotated[_Number, Field(gt=0.0), AfterValidator(_below_range_max)]
    atmospheric_extinction: Annotated[_Number, Field(ge=0.0)] = 0.0
    intensity_mode: Annotated[Literal[INTENSITY_MODES], _CHOICE] = "raw"
    beam_sample_quality: Annotated[_Whole, Field(ge=1, le=MAX_SAMPLE_QUALITY)] = 3
    noise_intensity_std: Annotated[_Number, Field(ge=0.0)] = 0.0
    noise_range_std: Annotated[_Number, Field(ge=0.0)] = 0.0
    detection_threshold: Annotated[_Number, Field(ge=0.0)]
    receiver_noise_std: Annotated[_Number, Field(ge=0.0)]
    dropout: Annotated[_Number, Field(ge=0.0, le=1.0)] = 0.0
    seed: Annotated[_Whole, Field(ge=0)] = 0
    fov_h_centred: Annotated[bool, _CHOICE] = False
    rotation_rate: Annotated[_Number, Field(gt=0.0, le=100.0)] = 10.0
    spin: Annotated[Literal[SPINS], _CHOICE] = "cw"
    scan_start_azimuth: Annotated[_Number, Field(ge=-360.0, le=360.0)] = 180.0
    beam_divergence: Annotated[_Number, Field(ge=0.0, le=100.0)] = 0.0
    return_mode: Annotated[Literal[RETURN_MODES], _CHOICE] = "strongest"
    return_separation: Annotated[_Number, Field(gt=0.0)] = 0.5

    @model_validator(mode="after")
    def _dual_needs_divergence(self) -> SensorParameters:
        if self.return_mode == "dual" and self.beam_divergence <= 0.0:
            raise _Problem(
                "'dual' needs beam_divergence > 0 (a beam of no width has one return); set "
                "beam_divergence or choose strongest, first or last",
                "return_mode",
            )
        return self


def _first_error(
    error: ValidationError, fail: Callable[[str, str], NidarError], model: type[BaseModel]
) -> NidarError:
    """The first problem of a validation of ``model``, as the plugin's one-line message."""
    e = error.errors()[0]
    problem = (e.get("ctx") or {}).get("error")
    field = str(e["loc"][0]) if e["loc"] else "?"
    if not isinstance(problem, _Problem):  # a constraint of the field's type
        return fail(field, validation_problem(model, e))
    return fail(problem.param or field, problem.why)


# --------------------------------------------------------------------------- the laser table


def _laser_table(lasers: LayoutParameters, fail) -> LaserTable | None:
    """The per-laser table: the calibration file's (with the preset's firing times when the
    preset has a table), the preset's published one, or None for a uniform layout."""
    if lasers.calibration_file is not None:
        try:
            table = read_calibration(lasers.calibration_file)
        except ValueError as e:
            raise fail("calibration_file", str(e)) from None
        if lasers.preset in TABLE_FILES:
            table = _with_preset_timing(table, preset_table(lasers.preset), fail)
        return table
    if lasers.layout == "per_laser":
        return preset_table(lasers.preset)
    return None


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
