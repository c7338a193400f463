"""The command-line contract, command by command: bad output paths, bad seeds and parameters,
unreadable inputs, Ctrl-C and SIGTERM. Every case: status 2 (130/143 for signals), one line on
stderr, no traceback, nothing half-written, nothing left over, the output as it was."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time

import pytest

from nidar_mi.cli import COMMANDS
from nidar_mi.cli._common import EXIT_INTERRUPTED, EXIT_TERMINATED, Terminated
from tests.helpers.signals import default_sigint

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _argv(command, out, tiny_scene, assign_inputs, synthetic_data, tmp_path):
    """Valid inputs of ``command`` with ``out`` as its output."""
    scenes = os.path.dirname(tiny_scene)
    return {
        "render": [tiny_scene, "-o", out, "-q", "--spp", "1"],
        "dataset": ["--scenes", scenes, "-o", out, "-q", "--spp", "1"],
        "assign": [*assign_inputs, "-o", out],
        "train": [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"],
        "evaluate": ["--data", tmp_path / "no_data", "-o", out, "-q"],
        "scenegen": ["--count", "1", "-o", out, "-q"],
        "materials": ["--plot", "grass", "-o", os.path.join(out, "spectra.png")],
        "drive": [
            "-o",
            out,
            "-q",
            "--blocks",
            "2,1",
            "--frames",
            "10",
            "--cols",
            "64",
            "--width",
            "16",
            "--height",
            "16",
            "--spp",
            "1",
            "--sources",
            "physics",
        ],
        "pseudo_nir": [assign_inputs[5], "-o", out, "-q"],
        "calibrate": [synthetic_data, "-o", out, "-q"],
        "weather": [assign_inputs[1], "-o", out, "--fog", "50", "-q"],
        "reflectance_cue": ["--test", synthetic_data, "-o", out, "-q"],
        "reconstruct": [_tiny_drive(tmp_path), "-o", out, "-q"],
    }[command]


def _tiny_drive(tmp_path) -> str:
    """A drive folder of two scans beside ``tmp_path`` (outside the folder the tests snapshot;
    its content is never read: the output is refused first)."""
    import numpy as np

    vel = tmp_path.parent / f"{tmp_path.name}_drive" / "velodyne"
    vel.mkdir(parents=True, exist_ok=True)
    for k in range(2):
        np.zeros((4, 4), "<f4").tofile(vel / f"{k:06d}.bin")
    return str(vel.parent)


# ------------------------------------------------------------------------ 1: output paths


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("where", ["a file", "under a file", "under /proc"])
def test_output_path_problems_are_one_line(
    command,
    where,
    tmp_path,
    call,
    one_error_line,
    snapshot,
    tiny_scene,
    assign_inputs,
    synthetic_data,
    variant,
):
    blocker = tmp_path / "blocker"
    blocker.write_text("keep me")
    out = {
        "a file": blocker,
        "under a file": blocker / "out",
        "under /proc": "/proc/nidar_mi_no_such/out",
    }[where]
    if command == "materials" and where == "a file":
        out = blocker.parent / "blocker" / "x"  # -o names the PNG: its folder is the file
    before = snapshot(tmp_path)
    status, _, err = call(
        command, _argv(command, out, tiny_scene, assign_inputs, synthetic_data, tmp_path)
    )
    one_error_line(status, err)
    assert snapshot(tmp_path) == before


# ------------------------------------------------------------------------ 2: seeds, -D values


@pytest.mark.parametrize(
    "command, extra, needle",
    [
        ("render", ["--seed", "4294967296"], "--seed"),
        ("render", ["--seed", "-1"], "--seed"),
        ("render", ["--seed", "1e3"], "--seed"),
        ("render", ["-D", "width=0"], "0x12 film"),
        ("render", ["-D", "cols=0"], "horizontal_resolution"),
        ("render", ["-D", "cols=abc"], "line 7, col 10: could not parse integer value"),
        ("render", ["-D", "nosuch=1"], "nosuch"),
        ("render", ["--spp", "0"], "--spp"),
        ("dataset", ["--seed", "-1"], "--seed"),
        ("dataset", ["--seed", "4294967296"], "--seed"),
        ("dataset", ["-D", "foo=1"], "-D foo"),
        ("dataset", ["--split", "nan,1,1"], "--split"),
        ("dataset", ["--intensity-scale", "nan"], "--intensity-scale"),
        ("train", ["--seed", "-1"], "--seed"),
        ("train", ["--epochs", "0"], "epochs"),
        ("train", ["--epochs", "-1"], "epochs"),
        ("train", ["--max-steps", "0"], "max_steps"),
        ("scenegen", ["--seed", "-1"], "--seed"),
        ("render", ["--no-such-option"], "unrecognized arguments"),
        ("weather", ["--seed", "-1"], "--seed"),
        ("weather", ["--fog", "0"], "--fog"),
        ("weather", ["--snow", "-2"], "--snow"),
        ("render", ["--rain", "301"], "--rain"),
    ],
)
def test_bad_seeds_and_parameters_are_one_line(
    command,
    extra,
    needle,
    tmp_path,
    call,
    one_error_line,
    tiny_scene,
    assign_inputs,
    synthetic_data,
    variant,
):
    out = tmp_path / "out"
    argv = _argv(command, out, tiny_scene, assign_inputs, synthetic_data, tmp_path)
    status, _, err = call(command, argv + extra)
    one_error_line(status, err, needle)
    assert not out.exists()


# ------------------------------------------------------------------------ 5: unreadable inputs


def test_dataset_with_a_non_utf8_scene_is_one_line(tmp_path, call, one_error_line, tiny_scene):
    bad = os.path.join(os.path.dirname(tiny_scene), "latin1.xml")
    with open(bad, "wb") as f:
        f.write('<scene version="3.0.0"><!-- caf\xe9 --></scene>'.encode("latin-1"))
    status, _, err = call("dataset", ["--scenes", os.path.dirname(bad), "-o", tmp_path / "d"])
    one_error_line(status, err, "latin1.xml")
    assert not (tmp_path / "d").exists()


# ------------------------------------------------------------------------ 4: Ctrl-C, SIGTERM


@pytest.fixture(params=[KeyboardInterrupt, Terminated], ids=["SIGINT", "SIGTERM"])
def stop(request):
    """The exception a signal raises in a command, its status and its word."""
    if request.param is KeyboardInterrupt:
        return KeyboardInterrupt, EXIT_INTERRUPTED, "interrupted"
    return Terminated, EXIT_TERMINATED, "terminated"


def _raise(exc):
    def _stop(*args, **kwargs):
        raise exc()

    return _stop


def test_stopped_dataset_publishes_nothing_and_keeps_complete_renders(
    stop, tmp_path, call, tiny_scene, monkeypatch, variant
):
    exc, status_want, word = stop
    data = tmp_path / "data"
    monkeypatch.setattr("nidar_mi.render_dataset.frames_of_render", _raise(exc))
    status, _, err = call("dataset", ["--scenes", os.path.dirname(tiny_scene), "-o", data, "-q"])
    assert status == status_want and "Traceback" not in err
    assert err.strip().splitlines()[-1].startswith(f"{word}; no dataset published")
    assert _names(data) == ["renders"]  # no splits, no meta.json
    (render,) = (data / "renders").iterdir()
    assert render.name == "tiny" and (render / "manifest.json").is_file()


def test_stopped_rebuild_withdraws_the_old_dataset(tmp_path, call, tiny_scene, monkeypatch):
    """A build with other inputs never leaves the old meta.json beside new renders."""
    data = tmp_path / "data"
    scenes = os.path.dirname(tiny_scene)
    assert call("dataset", ["--scenes", scenes, "-o", data, "-q", "--spp", "1"])[0] == 0
    assert (data / "meta.json").is_file() and (data / "train").is_dir()
    monkeypatch.setattr("nidar_mi.render_dataset.frames_of_render", _raise(KeyboardInterrupt))
    argv = ["--scenes", scenes, "-o", data, "-q", "--spp", "1", "-D", "width=20"]
    assert call("dataset", argv)[0] == EXIT_INTERRUPTED
    assert _names(data) == ["renders"]
    manifest = json.loads((data / "renders" / "tiny" / "manifest.json").read_text())
    assert manifest["params"] == {"width": "20"}  # the completed render of the new request


def test_stopped_train_leaves_nothing_or_its_checkpoints(
    stop, tmp_path, call, synthetic_data, monkeypatch
):
    exc, status_want, word = stop
    out = tmp_path / "run"
    argv = [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"]
    monkeypatch.setattr("nidar_mi.nidar.loop._StageRun.train_epoch", _raise(exc))
    status, _, err = call("train", argv)
    assert status == status_want and err.strip().splitlines()[-1] == f"{word}; nothing written"
    assert not out.exists()
    # stopped after the first checkpoint: the checkpoints stay for --resume
    monkeypatch.undo()
    monkeypatch.setattr("nidar_mi.nidar.loop._StageRun.end_epoch", _raise(exc))
    status, _, err = call("train", argv)
    assert status == status_want
    assert err.strip().splitlines()[-1] == (
        f"{word}; checkpoints kept in {out / 'checkpoints'}: --resume continues"
    )
    assert any((out / "checkpoints").iterdir())


def test_failed_train_leaves_no_config(tmp_path, call, one_error_line, synthetic_data):
    out = tmp_path / "run"
    argv = [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"]
    status, _, err = call("train", argv + ["--batch-size", "100"])
    one_error_line(status, err, "batch size 100")
    assert not out.exists()


def test_stopped_assign_writes_nothing(stop, tmp_path, call, assign_inputs, monkeypatch):
    exc, status_want, word = stop
    monkeypatch.setattr("nidar_mi.cloud_intensity.assign_intensity", _raise(exc))
    status, _, err = call("assign", [*assign_inputs, "-o", tmp_path / "out"])
    assert status == status_want and err.strip() == f"{word}; nothing written"
    assert not (tmp_path / "out").exists()


def test_stopped_evaluate_writes_nothing(stop, tmp_path, call, monkeypatch):
    """Stopped inside the evaluation: no OUT, no staging folder, no cache in OUT."""
    exc, status_want, word = stop
    data = tmp_path / "data"
    for name in ("a", "b"):
        (data / "renders" / name).mkdir(parents=True)
        (data / "renders" / name / "manifest.json").write_text("{}")
    meta = {"intensity_scale": 1.0, "scenes": {"train": ["a"], "val": [], "test": ["b"]}}
    (data / "meta.json").write_text(json.dumps(meta))
    monkeypatch.setattr("nidar_mi.eval.suite._evaluate", _raise(exc))
    status, _, err = call("evaluate", ["--data", data, "-o", tmp_path / "out", "--no-twin", "-q"])
    assert status == status_want and err.strip() == f"{word}; nothing written"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["data"]


def _wait_for(predicate, proc, what: str, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"never saw {what}"
        time.sleep(0.02)


@pytest.mark.slow
def test_sigterm_during_a_dataset_build(tmp_path):
    """A real SIGTERM while the scenes render: status 143, one line, no dataset, no staging."""
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    for k in range(4):
        shutil.copy(os.path.join(REPO, "scenes", "street.xml"), scenes / f"street{k}.xml")
    data = tmp_path / "data"
    argv = ["--scenes", scenes, "-o", data, "-q", "--spp", "1", "-D", "cols=512"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "nidar_mi.dataset", *map(str, argv)],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )
    _wait_for(lambda: (data / "renders").is_dir(), proc, "the first render")
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == EXIT_TERMINATED, err
    lines = err.strip().splitlines()
    assert lines[-1].startswith("terminated; no dataset published") and "Traceback" not in err
    assert _names(data) == ["renders"]
    for render in (data / "renders").iterdir():  # only complete render folders, no staging
        assert not render.name.startswith(".") and (render / "manifest.json").is_file()


# ------------------------------------------------------------------------ 18: help texts


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_has_help_and_the_description_is_whole(command):
    import importlib

    module = importlib.import_module(f"nidar_mi.cli.{command}")
    build = getattr(module, "build_parser", None) or module._parser
    p = build()
    assert p.description and p.description.rstrip().endswith("."), p.description
    assert "``" not in p.description
    for action in p._actions:
        if action.dest in ("help", "version"):
            continue
        assert action.help and action.help.strip(), f"{command}: {action.option_strings}"


# ------------------------------------------------------------------------ 7: dataset cache key


def test_dataset_rebuilds_frames_when_a_parameter_changes(tmp_path, call, tiny_scene, variant):
    data = tmp_path / "data"
    base = ["--scenes", os.path.dirname(tiny_scene), "-o", data, "-q", "--spp", "1"]
    base += ["--split", "1,0,0"]
    for width, height in ((16, 12), (24, 18)):
        argv = base + ["-D", f"width={width}", "-D", f"height={height}"]
        assert call("dataset", argv)[0] == 0
        meta = json.loads((data / "meta.json").read_text())
        assert meta["params"] == {"width": str(width), "height": str(height)}
        import numpy as np

        frame = np.load(data / "train" / "tiny__cam.npz")
        assert frame["rgb"].shape == (height, width, 3)  # the frame is the new render's
    assert _names(data) == ["meta.json", "renders", "train"]


def test_dataset_refuses_a_foreign_folder(
    tmp_path, call, one_error_line, snapshot, tiny_scene, variant
):
    data = tmp_path / "data"
    data.mkdir()
    (data / "notes.txt").write_text("mine")
    argv = ["--scenes", os.path.dirname(tiny_scene), "-o", data, "-q", "--spp", "1"]
    for extra in ([], ["--overwrite"]):  # a file dataset did not write is never removed
        status, _, err = call("dataset", argv + extra)
        one_error_line(status, err, "holds 1 file(s) that 'dataset --scenes' did not write")
        assert snapshot(data) == {"notes.txt": b"mine"}


# ------------------------------------------------------------------------ 8: scenegen index


def test_scenegen_rerun_with_another_kind_keeps_index_and_files_in_step(
    tmp_path, call, one_error_line, snapshot
):
    import hashlib

    out = tmp_path / "gen"
    assert call("scenegen", ["--count", "2", "--kind", "urban", "-o", out, "-q"])[0] == 0
    before = snapshot(out)
    status, _, err = call("scenegen", ["--count", "3", "--kind", "vegetated", "-o", out, "-q"])
    one_error_line(status, err, "--overwrite")
    assert snapshot(out) == before  # nothing written, not even scene 2
    argv = ["--count", "3", "--kind", "vegetated", "-o", out, "-q", "--overwrite"]
    assert call("scenegen", argv)[0] == 0
    index = json.loads((out / "index.json").read_text())
    assert [e["kind"] for e in index["scenes"]] == ["vegetated"] * 3
    for e in index["scenes"]:  # every entry describes the file beside it
        assert hashlib.sha256((out / e["file"]).read_bytes()).hexdigest() == e["sha256"]


# ------------------------------------------------------------------------ 11: train inputs


def test_train_with_a_file_that_is_no_stn_copies_nothing(
    tmp_path, call, one_error_line, synthetic_data
):
    out = tmp_path / "run"
    argv = [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"]
    argv += ["--stage", "irnet", "--stn-weights", os.path.join(REPO, "README.md")]
    status, _, err = call("train", argv)
    one_error_line(status, err, "README.md")
    assert not out.exists()


def test_train_into_a_foreign_folder_is_refused(
    tmp_path, call, one_error_line, snapshot, synthetic_data
):
    out = tmp_path / "run"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    argv = [synthetic_data, out, "--reduced", "--device", "cpu", "--no-progress", "-q"]
    for extra in ([], ["--overwrite"]):
        status, _, err = call("train", argv + extra)
        one_error_line(status, err, "holds 1 file(s) that 'train' did not write (notes.txt)")
        assert snapshot(out) == {"notes.txt": b"mine"}


def _names(folder) -> list[str]:
    """The entries of ``folder`` but its record of what wrote it."""
    from nidar_mi.io.ownership import RECORD

    return sorted(p.name for p in folder.iterdir() if p.name != RECORD)
