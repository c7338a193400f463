"""User-facing errors, and the checks of inputs every command shares.

A :class:`NidarError` carries a message meant to be shown to the user as one line; the
command-line entry points print it to stderr and exit with a non-zero status, without a
traceback. A message names a parameter by its Python name in backticks (`` `spp` must be >= 1``);
a command shows the flag it reads that parameter from in its place (:func:`flag_message`).
"""

import re
from collections.abc import Mapping

__all__ = ["MAX_SEED", "NidarError", "check_seed", "flag_message"]

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
