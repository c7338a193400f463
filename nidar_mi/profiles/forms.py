"""The profile forms by name, and the one entry point that fits any of them.

Every form is a class with the same interface (:class:`ProfileMap`): its ``form`` name, whether
it ``reads_incidence`` at all, ``__call__(values, range_m, *, ring=None, elevation_deg=None,
cos_incidence=None)`` giving (N,) float64 intensities in [0, 1], ``to_dict`` / ``from_dict``
(a profile file's ``mapping``), a classmethod ``fit`` of the same data and ``fit_options``, the
dataclass of its fitting options. A form that reads named inputs (``reads_context``: the
``context`` form, :mod:`nidar_mi.profiles.inputs`) also takes ``context=`` when called and fitted.
:data:`FORMS` is the only place that lists them.
"""

from __future__ import annotations

from typing import Any, ClassVar, Protocol

import numpy as np

from ..errors import NidarError
from .context import ContextMap
from .distance_quantile import DistanceQuantileMap
from .gbm import GbmMap
from .physical import PhysicalMap
from .range_ring import RangeRingMap

__all__ = ["FORMS", "ProfileMap", "fit", "form_class"]


class ProfileMap(Protocol):
    """What every profile form provides (module docstring)."""

    form: ClassVar[str]
    reads_incidence: ClassVar[bool]
    fit_options: ClassVar[type]

    @property
    def uses_incidence(self) -> bool: ...

    def __call__(
        self,
        values: Any,
        range_m: Any,
        *,
        ring: Any = None,
        elevation_deg: Any = None,
        cos_incidence: Any = None,
    ) -> np.ndarray: ...

    def to_dict(self) -> dict[str, Any]: ...


#: Form name -> its map class.
FORMS: dict[str, type] = {
    cls.form: cls for cls in (DistanceQuantileMap, RangeRingMap, GbmMap, PhysicalMap, ContextMap)
}


def form_class(form: str) -> type:
    """The map class of a form name; :class:`NidarError` for an unknown one."""
    if form not in FORMS:
        raise NidarError(f"profile form must be one of {', '.join(FORMS)} (got {form!r})")
    return FORMS[form]


def fit(
    form: str,
    values: Any,
    range_m: Any,
    intensity: Any,
    *,
    ring: Any = None,
    elevation_deg: Any = None,
    cos_incidence: Any = None,
    input: str = "R",
    context: Any = None,
    **form_options: Any,
) -> ProfileMap:
    """Fit a map of the given form on training returns.

    Args:
        form: one of :data:`FORMS`.
        values: (N,) model values at the returns.
        range_m: (N,) their ranges, m.
        intensity: (N,) the sensor's intensities on the [0, 1] scale.
        ring: optional (N,) rings, -1 unknown (read by ``range_ring``).
        elevation_deg: optional (N,) elevations above the sensor's xy plane, degrees
            (``range_ring``; required by ``gbm`` unless it reads the value and incidence only).
        cos_incidence: optional (N,) ``|cos θ|`` in [0, 1]: given, the map reads them (only
            ``gbm`` can; another form is an error).
        input: the value the map is fitted on (a profile's ``input``, e.g. ``"nidar:R"``), kept
            by forms that record it (``distance_quantile``'s ``branch``).
        context: name -> (N,) named inputs of the returns (:mod:`nidar_mi.profiles.inputs`),
            read by the ``context`` form (required there; another form is an error); its
            optional ``"frame"`` and ``"group"`` entries, (N,) the frame and the recording of
            each return, are not inputs (the form draws its training returns per frame and
            weighs the recordings alike).
        **form_options: the form's own fitting options (its class's ``fit_options``), e.g. ``gbm``'s
            ``use_value=False`` (geometry only), ``use_geometry=False`` (value and incidence
            only), ``trees``; ``range_ring``'s ``width``; ``distance_quantile``'s ``tau``;
            ``physical``'s ``range_exponent``.

    Raises:
        NidarError: an unknown form, incidences for a form that cannot read them, or unusable
            data.
    """
    cls = form_class(form)
    if cos_incidence is not None and not cls.reads_incidence:
        raise NidarError(
            f"only a gbm or physical profile reads the incidence (form {form!r} does not)"
        )
    extra = {}
    if getattr(cls, "reads_context", False):
        extra = {"context": context}
    elif context is not None:
        raise NidarError(f"only a context profile reads named inputs (form {form!r} does not)")
    return cls.fit(
        values,
        range_m,
        intensity,
        ring=ring,
        elevation_deg=elevation_deg,
        cos_incidence=cos_incidence,
        input=input,
        options=cls.fit_options(**form_options),
        **extra,
    )
