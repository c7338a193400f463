"""Checks of the sequence benchmark's command line and results file (not its timings)."""

from __future__ import annotations

import json
import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import bench_sequence as bench  # noqa: E402


def test_main_writes_json_and_compiles_nothing_after_warmup(tmp_path, capsys):
    out = tmp_path / "r.json"
    args = ["--frames", "2", "--cols", "32", "--camera-frames", "2", "--json", str(out)]
    assert bench.main(args) == 0
    r = json.loads(out.read_text())
    assert set(r["setups"]) == set(bench.SETUPS)
    for s in r["setups"].values():
        assert s["kernels_compiled_after_warmup"] == 0
        assert s["points_per_frame"] > 0 and s["sequence_frames_per_s"] > 0
        assert s["sequence_previews_frames_per_s"] > 0 and s["sequence_cpu_s_per_frame"] > 0
    cam = r["camera"]
    assert cam["kernels_compiled_after_warmup"] == 0 and cam["frames"] == 2
    assert cam["frames_per_s"] > 0 and set(cam["stage_median_s"]) == {"render", "write"}
    assert r["setups"]["per_laser + divergence"]["rays_per_frame"] == 64 * 32 * 19
    assert "kernels compiled after warm-up" in capsys.readouterr().out


@pytest.mark.parametrize("arg", ["--frames", "--cols"])
def test_main_rejects_non_positive_counts(arg, capsys):
    assert bench.main([arg, "0"]) == 2
    assert capsys.readouterr().err.startswith(f"error: {arg} must be >= 1")


def test_main_rejects_negative_camera_frames(capsys):
    assert bench.main(["--camera-frames", "-1"]) == 2
    assert capsys.readouterr().err.startswith("error: --camera-frames must be >= 0")
