"""The reflectance cue and the image gain on rendered-style frames."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from nidar_mi.eval.image_cues import frame_returns, image_gain, luminance, score_cues
from nidar_mi.nidar.config import IRNetConfig, STNConfig
from nidar_mi.nidar.model_io import build_irnet, build_stn
from nidar_mi.training_frames import list_frames, load_frame
from tests.helpers.synthetic_frames import write_synthetic_dataset


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    return write_synthetic_dataset(
        tmp_path_factory.mktemp("cue"), {"train": 3, "test": 2}, height=48, width=64
    )


def test_luminance_of_white_and_black():
    rgb = np.zeros((1, 2, 3), np.uint8)
    rgb[0, 1] = 255
    np.testing.assert_allclose(luminance(rgb), [[0.0, 1.0]], atol=1e-6)


def test_returns_fall_on_their_pixels(data):
    f = load_frame(list_frames(data, "train")[0], None)
    ret = frame_returns(f)
    assert len(ret["rows"]) == len(f["points_xyz"])
    assert f["mask"][ret["rows"], ret["cols"]].mean() > 0.9
    assert np.all((ret["cos"] >= 0) & (ret["cos"] <= 1))


def test_scores_of_every_source(data):
    torch.manual_seed(0)
    stn = build_stn(STNConfig(kind="lowres", width=4, depth=2, down=2)).eval()
    irnet = build_irnet(IRNetConfig(variant="unet", width=4, unet_depth=2)).eval()
    frames = list_frames(data, "test")
    cue = score_cues(frames, {"m": (stn, irnet)}, stn)
    ceiling = "true albedo colour -> rho (earthlib map)"
    assert set(cue) == {"luminance", "pseudo_nir", "R:m", ceiling}
    for v in cue.values():
        assert set(v) == {"per_frame", "pooled", "surface_per_frame", "surface_pooled"}
        assert all(-1.0 <= x <= 1.0 for x in v.values())
    # the synthetic frames have no gloss: ρ at the returns is the surface's own reflectance, and
    # the ceiling is the Spearman of the colour map of the albedo with it, pooled
    from scipy.stats import spearmanr

    from nidar_mi.materials.visible_albedo import colour_reflectance_map

    colours, rho = [], []
    for f in frames:
        a = load_frame(f, ("A_true", "mask", "reflectance"))
        colours.append(colour_reflectance_map(905.0)(a["A_true"][a["mask"]]))
        rho.append(a["reflectance"][a["mask"]])
    expected = spearmanr(np.concatenate(colours), np.concatenate(rho)).statistic
    assert cue[ceiling]["pooled"] == pytest.approx(expected, abs=1e-9)
    assert cue[ceiling]["surface_pooled"] == pytest.approx(expected, abs=1e-9)
    gain = image_gain(list_frames(data, "train"), frames, stn, irnet)
    assert set(gain) == {"image", "grey", "gain"}
    for key in ("per_frame", "pooled"):  # NaN where an untrained R gives a flat profile
        np.testing.assert_equal(gain["gain"][key], gain["image"][key] - gain["grey"][key])


def test_the_truth_gain_is_the_ceiling_of_a_perfect_cue(tmp_path):
    """With the true ρ in R's place the profile ranks the intensity (ρ times a shading the
    profile cannot see) about as well as ρ itself does, and far better than the incidence
    alone; the gain is the difference of the two. A map that is no truth is an error."""
    from scipy.stats import spearmanr

    from nidar_mi.errors import NidarError
    from nidar_mi.eval.image_cues import truth_gain

    data = write_synthetic_dataset(
        tmp_path, {"train": 3, "test": 2}, height=48, width=64, intensity_scale=1.0
    )
    train, test = list_frames(data, "train"), list_frames(data, "test")
    got = truth_gain(train, test, "reflectance")
    direct = []  # Spearman of ρ itself with the intensity, per test frame
    for path in test:
        f = load_frame(path, None)
        ret = frame_returns(f)
        rho = f["reflectance"][ret["rows"], ret["cols"]]
        direct.append(spearmanr(rho, ret["intensity"]).statistic)
    # the profile is a piecewise-constant map fitted on three frames that also reads the
    # incidence, on which this intensity does not depend: within 0.1 of ρ's own rank; the
    # incidence alone ranks it not at all
    assert got["truth"]["per_frame"] == pytest.approx(np.mean(direct), abs=0.1)
    assert abs(got["geometry"]["per_frame"]) < 0.15
    assert got["gain"]["per_frame"] > 0.5
    for key in ("per_frame", "pooled"):
        assert got["gain"][key] == got["truth"][key] - got["geometry"][key]
    with pytest.raises(NidarError, match="truth is one of"):
        truth_gain(train, test, "rgb")


def test_the_command_writes_the_truth_gain_and_refuses_bad_requests(tmp_path, capsys, monkeypatch):
    """``--truth-gain`` adds its numbers to the JSON (NaN written as null); a map that is no
    truth, or no training frames to fit on, is one line and exit 2, with nothing written."""
    import json

    from nidar_mi.cli.reflectance_cue import main

    data = write_synthetic_dataset(
        tmp_path / "d", {"train": 3, "test": 2}, height=48, width=64, intensity_scale=1.0
    )
    out = tmp_path / "cue.json"
    args = ["--test", str(data), "--train", str(data), "--truth-gain", "reflectance"]
    assert main([*args, "-o", str(out)]) == 0
    got = json.loads(out.read_text())["truth_gain"]["reflectance"]
    assert got["gain"]["per_frame"] == pytest.approx(
        got["truth"]["per_frame"] - got["geometry"]["per_frame"]
    )
    assert "truth gain reflectance" in capsys.readouterr().out
    import nidar_mi.eval.image_cues as cue

    flat = {"per_frame": float("nan"), "pooled": 0.5}  # e.g. a flat profile on a frame
    monkeypatch.setattr(
        cue, "truth_gain", lambda *a: {"truth": flat, "geometry": flat, "gain": flat}
    )
    assert main([*args, "-o", str(out)]) == 0
    assert json.loads(out.read_text())["truth_gain"]["reflectance"]["gain"]["per_frame"] is None
    monkeypatch.undo()
    for bad in (["--truth-gain", "rgb"], ["--no-gain"]):
        fresh = tmp_path / "none.json"
        assert main([*args, *bad, "-o", str(fresh)]) == 2
        assert not fresh.exists()
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--truth-gain" in err[0]

    meta = Path(data) / "meta.json"
    before = meta.read_bytes()
    for inside in (meta, Path(data)):  # a file of the input, or the input itself
        assert main([*args, "-o", str(inside)]) == 2
        assert "choose another" in capsys.readouterr().err
    assert meta.read_bytes() == before

    def interrupted(_args):
        raise KeyboardInterrupt

    import nidar_mi.cli.reflectance_cue as command

    monkeypatch.setattr(command, "_score", lambda *a: interrupted(a))
    assert main(args) == 130
    assert capsys.readouterr().err.strip() == "interrupted; nothing written"
