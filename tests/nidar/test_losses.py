"""Losses: hand-computed values, an independent SSIM reference, masking, gradcheck."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from nidar_mi.nidar import losses as L
from nidar_mi.nidar.config import LossConfig

C1, C2 = 0.01**2, 0.03**2


def _rand(*shape, seed=0, dtype=torch.float32):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g, dtype=dtype)


def _mask(*shape, p=0.4, seed=1):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(*shape, generator=g) < p


# --------------------------------------------------------------------------- SSIM


def _ssim_reference(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """SSIM map of two (H, W) images by explicit windows, each cut at the image edge and its
    weights renormalised to sum to 1."""
    r = np.arange(11) - 5
    g = np.exp(-(r**2) / (2 * 1.5**2))
    full = np.outer(g, g)
    H, W = x.shape
    out = np.empty_like(x)
    for i in range(H):
        for j in range(W):
            rows, cols = slice(max(i - 5, 0), min(i + 6, H)), slice(max(j - 5, 0), min(j + 6, W))
            w = full[rows.start - i + 5 : rows.stop - i + 5, cols.start - j + 5 : cols.stop - j + 5]
            w = w / w.sum()
            a, b = x[rows, cols], y[rows, cols]
            mx, my = (w * a).sum(), (w * b).sum()
            vx, vy = (w * (a - mx) ** 2).sum(), (w * (b - my) ** 2).sum()
            cxy = (w * (a - mx) * (b - my)).sum()
            out[i, j] = ((2 * mx * my + C1) * (2 * cxy + C2)) / (
                (mx**2 + my**2 + C1) * (vx + vy + C2)
            )
    return out


def test_gaussian_window_sums_to_one_and_is_symmetric():
    w = L.gaussian_window(11, 1.5, torch.float64)
    assert w.shape == (11, 11)
    assert float(w.sum()) == pytest.approx(1.0, abs=1e-12)
    torch.testing.assert_close(w, w.T)
    assert float(w[5, 5] / w[5, 6]) == pytest.approx(math.exp(1 / (2 * 1.5**2)))


def test_ssim_map_matches_explicit_window_reference():
    x, y = _rand(1, 1, 12, 14, seed=3, dtype=torch.float64), _rand(1, 1, 12, 14, seed=4).double()
    ref = _ssim_reference(x[0, 0].numpy(), y[0, 0].numpy())
    np.testing.assert_allclose(L.ssim_map_torch(x, y)[0, 0].numpy(), ref, rtol=1e-9, atol=1e-12)


def test_ssim_map_interior_matches_scikit_image():
    skimage_metrics = pytest.importorskip("skimage.metrics")
    rng = np.random.default_rng(7)
    x = rng.random((24, 27))
    y = np.clip(x + 0.3 * rng.standard_normal(x.shape), 0.0, 1.0)
    _, ref = skimage_metrics.structural_similarity(
        x,
        y,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
        data_range=1.0,
        full=True,
    )
    got = L.ssim_map_torch(torch.from_numpy(x)[None, None], torch.from_numpy(y)[None, None])[0, 0]
    # scikit-image truncates its Gaussian at 3.5 sigma (the same 11x11 window) and leaves the
    # 5 px border to padding; only the pixels whose window fits are compared
    np.testing.assert_allclose(got.numpy()[5:-5, 5:-5], ref[5:-5, 5:-5], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("shape", [(1, 2), (3, 4), (5, 17)])
def test_ssim_map_works_on_images_smaller_than_the_window(shape):
    x = _rand(1, 1, *shape, seed=8, dtype=torch.float64)
    y = _rand(1, 1, *shape, seed=9, dtype=torch.float64)
    ref = _ssim_reference(x[0, 0].numpy(), y[0, 0].numpy())
    np.testing.assert_allclose(L.ssim_map_torch(x, y)[0, 0].numpy(), ref, rtol=1e-9, atol=1e-12)


def test_ssim_map_is_per_channel_and_per_image():
    x, y = _rand(2, 3, 9, 10, seed=10), _rand(2, 3, 9, 10, seed=11)
    got = L.ssim_map_torch(x, y)
    for b in range(2):
        for c in range(3):
            one = L.ssim_map_torch(x[b : b + 1, c : c + 1], y[b : b + 1, c : c + 1])
            torch.testing.assert_close(got[b : b + 1, c : c + 1], one, rtol=1e-4, atol=1e-5)


def test_ssim_map_rejects_bad_inputs():
    with pytest.raises(ValueError, match="equal"):
        L.ssim_map_torch(torch.zeros(1, 1, 4, 4), torch.zeros(1, 1, 4, 5))
    with pytest.raises(ValueError, match="odd"):
        L.ssim_map_torch(torch.zeros(1, 1, 4, 4), torch.zeros(1, 1, 4, 4), window_size=4)


def test_masked_ssim_loss_is_one_minus_the_reported_metric():
    from nidar_mi.eval.metrics import ssim

    pred = _rand(1, 1, 20, 23, seed=12, dtype=torch.float64)
    target = _rand(1, 1, 20, 23, seed=13, dtype=torch.float64)
    mask = _mask(1, 1, 20, 23, p=0.5, seed=14)
    mask[0, 0, 0, :] = True  # border pixels take part
    loss = L.masked_ssim_loss(pred, target, mask, eps=0.0)
    metric = ssim(pred[0, 0].numpy(), target[0, 0].numpy(), mask[0, 0].numpy())
    assert float(loss) == pytest.approx(1.0 - metric, rel=1e-12, abs=1e-12)
    # float32 training precision
    loss32 = L.masked_ssim_loss(pred.float(), target.float(), mask, eps=0.0)
    assert float(loss32) == pytest.approx(1.0 - metric, abs=1e-5)


def test_ssim_of_constant_images_is_the_luminance_term():
    a, b = 0.3, 0.7
    x = torch.full((1, 1, 8, 8), a, dtype=torch.float64)
    y = torch.full((1, 1, 8, 8), b, dtype=torch.float64)
    expected = (2 * a * b + C1) / (a * a + b * b + C1)
    torch.testing.assert_close(L.ssim_map_torch(x, y), torch.full_like(x, expected))
    torch.testing.assert_close(L.ssim_map_torch(x, x), torch.ones_like(x))


# --------------------------------------------------------------------------- intrinsic terms


def test_reconstruction_is_zero_for_exact_product_and_l1_otherwise():
    r, s = _rand(2, 1, 8, 8, seed=1), _rand(2, 1, 8, 8, seed=2) * 3
    assert float(L.reconstruction_loss(r, s, r * s)) == 0.0
    half, one = torch.full((1, 1, 4, 4), 0.5), torch.ones(1, 1, 4, 4)
    assert float(L.reconstruction_loss(half, one, torch.full((1, 1, 4, 4), 0.25))) == 0.25


def test_reflectance_smoothness_hand_values():
    r = torch.tensor([[[[0.0, 1.0], [0.0, 1.0]]]])
    flat = torch.zeros_like(r)
    # One unit step per row in x, none in y; flat image: weights 1.
    assert float(L.reflectance_smoothness_loss(r, flat, gamma=10.0)) == pytest.approx(1.0)
    # The image has a step of 0.1 at the same place: weight exp(-10 * 0.1).
    img = 0.1 * r
    assert float(L.reflectance_smoothness_loss(r, img, 10.0)) == pytest.approx(math.exp(-1.0))
    assert (
        float(
            L.reflectance_smoothness_loss(torch.full((1, 1, 5, 5), 0.3), img.new_zeros(1, 1, 5, 5))
        )
        == 0.0
    )


def test_shading_prior_of_a_delta():
    s = torch.zeros(1, 1, 5, 5)
    s[0, 0, 2, 2] = 1.0
    # 3x3 box: the centre becomes 1/9 and its 8 neighbours 1/9; |1 - 1/9| + 8/9 = 16/9.
    assert float(L.shading_prior_loss(s, 3)) == pytest.approx(16 / 9 / 25)
    assert float(L.shading_prior_loss(torch.full((1, 1, 6, 6), 2.0), 5)) == pytest.approx(0.0)


def test_mean_reflectance_is_per_image():
    r = torch.cat([torch.full((1, 1, 4, 4), 0.3), torch.full((1, 1, 4, 4), 0.7)])
    # A batch-global mean would be 0.5 (loss 0); per image both are 0.2 away.
    assert float(L.mean_reflectance_loss(r, 0.5)) == pytest.approx(0.2)


# --------------------------------------------------------------------------- masked intensity


def _down_reference(a: np.ndarray, s: float) -> np.ndarray:
    """Bilinear (align_corners=False) down-sampling by 1/2 or 1/4 of (H, W) by hand."""
    k = int(round(1 / s))
    h, w = a.shape[0] // k, a.shape[1] // k
    if k == 2:  # samples at 2i + 0.5: mean of pixels 2i, 2i+1
        return a.reshape(h, 2, w, 2).mean(axis=(1, 3))
    # k == 4: samples at 4i + 1.5: mean of pixels 4i+1, 4i+2
    return a.reshape(h, 4, w, 4)[:, 1:3, :, 1:3].mean(axis=(1, 3))


def test_masked_multiscale_l1_matches_hand_reference():
    pred, target = _rand(1, 1, 8, 12, seed=7).double(), _rand(1, 1, 8, 12, seed=8).double()
    mask = _mask(1, 1, 8, 12, p=0.5, seed=9)
    m = mask[0, 0].numpy().astype(float)
    p, t = pred[0, 0].numpy() * m, target[0, 0].numpy() * m
    terms = []
    for s in (1.0, 0.5, 0.25):
        if s == 1.0:
            ps, ts, ms = p, t, m
        else:
            k = int(1 / s)
            ps, ts, ms = _down_reference(p, s), _down_reference(t, s), m[::k, ::k]
        terms.append((ms * np.abs(ps - ts)).sum() / (ms.sum() + 1e-6))
    got = L.masked_multiscale_l1(pred, target, mask, (1.0, 0.5, 0.25), eps=1e-6)
    assert float(got) == pytest.approx(np.mean(terms), rel=1e-12)


def test_masked_l2_hand_value_and_empty_mask():
    pred = torch.zeros(1, 1, 4, 4)
    target = torch.zeros(1, 1, 4, 4)
    mask = torch.zeros(1, 1, 4, 4, dtype=torch.bool)
    pred[0, 0, 0, :3] = torch.tensor([1.0, 2.0, 3.0])
    mask[0, 0, 0, :3] = True
    assert float(L.masked_l2(pred, target, mask, eps=0.0)) == pytest.approx((1 + 4 + 9) / 3)
    empty = torch.zeros_like(mask)
    for fn in (L.masked_l2, L.masked_multiscale_l1):
        assert float(fn(pred, target, empty)) == 0.0
    assert (
        float(
            L.masked_ssim_loss(
                _rand(1, 1, 8, 8), _rand(1, 1, 8, 8, seed=2), torch.zeros(1, 1, 8, 8)
            )
        )
        == 1.0
    )


def test_perfect_prediction_gives_zero_intensity_loss():
    target, mask = _rand(2, 1, 16, 16, seed=11), _mask(2, 1, 16, 16, seed=12)
    target = target * mask
    pred = target + 5.0 * (~mask)  # wrong only where nothing is supervised
    assert float(L.intensity_loss(pred, target, mask)) == pytest.approx(0.0, abs=1e-6)


@pytest.mark.parametrize(
    "fn", [L.masked_multiscale_l1, L.masked_l2, L.masked_ssim_loss, L.intensity_loss]
)
def test_masked_pixels_never_change_a_masked_loss(fn):
    pred, target = _rand(2, 1, 16, 16, seed=13), _rand(2, 1, 16, 16, seed=14)
    mask = _mask(2, 1, 16, 16, seed=15)
    before = fn(pred, target, mask)
    noise = 10 * _rand(2, 1, 16, 16, seed=16) - 5
    after = fn(pred + noise * ~mask, target - noise * ~mask, mask)
    assert float(after) == float(before)
    # ...while a supervised pixel does change it.
    idx = mask.nonzero()[0].tolist()
    bumped = pred.clone()
    bumped[tuple(idx)] += 0.5
    assert float(fn(bumped, target, mask)) != float(before)


def test_intensity_loss_weights():
    pred, target, mask = (
        _rand(1, 1, 16, 16, seed=17),
        _rand(1, 1, 16, 16, seed=18),
        _mask(1, 1, 16, 16),
    )
    expected = (
        1.0 * L.masked_multiscale_l1(pred, target, mask)
        + 0.5 * L.masked_l2(pred, target, mask)
        + 0.2 * L.masked_ssim_loss(pred, target, mask)
    )
    torch.testing.assert_close(L.intensity_loss(pred, target, mask), expected)


def test_linear_warmup():
    assert L.linear_warmup(0, 4) == 0.25
    assert L.linear_warmup(2, 4) == 0.75
    assert L.linear_warmup(3, 4) == 1.0
    assert L.linear_warmup(100, 4) == 1.0
    assert L.linear_warmup(0, 0) == 1.0


def test_irnet_objective_is_the_weighted_sum():
    cfg = LossConfig(lambda_s=0.3)
    r, s = _rand(2, 1, 16, 16, seed=19), _rand(2, 1, 16, 16, seed=20)
    i_hat, image = _rand(2, 1, 16, 16, seed=21), _rand(2, 1, 16, 16, seed=22)
    mask = _mask(2, 1, 16, 16)
    target = _rand(2, 1, 16, 16, seed=23) * mask
    out = {"R": r, "S": s, "I_hat": i_hat}
    total, terms = L.irnet_objective(out, image, target, mask, cfg, int_factor=0.5)
    expected = (
        1.0 * L.reconstruction_loss(r, s, image)
        + 0.01 * L.reflectance_smoothness_loss(r, image, 10.0)
        + 0.3 * L.shading_prior_loss(s, 5)
        + 0.01 * L.mean_reflectance_loss(r, 0.5)
        + 0.5 * 0.5 * L.intensity_loss(i_hat, target, mask)
    )
    torch.testing.assert_close(total, expected)
    assert terms["int"] == pytest.approx(float(L.intensity_loss(i_hat, target, mask)))


def test_stn_loss_single_scale_value():
    p, t = _rand(1, 1, 8, 8, seed=24), _rand(1, 1, 8, 8, seed=25)
    expected = 0.85 * ((1 - L.ssim_map_torch(p, t)) / 2).mean() + 0.15 * (p - t).abs().mean()
    torch.testing.assert_close(L.stn_loss([p], [t], 0.85), expected)
    assert float(L.stn_loss([p, p[..., :4, :4]], [p, p[..., :4, :4]])) == 0.0


# --------------------------------------------------------------------------- gradcheck


@pytest.mark.parametrize(
    "name,fn",
    [
        ("ms_l1", lambda p, t, m: L.masked_multiscale_l1(p, t, m)),
        ("l2", lambda p, t, m: L.masked_l2(p, t, m)),
        ("ssim", lambda p, t, m: L.masked_ssim_loss(p, t, m)),
        ("ssim_map", lambda p, t, m: L.ssim_map_torch(p, t)),
        ("int", lambda p, t, m: L.intensity_loss(p, t, m)),
        ("smooth", lambda p, t, m: L.reflectance_smoothness_loss(p, t, 10.0)),
        ("shading", lambda p, t, m: L.shading_prior_loss(p, 3)),
        ("stn", lambda p, t, m: L.stn_loss([p], [t])),
    ],
)
def test_gradcheck_float64(name, fn):
    pred = _rand(1, 1, 8, 8, seed=26, dtype=torch.float64).requires_grad_()
    target = _rand(1, 1, 8, 8, seed=27, dtype=torch.float64)
    mask = _mask(1, 1, 8, 8, p=0.6, seed=28)
    assert torch.autograd.gradcheck(lambda p: fn(p, target, mask), (pred,), eps=1e-6, atol=1e-5)


# ----------------------------------------------------------- supervised intrinsic terms


def test_reflectance_supervision_is_the_mean_error_on_surface_pixels():
    from nidar_mi.nidar.losses import reflectance_supervision_loss

    r = torch.full((1, 1, 4, 4), 0.5)
    r_true = torch.zeros(1, 1, 4, 4)  # sky: left out
    r_true[..., :2, :] = 0.3  # 8 pixels, error 0.2
    r_true[..., 2, :] = 7.0  # 4 retroreflector pixels, clipped to 1: error 0.5
    expected = (8 * 0.2 + 4 * 0.5) / 12
    assert float(reflectance_supervision_loss(r, r_true)) == pytest.approx(expected, rel=1e-5)


def test_shading_supervision_ignores_a_gain_and_sees_a_pattern():
    from nidar_mi.nidar.losses import shading_supervision_loss

    g = torch.Generator().manual_seed(0)
    s_true = torch.rand(2, 1, 8, 8, generator=g) + 0.1
    r_true = torch.full_like(s_true, 0.4)
    gained = 3.7 * (s_true + 1e-3) - 1e-3  # log(S + δ) = log 3.7 + log(S_true + δ)
    assert float(shading_supervision_loss(gained, s_true, r_true)) == pytest.approx(0, abs=1e-5)
    # d = log 2 on one pixel of 64, 0 elsewhere: mean |d - mean d| = 2 · 63 · log 2 / 64²
    doubled = s_true.clone()
    doubled[:, :, 0, 0] = 2 * (s_true[:, :, 0, 0] + 1e-3) - 1e-3
    expected = 2 * 63 * np.log(2) / 64**2
    loss = float(shading_supervision_loss(doubled, s_true, r_true))
    assert loss == pytest.approx(expected, rel=1e-4)


def test_objective_needs_true_maps_when_supervised():
    from nidar_mi.nidar.config import LossConfig
    from nidar_mi.nidar.losses import irnet_objective

    x = torch.rand(1, 1, 8, 8)
    out = {"R": x, "S": x, "I_hat": x}
    with pytest.raises(ValueError, match="r_true"):
        irnet_objective(out, x, x, x > 0.5, LossConfig(lambda_r_true=1.0))
    total, terms = irnet_objective(
        out, x, x, x > 0.5, LossConfig(lambda_r_true=1.0), r_true=1 - x, s_true=x
    )
    base, _ = irnet_objective(out, x, x, x > 0.5, LossConfig())
    assert terms["R_true"] > 0.1
    assert float(total - base) == pytest.approx(terms["R_true"], rel=1e-5)
