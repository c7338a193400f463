"""No command deletes what it did not write: every output folder carries the record of what
wrote it (:mod:`nidar_mi.io.ownership`), and a folder is an earlier output only when that record
names the same command and kind of run. Staging left by a killed run is removed by the next run
and said so; staging is flushed to the disk before it is published.

Each case was a way to lose a user's files (or leave hidden data behind) before the record."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
#: The record's file name (:data:`nidar_mi.io.ownership.RECORD`), spelled out for the tests.
RECORD = ".nidar_mi-output.json"


def read_record(folder):
    from nidar_mi.io.ownership import read_record

    return read_record(folder)


def _render(call, scene, out, *extra):
    return call("render", [scene, "-o", out, "-q", "--spp", "1", "--no-cameras", *extra])


def _trajectory(path):
    """A TUM trajectory of 0.3 s along x: two frames at the default 10 Hz."""
    lines = [f"{t:.2f} {t:.2f} 0 0 0 0 0 1" for t in (0.0, 0.1, 0.2, 0.3)]
    path.write_text("\n".join(lines) + "\n")
    return path


# ------------------------------------------------- files a command did not write stay put


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_pseudo_nir_into_a_scenegen_folder_is_refused(
    overwrite, tmp_path, call, one_error_line, snapshot, assign_inputs
):
    """Used to delete both scene XMLs (their folder has an ``index.json``)."""
    scenes = tmp_path / "my_scenes"
    assert call("scenegen", ["--count", "2", "-o", scenes, "-q"])[0] == 0
    before = snapshot(scenes)
    status, _, err = call("pseudo_nir", [assign_inputs[5], "-o", scenes, "-q", *overwrite])
    one_error_line(status, err, "is the output of 'scenegen'")
    assert snapshot(scenes) == before


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_render_keeps_a_file_it_did_not_write(
    overwrite, tmp_path, call, one_error_line, snapshot, tiny_scene, variant
):
    """``webapp`` holds ``manifest.json`` and ``index.html``: ``index.html`` used to go."""
    webapp = tmp_path / "webapp"
    webapp.mkdir()
    (webapp / "manifest.json").write_text('{"name": "my web app"}')
    (webapp / "index.html").write_text("<html></html>")
    before = snapshot(webapp)
    status, _, err = _render(call, tiny_scene, webapp, *overwrite)
    one_error_line(
        status, err, "holds 2 file(s) that 'render' did not write (index.html, manifest.json)"
    )
    assert "never deleted" in err and snapshot(webapp) == before


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_assign_keeps_notes_beside_its_points(
    overwrite, tmp_path, call, one_error_line, snapshot, assign_inputs
):
    """``analysis`` holds ``points.npz`` and ``notes.md``: ``notes.md`` used to go."""
    analysis = tmp_path / "analysis"
    analysis.mkdir()
    (analysis / "points.npz").write_bytes(b"mine")
    (analysis / "notes.md").write_text("# my notes\n")
    before = snapshot(analysis)
    status, _, err = call("assign", [*assign_inputs, "-o", analysis, *overwrite])
    one_error_line(status, err, "holds 1 file(s) that 'assign' did not write (notes.md)")
    assert snapshot(analysis) == before


def test_assign_into_a_render_folder_is_refused(
    tmp_path, call, one_error_line, snapshot, tiny_scene, assign_inputs, variant
):
    """``assign -o out/street/lidar`` used to delete the render's range image, previews and
    point files."""
    street = tmp_path / "street"
    assert _render(call, tiny_scene, street)[0] == 0
    before = snapshot(street)
    for extra in ([], ["--overwrite"]):
        status, _, err = call("assign", [*assign_inputs, "-o", street / "lidar", *extra])
        one_error_line(status, err, "is inside")
        assert "the output of 'render'" in err and snapshot(street) == before
    status, _, err = call("assign", [*assign_inputs, "-o", street / "new", "--overwrite"])
    one_error_line(status, err, "nothing is written into another output")


#: Folders a render replaces only with --overwrite: how each is made, and the words refusing it.
NEEDS_OVERWRITE = {
    "a sequence": ("is the output of 'render' (sequence), another kind of run"),
    "nidar_mi 0.1.0": ("holds no record of what wrote it (nidar_mi 0.1.0 wrote none)"),
}


@pytest.mark.parametrize("earlier", list(NEEDS_OVERWRITE))
def test_a_render_replaces_only_with_overwrite(
    earlier, tmp_path, call, one_error_line, snapshot, tiny_scene, variant
):
    """A single render used to replace a sequence folder ("the same command"); a folder of the
    previous version (no record) is replaced only with ``--overwrite``, and the message says so."""
    out = tmp_path / "out"
    if earlier == "a sequence":
        traj = _trajectory(tmp_path / "drive.tum")
        assert _render(call, tiny_scene, out, "--trajectory", traj)[0] == 0
        assert read_record(out)["kind"] == "sequence"
    else:
        assert _render(call, tiny_scene, out)[0] == 0
        (out / RECORD).unlink()
    before = snapshot(out)
    status, _, err = _render(call, tiny_scene, out)
    one_error_line(status, err, NEEDS_OVERWRITE[earlier])
    assert "--overwrite" in err and snapshot(out) == before
    assert _render(call, tiny_scene, out, "--overwrite")[0] == 0
    assert read_record(out)["kind"] == "scene"


def test_an_earlier_render_is_replaced_and_listed(tmp_path, call, tiny_scene, variant):
    out = tmp_path / "out"
    for _ in range(2):  # the second run replaces the first without --overwrite
        assert _render(call, tiny_scene, out)[0] == 0
    manifest = json.loads((out / "manifest.json").read_text())
    rec = read_record(out)
    assert (rec["command"], rec["kind"]) == ("render", "scene")
    assert rec["files"] == sorted(manifest["files"])  # every file it wrote, nothing else
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out", "scenes"]


@pytest.mark.parametrize("target", ["mine.png", "spectra.png"])
def test_materials_plot_does_not_overwrite_a_file(
    target, tmp_path, call, one_error_line, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    (tmp_path / target).write_bytes(b"my picture")
    argv = ["--plot", "grass"] + (["-o", target] if target != "spectra.png" else [])
    status, _, err = call("materials", argv)
    one_error_line(status, err, f"{target} exists: pass --overwrite to replace it")
    assert (tmp_path / target).read_bytes() == b"my picture"
    assert call("materials", [*argv, "--overwrite"])[0] == 0
    assert (tmp_path / target).read_bytes().startswith(b"\x89PNG")


def test_a_linked_output_is_written_through(tmp_path, call, tiny_scene, variant):
    """A symbolic link ``-o`` used to be renamed to a hidden ``.X.old-*`` and replaced by a real
    folder."""
    real = tmp_path / "real"
    link = tmp_path / "link"
    link.symlink_to(real, target_is_directory=True)
    real.mkdir()
    for _ in range(2):
        assert _render(call, tiny_scene, link)[0] == 0
        assert link.is_symlink() and os.readlink(link) == str(real)
        assert (real / "manifest.json").is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link", "real", "scenes"]


def test_calibrate_writes_through_a_linked_profile(tmp_path, call, synthetic_data):
    real = tmp_path / "profile.json"
    link = tmp_path / "p.json"
    link.symlink_to(real)
    assert call("calibrate", [synthetic_data, "-o", link, "-q", "--form", "physical"])[0] == 0
    assert link.is_symlink() and json.loads(real.read_text())["form"] == "physical"


# ------------------------------------------------------------------------------ staging

_KILLED = """
import os, signal, sys
from nidar_mi.io.atomic import staged_directory
from nidar_mi.io.ownership import Owner
with staged_directory(sys.argv[1], owner=Owner("render", "scene")) as stage:
    (stage / "big.bin").write_bytes(b"x" * 2_000_000)
    if sys.argv[2] == "kill":
        os.kill(os.getpid(), signal.SIGKILL)
    print("holding", flush=True)
    sys.stdin.read()
"""


def test_staging_a_killed_run_left_is_removed_and_said(tmp_path, call, tiny_scene, variant):
    """``kill -9`` used to leave ``.out.partial-*`` (25 MB, 131 MB) for ever."""
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-c", _KILLED, str(out), "kill"], cwd=REPO)
    assert proc.returncode == -signal.SIGKILL
    (stale,) = tmp_path.glob(".out.partial-*")
    status, _, err = _render(call, tiny_scene, out)
    assert status == 0, err
    lines = [ln for ln in err.splitlines() if stale.name in ln]
    assert len(lines) == 1 and lines[0].startswith("warning: removed ") and "1.9 MiB" in lines[0]
    assert not stale.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["out", "scenes"]


def test_staging_of_a_run_in_progress_is_left(tmp_path, call, tiny_scene, variant):
    out = tmp_path / "out"
    live = subprocess.Popen(
        [sys.executable, "-c", _KILLED, str(out), "hold"],
        cwd=REPO,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert live.stdout.readline().strip() == "holding"
        (stage,) = tmp_path.glob(".out.partial-*")
        status, _, err = _render(call, tiny_scene, out)
        assert status == 0, err
        assert f"warning: {stage} left in place: a run writing" in err
        assert (stage / "big.bin").is_file()
    finally:
        live.communicate("", timeout=60)
    assert live.returncode == 0 and not stage.exists()


def test_staging_is_flushed_before_it_is_published(tmp_path, monkeypatch):
    """Every file and folder of the staging is fsynced before the rename that publishes it."""
    from nidar_mi.io import atomic
    from nidar_mi.io.ownership import Owner

    events = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd):
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(a, b):
        events.append(("replace", str(a)))
        real_replace(a, b)

    monkeypatch.setattr(atomic.os, "fsync", fsync)
    monkeypatch.setattr(atomic.os, "replace", replace)
    with atomic.staged_directory(tmp_path / "out", owner=Owner("t", "t")) as stage:
        (stage / "sub").mkdir()
        (stage / "sub" / "a.bin").write_bytes(b"1")
        (stage / "b.bin").write_bytes(b"2")
    publish = events.index(("replace", str(stage)))
    flushed = {path for kind, path in events[:publish] if kind == "fsync"}
    want = {str(stage / p) for p in ("sub/a.bin", "b.bin", "sub", RECORD)} | {str(stage)}
    assert want <= flushed
    assert ("fsync", str(tmp_path)) in events[publish:]  # the rename itself


def test_the_record_lists_what_a_run_wrote_only(tmp_path):
    """A record lists files, never the record itself; a damaged record counts as none."""
    from nidar_mi.io.atomic import staged_directory
    from nidar_mi.io.ownership import Owner

    out = tmp_path / "out"
    with staged_directory(out, owner=Owner("t", "k")) as stage:
        (stage / "d").mkdir()
        (stage / "d" / "x").write_text("1")
    assert read_record(out)["files"] == ["d/x"]
    (out / RECORD).write_text("{broken")
    assert read_record(out) is None
