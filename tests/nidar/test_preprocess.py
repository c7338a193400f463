"""Image preparation: sRGB decoding, exposure normalisation, input checks."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.preprocess import normalize_exposure, prepare_nir, prepare_rgb


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
