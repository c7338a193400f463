"""Checks of the scaling benchmark's command line and its sizing arithmetic (not its timings)."""

from __future__ import annotations

import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import bench_scaling as bench  # noqa: E402


def test_sizing_by_hand():
    stages = {
        "median_after_first": {
            "frames": 2,
            "render_cpu_s": 7.0,
            "frame_project_cpu_s": 0.5,
            "frame_write_cpu_s": 0.5,
            "nidar_cpu_s": 0.9,
            "render_bytes": 3_000_000,
            "frame_bytes": 1_000_000,
        }
    }
    s = bench.sizing(stages, frames=1e6)
    assert s["cpu_s_per_frame"] == pytest.approx(4.0)  # (7 + 0.5 + 0.5) s / 2 frames
    assert s["core_hours"] == pytest.approx(1e6 * 4.0 / 3600)
    assert s["nidar_core_hours"] == pytest.approx(1e6 * 0.45 / 3600)
    assert s["terabytes"] == pytest.approx(2.0)  # 2 MB per frame
    assert s["frame_only_terabytes"] == pytest.approx(0.5)


@pytest.mark.parametrize("arg", ["--scenes", "--repeats", "--spp", "--noop-tasks"])
def test_main_rejects_non_positive_counts(arg, capsys):
    assert bench.main([arg, "0"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and err.count("\n") == 1


def test_main_needs_two_scenes(capsys):
    assert bench.main(["--scenes", "1"]) == 2
    assert "first scene warms the kernels" in capsys.readouterr().err


def test_main_without_ray(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "ray", None)
    out = tmp_path / "r.json"
    assert bench.main(["--json", str(out)]) == 2
    assert "[ray]" in capsys.readouterr().err and not out.exists()
