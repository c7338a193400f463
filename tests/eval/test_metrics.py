"""Metrics against hand-computed values and a direct (looped) SSIM reference."""

import sys
import types

import numpy as np
import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.eval import metrics as M

C1, C2 = 0.01**2, 0.03**2
A = np.exp(-1.0 / (2 * 1.5**2))  # Gaussian weight of a neighbour one pixel away
W0, W1 = 1.0 / (1.0 + A), A / (1.0 + A)  # window of a 1x2 image: self, other


def _ssim_formula(mx, my, vx, vy, cxy):
    return ((2 * mx * my + C1) * (2 * cxy + C2)) / ((mx**2 + my**2 + C1) * (vx + vy + C2))


def _ssim_reference_valid(x, y):
    """Wang et al. 2004, 'valid' windows only, one explicit 11x11 window per pixel."""
    k = np.arange(-5, 6)
    g = np.exp(-(k**2) / (2 * 1.5**2))
    w = np.outer(g, g) / np.outer(g, g).sum()
    H, W = x.shape
    out = np.empty((H - 10, W - 10))
    for i in range(H - 10):
        for j in range(W - 10):
            px, py = x[i : i + 11, j : j + 11], y[i : i + 11, j : j + 11]
            mx, my = (w * px).sum(), (w * py).sum()
            vx = (w * (px - mx) ** 2).sum()
            vy = (w * (py - my) ** 2).sum()
            cxy = (w * (px - mx) * (py - my)).sum()
            out[i, j] = _ssim_formula(mx, my, vx, vy, cxy)
    return out


# --- scaling and error metrics ------------------------------------------------------------------


def test_scale_intensity_divides_and_clips():
    out = M.scale_intensity([-1.0, 0.5, 2.0, 4.0], 2.0)
    np.testing.assert_allclose(out, [0.0, 0.25, 1.0, 1.0])


@pytest.mark.parametrize("scale", [0.0, -1.0, float("nan"), float("inf")])
def test_scale_intensity_rejects_bad_scales(scale):
    with pytest.raises(NidarError, match="scale"):
        M.scale_intensity([1.0], scale)


def test_rmse_mae_medae_by_hand():
    assert M.rmse([0.0, 1.0], [1.0, 1.0]) == pytest.approx(np.sqrt(0.5))
    pred = np.array([[0.1, 0.5], [0.9, 0.2]])
    gt = np.array([[0.2, 0.1], [0.6, 0.2]])  # errors 0.1, 0.4, 0.3, 0.0
    assert M.mae(pred, gt) == pytest.approx(0.2)
    assert M.medae(pred, gt) == pytest.approx(0.2)  # median of 0, 0.1, 0.3, 0.4
    mask = np.array([[True, True], [True, False]])  # errors 0.1, 0.4, 0.3
    assert M.medae(pred, gt, mask) == pytest.approx(0.3)
    assert M.rmse(pred, gt, mask) == pytest.approx(np.sqrt((0.01 + 0.16 + 0.09) / 3))


def test_psnr_of_mse_001_is_20_db():
    gt = np.zeros((4, 5))
    assert M.psnr(gt + 0.1, gt) == pytest.approx(20.0)
    assert M.psnr(gt, gt) == float("inf")


def test_values_outside_the_mask_are_ignored_even_non_finite():
    pred = np.array([[0.5, np.nan]])
    gt = np.array([[0.4, np.inf]])
    mask = np.array([[True, False]])
    assert M.rmse(pred, gt, mask) == pytest.approx(0.1)
    with pytest.raises(NidarError, match="non-finite"):
        M.rmse(pred, gt)


@pytest.mark.parametrize(
    "pred, gt, mask, match",
    [
        (np.zeros(3), np.zeros(4), None, "shapes differ"),
        (np.zeros(3), np.zeros(3), np.zeros(2, bool), "mask shape"),
        (np.zeros(3), np.zeros(3), np.zeros(3, bool), "no valid"),
    ],
)
def test_bad_inputs_are_user_errors(pred, gt, mask, match):
    with pytest.raises(NidarError, match=match):
        M.rmse(pred, gt, mask)


# --- SSIM ----------------------------------------------------------------------------------------


def test_ssim_of_identical_images_is_one():
    x = np.random.default_rng(0).random((20, 23))
    assert M.ssim(x, x) == pytest.approx(1.0, abs=1e-12)


def test_ssim_of_a_constant_offset_on_a_constant_image():
    # every local mean is the constant, every variance 0: (2*0.5*0.6 + C1) / (0.25 + 0.36 + C1)
    x = np.full((3, 4), 0.5)
    assert M.ssim(x, x + 0.1) == pytest.approx(0.6001 / 0.6101, rel=1e-12)


def test_ssim_of_a_constant_offset_on_a_1x2_image():
    # x = [0, 1], y = x + 0.2: variances and covariance equal, only the luminance term is left;
    # local mean of x is W1 at pixel 0 and W0 at pixel 1
    x = np.array([[0.0, 1.0]])
    expected = [(2 * m * (m + 0.2) + C1) / (m**2 + (m + 0.2) ** 2 + C1) for m in (W1, W0)]
    np.testing.assert_allclose(M.ssim_map(x, x + 0.2)[0], expected, rtol=1e-12)
    assert M.ssim(x, x + 0.2) == pytest.approx(np.mean(expected), rel=1e-12)


def test_ssim_of_a_scaled_1x2_image():
    # x = [0, 1], y = [0, 0.5]: at pixel p, mu_x = m, mu_y = m/2, var_x = W0*W1,
    # var_y = W0*W1/4, cov = W0*W1/2
    x = np.array([[0.0, 1.0]])
    v = W0 * W1
    expected = [_ssim_formula(m, m / 2, v, v / 4, v / 2) for m in (W1, W0)]
    np.testing.assert_allclose(M.ssim_map(x, x / 2)[0], expected, rtol=1e-12)


def test_masked_ssim_zeroes_invalid_pixels_and_averages_over_valid_ones():
    # valid pixel 0 (0.5 vs 0.6), invalid pixel 1 set to 0 in both:
    # mu_x = 0.5*W0, mu_y = 0.6*W0, var_x = 0.25*W0*W1, var_y = 0.36*W0*W1, cov = 0.3*W0*W1
    pred = np.array([[0.5, np.nan]])
    gt = np.array([[0.6, 0.9]])
    mask = np.array([[True, False]])
    v = W0 * W1
    expected = _ssim_formula(0.5 * W0, 0.6 * W0, 0.25 * v, 0.36 * v, 0.3 * v)
    assert M.ssim(pred, gt, mask) == pytest.approx(expected, rel=1e-12)


def test_ssim_interior_equals_the_reference_formulation():
    rng = np.random.default_rng(1)
    x = rng.random((16, 18))
    y = np.clip(x + 0.2 * rng.standard_normal(x.shape), 0, 1)
    got = M.ssim_map(x, y)
    assert got.shape == x.shape
    np.testing.assert_allclose(got[5:-5, 5:-5], _ssim_reference_valid(x, y), rtol=1e-10)
    assert np.all(got <= 1.0) and np.mean(got) < 0.9


# --- Spearman --------------------------------------------------------------------------------------


def test_spearman_of_monotone_and_reversed():
    x = np.random.default_rng(2).random(50)
    assert M.spearman(np.exp(3 * x), x) == pytest.approx(1.0)
    assert M.spearman(-(x**3), x) == pytest.approx(-1.0)
    assert M.spearman(np.sort(x)[::-1], np.sort(x)) == pytest.approx(-1.0)


def test_spearman_with_ties_by_hand():
    # ranks [1, 2.5, 2.5, 4] and [1, 3, 2, 4]: cov 4.5, var 4.5 and 5 -> 4.5 / sqrt(22.5)
    assert M.spearman([1, 2, 2, 3], [1, 3, 2, 4]) == pytest.approx(np.sqrt(0.9), rel=1e-12)


def test_spearman_of_a_constant_or_of_fewer_than_three_pairs_is_nan():
    assert np.isnan(M.spearman([1.0, 1.0, 1.0], [1.0, 2.0, 3.0]))
    assert np.isnan(M.spearman([1.0, 2.0, 3.0], [2.0, 2.0, 2.0]))
    assert np.isnan(M.spearman([1.0], [2.0]))
    assert np.isnan(M.spearman([1.0, 2.0], [2.0, 1.0]))  # scipy: -1, whatever the values
    assert np.isnan(M.spearman([], []))
    # three pairs are scored: ranks [1, 2, 3] and [1, 3, 2] -> 1 - 6 * 2 / (3 * 8)
    assert M.spearman([1.0, 2.0, 3.0], [1.0, 3.0, 2.0]) == pytest.approx(0.5, rel=1e-12)


def test_spearman_refuses_non_finite_values_and_other_shapes():
    with pytest.raises(NidarError, match="pred has non-finite values"):
        M.spearman([1.0, np.nan, 3.0], [1.0, 2.0, 3.0])
    with pytest.raises(NidarError, match="shapes differ"):
        M.spearman([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(NidarError, match="expected 1-D"):
        M.spearman(np.ones((2, 2)), np.ones((2, 2)))


# --- bundles ------------------------------------------------------------------------------------


def test_point_metrics_by_hand():
    # errors 0.5, 0, 0; ranks [1, 3, 2] and [1.5, 3, 1.5], centred [-1, 1, 0] and
    # [-0.5, 1, -0.5]: cov 1.5, variances 2 and 1.5 -> 1.5 / sqrt(3)
    out = M.point_metrics([0.0, 1.0, 0.5], [0.5, 1.0, 0.5])
    assert out["n"] == 3
    assert out["rmse"] == pytest.approx(np.sqrt(0.25 / 3))
    assert out["mae"] == pytest.approx(1 / 6)
    assert out["spearman"] == pytest.approx(np.sqrt(0.75), rel=1e-12)


def test_point_metrics_scale_before_comparing():
    out = M.point_metrics([2.0, 8.0], [4.0, 4.0], scale=4.0)  # -> [0.5, 1] vs [1, 1]
    assert out["rmse"] == pytest.approx(np.sqrt(0.125))
    assert out["mae"] == pytest.approx(0.25)


def test_map_metrics_report_lpips_unavailable_here():
    gt = np.zeros((40, 40))
    pred = gt + 0.1
    out = M.map_metrics(pred, gt)
    assert out["n"] == 1600
    assert out["rmse"] == pytest.approx(0.1) and out["medae"] == pytest.approx(0.1)
    assert out["psnr"] == pytest.approx(20.0)
    assert out["ssim"] == pytest.approx(0.0001 / 0.0101, rel=1e-9)  # (C1)/(0.01 + C1)
    assert out["lpips"] is None and "lpips" in out["lpips_reason"]
    skipped = M.map_metrics(pred, gt, lpips=False)
    assert skipped["lpips"] is None and skipped["lpips_reason"] == "not requested"
    scaled = M.map_metrics(2 * pred, 2 * gt, scale=2.0, lpips=False)
    assert scaled["rmse"] == pytest.approx(0.1)


# --- LPIPS ------------------------------------------------------------------------------------------


def test_lpips_is_unavailable_in_this_environment():
    reason = M.lpips_unavailable_reason()
    assert reason is not None and "lpips" in reason
    value, why = M.lpips_alex(np.zeros((32, 32)), np.ones((32, 32)))
    assert value is None and why == reason


def test_lpips_refuses_maps_smaller_than_alexnet_accepts():
    value, why = M.lpips_alex(np.zeros((30, 64)), np.zeros((30, 64)))
    assert value is None and "31" in why


class _FakeLPIPS(torch.nn.Module):
    """lpips.LPIPS's interface: ``net.sliceK.<features index>``; spatial squared difference of a
    1x1 convolution of the [-1, 1] inputs."""

    def __init__(self, net, pretrained, pnet_rand, spatial, verbose):
        super().__init__()
        assert net == "alex" and pnet_rand and not verbose
        self.spatial = spatial
        self.net = torch.nn.Module()
        self.net.slice1 = torch.nn.Sequential()
        self.net.slice1.add_module("0", torch.nn.Conv2d(3, 1, 1, bias=False))

    def forward(self, in0, in1, normalize=False):
        if normalize:
            in0, in1 = 2 * in0 - 1, 2 * in1 - 1
        d = (self.net.slice1(in0) - self.net.slice1(in1)) ** 2
        return d if self.spatial else d.mean(dim=(2, 3), keepdim=True)


@pytest.fixture()
def fake_lpips(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "lpips", types.SimpleNamespace(LPIPS=_FakeLPIPS))
    monkeypatch.setattr(torch.hub, "get_dir", lambda: str(tmp_path))
    return tmp_path / "checkpoints" / M.ALEXNET_CHECKPOINT


def test_lpips_needs_the_alexnet_checkpoint(fake_lpips):
    reason = M.lpips_unavailable_reason()
    assert reason is not None and str(fake_lpips) in reason
    assert M.lpips_alex(np.zeros((32, 32)), np.zeros((32, 32)))[0] is None


def test_lpips_uses_the_checkpoint_backbone_and_the_mask(fake_lpips):
    fake_lpips.parent.mkdir(parents=True)
    torch.save({"features.0.weight": torch.full((1, 3, 1, 1), 1 / 3)}, fake_lpips)
    assert M.lpips_unavailable_reason() is None
    rng = np.random.default_rng(3)
    pred, gt = rng.random((32, 33)), rng.random((32, 33))
    mask = rng.random((32, 33)) < 0.5
    value, why = M.lpips_alex(pred, gt, mask)
    # channel mean of the replicated map is the map: (2p - 2g)^2 over the valid pixels
    assert why is None
    assert value == pytest.approx(np.mean(4 * (pred - gt)[mask] ** 2), rel=1e-5)
    value, why = M.lpips_alex(pred, gt)  # no mask: the model's own spatial average
    assert why is None and value == pytest.approx(np.mean(4 * (pred - gt) ** 2), rel=1e-5)


def test_lpips_with_an_incomplete_checkpoint_is_unavailable(fake_lpips):
    fake_lpips.parent.mkdir(parents=True)
    torch.save({"features.3.weight": torch.zeros(1)}, fake_lpips)
    value, why = M.lpips_alex(np.zeros((32, 32)), np.zeros((32, 32)))
    assert value is None and "features.0.weight" in why


def test_lpips_with_an_unreadable_checkpoint_is_unavailable(fake_lpips):
    fake_lpips.parent.mkdir(parents=True)
    fake_lpips.write_bytes(b"not a checkpoint")
    value, why = M.lpips_alex(np.zeros((32, 32)), np.zeros((32, 32)))
    assert value is None and "not readable" in why
