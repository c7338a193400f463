"""A bounded background writer: files are written on one thread while the caller computes on.

A sequence renders frame ``k + 1`` while frame ``k`` is written::

    with BackgroundWriter(depth=2) as writer:
        for frame in frames:
            writer.submit(write_frame, render(frame))

Jobs run in the order submitted, one at a time, on one thread; :meth:`BackgroundWriter.submit`
blocks while ``depth`` jobs wait, so at most ``depth + 1`` results are held in memory. A job's
exception is raised again in the caller (at the next :meth:`~BackgroundWriter.submit`, or when
the ``with`` block ends) and no later job runs. When the block ends normally every job is
finished first; when it ends with an exception (a failure, Ctrl-C, SIGTERM) the waiting jobs are
dropped, the running one is waited for and ``on_abort`` runs on the writer thread: nothing
writes after the block, so the caller's clean-up (removing a staging folder) never races a
write. Jobs should hold plain data (NumPy arrays), not Dr.Jit values: only the caller's thread
drives the JIT.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable

__all__ = ["BackgroundWriter"]


class BackgroundWriter:
    """Run write jobs in order on one background thread, at most ``depth`` waiting.

    Args:
        depth: jobs that may wait while one runs (>= 1).
        on_abort: called on the writer thread after the last job when the writer stops after a
            job's failure or the caller's exception (e.g. to discard a half-written file that
            only this thread may touch); its own exceptions are ignored.
        name: the thread's name.
    """

    def __init__(
        self, depth: int = 2, on_abort: Callable[[], None] | None = None, name: str = "writer"
    ):
        self._queue: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
        self._on_abort = on_abort
        self._error: BaseException | None = None
        self._abort = False
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)

    def __enter__(self) -> BackgroundWriter:
        self._thread.start()
        return self

    def submit(self, fn: Callable, *args, **kwargs) -> None:
        """Queue ``fn(*args, **kwargs)``; blocks while ``depth`` jobs wait.

        Raises:
            BaseException: the exception of an earlier job, as it was raised there.
        """
        self._raise()
        self._queue.put((fn, args, kwargs))

    def _raise(self) -> None:
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        while True:
            job = self._queue.get()
            if job is None:
                break
            if self._error is not None or self._abort:
                continue
            fn, args, kwargs = job
            try:
                fn(*args, **kwargs)
            except BaseException as e:  # handed to the caller's thread
                self._error = e
        if (self._error is not None or self._abort) and self._on_abort is not None:
            try:
                self._on_abort()
            except Exception:  # noqa: BLE001 - clean-up after a failure already reported
                pass

    def _stop(self) -> None:
        """Drop the waiting jobs and wait for the running one."""
        self._abort = True
        while True:
            try:
                self._queue.get_nowait()
            except queue.Empty:
                break
        self._queue.put(None)
        self._thread.join()

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is not None:
            self._stop()
            return
        try:
            self._queue.put(None)
            self._thread.join()
        except BaseException:  # Ctrl-C or SIGTERM while the last jobs are written
            self._stop()
            raise
        self._raise()
