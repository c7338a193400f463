"""Inference: padding to the network stride, cropping back, agreement with a direct pass."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.nidar.infer import pad_to_multiple, predict
from nidar_mi.nidar.irnet import IRNet
from nidar_mi.nidar.preprocess import prepare_rgb
from nidar_mi.nidar.stn import STN


@pytest.fixture(scope="module")
def nets():
    torch.manual_seed(0)
    stn = STN(width=4, levels=3, num_outputs=2).eval()
    irnet = IRNet("unet+deeplabv3", 1, width=4, unet_depth=2, output_stride=4, aspp_rates=(1, 2))
    return stn, irnet.eval()


def _rgb(h, w, seed=0):
    return np.random.default_rng(seed).integers(0, 256, (h, w, 3), dtype=np.uint8)


def test_pad_to_multiple_replicates_the_edge():
    x = torch.arange(6.0).reshape(1, 1, 2, 3)
    y = pad_to_multiple(x, 4)
    assert y.shape == (1, 1, 4, 4)
    torch.testing.assert_close(y[..., :2, :3], x)
    torch.testing.assert_close(y[0, 0, :, 3], torch.tensor([2.0, 5.0, 5.0, 5.0]))
    assert pad_to_multiple(x, 1) is x


def test_predict_matches_a_direct_pass_when_no_padding_is_needed(nets):
    stn, irnet = nets
    rgb = _rgb(16, 24)
    out = predict(stn, irnet, rgb)
    with torch.no_grad():
        x = torch.from_numpy(prepare_rgb(rgb))[None]
        p = stn(x)
        direct = irnet(p)
    np.testing.assert_allclose(out["pseudo_nir"], p[0, 0].numpy(), rtol=1e-6)
    for key in ("R", "S", "I_hat"):
        np.testing.assert_allclose(out[key], direct[key][0, 0].numpy(), rtol=1e-5, atol=1e-6)


def test_predict_any_size(nets):
    stn, irnet = nets
    out = predict(stn, irnet, _rgb(13, 27))
    assert {k: v.shape for k, v in out.items()} == {
        k: (13, 27) for k in ("pseudo_nir", "R", "S", "I_hat")
    }
    assert all(v.dtype == np.float32 for v in out.values())


def test_predict_keeps_the_training_mode_and_needs_an_stn(nets):
    stn, irnet = nets
    irnet.train()
    predict(stn, irnet, _rgb(16, 16))
    assert irnet.training
    irnet.eval()
    with pytest.raises(NidarError, match="STN is required"):
        predict(None, irnet, _rgb(16, 16))


def test_predict_as_tensors_keeps_the_maps_on_the_device(nets):
    """``as_tensors``: the same maps as tensors on the networks' device; the image may be a
    uint8 tensor too."""
    stn, irnet = nets
    rgb = _rgb(13, 27, seed=2)
    arrays = predict(stn, irnet, rgb, scale=0.5)
    tensors = predict(stn, irnet, torch.from_numpy(rgb), scale=0.5, as_tensors=True)
    assert set(tensors) == set(arrays)
    for key, t in tensors.items():
        assert isinstance(t, torch.Tensor) and t.device == next(irnet.parameters()).device
        np.testing.assert_array_equal(t.numpy(), arrays[key])


@pytest.mark.parametrize("mode", ["rgb+pseudo_nir", "chroma+pseudo_nir"])
@pytest.mark.parametrize("scale", [1.0, 0.5, 0.25])
def test_predict_gives_the_maps_asked_for_as_the_stages_in_turn_do(mode, scale):
    """``predict`` resizes the image to the inference size once and computes only the maps
    asked for; each equals, bit for bit, the stages run one after the other by definition:
    the full-size pseudo-NIR, stacked after the colour channels, area-resized as one input
    (:func:`run_irnet`)."""
    from nidar_mi.nidar.infer import pseudo_nir, run_irnet
    from nidar_mi.nidar.preprocess import colour_input
    from nidar_mi.nidar.stn_lowres import LowResSTN

    torch.manual_seed(1)
    stn = LowResSTN(width=4, depth=2, down=2).eval()
    irnet = IRNet("unet", 4, width=4, unet_depth=2, input_mode=mode).eval()
    rgb = _rgb(45, 70, seed=3)
    p = pseudo_nir(stn, rgb, scale=scale)
    x = torch.from_numpy(np.concatenate([colour_input(rgb, mode), p[None]]))[None]
    ref = run_irnet(irnet, x, scale=scale) | {"pseudo_nir": p}
    for outputs in (("R",), ("I_hat", "R"), ("pseudo_nir",), ("pseudo_nir", "R", "S", "I_hat")):
        got = predict(stn, irnet, rgb, scale=scale, outputs=outputs)
        assert set(got) == set(outputs)
        for key in outputs:
            np.testing.assert_array_equal(got[key], ref[key])
    with pytest.raises(NidarError, match="unknown NIDAR map"):
        predict(stn, irnet, rgb, outputs=("albedo",))
