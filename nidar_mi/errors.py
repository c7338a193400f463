"""User-facing errors, and the checks of inputs every command shares.

A :class:`NidarError` carries a message meant to be shown to the user as one line; the
command-line entry points print it to stderr and exit with a non-zero status, without a
traceback. A message names a parameter by its Python name in backticks (`` `spp` must be >= 1``);
a command shows the flag it reads that parameter from in its place (:func:`flag_message`).
"""

import re
from collections.abc import Mapping
from types import UnionType
from typing import Annotated, Any, Union, get_args, get_origin, get_type_hints

__all__ = ["MAX_SEED", "NidarError", "check_seed", "flag_message", "validation_problem"]

#: Largest seed any command accepts: Mitsuba's samplers take a 32-bit seed.
MAX_SEED = 2**32 - 1


class NidarError(Exception):
    """An error caused by the user's input or environment (bad file, bad parameter, missing library)."""


def check_seed(seed, name: str = "`seed`") -> int:
    """``seed`` as an int in [0, :data:`MAX_SEED`].

    Raises:
        NidarError: not an integer, or out of range (the message names ``name``: by default
            the parameter ``seed``, shown by a command as its ``--seed`` flag).
    """
    if isinstance(seed, bool) or not isinstance(seed, int):
        raise NidarError(f"{name} must be an integer (got {seed!r})")
    if not 0 <= seed <= MAX_SEED:
        raise NidarError(f"{name} must lie in [0, {MAX_SEED}] (got {seed})")
    return seed


#: How a message reads each interval bound of a pydantic constraint.
_BOUNDS = {"gt": ">", "ge": ">=", "lt": "<", "le": "<="}


def validation_problem(kind: Any, error: Mapping[str, Any]) -> str:
    """One pydantic validation error, in words: ``must lie in (0, 1] (got 1.5)``.

    The package's configs and XML parameters are pydantic models (or dataclasses validated
    by pydantic) whose values are constrained in their type hints (``Literal[...]`` for a
    choice, ``Annotated[float, Field(gt=0, le=1)]`` for an interval); this turns the error
    pydantic reports into the problem part of a one-line :class:`NidarError` (the caller
    names the field). A value out of its interval is shown with the whole interval, a value
    not among the choices with every choice.

    Args:
        kind: the model or dataclass validated (its type hints give the interval and choices).
        error: one item of ``pydantic.ValidationError.errors()``.
    """
    what, got = error["type"], _shown(error.get("input"))
    if what in ("extra_forbidden", "unexpected_keyword_argument"):
        return "unknown key"
    if what in ("dataclass_type", "dict_type", "model_type"):
        return "must be a JSON object"
    if what == "value_error":  # a rule between fields, in the words of its validator
        return str(error["ctx"]["error"])
    hint = _field_hint(kind, tuple(error.get("loc", ())))
    if what == "literal_error":
        choices = get_args(_bare(hint))
        shown = ", ".join(map(str, choices)) if choices else error["ctx"]["expected"]
        return f"must be one of {shown} (got {got})"
    if what in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        bounds = _bounds(hint) or dict(error.get("ctx") or {})
        low = [(k, v) for k, v in bounds.items() if k in ("gt", "ge")]
        high = [(k, v) for k, v in bounds.items() if k in ("lt", "le")]
        if low and high:
            (lk, lv), (hk, hv) = low[0], high[0]
            left, right = "(" if lk == "gt" else "[", ")" if hk == "lt" else "]"
            return f"must lie in {left}{_shown(lv)}, {_shown(hv)}{right} (got {got})"
        k, v = (low or high)[0]
        return f"must be {_BOUNDS[k]} {_shown(v)} (got {got})"
    if what == "string_pattern_mismatch":
        return f"must match {error['ctx']['pattern']} (got {got})"
    # a value of the wrong type: pydantic's words, up to their first comma
    return f"{error['msg'].replace('Input should', 'should').split(',')[0]} (got {got})"


def _shown(value: Any) -> str:
    """A value as a message shows it: numbers as written (floats with ``:g``), else ``repr``."""
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return repr(value)


def _bare(hint: Any) -> Any:
    """``hint`` without ``Annotated`` metadata and without ``| None``."""
    while True:
        if get_origin(hint) is Annotated:
            hint = get_args(hint)[0]
        elif get_origin(hint) in (Union, UnionType) and len(_some(hint)) == 1:
            hint = _some(hint)[0]
        else:
            return hint


def _some(hint: Any) -> list[Any]:
    """The members of a union other than None."""
    return [a for a in get_args(hint) if a is not type(None)]


def _field_hint(kind: Any, loc: tuple) -> Any:
    """The type hint (``Annotated`` kept) of the value at ``loc`` under the dataclass or
    pydantic model ``kind``: a field for a name, an item of a tuple for a number; None when
    ``loc`` leaves the hints."""
    hint = kind
    for part in loc:
        bare = _bare(hint)
        try:
            if isinstance(part, int):
                hint = get_args(bare)[0]
            else:
                hint = get_type_hints(bare, include_extras=True)[part]
        except (IndexError, KeyError, TypeError, NameError):
            return None
    return hint


def _bounds(hint: Any) -> dict[str, Any]:
    """``{"gt": 0, "le": 1}``: the interval the ``Annotated`` metadata of ``hint`` sets."""
    while get_origin(hint) in (Union, UnionType) and len(_some(hint)) == 1:
        hint = _some(hint)[0]
    found: dict[str, Any] = {}
    for meta in get_args(hint)[1:] if get_origin(hint) is Annotated else ():
        for item in (meta, *getattr(meta, "metadata", ())):
            found |= {k: getattr(item, k) for k in _BOUNDS if getattr(item, k, None) is not None}
    return found


_PARAM = re.compile(r"`([A-Za-z_][A-Za-z0-9_]*)`")


def flag_message(message: str, flags: Mapping[str, str] | None = None) -> str:
    """``message`` with every parameter it names in backticks shown as a flag.

    Args:
        message: a library message (:class:`~nidar_mi.errors.NidarError`).
        flags: parameter name -> its flag where the two differ (e.g. ``{"images": "--image"}``);
            any other name ``a_b`` is shown as ``--a-b``.
    """
    flags = flags or {}

    def flag(m: re.Match) -> str:
        name = m.group(1)
        return flags.get(name, "--" + name.replace("_", "-"))

    return _PARAM.sub(flag, message)
