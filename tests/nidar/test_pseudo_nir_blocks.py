"""No JPEG block artefacts in the pseudo-NIR image (``pseudo_nir`` showed 8-16 px blocks in dark
areas that the real NIR photo lacks).

The blocks come from the image, not from the weights' upsampling: the STN's weights of opposite
sign amplify a JPEG's chroma blocks (16 px with 4:2:0 chroma). The pseudo-NIR image low-passes the
colour differences (:func:`nidar_mi.nidar.infer.smooth_chroma`).
"""

from __future__ import annotations

import numpy as np
import torch

from nidar_mi.nidar.infer import _stn_forward, pseudo_nir, pseudo_nir_linear, smooth_chroma
from nidar_mi.nidar.stn_lowres import LowResSTN


def blockiness(img: np.ndarray, period: int = 16) -> float:
    """Mean absolute step across the ``period``-px grid lines over the mean step elsewhere
    (both directions): ~1 for a smooth image, > 1 with blocks on that grid, inf for an image flat
    between the grid lines."""
    out = []
    for x in (np.asarray(img, np.float64), np.asarray(img, np.float64).T):
        d = np.abs(np.diff(x, axis=1))
        on = np.arange(d.shape[1]) % period == period - 1
        off = d[:, ~on].mean()
        out.append(d[:, on].mean() / off if off > 0 else np.inf)
    return float(np.mean(out))


def _dark_image(chroma_blocks: float, h: int = 128, w: int = 192) -> np.ndarray:
    """A smooth, dark, colourful 8-bit sRGB image with a JPEG's kind of chroma blocks: on every
    16 x 16 block, ``chroma_blocks`` levels of (+1, +1, -2) with a random sign (the channel mean,
    and so the brightness, unchanged)."""
    y, x = np.mgrid[0:h, 0:w] / np.array([h, w])[:, None, None]
    srgb = np.stack([40 + 20 * x, 50 + 25 * y, 35 + 20 * (1 - x) * y], axis=-1)
    srgb += 4 * np.sin(6.0 * x + 4.0 * y)[..., None]
    sign = np.random.default_rng(0).choice([-1.0, 1.0], size=(h // 16, w // 16))
    blocks = np.kron(sign, np.ones((16, 16)))[..., None] * np.array([1.0, 1.0, -2.0])
    return np.round(np.clip(srgb + chroma_blocks * blocks, 0, 255)).astype(np.uint8)


def _vegetation_stn() -> LowResSTN:
    """A LowResSTN whose weights are those of the shipped one on vegetation: +6 G, -5 B."""
    stn = LowResSTN(width=4, depth=2, down=2)
    with torch.no_grad():
        stn.unet.head.weight.zero_()
        stn.unet.head.bias.copy_(torch.tensor([0.1, 6.0, -5.0, 0.0]))
    return stn.eval()


def test_pseudo_nir_image_has_no_jpeg_blocks():
    stn = _vegetation_stn()
    rgb = _dark_image(chroma_blocks=1.0)  # one 8-bit level: invisible in the photo
    assert blockiness(rgb.astype(np.float64).mean(-1)) < 1.1
    raw = pseudo_nir(stn, rgb, scale=0.5)  # the IRNet's input: the colours as they are
    shown = pseudo_nir_linear(stn, rgb, scale=0.5)
    assert blockiness(raw) > 5.0  # the artefact, detected
    assert blockiness(shown) < 0.3 * blockiness(raw)
    clean = pseudo_nir_linear(stn, _dark_image(chroma_blocks=0.0), scale=0.5)
    assert blockiness(clean) < 1.1


def test_weight_maps_are_upsampled_smoothly(monkeypatch):
    """The coefficient maps, predicted at 1/16 of the size, are upsampled without block edges."""
    stn = LowResSTN(width=4, depth=2, down=2).eval()
    gen = torch.Generator().manual_seed(0)

    def coefficients(xs):  # random weights per low-resolution pixel
        h, w = xs.shape[-2] // stn.down, xs.shape[-1] // stn.down
        return torch.rand(1, 4, h, w, generator=gen)

    monkeypatch.setattr(stn, "coefficients", coefficients)
    x = torch.full((1, 3, 128, 192), 0.5)
    out = _stn_forward(stn, x, 0.125)[0, 0].numpy()
    blocky = torch.nn.functional.interpolate(coefficients(x[..., ::8, ::8]), scale_factor=16)
    assert blockiness(LowResSTN.apply(x, blocky)[0, 0].numpy()) > 3.0  # what blocks would score
    for period in (8, 16):
        assert blockiness(out, period) < 1.3


def test_smooth_chroma_keeps_the_channel_mean():
    x = torch.rand(1, 3, 40, 50, dtype=torch.float64)
    y = smooth_chroma(x, 2.0)
    torch.testing.assert_close(y.mean(1), x.mean(1))
    assert smooth_chroma(x, 0.0) is x
    assert float((y - y.mean(1, keepdim=True)).std()) < float((x - x.mean(1, keepdim=True)).std())
