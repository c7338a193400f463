"""The low-resolution STN, its photo crops and loss, and its training on photo pairs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import STNConfig, TrainConfig
from nidar_mi.nidar.fold import prepare_for_inference
from nidar_mi.nidar.infer import pseudo_nir
from nidar_mi.nidar.losses import gain_offset_fit, pearson_r, photo_stn_loss
from nidar_mi.nidar.model_io import build_stn
from nidar_mi.nidar.photo_data import PhotoCropDataset
from nidar_mi.nidar.stn_lowres import LowResSTN


@pytest.mark.parametrize("channels_last", [False, True])
def test_apply_equals_the_channel_sum(channels_last):
    """``apply`` equals ``(w[:, :3] * rgb).sum(1) + w[:, 3]`` bit for bit, for coefficients in
    either memory format (a channels-last network returns channels-last ones)."""
    gen = torch.Generator().manual_seed(2)
    rgb = torch.rand(2, 3, 37, 61, generator=gen) * 5
    coef = torch.randn(2, 4, 37, 61, generator=gen) * 4
    if channels_last:
        coef = coef.contiguous(memory_format=torch.channels_last)
    want = (coef[:, :3] * rgb).sum(1, keepdim=True) + coef[:, 3:4]
    got = LowResSTN.apply(rgb, coef)
    assert got.shape == (2, 1, 37, 61)
    assert torch.equal(got, want)


def test_untrained_network_is_the_channel_mean():
    net = LowResSTN(width=4, depth=2, down=2).eval()
    torch.nn.init.zeros_(net.unet.head.weight)  # coefficients = the head bias everywhere
    rgb = torch.rand(2, 3, 16, 24, generator=torch.Generator().manual_seed(0))
    with torch.no_grad():
        out = net(rgb)
    torch.testing.assert_close(out, rgb.mean(1, keepdim=True), rtol=0, atol=1e-6)


def test_apply_is_the_weighted_sum_plus_offset():
    rgb = torch.rand(1, 3, 8, 8, generator=torch.Generator().manual_seed(1))
    coef = torch.tensor([0.2, -0.5, 1.5, 0.3]).reshape(1, 4, 1, 1).expand(1, 4, 8, 8)
    expected = 0.2 * rgb[:, :1] - 0.5 * rgb[:, 1:2] + 1.5 * rgb[:, 2:3] + 0.3
    torch.testing.assert_close(LowResSTN.apply(rgb, coef), expected)


def test_stride_and_output_size():
    net = LowResSTN(width=4, depth=3, down=2)
    assert net.stride == 16
    assert net(torch.rand(1, 3, 32, 48)).shape == (1, 1, 32, 48)
    with pytest.raises(ValueError):
        LowResSTN(down=0)


def test_config_builds_the_kind():
    assert isinstance(build_stn(STNConfig(kind="lowres", width=4, depth=2, down=2)), LowResSTN)
    with pytest.raises(NidarError, match=r"^config\.stn\.kind: must be one of cs_stereo, lowres"):
        TrainConfig.from_dict({"stn": {"kind": "nope"}})


def test_folding_keeps_outputs_and_reduced_scale_keeps_the_size():
    net = LowResSTN(width=4, depth=2, down=2)
    net.train()
    for _ in range(3):  # give BatchNorm running statistics
        net(torch.rand(2, 3, 32, 32, generator=torch.Generator().manual_seed(2)))
    net.eval()
    rgb = (np.random.default_rng(0).random((37, 53, 3)) * 255).astype(np.uint8)
    before = pseudo_nir(net, rgb)
    folded = prepare_for_inference(net, torch.rand(1, 3, 16, 16))
    np.testing.assert_allclose(pseudo_nir(folded, rgb), before, atol=1e-5)
    assert pseudo_nir(folded, rgb, scale=0.5).shape == (37, 53)


def test_gain_offset_fit_and_pearson_are_blind_to_gain_and_offset():
    g = torch.Generator().manual_seed(3)
    target = torch.rand(2, 1, 16, 16, generator=g)
    pred = 3.0 * target - 0.7
    torch.testing.assert_close(gain_offset_fit(pred, target), target, rtol=0, atol=1e-5)
    torch.testing.assert_close(pearson_r(pred, target), torch.ones(2), rtol=0, atol=1e-5)
    assert float(photo_stn_loss(pred, target)) == pytest.approx(0.0, abs=1e-4)
    # an anti-correlated prediction costs 2 in the r term alone
    assert float(photo_stn_loss(-pred, target, ssim_weight=0.0)) == pytest.approx(2.0, abs=1e-4)


def _photos(n=3, h=40, w=60):
    rng = np.random.default_rng(4)
    out = []
    for _ in range(n):
        rgb = (rng.random((h, w, 3)) * 255).astype(np.uint8)
        nir = rgb[..., 1].copy()
        out.append((rgb, nir))
    return out


def test_crops_are_seeded_and_aligned():
    photos = _photos()
    a = PhotoCropDataset(photos, 16, 4, seed=5, train=False, zoom_min=1.0)
    b = PhotoCropDataset(photos, 16, 4, seed=5, train=False, zoom_min=1.0)
    for i in range(4):
        x, y = a[i], b[i]
        assert torch.equal(x["rgb"], y["rgb"]) and torch.equal(x["nir"], y["nir"])
        assert x["rgb"].shape == (3, 16, 16) and x["nir"].shape == (1, 16, 16)
        # at zoom 1 and without augmentation the NIR crop is the green channel's crop:
        # the linear green of the RGB input is proportional to the NIR target
        r = pearson_r(x["rgb"][1:2][None], x["nir"][None])
        assert float(r[0]) > 0.999
    c = PhotoCropDataset(photos, 16, 4, seed=5, train=True)
    c.set_epoch(1)
    d = PhotoCropDataset(photos, 16, 4, seed=5, train=True)
    d.set_epoch(2)
    assert not torch.equal(c[0]["rgb"], d[0]["rgb"])


def test_render_fraction_needs_renders():
    with pytest.raises(Exception, match="no rendered"):
        PhotoCropDataset(_photos(), 16, 4, render_fraction=0.5)


def test_cli_trains_on_photo_pairs_and_learns_their_colour_map(tmp_path):
    """Pairs made by a known linear map (NIR = 0.6 r - 0.2 g + 0.5 b + 0.1, linear light): the
    trained network must score r well above luminance on the held-out test pairs."""
    import json

    from nidar_mi.cli.train import main
    from nidar_mi.datasets.rgbnir import list_pairs, load_pair, split_pairs
    from nidar_mi.eval.photos import image_scores
    from nidar_mi.io.images import REC709_LUMA, linear_to_srgb, srgb_to_linear, write_png
    from nidar_mi.nidar.model_io import load_stn
    from tests.helpers.synthetic_frames import write_synthetic_dataset

    w_true = np.array([0.6, -0.2, 0.5, 0.1])
    rng = np.random.default_rng(1)
    photos = tmp_path / "photos"
    for cat in ("a", "b", "c"):
        (photos / cat).mkdir(parents=True)
        for i in range(5):
            lin = rng.uniform(0.1, 0.8, (48, 64, 3))
            nir = np.clip(lin @ w_true[:3] + w_true[3], 0, 1)
            for kind, img in (("rgb", lin), ("nir", nir)):
                write_png(
                    photos / cat / f"{i:04d}_{kind}.png",
                    np.round(linear_to_srgb(img) * 255).astype(np.uint8),
                )
    data = write_synthetic_dataset(tmp_path / "data", height=48, width=64)
    config = {
        "stn": {"kind": "lowres", "width": 4, "depth": 2, "down": 2},
        "stn_optim": {"lr": 0.01, "batch_size": 4, "epochs": 2, "schedule": "onecycle"},
        "photos": {"crops_per_epoch": 120, "zoom_min": 1.0},
        "crop_size": 32,
        "device": "cpu",
    }
    (tmp_path / "cfg.json").write_text(json.dumps(config))
    out = tmp_path / "run"
    argv = [str(data), str(out), "--config", str(tmp_path / "cfg.json"), "--stage", "stn"]
    assert main([*argv, "--photos", str(photos), "--no-progress", "-q"]) == 0
    stn = load_stn(out / "stn.safetensors", "cpu")
    assert isinstance(stn, LowResSTN)
    pairs = list_pairs(photos)
    by = {p.name: p for p in pairs}
    luma = np.asarray(REC709_LUMA, dtype=np.float32)
    r_net, r_luma = [], []
    for name in split_pairs(pairs)["test"]:
        rgb, nir = load_pair(by[name])
        target = srgb_to_linear(nir / 255.0)
        r_net.append(image_scores(pseudo_nir(stn, rgb), target)["r"])
        r_luma.append(image_scores(srgb_to_linear(rgb / 255.0) @ luma, target)["r"])
    assert np.mean(r_luma) < 0.6  # the map is far from luminance ...
    assert np.mean(r_net) > 0.9  # ... and the network learns it from the pairs
