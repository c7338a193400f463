"""A sensor profile fitted on arrays in one call (the tests' shorthand)."""

from __future__ import annotations

from typing import Any

from nidar_mi.profiles import SensorProfile, fit


def fitted_profile(
    values: Any,
    range_m: Any,
    intensity: Any,
    *,
    form: str,
    name: str = "p",
    sensor: str = "",
    input: str = "nidar:R",
    model: dict[str, str] | None = None,
    provenance: dict[str, Any] | None = None,
    **fit_options: Any,
) -> SensorProfile:
    """:func:`nidar_mi.profiles.fit` of ``form`` wrapped in a profile with these fields."""
    mapping = fit(form, values, range_m, intensity, input=input, **fit_options)
    return SensorProfile(
        name=name,
        sensor=sensor,
        form=form,
        input=input,
        mapping=mapping,
        model=model,
        provenance=dict(provenance or {}),
    )
