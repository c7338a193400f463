"""``python -m nidar_mi.scenegen``: writes scenes, resumes, reports bad input on one line."""

import json
import subprocess
import sys

from nidar_mi.cli.scenegen import main
from nidar_mi.scenegen.generate import generate_scene


def test_module_runs_and_resumes(tmp_path):
    out = tmp_path / "gen"
    cmd = [sys.executable, "-m", "nidar_mi.scenegen", "--count", "2", "--seed", "6", "-o", str(out)]
    cmd += ["--progress"]  # a pipe is not a terminal: bars only when asked for
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "2 scenes written, 0 already there" in r.stdout
    assert "scenegen" in r.stderr  # the progress bar
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
