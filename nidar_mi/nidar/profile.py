"""Sensor profiles: how one sensor turns a surface's model value into its intensity.

NIDAR's networks rank surfaces (a reflectance-like value per pixel); how bright a return of a
given surface comes out depends on the sensor: its range response (some sensors report
range-compensated intensity, some do not), per-laser gains, its intensity scale. A sensor
profile holds that part, fitted on the sensor's own scans
(``python -m nidar_mi.calibrate``) and kept out of the model. Three forms:

* ``distance_quantile``: the paper's (§III.E) distance encoding and quantile map
  (:class:`nidar_mi.nidar.calibration.Calibration`);
* ``range_ring``: a monotone map of the model value per range bin and a gain per ring
  (:class:`nidar_mi.nidar.range_ring.RangeRingMap`);
* ``gbm``: a gradient-boosted regression of the intensity on the value, the range and the
  elevation, monotone in the value, or on the range and elevation alone; optionally also on
  the incidence ``|cos θ|`` of the ray on the surface, estimated from the scan's own points;
  or on the value and the incidence alone, without range and elevation
  (:class:`nidar_mi.nidar.gbm_profile.GbmMap`; LightGBM's text model in the file).

**File format** (JSON, UTF-8)::

    {
      "schema": "nidar_mi.sensor_profile/1",
      "name": "kitti-hdl64e",                 # letters, digits, '-', '_', '.'
      "sensor": "Velodyne HDL-64E (KITTI)",   # free text
      "form": "range_ring",                   # or "distance_quantile", "gbm"
      "input": "nidar:R",                     # the value it maps (nidar:<branch>, or a baseline)
      "model": {"irnet_sha256": "...", "stn_sha256": "..."},   # or null: any model
      "mapping": {...},                       # the form's parameters (its to_dict())
      "provenance": {...}                     # data, frames, returns, command, numbers (free)
    }

:func:`load_profile` checks every field and names the file and the field in a one-line error.
Applying a profile to values that are not finite is an error, never a silent NaN.
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import NidarError
from .calibration import Calibration, fit_calibration
from .gbm_profile import GbmMap, fit_gbm
from .range_ring import RangeRingMap, fit_range_ring

__all__ = [
    "PROFILE_FORMS",
    "PROFILE_SCHEMA",
    "SensorProfile",
    "fit_profile",
    "load_profile",
]

PROFILE_SCHEMA = "nidar_mi.sensor_profile/1"
#: The forms a profile can take and their mapping classes.
PROFILE_FORMS = {"distance_quantile": Calibration, "range_ring": RangeRingMap, "gbm": GbmMap}
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


@dataclass(frozen=True, eq=False)
class SensorProfile:
    """A fitted sensor profile (module docstring for the fields)."""

    name: str
    sensor: str
    form: str
    input: str
    mapping: Calibration | RangeRingMap | GbmMap
    model: dict[str, str] | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise NidarError(
                f"profile name must be letters, digits, '-', '_', '.' (got {self.name!r})"
            )
        if self.form not in PROFILE_FORMS:
            raise NidarError(
                f"profile form must be one of {', '.join(PROFILE_FORMS)} (got {self.form!r})"
            )
        if not isinstance(self.mapping, PROFILE_FORMS[self.form]):
            raise NidarError(
                f"profile {self.name}: a {self.form} profile needs a {PROFILE_FORMS[self.form].__name__}"
            )
        if not isinstance(self.input, str) or not self.input:
            raise NidarError(f"profile {self.name}: 'input' must be a non-empty string")
        if self.model is not None and not (
            isinstance(self.model, Mapping) and all(isinstance(v, str) for v in self.model.values())
        ):
            raise NidarError(f"profile {self.name}: 'model' must be null or an object of strings")

    @property
    def uses_incidence(self) -> bool:
        """Whether :meth:`apply` needs the returns' incidence cosines (an incidence-aware
        ``gbm`` profile)."""
        return isinstance(self.mapping, GbmMap) and self.mapping.uses_incidence

    @property
    def branch(self) -> str | None:
        """The NIDAR map the profile reads (``"R"``, ``"I_hat"``, ...), None for other inputs."""
        return self.input.split(":", 1)[1] if self.input.startswith("nidar:") else None

    def apply(
        self,
        values: Any,
        range_m: Any,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray:
        """The sensor's intensity of returns with these model values.

        Args:
            values: (N,) model values (the profile's ``input``), finite.
            range_m: (N,) ranges from the sensor, m.
            ring: optional (N,) rings (-1 unknown); used by ``range_ring``.
            elevation_deg: optional (N,) elevations above the sensor's xy plane, degrees
                (``range_ring``: rings of returns without one; ``gbm``: required unless it
                reads the value and incidence only).
            cos_incidence: optional (N,) ``|cos θ|`` of the rays on the surfaces, in [0, 1]
                (:func:`nidar_mi.geometry.incidence_cosine`); required when
                :attr:`uses_incidence`, ignored otherwise.

        Returns:
            (N,) float32 intensities in [0, 1].

        Raises:
            NidarError: mismatched lengths, non-finite values or ranges, or no incidences
                for a profile that reads them.
        """
        v = np.asarray(values, dtype=np.float64).reshape(-1)
        d = np.asarray(range_m, dtype=np.float64).reshape(-1)
        if v.shape != d.shape:
            raise NidarError(f"profile {self.name}: {v.size} values but {d.size} ranges")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(d))):
            raise NidarError(f"profile {self.name}: values and ranges must be finite")
        if self.form == "distance_quantile":
            out = self.mapping.quantile_map(self.mapping.encode(v, d))
        elif self.form == "gbm":
            out = self.mapping(v, d, ring, elevation_deg, cos_incidence)
        else:
            out = self.mapping(v, d, ring, elevation_deg)
        return out.astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """The profile as JSON data (module docstring)."""
        mapping = self.mapping.to_dict()
        mapping.pop("schema", None)
        return {
            "schema": PROFILE_SCHEMA,
            "name": self.name,
            "sensor": self.sensor,
            "form": self.form,
            "input": self.input,
            "model": dict(self.model) if self.model is not None else None,
            "mapping": mapping,
            "provenance": self.provenance,
        }

    @classmethod
    def from_dict(cls, data: Any, where: str = "profile") -> SensorProfile:
        """Inverse of :meth:`to_dict`; :class:`NidarError` names ``where`` and the field."""
        if not isinstance(data, Mapping):
            raise NidarError(f"{where}: a sensor profile is a JSON object")
        if data.get("schema") != PROFILE_SCHEMA:
            raise NidarError(
                f"{where}: 'schema' must be {PROFILE_SCHEMA!r} (got {data.get('schema')!r})"
            )
        missing = [k for k in ("name", "sensor", "form", "input", "mapping") if k not in data]
        if missing:
            raise NidarError(f"{where}: missing field(s) {', '.join(missing)}")
        unknown = sorted(
            set(data)
            - {"schema", "name", "sensor", "form", "input", "model", "mapping", "provenance"}
        )
        if unknown:
            raise NidarError(f"{where}: unknown field(s) {', '.join(unknown)}")
        form = data["form"]
        if form not in PROFILE_FORMS:
            raise NidarError(
                f"{where}: 'form' must be one of {', '.join(PROFILE_FORMS)} (got {form!r})"
            )
        mapping = data["mapping"]
        try:
            if form == "distance_quantile":
                if not isinstance(mapping, Mapping):
                    raise NidarError("expected an object")
                mapping = Calibration.from_dict({"schema": "nidar_mi.calibration/1", **mapping})
            elif form == "gbm":
                mapping = GbmMap.from_dict(mapping)
            else:
                mapping = RangeRingMap.from_dict(mapping)
        except NidarError as e:
            raise NidarError(f"{where}: 'mapping': {e}") from None
        provenance = data.get("provenance") or {}
        if not isinstance(provenance, Mapping):
            raise NidarError(f"{where}: 'provenance' must be an object")
        for key in ("sensor", "input"):
            if not isinstance(data[key], str):
                raise NidarError(f"{where}: {key!r} must be a string")
        try:
            return cls(
                name=data["name"],
                sensor=data["sensor"],
                form=form,
                input=data["input"],
                mapping=mapping,
                model=data.get("model"),
                provenance=dict(provenance),
            )
        except NidarError as e:
            raise NidarError(f"{where}: {e}") from None

    def save(self, path: str | os.PathLike) -> None:
        """Write the profile as JSON, atomically."""
        from ..io.atomic import atomic_write_json

        atomic_write_json(path, self.to_dict())


def load_profile(path: str | os.PathLike) -> SensorProfile:
    """Read and check a profile file (module docstring).

    Raises:
        NidarError: unreadable file, invalid JSON or an invalid field (one line).
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise NidarError(f"{p}: no such profile file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise NidarError(f"{p}: cannot read ({getattr(e, 'strerror', None) or e})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise NidarError(f"{p}: not valid JSON ({e})") from None
    return SensorProfile.from_dict(data, str(p))


def fit_profile(
    values: Any,
    range_m: Any,
    reference: Any,
    *,
    form: str,
    name: str,
    sensor: str,
    input: str,
    ring: Any = None,
    elevation_deg: Any = None,
    cos_incidence: Any = None,
    model: dict[str, str] | None = None,
    provenance: dict[str, Any] | None = None,
    **options: Any,
) -> SensorProfile:
    """Fit a profile of the given form on training returns.

    Args:
        values: (N,) model values at the returns (the profile's ``input``).
        range_m: (N,) their ranges, m.
        reference: (N,) the sensor's intensities on the [0, 1] scale.
        form: one of :data:`PROFILE_FORMS`.
        name, sensor, input, model, provenance: the profile's fields.
        ring: optional (N,) rings (``range_ring``).
        elevation_deg: optional (N,) elevations, degrees (``range_ring``; required by ``gbm``).
        cos_incidence: optional (N,) incidence cosines: given, a ``gbm`` profile reads them
            (the other forms do not: an error).
        **options: passed to :func:`~nidar_mi.nidar.calibration.fit_calibration`,
            :func:`~nidar_mi.nidar.range_ring.fit_range_ring` or
            :func:`~nidar_mi.nidar.gbm_profile.fit_gbm` (``use_value=False``: geometry only;
            ``use_geometry=False``: the value and the incidence only).

    Raises:
        NidarError: an unknown form or unusable data.
    """
    if cos_incidence is not None and form != "gbm":
        raise NidarError(f"only a gbm profile reads the incidence (form {form!r} does not)")
    if form == "distance_quantile":
        mapping = fit_calibration(values, range_m, reference, branch=input, **options)
    elif form == "range_ring":
        mapping = fit_range_ring(values, range_m, reference, ring, elevation_deg, **options)
    elif form == "gbm":
        mapping = fit_gbm(
            values, range_m, reference, elevation_deg, cos_incidence=cos_incidence, **options
        )
    else:
        raise NidarError(f"profile form must be one of {', '.join(PROFILE_FORMS)} (got {form!r})")
    return SensorProfile(
        name=name,
        sensor=sensor,
        form=form,
        input=input,
        mapping=mapping,
        model=model,
        provenance=dict(provenance or {}),
    )
