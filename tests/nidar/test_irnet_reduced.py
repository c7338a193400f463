"""IRNet at reduced resolution on KITTI-like frames: sparse re-projection, deterministic training,
full-size inference at the trained scale, and the per-fold leave-one-out rows."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
from safetensors.numpy import load_file

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import IRNetConfig, STNConfig, TrainConfig
from nidar_mi.nidar.data import IRNetDataset, area_resize, reduce_sparse
from nidar_mi.nidar.model_io import build_stn, save_stn
from nidar_mi.nidar.pipeline import NidarModel
from nidar_mi.nidar.training import train_irnet
from nidar_mi.training_frames import list_frames, load_frame
from tests.helpers.synthetic_kitti import make_kitti

SCALE = 0.25


def test_reduce_sparse_keeps_the_nearest_return_of_each_coarse_pixel():
    mask = np.zeros((8, 8), bool)
    rng = np.zeros((8, 8), np.float32)
    val = np.zeros((8, 8), np.float32)
    # coarse pixel (0, 0) of a 2x2 grid gets three returns: the one at 3 m wins
    for (v, u), r, x in (((0, 0), 9.0, 0.1), ((3, 3), 3.0, 0.7), ((1, 2), 5.0, 0.4)):
        mask[v, u], rng[v, u], val[v, u] = True, r, x
    mask[6, 5], rng[6, 5], val[6, 5] = True, 20.0, 0.9  # alone in coarse pixel (1, 1)
    out_mask, out = reduce_sparse(mask, rng, {"v": val, "r": rng}, (2, 2))
    assert out_mask.tolist() == [[True, False], [False, True]]
    np.testing.assert_allclose(out["v"], [[0.7, 0.0], [0.0, 0.9]], rtol=1e-6)
    assert out["r"][0, 0] == 3.0
    # a non-integer factor: the pixel centre (u + 0.5) * w / W decides (8 -> 3 pixels:
    # 0..2 | 3..5 | 6..7), so (1, 2) at 5 m now beats (0, 0) at 9 m and (3, 3) moves to (1, 1)
    m3, o3 = reduce_sparse(mask, rng, {"v": val}, (3, 3))
    assert np.argwhere(m3).tolist() == [[0, 0], [1, 1], [2, 2]]
    np.testing.assert_allclose(o3["v"][m3], [0.4, 0.7, 0.9], rtol=1e-6)


def test_area_resize_is_the_block_mean():
    x = np.arange(2 * 4 * 8, dtype=np.float32).reshape(2, 4, 8)
    expect = x.reshape(2, 2, 2, 4, 2).mean(axis=(2, 4))
    np.testing.assert_allclose(area_resize(x, (2, 4)), expect, rtol=1e-6)


@pytest.fixture(scope="module")
def kitti_data(tmp_path_factory):
    from nidar_mi.datasets.kitti_frames import build_kitti_frames

    root = tmp_path_factory.mktemp("kitti")
    make_kitti(root / "kitti", frames=5, cols=180)
    out = root / "data"
    build_kitti_frames([root / "kitti"], out, held_out={"test": ("kitti__000000",)}, progress=False)
    torch.manual_seed(0)
    stn_cfg = STNConfig(kind="lowres", width=4, depth=2, down=2)
    stn = save_stn(root / "stn.safetensors", build_stn(stn_cfg), stn_cfg)
    return out, stn


def _cfg(**kw) -> TrainConfig:
    base = TrainConfig.reduced()
    return dataclasses.replace(
        base,
        irnet=IRNetConfig(variant="unet", width=4, unet_depth=2),
        irnet_optim=dataclasses.replace(base.irnet_optim, max_steps=3, epochs=2),
        crop_size=16,
        crop_width=48,
        scale=SCALE,
        threads=1,
        device="cpu",
        **kw,
    )


@pytest.fixture(scope="module")
def trained(kitti_data, tmp_path_factory):
    data, stn = kitti_data
    out = tmp_path_factory.mktemp("run")
    train_irnet(_cfg(), data, out, stn, progress=False)
    return out


def test_dataset_gives_reduced_wide_crops_of_the_frames_returns(kitti_data):
    data, _ = kitti_data
    frames = list_frames(data, "train")
    ds = IRNetDataset(frames, 1.0, (16, 48), seed=0, train=False, scale=SCALE)
    whole = ds.frame_arrays(0)
    full = load_frame(frames[0], ("rgb", "mask", "intensity"))
    h, w = round(SCALE * 375), round(SCALE * 1242)
    assert whole["x"].shape == (3, h, w) and whole["mask"].shape == (1, h, w)
    # every coarse pixel with a return holds one of the frame's intensities, and there are
    # no more returns than coarse pixels the full-resolution returns fall into
    vals = whole["intensity"][whole["mask"] > 0]
    assert np.isin(vals, full["intensity"][full["mask"]]).all()
    v, u = np.nonzero(full["mask"])
    cells = {(int((a + 0.5) * h / 375), int((b + 0.5) * w / 1242)) for a, b in zip(v, u)}
    assert int(whole["mask"].sum()) == len(cells)
    item = ds[0]
    assert item["x"].shape == (3, 16, 48) and item["intensity"].shape == (1, 16, 48)


def test_training_at_reduced_scale_is_deterministic(kitti_data, trained, tmp_path):
    data, stn = kitti_data
    again = tmp_path / "again"
    train_irnet(_cfg(), data, again, stn, progress=False)
    a, b = (
        load_file(str(trained / "irnet.safetensors")),
        load_file(str(again / "irnet.safetensors")),
    )
    assert a.keys() == b.keys() and all(np.array_equal(a[k], b[k]) for k in a)
    other = tmp_path / "other"
    train_irnet(dataclasses.replace(_cfg(), seed=1), data, other, stn, progress=False)
    c = load_file(str(other / "irnet.safetensors"))
    assert not all(np.array_equal(a[k], c[k]) for k in a)


def test_model_infers_at_its_trained_scale_and_returns_full_size_maps(kitti_data, trained):
    data, _ = kitti_data
    record = json.loads((trained / "config.json").read_text())
    assert record["train"]["scale"] == SCALE and record["train"]["crop_width"] == 48
    # the configuration describes the STN the run was given, not the default one
    assert record["train"]["stn"] == {
        "kind": "lowres",
        "width": 4,
        "levels": 5,
        "num_outputs": 4,
        "depth": 2,
        "down": 2,
    }
    model = NidarModel.load(trained, device="cpu")
    assert model.scale == SCALE
    rgb = load_frame(list_frames(data, "train")[0], ("rgb",))["rgb"]
    maps = model.predict_image(rgb)
    for key in ("pseudo_nir", "R", "S", "I_hat"):
        assert maps[key].shape == rgb.shape[:2] and np.isfinite(maps[key]).all()
    # the default is the trained scale: the same maps as asking for it
    np.testing.assert_array_equal(maps["R"], model.predict_image(rgb, scale=SCALE)["R"])
    assert NidarModel.load(trained, device="cpu", scale=1.0).scale == 1.0


def test_config_rejects_a_bad_scale_and_a_crop_off_the_stride(kitti_data, tmp_path):
    data, stn = kitti_data
    with pytest.raises(NidarError, match=r"^config\.scale: must lie in \(0, 1\] \(got 1\.5\)$"):
        dataclasses.replace(_cfg(), scale=1.5).validate()
    with pytest.raises(NidarError, match="crop_size 50 is not a multiple"):
        train_irnet(dataclasses.replace(_cfg(), crop_width=50), data, tmp_path / "x", stn)


def test_loo_rows_train_one_network_per_fold_without_the_test_frame(kitti_data, tmp_path):
    from nidar_mi.datasets.scans import frames_from_data
    from nidar_mi.eval.loo import leave_one_out
    from nidar_mi.eval.loo_irnet import FoldModels, irnet_methods

    data, stn = kitti_data
    scans = frames_from_data(data)
    models = FoldModels(_cfg(), data, tmp_path / "work", stn)
    methods = irnet_methods(models, forms=("range_ring",))
    assert list(methods) == ["irnet_R_range_ring", "irnet_I_hat_raw", "irnet_I_hat_range_ring"]
    res = leave_one_out(scans, ["kitti__000000"], methods, progress=False)
    fold = tmp_path / "work" / "fold-kitti__000000"
    used = json.loads((fold / "config.json").read_text())["data"]["frames"]["train"]
    assert "kitti__000000" not in used and len(used) == len(scans) - 1
    assert len(list((tmp_path / "work").glob("fold-*"))) == 1  # one network for three rows
    assert {r["method"] for r in res["rows"]} == set(methods)
    assert all(np.isfinite(r["spearman"]) for r in res["rows"])
    # a finished fold is reused by the same evaluation, refused by one of another configuration
    train = [s for s in scans if s.name != "kitti__000000"]
    FoldModels(_cfg(), data, tmp_path / "work", stn).model(train)
    other = dataclasses.replace(_cfg(), seed=7)
    with pytest.raises(NidarError, match="finished run of another configuration"):
        FoldModels(other, data, tmp_path / "work", stn).model(train)
    with pytest.raises(NidarError, match="finished run of another configuration"):
        FoldModels(
            _cfg(), data, tmp_path / "work", stn, init_weights=fold / "irnet.safetensors"
        ).model(train)


def test_cli_trains_on_every_frame_at_the_given_scale(kitti_data, tmp_path, capsys):
    from nidar_mi.cli.train import main

    data, stn = kitti_data
    out = tmp_path / "cli"
    args = [str(data), str(out), "--reduced", "--stage", "irnet", "--variant", "unet"]
    args += ["--stn-weights", str(stn), "--scale", "0.25", "--crop-size", "16"]
    args += ["--crop-width", "48", "--threads", "1", "--all-frames", "--no-progress", "-q"]
    assert main(args) == 0
    record = json.loads((out / "config.json").read_text())
    every = sorted(f.stem for split in ("train", "val", "test") for f in list_frames(data, split))
    assert record["data"]["frames"] == {"train": every, "val": []}
    assert (record["train"]["scale"], record["train"]["threads"]) == (0.25, 1)
    assert main([str(data), str(tmp_path / "no"), "--all-frames", "-q"]) == 2
    assert "--all-frames applies to IRNet only" in capsys.readouterr().err
    assert not (tmp_path / "no").exists()
