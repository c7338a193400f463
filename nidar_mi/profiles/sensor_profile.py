"""A sensor profile: a fitted form's map with its name, sensor, input and provenance; its file.

A profile's ``mapping`` is one of the forms of :data:`nidar_mi.profiles.forms.FORMS`; calling
the profile calls it, after checking the inputs, and gives float32.

**File format** (JSON, UTF-8)::

    {
      "schema": "nidar_mi.sensor_profile/1",
      "name": "kitti-hdl64e",                 # letters, digits, '-', '_', '.'
      "sensor": "Velodyne HDL-64E (KITTI)",   # free text
      "form": "range_ring",                   # or "distance_quantile", "gbm", "physical", "context"
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
from .forms import FORMS, ProfileMap, form_class

__all__ = ["PROFILE_SCHEMA", "SensorProfile", "load_profile"]

PROFILE_SCHEMA = "nidar_mi.sensor_profile/1"
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


@dataclass(frozen=True, eq=False)
class SensorProfile:
    """A fitted sensor profile (module docstring for the fields)."""

    name: str
    sensor: str
    form: str
    input: str
    mapping: ProfileMap
    model: dict[str, str] | None = None
    provenance: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise NidarError(
                f"profile name must be letters, digits, '-', '_', '.' (got {self.name!r})"
            )
        cls = form_class(self.form)
        if not isinstance(self.mapping, cls):
            raise NidarError(f"profile {self.name}: a {self.form} profile needs a {cls.__name__}")
        if not isinstance(self.input, str) or not self.input:
            raise NidarError(f"profile {self.name}: 'input' must be a non-empty string")
        if self.model is not None and not (
            isinstance(self.model, Mapping) and all(isinstance(v, str) for v in self.model.values())
        ):
            raise NidarError(f"profile {self.name}: 'model' must be null or an object of strings")

    @property
    def uses_incidence(self) -> bool:
        """Whether calling the profile needs the returns' incidence cosines (an
        incidence-aware ``gbm`` profile)."""
        return self.mapping.uses_incidence

    @property
    def reads_context(self) -> bool:
        """Whether calling the profile needs the returns' named inputs (``context=``: a
        ``context`` profile, :mod:`nidar_mi.profiles.inputs`)."""
        return bool(getattr(self.mapping, "reads_context", False))

    @property
    def needs_image(self) -> bool:
        """Whether the profile reads the camera image at the returns (image or NIDAR inputs)."""
        return bool(getattr(self.mapping, "needs_image", False))

    @property
    def branch(self) -> str | None:
        """The NIDAR map the profile reads (``"R"``, ``"I_hat"``, ...), None for other inputs."""
        return self.input.split(":", 1)[1] if self.input.startswith("nidar:") else None

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
        context: Any = None,
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
            context: name -> (N,) named inputs (:mod:`nidar_mi.profiles.inputs`); required
                when :attr:`reads_context`, ignored otherwise.

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
        extra = {"context": context} if self.reads_context else {}
        out = self.mapping(
            v, d, ring=ring, elevation_deg=elevation_deg, cos_incidence=cos_incidence, **extra
        )
        return out.astype(np.float32)

    def to_dict(self) -> dict[str, Any]:
        """The profile as JSON data (module docstring)."""
        return {
            "schema": PROFILE_SCHEMA,
            "name": self.name,
            "sensor": self.sensor,
            "form": self.form,
            "input": self.input,
            "model": dict(self.model) if self.model is not None else None,
            "mapping": self.mapping.to_dict(),
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
        if form not in FORMS:
            raise NidarError(f"{where}: 'form' must be one of {', '.join(FORMS)} (got {form!r})")
        try:
            mapping = FORMS[form].from_dict(data["mapping"])
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
