"""Checks of the NIDAR speed benchmark's inputs, command line and results file (not its timings)."""

from __future__ import annotations

import json
import os
import sys

import numpy as np
import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import bench_nidar as bench  # noqa: E402


def test_procedural_inputs():
    img = bench.street_image(120, 40)
    assert img.shape == (40, 120, 3) and img.dtype == np.uint8
    xyz = bench.hdl64e_cloud(64)
    assert xyz.shape == (64 * 64, 3)
    # every beam hits the ground 1.73 m below or the wall at x = 30 m (or stops at 80 m)
    r = np.linalg.norm(xyz, axis=1)
    on_ground = np.isclose(xyz[:, 2], -1.73)
    on_wall = np.isclose(xyz[:, 0], 30.0)
    assert np.all(on_ground | on_wall | np.isclose(r, 80.0))
    cam = bench.kitti_like_camera(120, 40)
    assert cam.width == 120 and cam.K[0, 0] == pytest.approx(0.58 * 120)


def test_main_writes_json(tmp_path, capsys):
    out = tmp_path / "b.json"
    args = ["--sizes", "96x48", "--configs", "before,fold+cl+s0.5", "--repeats", "1"]
    assert bench.main(args + ["--cols", "64", "--threads", "1", "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert [x["config"] for x in r["results"]] == ["before", "fold+cl+s0.5"]
    for x in r["results"]:
        stages = {"pseudo_nir", "irnet", "sampling", "normals", "image", "profile", "assign"}
        assert set(x["seconds"]) == stages | {"end_to_end"}
        assert x["observed"] > 0 and x["device"] == "cpu"
        assert x["total_s"] > 0 and x["seconds"]["end_to_end"] > 0
        s = x["seconds"]
        assert s["assign"] == pytest.approx(
            s["sampling"] + s["normals"] + s["image"] + s["profile"]
        )
        assert s["image"] == 0.0  # the weights' own profile reads no image
    assert "| before | 96x48 | cpu |" in capsys.readouterr().out


def test_a_context_profile_is_timed_with_its_image_stage(tmp_path):
    """A context profile file (a few trees on made-up inputs) runs through every stage: its
    image inputs are timed, and the whole frame gives it the observed points."""
    from nidar_mi.profiles import SensorProfile, fit
    from nidar_mi.profiles.inputs import GROUPS

    rng = np.random.default_rng(0)
    names = [f for g in ("return", "geometry", "image", "nidar") for f in GROUPS[g]]
    ctx = {f: rng.uniform(0, 1, 400) for f in names}
    m = fit("context", ctx["R"], ctx["range_m"], rng.uniform(0, 1, 400), context=ctx, trees=3)
    path = tmp_path / "ctx.json"
    SensorProfile("ctx", "test", "context", "nidar:R", m).save(path)
    out = tmp_path / "b.json"
    args = ["--sizes", "96x48", "--configs", "fold+cl", "--repeats", "1", "--cols", "64"]
    assert bench.main([*args, "--threads", "1", "--profile", str(path), "--json", str(out)]) == 0
    r = json.loads(out.read_text())
    assert r["profile"] == str(path)
    (x,) = r["results"]
    assert x["observed"] > 0 and x["seconds"]["image"] > 0 and x["seconds"]["normals"] > 0


def test_bad_arguments(capsys):
    assert bench.main(["--configs", "fold+turbo"]) == 2
    assert "configuration part" in capsys.readouterr().err
    assert bench.main(["--sizes", "12"]) == 2
    capsys.readouterr()
    assert bench.main(["--devices", "tpu"]) == 2
    assert "--devices" in capsys.readouterr().err
