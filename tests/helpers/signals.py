"""Child processes that a test interrupts with SIGINT.

A test run started as a background job of a non-interactive shell (``pytest &``, ``nohup``)
inherits SIGINT ignored, and Python then installs no ``KeyboardInterrupt`` handler in a child:
the child would never see the signal. ``preexec_fn=default_sigint`` restores the default
disposition before the child starts, as an interactive terminal would have it.
"""

import signal


def default_sigint() -> None:
    """Restore SIGINT's default disposition (for ``subprocess.Popen(preexec_fn=...)``)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
