"""``python -m nidar_mi.scenegen``: writes scenes, resumes, reports bad input on one line."""

import json
import signal
import subprocess
import sys
import time

import pytest

from nidar_mi.cli.scenegen import main
from nidar_mi.scenegen.generate import generate_scene
from tests.helpers.signals import default_sigint


def test_module_runs_and_resumes(tmp_path):
    out = tmp_path / "gen"
    cmd = [sys.executable, "-m", "nidar_mi.scenegen", "--count", "2", "--seed", "6", "-o", str(out)]
    r = subprocess.run([*cmd, "--progress"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "2 scenes written, 0 already there" in r.stdout
    assert "scenegen" in r.stderr  # the progress bar, asked for (stderr is not a terminal)
    assert (out / "scene_6_1.xml").read_text() == generate_scene(6, 1)[1]
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "0 scenes written, 2 already there" in r.stdout


def test_kind_option(tmp_path, capsys):
    assert (
        main(["--count", "2", "--seed", "1", "--kind", "vegetated", "-o", str(tmp_path), "-q"]) == 0
    )
    index = json.loads((tmp_path / "index.json").read_text())
    assert {e["kind"] for e in index["scenes"]} == {"vegetated"}
    assert capsys.readouterr().out == ""


def test_spectra_option_and_a_run_of_another_regime_is_refused(tmp_path, capsys):
    args = ["--count", "1", "--seed", "3", "--kind", "urban", "-o", str(tmp_path), "-q"]
    assert main([*args, "--spectra", "earthlib"]) == 0
    entry = json.loads((tmp_path / "index.json").read_text())["scenes"][0]
    text = (tmp_path / "scene_3_0.xml").read_text()
    assert entry["spectra"] and text == generate_scene(3, 0, "urban", spectra="earthlib")[1]
    assert main(args) == 2  # the library regime would replace that scene: refused
    assert "holds scene 0 of another run (kind urban, materials all, spectra earthlib)" in (
        capsys.readouterr().err
    )
    assert (tmp_path / "scene_3_0.xml").read_text() == text


def test_bad_count_is_one_line_exit_2(tmp_path, capsys):
    assert main(["--count", "0", "-o", str(tmp_path / "gen")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: --count") and err.count("\n") == 1
    assert not (tmp_path / "gen").exists()


def test_output_that_is_a_file(tmp_path, capsys):
    f = tmp_path / "f"
    f.write_text("x")
    assert main(["--count", "1", "-o", str(f)]) == 2
    assert "not a directory" in capsys.readouterr().err
    assert f.read_text() == "x"


def test_count_is_bounded_with_one_line(tmp_path, capsys):
    out = tmp_path / "gen"
    assert main(["--count", "10000000000", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("error: --count 10000000000 is more than 100000 scenes")
        and err.count("\n") == 1
    ), err
    assert not out.exists()


@pytest.mark.parametrize(
    "signum, status, word",
    [(signal.SIGTERM, 143, "terminated"), (signal.SIGINT, 130, "interrupted")],
)
def test_an_interrupted_run_leaves_complete_indexed_scenes(tmp_path, variant, signum, status, word):
    """Scenes are written as they are drawn: after a signal, those on disk are complete (they
    load), the index lists them, and the message says so."""
    from nidar_mi.scene import load_scene

    out = tmp_path / "gen"
    cmd = [sys.executable, "-m", "nidar_mi.scenegen", "--count", "500", "--seed", "3"]
    proc = subprocess.Popen(
        [*cmd, "--kind", "vegetated", "-o", str(out), "-q"],
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and len(list(out.glob("scene_*.xml"))) < 2:
        time.sleep(0.2)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == status, err
    assert err.strip().splitlines()[-1] == f"{word}; the scenes written so far are complete"
    files = sorted(out.glob("scene_*.xml"), key=lambda p: int(p.stem.split("_")[-1]))
    assert 2 <= len(files) < 500
    index = json.loads((out / "index.json").read_text())
    assert [e["file"] for e in index["scenes"]] == [p.name for p in files]
    for e, path in zip(index["scenes"], files):
        assert path.read_text() == generate_scene(3, e["index"], "vegetated")[1]
    for path in files[:2]:
        assert load_scene(str(path)).lidars
