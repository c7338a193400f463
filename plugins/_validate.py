"""Parameter checks shared by the BSDF plugins: a number read from ``mi.Properties``, finite
and inside its interval, or a :class:`~nidar_mi.errors.NidarError` of one line
naming the plugin and the parameter, e.g.
``roughdiffuse 'road': parameter 'sigma' must be in [0, 90) degrees (got 90)``.

Not a plugin (:data:`nidar_mi.plugins.PLUGIN_MODULES` does not list it): it imports no Mitsuba
and runs under any variant.
"""

from __future__ import annotations

import math
from typing import Any

from nidar_mi.errors import NidarError

__all__ = ["bounded", "plugin_name"]


def plugin_name(kind: str, props: Any) -> str:
    """How messages name a plugin instance: ``kind 'id'`` when it has an id, else ``kind``."""
    return f"{kind} '{props.id()}'" if props.id() else kind


def bounded(
    props: Any,
    where: str,
    name: str,
    default: float,
    interval: tuple[str, float, float, str],
    unit: str = "",
) -> float:
    """The float parameter ``name`` of ``props`` (``default`` when absent), checked.

    Args:
        props: the plugin's ``mi.Properties``.
        where: the plugin as messages name it (:func:`plugin_name`).
        name: the parameter.
        default: its value when absent.
        interval: ``(open, low, high, close)``, e.g. ``("(", 0, 90, "]")`` for ``0 < x <= 90``.
        unit: appended to the interval in the message (e.g. ``" degrees"``).

    Raises:
        NidarError: not a number, not finite, or outside the interval.
    """
    raw = props.get(name, default)
    try:
        value = float(raw)
    except (TypeError, ValueError):
        raise NidarError(f"{where}: parameter '{name}' must be a number (got '{raw}')") from None
    if not math.isfinite(value):
        raise NidarError(f"{where}: parameter '{name}' must be finite (got '{raw}')")
    left, low, high, right = interval
    above = value > low if left == "(" else value >= low
    below = value < high if right == ")" else value <= high
    if not (above and below):
        raise NidarError(
            f"{where}: parameter '{name}' must be in {left}{low:g}, {high:g}{right}{unit} "
            f"(got {value:g})"
        )
    return value
