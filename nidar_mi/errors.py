"""User-facing errors.

A :class:`NidarError` carries a message meant to be shown to the user as one line; the
command-line entry points print it to stderr and exit with a non-zero status, without a
traceback.
"""

__all__ = ["NidarError"]


class NidarError(Exception):
    """An error caused by the user's input or environment (bad file, bad parameter, missing library)."""
