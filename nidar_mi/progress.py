"""The one place a progress bar is made: a tqdm bar on stderr, shown only where it is wanted.

Every module that reports progress takes a ``progress`` flag and builds its bar with
:func:`progress_bar`. The commands decide the flag once (:func:`nidar_mi.cli._common.show_progress`):
bars on a terminal, none when stderr is a file or a pipe (a log), ``--progress`` to force them
and ``--no-progress`` / ``-q`` to hide them.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from typing import Any

__all__ = ["progress_bar", "stderr_is_terminal"]


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
            when stderr is a terminal.
        **kwargs: tqdm's options (``total``, ``desc``, ``unit``, ``initial``, ...).

    Returns:
        A ``tqdm`` object (iterate over it, or call ``update``/``close``).
    """
    from tqdm.auto import tqdm

    if show is None:
        show = stderr_is_terminal()
    kwargs.setdefault("file", sys.stderr)
    return tqdm(iterable, disable=not show, **kwargs)
