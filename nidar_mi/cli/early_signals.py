"""Ctrl-C and SIGTERM before a command's :func:`~nidar_mi.cli._common.run` takes them.

Python turns SIGINT into a ``KeyboardInterrupt`` traceback and lets SIGTERM end the process
without a word while a command is still importing its modules (tenths of a second on a busy
machine). :func:`install` is the first thing a command's ``__main__`` does: until ``run``
installs its own handlers, either signal prints ``interrupted; nothing written`` or
``terminated; nothing written`` (nothing has been written yet) and exits with ``run``'s status
for it. It imports nothing beyond the standard library's ``os`` and ``signal``.
"""

from __future__ import annotations

import os
import signal

__all__ = ["install", "early_handler"]

#: The status and the word of each signal (``run``'s: 130 and 143).
_STOPS = {signal.SIGINT: (130, "interrupted"), signal.SIGTERM: (143, "terminated")}


def early_handler(signum, frame):  # noqa: ARG001 - signal handler signature
    """Say that the command stopped before it wrote anything, and exit at once."""
    status, word = _STOPS[signum]
    os.write(2, f"{word}; nothing written\n".encode())
    os._exit(status)


def install() -> None:
    """Take SIGINT and SIGTERM where they still have Python's default handling (a signal the
    caller ignores stays ignored)."""
    defaults = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL}
    for sig, default in defaults.items():
        if signal.getsignal(sig) is default:
            signal.signal(sig, early_handler)
