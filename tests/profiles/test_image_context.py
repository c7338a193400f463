"""Image context at pixels against analytic values: a uniform image, a step edge, and box
filters computed independently (SciPy)."""

from __future__ import annotations

import colorsys

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.images import srgb_to_linear
from nidar_mi.profiles.image_context import (
    IMAGE_FEATURES,
    RELATIVE_FEATURES,
    WINDOWS,
    image_context,
)

LUMA = np.array([0.2126, 0.7152, 0.0722])


def test_a_uniform_image():
    """Every window holds the one colour (borders included: a window's part inside the image):
    means equal the pixel, no spread, no gradient, no contrast; chromaticity and HSV as the
    colour's own."""
    code = np.array([200, 120, 40], np.uint8)
    img = np.broadcast_to(code, (40, 70, 3)).copy()
    uv = np.array([[0.0, 0.0], [69.0, 39.0], [35.2, 20.4], [-0.4, 39.4]])
    f = image_context(img, uv)
    assert list(f) == [*IMAGE_FEATURES, *RELATIVE_FEATURES]
    lin = srgb_to_linear(code / 255.0)
    for i, c in enumerate("rgb"):
        np.testing.assert_allclose(f[f"{c}_lin"], lin[i], rtol=1e-12)
        for w in WINDOWS:
            np.testing.assert_allclose(f[f"{c}_mean{w}"], lin[i], rtol=1e-9)
    np.testing.assert_allclose(f["chroma_r"], lin[0] / (lin.sum() + 1e-3), rtol=1e-12)
    h, s, v = colorsys.rgb_to_hsv(*(code / 255.0))
    np.testing.assert_allclose([f["hue"][0], f["sat"][0], f["val"][0]], [h, s, v], rtol=1e-12)
    for name in ("lum_sd5", "lum_sd15", "sobel", "laplacian", "contrast", "lum_log"):
        np.testing.assert_allclose(f[name], 0.0, atol=1e-6)
    y = lin @ LUMA
    np.testing.assert_allclose(f["g_rel"], lin[1] / (y + 1e-3), rtol=1e-9)
    np.testing.assert_allclose(f["b_rel61"], lin[2] / (y + 1e-3), rtol=1e-9)


def test_the_relative_features_do_not_depend_on_the_exposure():
    """Twice the exposure (linear values doubled, re-encoded to 8 bits): the relative features
    stay within the 8-bit rounding, the absolute ones double."""
    from nidar_mi.io.images import linear_to_srgb

    rng = np.random.default_rng(5)
    lin = rng.uniform(0.02, 0.45, (60, 80, 3))
    a, b = (np.rint(linear_to_srgb(k * lin) * 255).astype(np.uint8) for k in (1.0, 2.0))
    uv = np.stack([rng.uniform(0, 79, 50), rng.uniform(0, 59, 50)], axis=1)
    fa, fb = image_context(a, uv), image_context(b, uv)
    for name in ("r_rel", "g_rel15", "lum_rel_sd15", "chroma_r", "lum_log"):
        np.testing.assert_allclose(fb[name], fa[name], rtol=0.02, atol=0.02)
    np.testing.assert_allclose(fb["g_mean15"], 2 * fa["g_mean15"], rtol=0.02)


def test_a_vertical_step_edge():
    """Black left of column 10, white from it: one column left of the edge the 3 × 3 Sobel
    gradient is 4 (1 + 2 + 1 times the unit step), the Laplacian 1, and the 5-pixel window
    holds 2 white columns of 5."""
    img = np.zeros((30, 30, 3), np.uint8)
    img[:, 10:] = 255
    f = image_context(img, np.array([[9.0, 15.0], [10.0, 15.0], [3.0, 15.0]]))
    np.testing.assert_allclose(f["sobel"], [4.0, 4.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f["laplacian"], [1.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(f["g_mean5"], [0.4, 0.6, 0.0], atol=1e-12)
    np.testing.assert_allclose(f["lum_sd5"][:2], np.sqrt(0.4 * 0.6), atol=1e-9)


def test_windows_against_box_filters():
    """Means and spreads over the windows equal SciPy's box filters wherever the window lies
    inside the image."""
    from scipy.ndimage import uniform_filter

    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (90, 120, 3), dtype=np.uint8)
    uv = np.stack([rng.uniform(31, 88, 300), rng.uniform(31, 58, 300)], axis=1)
    f = image_context(img, uv)
    u, v = np.rint(uv).astype(int).T
    lin = srgb_to_linear(img / 255.0)
    y = lin @ LUMA
    for w in WINDOWS:
        for i, c in enumerate("rgb"):
            box = uniform_filter(lin[..., i], w, mode="constant")
            np.testing.assert_allclose(f[f"{c}_mean{w}"], box[v, u], atol=1e-12)
    for w in (5, 15):
        sd = np.array(
            [
                y[b - w // 2 : b + w // 2 + 1, a - w // 2 : a + w // 2 + 1].std()
                for a, b in zip(u, v)
            ]
        )
        np.testing.assert_allclose(f[f"lum_sd{w}"], sd, atol=1e-9)
    mean_y = (lin @ LUMA).mean()
    np.testing.assert_allclose(f["lum_log"], np.log((y[v, u] + 1e-3) / (mean_y + 1e-3)), rtol=1e-9)


def test_bad_input():
    img = np.zeros((10, 12, 3), np.uint8)
    with pytest.raises(NidarError, match="outside the image"):
        image_context(img, np.array([[11.6, 2.0]]))
    with pytest.raises(NidarError, match="uint8"):
        image_context(img.astype(np.float32), np.zeros((1, 2)))
    with pytest.raises(NidarError, match=r"\(M, 2\)"):
        image_context(img, np.array([[np.nan, 1.0]]))
    assert all(v.shape == (0,) for v in image_context(img, np.zeros((0, 2))).values())
