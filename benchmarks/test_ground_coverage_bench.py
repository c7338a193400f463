"""Checks of the ground-coverage benchmark's command line (its numbers: docs/SENSORS.md)."""

from __future__ import annotations

import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import ground_coverage as bench  # noqa: E402


def test_bad_inputs_one_line_and_status_2(tmp_path, capsys):
    assert bench.main(["--kitti", str(tmp_path), "--calibration", str(tmp_path / "no.xml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: calibration file not found: {tmp_path / 'no.xml'}"]
    (tmp_path / "rows.csv").write_text("keep me")
    assert bench.main(["--kitti", str(tmp_path), "--rings-csv", str(tmp_path / "rows.csv")]) == 2
    assert (tmp_path / "rows.csv").read_text() == "keep me"
    assert "exists; not overwritten" in capsys.readouterr().err


def test_a_folder_without_sweeps_is_an_error(tmp_path, capsys):
    (tmp_path / "velodyne").mkdir()
    np.zeros((10, 4), np.float32).tofile(tmp_path / "velodyne" / "000000.bin")
    assert bench.main(["--kitti", str(tmp_path)]) == 2
    err = capsys.readouterr().err  # the progress bar, then one error line
    assert "Traceback" not in err
    assert [ln for ln in err.splitlines() if ln.startswith("error: ")] == [
        f"error: {tmp_path / 'velodyne'}: no whole 64-ring KITTI sweep found"
    ]
