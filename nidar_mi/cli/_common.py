"""What every command shares: one-line errors, exit codes, Ctrl-C and SIGTERM, ``-D``, ``--version``.

A command is ``main(argv=None) -> int``: it parses its arguments (:func:`parser`), then hands
the work to :func:`run`, which turns every expected failure into one line on stderr and an exit
status:

======  ====================================================================================
status  meaning
======  ====================================================================================
0       success
2       bad input or environment (:class:`~nidar_mi.errors.NidarError`, an OS error on a file,
        a module of an optional extra that is not installed: :mod:`nidar_mi.extras`)
130     interrupted by Ctrl-C (SIGINT)
143     terminated (SIGTERM)
======  ====================================================================================

Library messages name a parameter in backticks (`` `spp` ``); :func:`run` shows each as the
command's flag (``--spp``; :func:`flag_message`).

Outputs are written through staging folders (:func:`nidar_mi.io.atomic.staged_directory`), so an
interrupted or failed command leaves nothing behind. Warnings are printed as one
``warning: ...`` line each.

Every command takes ``-q``/``--quiet`` (warnings and errors only, no summary) and
``-v``/``--verbose`` (debug lines too; each command's ``--help`` says which: one per frame
rendered, per scene, per epoch, ...); the package's log lines go to stderr at that level while
:func:`run` runs. Progress bars (:func:`show_progress`) show on a terminal only, unless
``--progress`` or ``--no-progress`` says otherwise; ``-q`` hides them, and no bar of the
command's work shows where it decided on none (:func:`nidar_mi.progress.bars_allowed`).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import signal
import sys
import warnings
from collections.abc import Callable, Mapping

from ..errors import MAX_SEED, NidarError, check_seed, flag_message
from ..extras import extra_of, missing_extra
from ..progress import bars_allowed, stderr_is_terminal
from . import early_signals

__all__ = [
    "EXIT_OK",
    "EXIT_USER_ERROR",
    "EXIT_INTERRUPTED",
    "EXIT_TERMINATED",
    "Terminated",
    "flag_message",
    "out_path",
    "parser",
    "parse_defines",
    "run",
    "scene_inputs",
    "seed_arg",
    "show_progress",
    "add_weather_args",
    "weather_of",
]

EXIT_OK = 0
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_TERMINATED = 143


class Terminated(KeyboardInterrupt):
    """Raised in the main thread when the process receives SIGTERM.

    A subclass of :class:`KeyboardInterrupt`, so every clean-up path that handles Ctrl-C
    (staging folders, progress bars) handles SIGTERM alike.
    """


#: The signals that arrived during :func:`run`'s work, in order.
_signalled: list[int] = []


def _on_sigterm(signum, frame):  # noqa: ARG001 - signal handler signature
    _signalled.append(signal.SIGTERM)
    raise Terminated()


def _on_sigint(signum, frame):  # noqa: ARG001 - signal handler signature
    _signalled.append(signal.SIGINT)
    raise KeyboardInterrupt()


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one ``error: ...`` line and status 2."""

    def error(self, message: str):
        print(f"error: {_one_line(message)} (see {self.prog} --help)", file=sys.stderr)
        raise SystemExit(EXIT_USER_ERROR)


def parser(
    command: str, description: str, *, verbose: str, progress: bool = True, **kwargs
) -> argparse.ArgumentParser:
    """An argument parser for ``python -m nidar_mi.<command>`` with ``--version``, ``-q`` and
    ``-v`` (and ``--progress``/``--no-progress`` where the command shows ``progress`` bars); a
    usage error (unknown option, a value of the wrong type) is one line on stderr and status 2.

    Args:
        command: the command's name.
        description: what it does, for ``--help``.
        verbose: what ``-v`` adds for this command (its debug lines), for ``--help``.
        progress: the command shows progress bars.
    """
    from .. import __version__

    p = _Parser(prog=f"python -m nidar_mi.{command}", description=description, **kwargs)
    p.add_argument("--version", action="version", version=f"nidar_mi {__version__}")
    level = p.add_mutually_exclusive_group()
    level.add_argument(
        "-q", "--quiet", action="store_true", help="warnings and errors only (no summary, no bars)"
    )
    level.add_argument("-v", "--verbose", action="store_true", help=f"debug lines too: {verbose}")
    if progress:
        bars = p.add_mutually_exclusive_group()
        bars.add_argument(
            "--progress",
            action="store_true",
            default=None,
            help="progress bars even when stderr is not a terminal (default: on a terminal only)",
        )
        bars.add_argument(
            "--no-progress", dest="progress", action="store_false", help="no progress bars"
        )
    return p


def out_path(text: str) -> str:
    """argparse ``type`` of an output path: any path but an empty one."""
    if not text.strip():
        raise argparse.ArgumentTypeError("an empty path; name the output")
    return text


def show_progress(args: argparse.Namespace) -> bool:
    """Whether the command shows progress bars: ``--progress`` / ``--no-progress`` when given,
    none with ``-q``, else only when stderr is a terminal (never in a log file or a pipe)."""
    chosen = getattr(args, "progress", None)
    if chosen is not None:
        return bool(chosen)
    if getattr(args, "quiet", False):
        return False
    return stderr_is_terminal()


class _StderrHandler(logging.StreamHandler):
    """Log lines on the current ``sys.stderr`` (which tests and notebooks may replace)."""

    def __init__(self):
        super().__init__(sys.stderr)
        self.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):  # the base class sets it; the property always answers sys.stderr
        pass


@contextlib.contextmanager
def _log_level(args: argparse.Namespace | None):
    """The package's log lines on stderr at the level ``-q`` / ``-v`` pick (INFO by default)."""
    level = logging.INFO
    if getattr(args, "quiet", False):
        level = logging.WARNING
    elif getattr(args, "verbose", False):
        level = logging.DEBUG
    logger = logging.getLogger("nidar_mi")
    handler = _StderrHandler()
    handler.setLevel(level)
    previous = logger.level
    logger.setLevel(min(level, logger.getEffectiveLevel()))
    logger.addHandler(handler)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(previous)


def seed_arg(text: str) -> int:
    """argparse ``type`` of a ``--seed`` option: an integer in [0, 2**32 - 1]."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got '{text}'") from None
    try:
        return check_seed(value)
    except NidarError:
        raise argparse.ArgumentTypeError(f"must lie in [0, {MAX_SEED}] (got {value})") from None


def parse_defines(items: list[str]) -> dict[str, str]:
    """``-D NAME=VALUE`` options as a dict (later ones win).

    Raises:
        NidarError: an item without ``=``, with an empty name or an empty value.
    """
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise NidarError(f"-D expects NAME=VALUE (got '{item}')")
        if not value.strip():
            raise NidarError(
                f"-D {name.strip()}= has no value: give NAME=VALUE (leave -D {name.strip()} out "
                "to keep the scene's own value)"
            )
        out[name.strip()] = value.strip()
    return out


def scene_inputs(scene: str, depth: int = 8) -> list[str]:
    """A scene file and the files it names (``<include>``, meshes, textures, ``filename``
    strings), resolved against its folder, includes followed ``depth`` levels: the inputs an
    output must not hold (:func:`nidar_mi.io.atomic.check_outside_inputs`). A file that does not
    parse lists only itself; the scene's own checks report it."""
    import os
    import xml.etree.ElementTree as ET

    from ..io.atomic import file_problem

    found = [scene]
    if file_problem(scene):  # a pipe or a device is never opened here; the scene's checks say
        return found
    try:
        root = ET.parse(scene).getroot()
    except (OSError, ET.ParseError):
        return found
    base = os.path.dirname(os.path.abspath(scene))
    for el in root.iter():
        name = el.get("filename") if el.tag == "include" else None
        if el.tag == "string" and el.get("name") == "filename":
            name = el.get("value")
        if not name or "$" in name:
            continue
        path = os.path.join(base, name)
        if el.tag == "include" and depth > 0 and path not in found:
            found += [p for p in scene_inputs(path, depth - 1) if p not in found]
        elif path not in found:
            found.append(path)
    return found


#: A parameter named in a library message: a Python identifier in backticks.
def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def _show_warning(message, category, filename, lineno, file=None, line=None):  # noqa: ARG001
    print(f"warning: {_one_line(message)}", file=sys.stderr)


def _left(on_interrupt: str | Callable[[], str]) -> str:
    return _one_line(on_interrupt() if callable(on_interrupt) else on_interrupt)


def run(
    work: Callable[[], int | None],
    *,
    on_interrupt: str | Callable[[], str] = "nothing written",
    flags: Mapping[str, str] | None = None,
    args: argparse.Namespace | None = None,
) -> int:
    """Run a command's work and map every expected failure to one line and an exit status.

    Args:
        work: the command body; returns an exit status or None (success).
        on_interrupt: what the user is told is left after Ctrl-C or SIGTERM (or a function
            that says it, called after the work was stopped).
        flags: the command's flags of the parameters library messages name, where a flag is
            not ``--`` and the name with hyphens (:func:`flag_message`).
        args: the parsed command line, whose ``-q`` / ``-v`` set the log level (INFO without).

    Returns:
        The exit status (see the module docstring).
    """
    previous = {signal.SIGTERM: signal.getsignal(signal.SIGTERM)}
    sigint = signal.getsignal(signal.SIGINT)
    if sigint in (signal.default_int_handler, early_signals.early_handler):  # not ignored
        previous[signal.SIGINT] = sigint
    handlers = {signal.SIGTERM: _on_sigterm, signal.SIGINT: _on_sigint}
    try:
        for sig in previous:
            signal.signal(sig, handlers[sig])
    except ValueError:  # not the main thread: leave the signals alone
        previous = {}
    _signalled.clear()
    try:
        bars = show_progress(args) if args is not None else stderr_is_terminal()
        with warnings.catch_warnings(), _log_level(args), bars_allowed(bars):
            warnings.simplefilter("default")
            warnings.showwarning = _show_warning
            status = work()
        return EXIT_OK if status is None else int(status)
    except NidarError as e:
        print(f"error: {_one_line(flag_message(str(e), flags))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except Terminated:
        print(f"terminated; {_left(on_interrupt)}", file=sys.stderr)
        return EXIT_TERMINATED
    except KeyboardInterrupt:
        print(f"interrupted; {_left(on_interrupt)}", file=sys.stderr)
        return EXIT_INTERRUPTED
    except ModuleNotFoundError as e:  # a module of an extra that is not installed
        extra = extra_of(e.name or "")
        if extra is None:
            raise
        message = missing_extra(extra, "this command", ((e.name or "").split(".")[0],))
        print(f"error: {message}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as e:
        if _signalled:
            return _stopped(on_interrupt)
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        print(f"error: {where}{_one_line(e.strerror or e)}", file=sys.stderr)
        return EXIT_USER_ERROR
    except Exception:
        if _signalled:  # a signal unwinding an import: the extension's loader re-raised it
            return _stopped(on_interrupt)
        raise
    finally:
        for sig, handler in previous.items():
            if handler is early_signals.early_handler:  # its "nothing written" no longer holds
                handler = signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL
            signal.signal(sig, handler)


def _stopped(on_interrupt) -> int:
    """The line and status of a run that a signal stopped, whatever exception it became."""
    if _signalled[-1] == signal.SIGTERM:
        print(f"terminated; {_left(on_interrupt)}", file=sys.stderr)
        return EXIT_TERMINATED
    print(f"interrupted; {_left(on_interrupt)}", file=sys.stderr)
    return EXIT_INTERRUPTED


def add_weather_args(p: argparse.ArgumentParser, *, what: str) -> None:
    """``--fog``, ``--fog-type``, ``--rain`` and ``--snow`` (:mod:`nidar_mi.weather`) in one
    group; ``what`` says what they apply to."""
    g = p.add_argument_group("weather (docs/WEATHER.md)")
    g.add_argument(
        "--fog",
        type=float,
        default=None,
        metavar="MOR_M",
        help=f"fog of this meteorological optical range in m (5 .. 100000) {what}",
    )
    g.add_argument(
        "--fog-type",
        default=None,
        choices=("advection", "radiation"),
        help="the fog's droplets: advection (default) or radiation fog",
    )
    g.add_argument(
        "--rain", type=float, default=None, metavar="MM_PER_H", help=f"rain, mm/h (0 .. 300) {what}"
    )
    g.add_argument(
        "--snow",
        type=float,
        default=None,
        metavar="MM_PER_H",
        help=f"snowfall as melted water, mm/h (0 .. 50; not with --rain) {what}",
    )


def weather_of(args: argparse.Namespace):
    """The :class:`nidar_mi.weather.Weather` of the weather flags (checked), or None when no
    flag was given.

    Raises:
        NidarError: an impossible value, or ``--fog-type`` without ``--fog``.
    """
    from ..weather import Weather, check_weather

    if args.fog_type is not None and args.fog is None:
        raise NidarError("`fog_type` needs `fog`")
    if args.fog is None and args.rain is None and args.snow is None:
        return None
    from ..extras import require

    w = check_weather(
        Weather(fog=args.fog, fog_type=args.fog_type or "advection", rain=args.rain, snow=args.snow)
    )
    require("weather", "fog, rain and snow")
    return w
