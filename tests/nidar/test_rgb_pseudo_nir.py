"""IRNet on colour and pseudo-NIR stacked (``input`` ``rgb+pseudo_nir``, ``chroma+pseudo_nir``):
the target, the data, training with the true maps, and inference."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from nidar_mi.nidar.config import INPUT_CHANNELS, INPUT_MODES, IRNetConfig, STNConfig, TrainConfig
from nidar_mi.nidar.data import IRNetDataset
from nidar_mi.nidar.infer import predict
from nidar_mi.nidar.irnet import IRNet
from nidar_mi.nidar.model_io import build_irnet, build_stn, load_pipeline, save_stn
from nidar_mi.nidar.preprocess import chromaticity, colour_input, prepare_rgb
from nidar_mi.nidar.training import train_irnet
from nidar_mi.training_frames import list_frames, load_frame
from tests.helpers.synthetic_frames import write_synthetic_dataset


def test_every_input_mode_has_its_channels():
    assert set(INPUT_CHANNELS) == set(INPUT_MODES)
    for mode, channels in INPUT_CHANNELS.items():
        assert (
            build_irnet(IRNetConfig(variant="unet", width=4, unet_depth=2, input=mode)).in_channels
            == channels
        )


def test_the_decomposition_explains_the_pseudo_nir_channel():
    net = IRNet("unet", 4, width=4, unet_depth=2)
    x = torch.rand(1, 4, 8, 8)
    torch.testing.assert_close(net.intrinsic_target(x), x[:, 3:4])
    with torch.no_grad():
        assert net(x)["R"].shape == (1, 1, 8, 8)
    with pytest.raises(ValueError, match="1, 3 or 4"):
        IRNet("unet", 2, width=4, unet_depth=2)


@pytest.fixture(scope="module")
def data_and_stn(tmp_path_factory):
    root = tmp_path_factory.mktemp("rgbpn")
    data = write_synthetic_dataset(root / "data", height=48, width=64)
    torch.manual_seed(0)
    stn_cfg = STNConfig(kind="lowres", width=4, depth=2, down=2)
    return data, save_stn(root / "stn.safetensors", build_stn(stn_cfg), stn_cfg)


def test_the_dataset_stacks_rgb_before_the_cached_pseudo_nir(data_and_stn, tmp_path):
    data, _ = data_and_stn
    frame = list_frames(data, "train")[0]
    cache = tmp_path / "cache"
    cache.mkdir()
    pn = np.full((1, 48, 64), 0.25, np.float32)
    np.save(cache / f"{frame.stem}.npy", pn)
    ds = IRNetDataset(
        [frame], 255.0, (48, 64), train=False, input_dir=cache, colour="rgb+pseudo_nir"
    )
    x = ds.frame_arrays(0)["x"]
    assert x.shape == (4, 48, 64)
    np.testing.assert_allclose(x[:3], prepare_rgb(load_frame(frame, ("rgb",))["rgb"]))
    np.testing.assert_allclose(x[3], 0.25)


def test_chromaticity_ignores_the_light():
    rgb = np.zeros((2, 2, 3), np.uint8)
    rgb[0] = (200, 100, 50)
    rgb[1] = (100, 50, 25)  # the same surface in a shadow (sRGB halves are not linear halves)
    c = colour_input(rgb, "chroma+pseudo_nir")
    assert c.shape == (3, 2, 2)
    np.testing.assert_allclose(c.sum(0), 1.0, atol=0.05)
    x = prepare_rgb(rgb)
    np.testing.assert_allclose(chromaticity(x * 0.5), chromaticity(x), atol=0.02)
    with pytest.raises(Exception, match="no colour channels"):
        colour_input(rgb, "rgb")


@pytest.mark.parametrize("mode", ["rgb+pseudo_nir", "chroma+pseudo_nir"])
def test_training_with_the_true_maps_and_inference(data_and_stn, tmp_path, mode):
    data, stn = data_and_stn
    base = TrainConfig.reduced()
    cfg = dataclasses.replace(
        base,
        irnet=IRNetConfig(variant="unet", width=4, unet_depth=2, input=mode),
        irnet_optim=dataclasses.replace(base.irnet_optim, max_steps=2, epochs=1, batch_size=2),
        loss=dataclasses.replace(base.loss, lambda_r_true=1.0, lambda_s_true=0.2),
        crop_size=16,
        device="cpu",
    )
    train_irnet(cfg, data, tmp_path, stn, progress=False)
    m_stn, irnet, loaded = load_pipeline(tmp_path, "cpu")
    assert loaded.irnet.input == mode and irnet.input_mode == mode and irnet.in_channels == 4
    rgb = load_frame(list_frames(data, "test")[0], ("rgb",))["rgb"]
    out = predict(m_stn, irnet, rgb)
    assert out["R"].shape == rgb.shape[:2] and "pseudo_nir" in out
    with pytest.raises(Exception, match="STN"):
        predict(None, irnet, rgb)
