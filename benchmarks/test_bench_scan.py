"""Checks of the scan benchmark's command line and its results file (not its timings).

Run: ``.venv/bin/pytest benchmarks/`` (outside ``testpaths``: not part of the default suite).
"""

from __future__ import annotations

import json
import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import bench_scan as bench  # noqa: E402


def test_main_writes_json_and_both_casters_agree(tmp_path, capsys):
    pytest.importorskip("open3d")
    out = tmp_path / "r.json"
    args = ["--repeats", "1", "--rings", "8", "--cols", "64", "--grid", "41", "--json", str(out)]
    assert bench.main(args) == 0
    r = json.loads(out.read_text())
    assert r["rays"] == 8 * 64 and r["triangles"] == 2 * 40 * 40 + 1000
    assert set(r["rays_per_s"]) == {"scan", "bare", "open3d"}
    assert r["ratio_scan_over_open3d"] == pytest.approx(
        r["median_s"]["open3d"] / r["median_s"]["scan"]
    )
    agree = r["agreement_m"]
    assert agree["compared"] > 0.9 * r["rays"]
    assert agree["scan_vs_open3d_median"] < 1e-5 and agree["scan_vs_open3d_max"] < 1e-3
    assert agree["hit_mismatch"] == 0
    assert "Open3D cast_rays" in capsys.readouterr().out


def test_main_without_open3d(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # import open3d raises ImportError
    out = tmp_path / "r.json"
    assert bench.main(["--json", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: Open3D is not importable") and err.count("\n") == 1
    assert "[bench]" in err and not out.exists()


@pytest.mark.parametrize("arg", ["--repeats", "--rings", "--cols", "--grid"])
def test_main_rejects_non_positive_counts(arg, capsys):
    assert bench.main([arg, "0"]) == 2
    assert capsys.readouterr().err.startswith(f"error: {arg} must be >= ")
