"""User-facing errors, and the checks of inputs every command shares.

A :class:`NidarError` carries a message meant to be shown to the user as one line; the
command-line entry points print it to stderr and exit with a non-zero status, without a
traceback. A message names a parameter by its Python name in backticks (`` `spp` must be >= 1``);
a command shows the flag it reads that parameter from in its place
(:func:`nidar_mi.cli._common.flag_message`).
"""

__all__ = ["MAX_SEED", "NidarError", "check_seed"]

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
