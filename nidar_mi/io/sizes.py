"""Sizes in bytes: read and written as text, and whether an output fits on its disk.

A command that writes an output of a size known from its options (a rendered sequence, a run of
scenes) estimates it before any work and refuses it, with both numbers, when it exceeds the free
space of the output's filesystem or a limit the user gave (:func:`check_disk`).
"""

from __future__ import annotations

import os
import shutil

from ..errors import NidarError

__all__ = ["check_disk", "format_size", "free_space", "parse_size"]


def parse_size(text: str) -> int:
    """Bytes from ``'512M'``, ``'16G'``, ``'1.5T'`` (K, M, G, T, P: powers of 1024) or a plain
    number of bytes.

    Raises:
        ValueError: not a positive size.
    """
    t = str(text).strip().upper().removesuffix("B").removesuffix("I")
    units = {"K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40, "P": 1 << 50}
    scale = units.get(t[-1:], 1)
    number = t[:-1] if t[-1:] in units and t else t
    try:
        value = float(number) * scale
    except ValueError:
        raise ValueError(f"not a size in bytes: '{text}' (e.g. 512M, 16G)") from None
    if not value > 0 or value != value or value == float("inf"):
        raise ValueError(f"not a positive size in bytes: '{text}'")
    return int(value)


def format_size(n: int | float) -> str:
    """``'1.5 GiB'``-style text."""
    for unit, scale in (
        ("PiB", 1 << 50),
        ("TiB", 1 << 40),
        ("GiB", 1 << 30),
        ("MiB", 1 << 20),
        ("KiB", 1 << 10),
    ):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{int(n)} B"


def _existing(path: str | os.PathLike) -> str:
    """``path`` or its nearest existing parent folder."""
    p = os.path.abspath(os.fspath(path))
    while not os.path.exists(p) and os.path.dirname(p) != p:
        p = os.path.dirname(p)
    return p


def free_space(path: str | os.PathLike) -> int:
    """Bytes free on the filesystem that holds (or would hold) ``path``."""
    return int(shutil.disk_usage(_existing(path)).free)


def check_disk(need: int, out: str | os.PathLike, what: str, limit: int | None = None) -> None:
    """Refuse an output estimated at ``need`` bytes that does not fit: more than the free space
    of ``out``'s filesystem, or more than ``limit`` (the ``max_disk`` parameter).

    Args:
        need: the output's estimated size, bytes.
        out: where it is written (it need not exist yet).
        what: the output and how the estimate is made up, e.g. ``"100 frames x 1.2 MiB"``.
        limit: bytes the output may take (None: only the free space bounds it).

    Raises:
        NidarError: one line naming the estimate and the limit or the free space.
    """
    if limit is not None and need > limit:
        raise NidarError(
            f"the output needs about {format_size(need)} ({what}), more than the limit of "
            f"{format_size(limit)} (`max_disk`)"
        )
    free = free_space(out)
    if need > free:
        raise NidarError(
            f"the output needs about {format_size(need)} ({what}), more than the "
            f"{format_size(free)} free on {_existing(out)}"
        )
