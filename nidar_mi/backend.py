"""Dr.Jit / Mitsuba back end: LLVM discovery, variant choice and plugin registration.

Dr.Jit's LLVM back end needs ``libLLVM`` >= 16 (older versions fail with "Cannot select
fminimum"). :func:`configure_llvm` looks for the newest libLLVM on the system and exports
``DRJIT_LIBLLVM_PATH`` unless the user already set it; it runs when :mod:`nidar_mi` is
imported, before Dr.Jit initialises its LLVM back end.

:func:`set_variant` picks ``cuda_ad_spectral`` when a CUDA device works, else
``llvm_ad_spectral``, and registers this package's Mitsuba plugins for that variant
(Python plugin classes are bound to the variant active when they are defined; see
:mod:`nidar_mi.plugins`). Only entry points (commands, workers' set-up, test fixtures) call it;
library code reads the variant they chose with :func:`active_variant`, and hands it to the
worker processes of a parallel job with :func:`worker_setup`.
"""

from __future__ import annotations

import contextlib
import glob
import os
import re
import signal
import sys
import threading

from .errors import NidarError

__all__ = [
    "LLVM_MIN_VERSION",
    "find_libllvm",
    "configure_llvm",
    "default_variant",
    "set_variant",
    "signals_deferred",
    "active_variant",
    "prepare_worker",
    "worker_setup",
    "SUPPORTED_VARIANTS",
]

#: Oldest libLLVM major version Dr.Jit 1.5 works with here.
LLVM_MIN_VERSION = 16

SUPPORTED_VARIANTS = ("cuda_ad_spectral", "llvm_ad_spectral")

_LLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/aarch64-linux-gnu/libLLVM-*.so*",
    "/usr/lib/x86_64-linux-gnu/libLLVM.so.*",
    "/usr/lib/aarch64-linux-gnu/libLLVM.so.*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*",
    "/usr/lib64/libLLVM*.so*",
    "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*",
    "/opt/homebrew/opt/llvm/lib/libLLVM.dylib",
    "/usr/local/opt/llvm/lib/libLLVM.dylib",
)

_FIX = (
    f"install LLVM >= {LLVM_MIN_VERSION} (Debian/Ubuntu: apt-get install libllvm19) "
    "or point DRJIT_LIBLLVM_PATH at libLLVM.so"
)


def _llvm_major(path: str) -> int | None:
    """Major version encoded in a libLLVM file name, e.g. ``libLLVM-19.so`` -> 19."""
    name = os.path.basename(path)
    m = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", name) or re.search(r"llvm-(\d+)", path)
    return int(m.group(1)) if m else None


def find_libllvm(patterns: tuple[str, ...] = _LLVM_GLOBS) -> str | None:
    """Path of the newest libLLVM with major version >= :data:`LLVM_MIN_VERSION`, or None."""
    best: tuple[int, str] | None = None
    for pattern in patterns:
        for path in glob.glob(pattern):
            major = _llvm_major(path)
            if major is None or major < LLVM_MIN_VERSION or not os.path.exists(path):
                continue
            if best is None or major > best[0]:
                best = (major, path)
    return None if best is None else best[1]


def configure_llvm() -> str | None:
    """Export ``DRJIT_LIBLLVM_PATH`` to the newest suitable libLLVM unless already set.

    Returns the path in use, or None when none was found (the error is raised later, only
    if the LLVM back end is actually needed).
    """
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return os.environ["DRJIT_LIBLLVM_PATH"]
    path = find_libllvm()
    if path is not None:
        os.environ["DRJIT_LIBLLVM_PATH"] = path
    return path


def cuda_available() -> bool:
    """Whether Dr.Jit's CUDA back end works here (a CUDA device and its driver)."""
    configure_llvm()
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.CUDA))
    except Exception:  # pragma: no cover - depends on drivers
        return False


def _llvm_available() -> bool:
    import drjit as dr

    try:
        return bool(dr.has_backend(dr.JitBackend.LLVM))
    except Exception:  # pragma: no cover
        return False


def default_variant() -> str:
    """``cuda_ad_spectral`` when CUDA works, else ``llvm_ad_spectral``."""
    if os.environ.get("NIDAR_VARIANT"):
        return os.environ["NIDAR_VARIANT"]
    return "cuda_ad_spectral" if cuda_available() else "llvm_ad_spectral"


def set_variant(variant: str | None = None) -> str:
    """Activate a Mitsuba variant and register this package's plugins for it.

    Args:
        variant: a Mitsuba variant name; None picks :func:`default_variant`.

    Returns:
        The variant now active.

    Raises:
        NidarError: the variant is unknown, not a spectral one, or its back end is missing.
    """
    configure_llvm()
    with signals_deferred():
        return _set_variant(variant)


@contextlib.contextmanager
def signals_deferred():
    """SIGINT and SIGTERM held back until the block ends, then delivered to their handlers.

    Dr.Jit's and Mitsuba's extensions load and start their back end in C++: a Python exception
    raised by a signal handler inside it comes out as another error (an ImportError, a
    SystemError) or aborts the process. Held back (the block's handlers only note the signal),
    it is raised again when the block ends and handled as anywhere else. A signal the process
    ignores stays ignored; outside the main thread nothing is held back.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held: list[int] = []

    def hold(signum, frame):  # noqa: ARG001 - signal handler signature
        held.append(signum)

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(sig)
        if handler not in (signal.SIG_IGN, None):
            previous[sig] = handler
            signal.signal(sig, hold)
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        for sig in dict.fromkeys(held):
            signal.raise_signal(sig)


def _set_variant(variant: str | None) -> str:
    import mitsuba as mi

    variant = variant or default_variant()
    if variant not in mi.variants():
        raise NidarError(
            f"unknown Mitsuba variant '{variant}' (available: {', '.join(mi.variants())})"
        )
    if "spectral" not in variant:
        raise NidarError(
            f"variant '{variant}' is not spectral: use one of {', '.join(SUPPORTED_VARIANTS)}"
        )
    if variant.startswith("llvm") and not _llvm_available():
        raise NidarError(f"Dr.Jit cannot load libLLVM for variant '{variant}': {_FIX}")
    if variant.startswith("cuda") and not cuda_available():
        raise NidarError(
            f"variant '{variant}' needs a working CUDA device; use `variant` llvm_ad_spectral"
        )
    if mi.variant() != variant:
        mi.set_variant(variant)
    from . import plugins

    plugins.register_all()  # once per variant; makes nidar_mi.plugins.<name> this variant's
    return variant


def active_variant(expected: str | None = None) -> str:
    """The active Mitsuba variant, with this package's plugins registered for it.

    Args:
        expected: the variant the caller expects (None: any spectral one).

    Raises:
        NidarError: no spectral variant is active, or another than ``expected``.
    """
    configure_llvm()
    import mitsuba as mi

    from . import plugins

    variant = mi.variant()
    if variant is None or "spectral" not in variant:
        raise NidarError(
            f"no spectral Mitsuba variant is active (active: {variant}): choose one first with "
            "nidar_mi.backend.set_variant()"
        )
    if expected is not None and expected != variant:
        raise NidarError(f"variant '{expected}' is not the active one ('{variant}')")
    plugins.register_all()  # once per variant; a variant set by mi.set_variant alone has none
    return variant


def prepare_worker(threads: int | None = None, variant: str | None = None) -> str:
    """Make a worker process ready to render: Dr.Jit's CPU threads, the variant, the plugins.

    The set-up of every task of :func:`nidar_mi.tasks.run_tasks` that renders (plugins register
    per variant per process, so each worker process sets the variant itself). Cheap when
    repeated. A process that has a spectral variant active keeps it unless ``variant`` names
    another: a serial job runs its tasks in the caller's process, whose variant its entry point
    chose. Callers pass their own variant (:func:`worker_setup`) so that the workers of a
    parallel job render in it too.

    Args:
        threads: CPU threads Dr.Jit may use in this process (None: leave Dr.Jit's default,
            every core).
        variant: as for :func:`set_variant`; None: the active spectral variant, else the
            default one (a fresh worker process).

    Returns:
        The variant now active.
    """
    if threads is not None:
        configure_llvm()
        import drjit as dr

        if dr.thread_count() != threads:
            dr.set_thread_count(threads)
    return set_variant(variant or _active_spectral())


def worker_setup():
    """The ``setup`` of a job whose tasks render: :func:`prepare_worker` with the caller's
    variant (:func:`active_variant`), so that workers render in the variant the entry point
    chose and a serial job leaves it as it was.

    Raises:
        NidarError: no spectral variant is active.
    """
    import functools

    return functools.partial(prepare_worker, variant=active_variant())


def _active_spectral() -> str | None:
    """The active Mitsuba variant when it is a spectral one, else None."""
    configure_llvm()
    import mitsuba as mi

    variant = mi.variant()
    return variant if variant is not None and "spectral" in variant else None


if sys.platform == "darwin":  # pragma: no cover
    _LLVM_GLOBS = _LLVM_GLOBS + ("/opt/local/libexec/llvm-*/lib/libLLVM.dylib",)
