"""``python -m nidar_mi.pseudo_nir``: outputs, exposure, name clashes and the bad-input contract."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.cli.pseudo_nir import main, output_names
from nidar_mi.io.images import read_exr, read_png, srgb_to_linear, write_png
from nidar_mi.io.ownership import RECORD
from nidar_mi.nidar.infer import pseudo_nir_linear
from nidar_mi.nidar.pipeline import NidarModel

REPO = Path(__file__).resolve().parents[2]


def _photo(h=40, w=56, seed=0, gain=1.0) -> np.ndarray:
    """A smooth colour test image; ``gain`` scales its linear radiance (an exposure change)."""
    y, x = np.mgrid[0:h, 0:w] / max(h, w)
    lin = np.stack([0.2 + 0.5 * x, 0.15 + 0.4 * y, 0.3 + 0.2 * np.sin(6 * x * y)], -1)
    lin *= 0.6 + 0.4 * np.random.default_rng(seed).random((1, 1, 3))
    from nidar_mi.io.images import linear_to_srgb

    return np.round(linear_to_srgb(np.clip(lin * gain, 0, 1)) * 255).astype(np.uint8)


def test_output_names_resolve_clashes():
    paths = [Path("/d/a/0001.png"), Path("/d/b/0001.jpg"), Path("/d/c.png"), Path("/e/a/0001.png")]
    assert output_names(paths) == ["d__a__0001", "d__b__0001", "c", "e__a__0001"]
    same_dir = [Path("/d/x.png"), Path("/d/x.jpg"), Path("/d/y.png")]
    assert output_names(same_dir) == ["x_png", "x_jpg", "y"]
    assert output_names([Path("/d/a.png")]) == ["a"]


def test_exposure_is_kept():
    """Half the linear exposure gives half the pseudo-NIR (up to 8-bit quantisation)."""
    model = NidarModel.load(device="cpu")
    a = pseudo_nir_linear(model.stn, _photo(gain=0.8))
    b = pseudo_nir_linear(model.stn, _photo(gain=0.4))
    assert a.shape == (40, 56) and np.isfinite(a).all() and (a >= 0).all()
    ratio = np.median(b[a > 0.05] / a[a > 0.05])
    assert ratio == pytest.approx(0.5, abs=0.02)


def test_files_and_folders_with_clashes_and_exr(tmp_path, capsys):
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    write_png(tmp_path / "a" / "0001.png", _photo(seed=1))
    write_png(tmp_path / "b" / "0001.png", _photo(31, 45, seed=2))
    (tmp_path / "b" / "notes.txt").write_text("not an image")
    out = tmp_path / "out"
    assert main([str(tmp_path / "a"), str(tmp_path / "b"), "-o", str(out), "--exr", "-q"]) == 0
    err = capsys.readouterr().err
    assert "skipped 1 file(s) that are not images" in err
    assert sorted(p.name for p in out.iterdir()) == [
        RECORD,
        "a__0001.exr",
        "a__0001.png",
        "b__0001.exr",
        "b__0001.png",
        "index.json",
    ]
    png = read_png(out / "b__0001.png")
    exr = read_exr(out / "b__0001.exr")["Y"]
    assert png.shape == exr.shape == (31, 45) and png.dtype == np.uint8
    # the PNG is the sRGB encoding of the EXR (half an 8-bit step in sRGB space)
    lin = srgb_to_linear(png / 255.0)
    hi = srgb_to_linear(np.minimum(png + 0.5, 255) / 255.0)
    lo = srgb_to_linear(np.maximum(png - 0.5, 0) / 255.0)
    clipped = np.clip(exr, 0, 1)
    assert np.all((clipped >= lo - 1e-6) & (clipped <= hi + 1e-6)), np.abs(lin - clipped).max()
    index = json.loads((out / "index.json").read_text())
    assert [i["outputs"][0] for i in index["images"]] == ["a__0001.png", "b__0001.png"]
    assert index["images"][1]["size"] == [45, 31]


def test_max_side_infers_smaller_but_writes_full_size(tmp_path):
    write_png(tmp_path / "big.png", _photo(64, 96))
    out = tmp_path / "o"
    assert main([str(tmp_path / "big.png"), "-o", str(out), "--max-side", "48", "-q"]) == 0
    assert read_png(out / "big.png").shape == (64, 96)
    index = json.loads((out / "index.json").read_text())
    assert index["images"][0]["inference_scale"] == pytest.approx(0.5)


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "nidar_mi.pseudo_nir", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=300,
    )


def test_bad_inputs_are_one_line_and_write_nothing(tmp_path, capsys):
    write_png(tmp_path / "ok.png", _photo())
    (tmp_path / "fake.png").write_bytes(b"\x89PNG but not really")
    write_png(tmp_path / "grey.png", np.full((8, 8), 100, np.uint8))
    out = tmp_path / "out"
    for bad, words in (
        (tmp_path / "fake.png", "not an image"),
        (tmp_path / "grey.png", "needs a colour image"),
        (tmp_path / "missing.png", "no such file"),
    ):
        assert main([str(tmp_path / "ok.png"), str(bad), "-o", str(out)]) == 2
        lines = capsys.readouterr().err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error:") and words in lines[0]
        assert not out.exists()
    assert main([str(tmp_path / "ok.png"), "-o", str(out), "--scale", "0"]) == 2
    assert "scale" in capsys.readouterr().err and not out.exists()
    # in a process of its own, with --skip-bad
    r = _cli(str(tmp_path / "ok.png"), str(tmp_path / "fake.png"), "-o", str(out), "--skip-bad")
    assert r.returncode == 0, r.stderr
    assert "warning: skipped" in r.stderr and sorted(p.name for p in out.iterdir()) == [
        RECORD,
        "index.json",
        "ok.png",
    ]
