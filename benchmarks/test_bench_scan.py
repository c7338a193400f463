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

_SMALL = ["--repeats", "1", "--rings", "8", "--grid", "41"]


def test_main_writes_json_and_scan_agrees_with_the_bare_cast(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)  # import open3d raises ImportError
    out = tmp_path / "r.json"
    assert bench.main([*_SMALL, "--cols", "64", "32", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert [r["cols"] for r in result["runs"]] == [64, 32]
    assert result["machine"]["open3d"] is None
    r = result["runs"][0]
    assert r["rays"] == 8 * 64 and r["triangles"] == 2 * 40 * 40 + 1000
    assert set(r["rays_per_s"]) == {"scan", "bare"} and "ratio_scan_over_open3d" not in r
    assert r["ratio_scan_over_bare"] == pytest.approx(r["median_s"]["bare"] / r["median_s"]["scan"])
    agree = r["agreement_m"]
    assert agree["compared"] > 0.9 * r["rays"]
    assert agree["scan_vs_bare_median"] < 1e-5 and agree["scan_vs_bare_max"] < 1e-3
    assert agree["hit_mismatch"] == 0
    text = capsys.readouterr().out
    assert "full / bare" in text and "Open3D" not in text


def test_main_with_open3d_compares_it_too(tmp_path, capsys):
    pytest.importorskip("open3d")
    out = tmp_path / "r.json"
    assert bench.main([*_SMALL, "--cols", "64", "--json", str(out)]) == 0
    r = json.loads(out.read_text())["runs"][0]
    assert set(r["rays_per_s"]) == {"scan", "bare", "open3d"}
    assert r["agreement_m"]["bare_vs_open3d_median"] < 1e-5
    assert "Open3D cast_rays" in capsys.readouterr().out


@pytest.mark.parametrize("arg", ["--repeats", "--rings", "--cols", "--grid"])
def test_main_rejects_non_positive_counts(arg, capsys):
    assert bench.main([arg, "0"]) == 2
    assert capsys.readouterr().err.startswith(f"error: {arg} must be >= ")


def test_main_rejects_unknown_variant(capsys):
    assert bench.main(["--variants", "no_such_variant"]) == 2
    err = capsys.readouterr().err
    assert (
        err.startswith("error: variant 'no_such_variant' is not available") and err.count("\n") == 1
    )


def test_weather_runs_time_each_condition_on_the_same_rays(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "open3d", None)
    out = tmp_path / "r.json"
    assert bench.main([*_SMALL, "--cols", "32", "--weather", "--json", str(out)]) == 0
    r = json.loads(out.read_text())["runs"][0]
    assert set(r["rays_per_s"]) == {"scan", "bare", "fog", "rain", "snow"}
    ratios = r["ratio_weather_over_clear"]
    assert set(ratios) == {"fog", "rain", "snow"}
    assert ratios["fog"] == pytest.approx(r["median_s"]["fog"] / r["median_s"]["scan"])
    assert "ratio scan in snow / clear scan (s)" in capsys.readouterr().out
