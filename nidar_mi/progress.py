"""The one place a progress bar is made: a tqdm bar on stderr, shown only where it is wanted.

Every module that reports progress takes a ``progress`` flag and builds its bar with
:func:`progress_bar`. The commands decide the flag once (:func:`nidar_mi.cli._common.show_progress`):
bars on a terminal, none when stderr is a file or a pipe (a log), ``--progress`` to force them
and ``--no-progress`` / ``-q`` to hide them.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["bars_allowed", "progress_bar", "shown", "stderr_is_terminal"]

#: Whether the running command allows bars (None: no command decided; :func:`bars_allowed`).
_allowed: bool | None = None


@contextmanager
def bars_allowed(allowed: bool) -> Iterator[None]:
    """Within the block no bar shows unless ``allowed``, whatever a caller's ``progress`` flag
    says: a command decides once (``-q``, a log file, ``--no-progress``) for every bar of its
    work, those of library functions called with their default included."""
    global _allowed
    previous, _allowed = _allowed, bool(allowed)
    try:
        yield
    finally:
        _allowed = previous


def shown(show: bool | None) -> bool:
    """Whether a bar asked for with ``show`` (None: on a terminal) shows (:func:`bars_allowed`)."""
    if _allowed is False:
        return False
    return stderr_is_terminal() if show is None else bool(show)


def stderr_is_terminal() -> bool:
    """Whether stderr is an interactive terminal (not a file, a pipe or a closed stream)."""
    try:
        return bool(sys.stderr and sys.stderr.isatty())
    except (AttributeError, ValueError):  # replaced or closed stream
        return False


def progress_bar(iterable: Iterable | None = None, *, show: bool | None = True, **kwargs: Any):
    """A tqdm progress bar on stderr (tqdm's notebook widget inside Jupyter).

    Args:
        iterable: what to iterate over, or None for a bar advanced by ``update``.
        show: True shows the bar, False makes a silent one (same interface), None shows it only
            when stderr is a terminal; no bar shows where the command allows none
            (:func:`bars_allowed`).
        **kwargs: tqdm's options (``total``, ``desc``, ``unit``, ``initial``, ...).

    Returns:
        A ``tqdm`` object (iterate over it, or call ``update``/``close``).
    """
    from tqdm.auto import tqdm

    kwargs.setdefault("file", sys.stderr)
    return tqdm(iterable, disable=not shown(show), **kwargs)
