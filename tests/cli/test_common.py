"""The shared command-line contract: one line and status 2 on bad input, 130/143 on SIGINT/SIGTERM
with nothing left behind, ``-D`` parsing, ``--version`` on every command, the command list."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
import warnings

import pytest

from nidar_mi import __version__
from nidar_mi.cli import COMMANDS
from nidar_mi.cli._common import (
    EXIT_INTERRUPTED,
    EXIT_TERMINATED,
    EXIT_USER_ERROR,
    flag_message,
    parse_defines,
    run,
)
from nidar_mi.errors import NidarError
from tests.helpers.signals import default_sigint

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def test_run_maps_failures_to_one_line_and_a_status(capsys):
    assert run(lambda: None) == 0
    assert run(lambda: 3) == 3

    def bad():
        raise NidarError("scene.xml: line 3,\n  col 4: broken")

    assert run(bad) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err == "error: scene.xml: line 3, col 4: broken\n"

    def missing():
        open(os.path.join(REPO, "no", "such", "file"))

    assert run(missing) == EXIT_USER_ERROR
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1 and "no/such/file" in err

    def ctrl_c():
        raise KeyboardInterrupt

    assert run(ctrl_c, on_interrupt="x kept") == EXIT_INTERRUPTED
    assert capsys.readouterr().err == "interrupted; x kept\n"


def test_warnings_are_one_line(capsys):
    def warn():
        warnings.warn("first part\nsecond part", RuntimeWarning, stacklevel=1)

    assert run(warn) == 0
    assert capsys.readouterr().err == "warning: first part second part\n"


def test_library_parameters_are_shown_as_flags(capsys):
    msg = "`ray_address` a:1: `scene_dir` and `spp` in scenes/spp `x-y` `a b`"
    assert flag_message(msg, {"scene_dir": "--scenes"}) == (
        "--ray-address a:1: --scenes and --spp in scenes/spp `x-y` `a b`"
    )

    def fail():
        raise NidarError("`scene_dir`: no such directory /x/scene_dir")

    assert run(fail, flags={"scene_dir": "--scenes"}) == EXIT_USER_ERROR
    assert capsys.readouterr().err == "error: --scenes: no such directory /x/scene_dir\n"


def test_parse_defines():
    assert parse_defines(["a=1", " b = x y ", "a=2"]) == {"a": "2", "b": "x y"}
    for bad in (["a"], ["=1"], [" =1"]):
        with pytest.raises(NidarError, match="NAME=VALUE"):
            parse_defines(bad)


@pytest.mark.parametrize("item", ["drop=", "drop=  ", "drop=\t"])
def test_an_empty_define_is_refused(item):
    """``-D drop=`` used to set the parameter to an empty string, which the scene then read as
    0.0 instead of its own value."""
    with pytest.raises(NidarError, match=r"^-D drop= has no value: give NAME=VALUE"):
        parse_defines(["cols=8", item])


def _cli(*args, **kw):
    return subprocess.run(
        [sys.executable, "-m", *args], capture_output=True, text=True, cwd=REPO, timeout=300, **kw
    )


def test_command_list_and_versions():
    r = _cli("nidar_mi")
    assert r.returncode == 0
    listed = [line.split()[0] for line in r.stdout.splitlines() if line.startswith("  ")]
    assert listed == list(COMMANDS)
    for name in COMMANDS:
        r = _cli(f"nidar_mi.{name}", "--version")
        assert (r.returncode, r.stdout.strip()) == (0, f"nidar_mi {__version__}"), name
    r = _cli("nidar_mi", "frobnicate")
    assert r.returncode == 2 and r.stderr.startswith("error: unknown command 'frobnicate'")
    r = _cli("nidar_mi", "render", "--help")
    assert r.returncode == 0 and "python -m nidar_mi.render" in r.stdout


@pytest.mark.parametrize(
    "sig, status, word",
    [
        (signal.SIGTERM, EXIT_TERMINATED, "terminated"),
        (signal.SIGINT, EXIT_INTERRUPTED, "interrupted"),
    ],
)
def test_signal_during_render_leaves_nothing(tmp_path, sig, status, word):
    """A render stopped while it writes leaves neither OUT nor its staging folder."""
    out = tmp_path / "street"
    proc = subprocess.Popen(
        # large enough (~20 camera-seconds) that the signal always lands while it works
        [sys.executable, "-m", "nidar_mi.render", "scenes/street.xml", "-o", str(out), "-q"]
        + ["-D", "width=1280", "-D", "height=720", "--spp", "64"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # a test run started as a background job of a non-interactive shell ignores SIGINT, and
        # children inherit that: give the command the default disposition a terminal gives it
        preexec_fn=default_sigint,
    )
    deadline = time.monotonic() + 120
    while not any(p.name.startswith(".street.partial-") for p in tmp_path.iterdir()):
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the render never started writing"
        time.sleep(0.05)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == status, err
    assert err.strip().splitlines()[-1] == f"{word}; nothing written"
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "sig, status, word",
    [
        (signal.SIGTERM, EXIT_TERMINATED, "terminated"),
        (signal.SIGINT, EXIT_INTERRUPTED, "interrupted"),
    ],
)
def test_a_signal_that_an_import_turns_into_another_error_is_still_one_line(
    sig, status, word, capsys
):
    """A C extension's loader re-raises the signal's exception as an ImportError (Dr.Jit's
    does, while it initialises): still the signal's line and status, no traceback."""
    from nidar_mi.cli._common import run

    def work():
        try:
            os.kill(os.getpid(), sig)
            time.sleep(5)
        except KeyboardInterrupt as e:
            raise ImportError("Encountered an error while initializing the extension.") from e

    old = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        assert run(work) == status
    finally:
        signal.signal(signal.SIGINT, old)
    assert capsys.readouterr().err == f"{word}; nothing written\n"

    def bug():
        raise ImportError("a bug, not a signal")

    with pytest.raises(ImportError):  # without a signal: a traceback, as before
        run(bug)


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_command_has_quiet_verbose_and_progress_options(command, capsys):
    """``-q`` / ``-v`` on every command; ``--progress`` / ``--no-progress`` where it has bars."""
    import importlib

    module = importlib.import_module(f"nidar_mi.cli.{command}")
    with pytest.raises(SystemExit) as e:
        module.main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert "-q, --quiet" in text and "-v, --verbose" in text
    if command != "materials":
        assert "--progress" in text and "--no-progress" in text


def test_every_command_says_what_verbose_adds():
    """``-v``'s help used to say "one per epoch" on every command; each says its own lines."""
    import importlib

    helps = {}
    for command in COMMANDS:
        module = importlib.import_module(f"nidar_mi.cli.{command}")
        build = getattr(module, "build_parser", None) or module._parser
        (verbose,) = [a.help for a in build()._actions if "--verbose" in a.option_strings]
        helps[command] = verbose
    assert len(set(helps.values())) == len(COMMANDS), helps
    assert [c for c, h in helps.items() if "epoch" in h] == ["train"]
    assert "per frame" in helps["render"] and "per scene" in helps["scenegen"]


@pytest.mark.parametrize("argv", [["-q"], [], ["-q", "--no-progress"]])
def test_no_bar_of_the_work_shows_where_the_command_wants_none(argv, capsys):
    """A library function asked for its bar (``progress=True``, a default) inside a command run
    with ``-q`` or into a log used to draw it there all the same."""
    from nidar_mi.progress import progress_bar

    def work():
        assert list(progress_bar(range(3), show=True, desc="library bar")) == [0, 1, 2]

    assert run(work, args=_args(argv)) == 0
    assert "library bar" not in capsys.readouterr().err
    assert run(work, args=_args(["--progress"])) == 0
    assert "library bar" in capsys.readouterr().err


def _args(argv):
    from nidar_mi.cli._common import parser

    return parser("x", "a command", verbose="none").parse_args(argv)


@pytest.mark.parametrize(
    "argv, terminal, shown",
    [
        ([], False, False),  # a log file or a pipe: no bar
        ([], True, True),  # a terminal: bars
        (["--progress"], False, True),
        (["--no-progress"], True, False),
        (["-q"], True, False),
        (["-q", "--progress"], False, True),
    ],
)
def test_progress_bars_only_on_a_terminal_unless_asked(argv, terminal, shown, monkeypatch):
    from nidar_mi.cli import _common

    monkeypatch.setattr(_common, "stderr_is_terminal", lambda: terminal)
    assert _common.show_progress(_args(argv)) is shown


def test_progress_bar_follows_the_terminal(monkeypatch, capsys):
    """``show=None`` shows the bar on a terminal only; the helper writes to stderr."""
    import nidar_mi.progress as progress

    monkeypatch.setattr(progress, "stderr_is_terminal", lambda: False)
    assert list(progress.progress_bar(range(3), show=None, desc="quiet")) == [0, 1, 2]
    assert capsys.readouterr().err == ""
    list(progress.progress_bar(range(3), show=True, desc="shown"))
    assert "shown" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, lines",
    [([], ["INFO", "WARNING"]), (["-v"], ["DEBUG", "INFO", "WARNING"]), (["-q"], ["WARNING"])],
)
def test_log_level_follows_quiet_and_verbose(argv, lines, capsys):
    """INFO by default, DEBUG with ``-v`` (e.g. training's per-epoch lines), warnings only with
    ``-q``; the handler goes away with the command."""
    import logging

    log = logging.getLogger("nidar_mi.some_module")

    def work():
        log.debug("per-epoch detail")
        log.info("a step done")
        log.warning("look at this")

    assert run(work, args=_args(argv)) == 0
    err = capsys.readouterr().err.splitlines()
    assert [line.split()[0] for line in err] == lines
    assert run(work) == 0  # without args: INFO
    assert len(capsys.readouterr().err.splitlines()) == 2
    assert not any(
        type(h).__name__ == "_StderrHandler" for h in logging.getLogger("nidar_mi").handlers
    )


def test_no_progress_bar_in_a_log(tmp_path, capsys):
    """A command whose stderr is not a terminal (here captured) writes no progress bar."""
    from nidar_mi.cli.scenegen import main

    assert main(["-o", str(tmp_path / "s"), "--count", "1"]) == 0
    err = capsys.readouterr().err
    assert "%|" not in err and "scenegen" not in err, err


def test_readme_names_the_installed_console_scripts():
    """The README lists every console script of pyproject.toml by its installed name, one per
    command, and no other ``nidar-...`` script."""
    import re

    pyproject = open(os.path.join(REPO, "pyproject.toml"), encoding="utf-8").read()
    table = pyproject.split("[project.scripts]", 1)[1].split("\n[", 1)[0]
    scripts = set(re.findall(r"^([a-z-]+) = ", table, re.M))
    readme = open(os.path.join(REPO, "README.md"), encoding="utf-8").read()
    assert {f"nidar-{c.replace('_', '-')}" for c in COMMANDS} | {"nidar-mi"} == set(scripts)
    named = set(re.findall(r"`(nidar-[a-z<][a-z>-]*)", readme))
    assert named == set(scripts)


@pytest.mark.parametrize(
    "sig, status, word",
    [
        (signal.SIGTERM, EXIT_TERMINATED, "terminated"),
        (signal.SIGINT, EXIT_INTERRUPTED, "interrupted"),
    ],
)
def test_a_signal_while_a_command_imports_is_one_line(sig, status, word):
    """What a command's ``__main__`` does first: a signal before its run (while it imports) is
    the same line and status as one during it, not a traceback or a silent exit."""
    code = (
        "import os, signal, time\n"
        "from nidar_mi.cli import early_signals\n"
        "early_signals.install()\n"
        f"os.kill(os.getpid(), {int(sig)})\n"
        "time.sleep(10)\n"
        "print('not stopped')\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=60,
        preexec_fn=default_sigint,
    )
    assert (proc.returncode, proc.stderr, proc.stdout) == (status, f"{word}; nothing written\n", "")


def test_run_takes_over_from_the_early_handlers(capsys):
    """After :func:`early_signals.install`, ``run`` still turns Ctrl-C into its own line (its
    clean-up runs) and leaves Python's defaults, not the early handlers (whose "nothing
    written" would no longer be true); an ignored SIGINT stays ignored."""
    from nidar_mi.cli import early_signals
    from nidar_mi.cli._common import run

    def work():
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(5)

    old = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        signal.signal(signal.SIGINT, signal.default_int_handler)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        early_signals.install()
        assert run(work, on_interrupt="the partial output removed") == EXIT_INTERRUPTED
        assert capsys.readouterr().err == "interrupted; the partial output removed\n"
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        early_signals.install()
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        for s, h in old.items():
            signal.signal(s, h)


def test_every_command_module_takes_the_signals_first():
    """Every ``python -m`` entry of a command installs the early handlers before it imports
    the command."""
    import pathlib
    import re

    entries = [
        p
        for p in pathlib.Path(REPO, "nidar_mi").rglob("*.py")
        if re.search(r"^\s*from nidar_mi\.cli(\.\w+)? import .*\bmain\b", p.read_text(), re.M)
    ]
    assert len(entries) >= len(COMMANDS)
    for path in entries:
        text = path.read_text()
        assert "early_signals.install()" in text, path
        first = text.index("early_signals.install()")
        assert first < text.index("sys.exit(main())"), path
        command = re.search(r"from nidar_mi\.cli\.\w+ import main", text)
        assert command is None or first < command.start(), path
