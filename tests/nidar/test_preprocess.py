"""Image preparation: sRGB decoding, exposure normalisation, input checks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.nidar.preprocess import (
    colour_from_prepared,
    colour_input,
    normalize_exposure,
    prepare_nir,
    prepare_rgb,
    prepare_rgb_tensor,
    srgb8_to_linear,
)


def test_prepare_rgb_decodes_srgb_then_normalises():
    rgb = np.zeros((2, 2, 3), dtype=np.uint8)
    rgb[0, 0] = (128, 10, 255)
    out = prepare_rgb(rgb)
    assert out.shape == (3, 2, 2) and out.dtype == np.float32
    lin = np.array([((128 / 255 + 0.055) / 1.055) ** 2.4, 10 / 255 / 12.92, 1.0])
    ratio = 0.5 / (lin.sum() / 12 + 1e-3)
    np.testing.assert_allclose(out[:, 0, 0], lin * ratio, rtol=1e-5)
    assert float(out[:, 1, 1].max()) == 0.0


def test_normalize_exposure_mean_and_clip():
    img = np.linspace(0.0, 2.0, 101, dtype=np.float32)
    out = normalize_exposure(img)
    np.testing.assert_allclose(out, img * 0.5 / (1.0 + 1e-3), rtol=1e-6)
    spike = np.zeros(100, dtype=np.float32)
    spike[0] = 100.0  # mean 1 -> the spike becomes ~50, clipped to 5
    assert float(normalize_exposure(spike).max()) == 5.0
    # Exposure does not matter: a 10x brighter image normalises to the same values.
    np.testing.assert_allclose(normalize_exposure(10 * img), out, rtol=1e-3)


def test_prepare_nir_shape_and_errors():
    assert prepare_nir(np.ones((3, 4), np.float32)).shape == (1, 3, 4)
    with pytest.raises(NidarError, match=r"\(H, W\)"):
        prepare_nir(np.ones((3, 4, 1)))
    with pytest.raises(NidarError, match="uint8"):
        prepare_rgb(np.ones((3, 4, 3), np.float32))
    with pytest.raises(NidarError, match=r"\(H, W, 3\)"):
        prepare_rgb(np.ones((3, 4), np.uint8))
    with pytest.raises(NidarError, match="NaN"):
        normalize_exposure(np.array([1.0, np.nan]))


def _srgb_decode(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decoding in float64, written out."""
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def _prepared_by_formula(rgb: np.ndarray) -> np.ndarray:
    """(3, H, W) float64: decoded, scaled to mean 0.5 (+1e-3 in the denominator), clipped."""
    lin = _srgb_decode(rgb.astype(np.float64) / 255.0)
    return np.clip(lin * 0.5 / (lin.mean() + 1e-3), 0.0, 5.0).transpose(2, 0, 1)


def test_the_sRGB_table_is_the_standard_decoding():
    codes = torch.arange(256, dtype=torch.uint8)
    got = srgb8_to_linear(codes).numpy()
    assert got.dtype == np.float32
    np.testing.assert_allclose(got, _srgb_decode(np.arange(256) / 255.0), rtol=0, atol=1e-7)


def test_torch_preparation_equals_the_formula():
    """The device preparation (here on the CPU) of an 8-bit image against the formula in
    float64: linear RGB, exposure-normalised, chromaticity; within 1e-6 (float32 rounding)."""
    rng = np.random.default_rng(4)
    rgb = rng.integers(0, 256, (37, 53, 3), dtype=np.uint8)
    rgb[:5, :5] = 255  # some pixels clipped at 5 after normalisation
    rgb[-3:] = 0
    want = _prepared_by_formula(rgb)
    x = prepare_rgb_tensor(torch.from_numpy(rgb), "cpu")
    assert x.shape == (3, 37, 53) and x.dtype == torch.float32
    np.testing.assert_allclose(x.numpy(), want, rtol=1e-6, atol=1e-6)
    chroma = colour_from_prepared(x, "chroma+pseudo_nir").numpy()
    np.testing.assert_allclose(chroma, want / (want.sum(0) + 1e-2), rtol=0, atol=1e-6)
    # the NumPy entry points are the same computation
    np.testing.assert_array_equal(prepare_rgb(rgb), x.numpy())
    np.testing.assert_array_equal(colour_input(rgb, "chroma+pseudo_nir"), chroma)
    np.testing.assert_array_equal(colour_input(rgb, "rgb+pseudo_nir"), x.numpy())
    nir = rng.uniform(0, 3, (9, 11))
    np.testing.assert_allclose(
        prepare_nir(nir)[0], np.clip(nir * 0.5 / (nir.mean() + 1e-3), 0, 5), rtol=1e-6, atol=1e-6
    )


def test_preparation_by_table_equals_decoding_then_normalising():
    """The prepared image (the normalisation applied to the 256-entry table, one look-up per
    pixel) equals, bit for bit, decoding every pixel and then scaling and clipping them."""
    from nidar_mi.nidar.preprocess import _normalize, srgb8_mean

    rng = np.random.default_rng(7)
    for shape in ((37, 53, 3), (120, 331, 3)):
        rgb = torch.from_numpy(rng.integers(0, 256, shape, dtype=np.uint8))
        rgb[:4, :4] = 255
        decoded = srgb8_to_linear(rgb.permute(2, 0, 1))
        want = _normalize(decoded, srgb8_mean(rgb), 0.5, 5.0)
        assert torch.equal(prepare_rgb_tensor(rgb), want)


def test_tensor_preparation_refuses_other_images():
    with pytest.raises(NidarError, match="uint8 tensor"):
        prepare_rgb_tensor(torch.zeros(4, 5, 3))
    with pytest.raises(NidarError, match="uint8 tensor"):
        prepare_rgb_tensor(torch.zeros(3, 4, 5, dtype=torch.uint8))
    with pytest.raises(NidarError, match="no colour channels"):
        colour_from_prepared(torch.zeros(3, 2, 2), "pseudo_nir")
