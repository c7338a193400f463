"""Folding BatchNorm into convolutions: the analytic fold, every network variant, < 1e-5."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import IRNET_VARIANTS
from nidar_mi.nidar.fold import (
    FOLD_TOLERANCE,
    fold_batchnorm,
    fold_conv_bn,
    fold_error,
    prepare_for_inference,
)
from nidar_mi.nidar.irnet import IRNet
from nidar_mi.nidar.precision import emulated_convolutions, round_mantissa
from nidar_mi.nidar.stn import STN


def _randomise_bn(net: nn.Module, seed: int = 0) -> nn.Module:
    """Give every BatchNorm non-trivial statistics and affine parameters (as after training)."""
    g = torch.Generator().manual_seed(seed)
    for m in net.modules():
        if isinstance(m, nn.BatchNorm2d):
            n = m.num_features
            m.running_mean.copy_(torch.randn(n, generator=g) * 0.5)
            m.running_var.copy_(torch.rand(n, generator=g) * 2.0 + 0.1)
            m.weight.data.copy_(torch.randn(n, generator=g))
            m.bias.data.copy_(torch.randn(n, generator=g))
    return net.eval()


def test_fold_conv_bn_is_the_affine_formula_in_float64():
    torch.manual_seed(0)
    conv = nn.Conv2d(3, 5, 3, stride=2, padding=2, dilation=2, bias=True).double()
    bn = _randomise_bn(nn.BatchNorm2d(5)).double()
    x = torch.randn(2, 3, 17, 13, dtype=torch.float64)
    y = conv(x)
    s = bn.weight / torch.sqrt(bn.running_var + bn.eps)
    expected = (y - bn.running_mean.reshape(1, -1, 1, 1)) * s.reshape(
        1, -1, 1, 1
    ) + bn.bias.reshape(1, -1, 1, 1)
    with torch.no_grad():
        torch.testing.assert_close(fold_conv_bn(conv, bn)(x), expected, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("variant", IRNET_VARIANTS)
def test_folding_every_irnet_variant_changes_outputs_below_1e_5(variant):
    torch.manual_seed(1)
    net = _randomise_bn(
        IRNet(variant, 1, width=4, unet_depth=2, output_stride=4, aspp_rates=(1, 2))
    )
    x = torch.rand(1, 1, 32, 48)
    folded = fold_batchnorm(net, torch.rand(1, 1, 16, 16))
    assert not any(isinstance(m, nn.BatchNorm2d) for m in folded.modules())
    assert any(isinstance(m, nn.BatchNorm2d) for m in net.modules())  # the original is unchanged
    with torch.no_grad():
        a, b = net(x), folded(x)
    for k in ("R", "S", "I_hat"):
        rel = ((a[k] - b[k]).abs() / a[k].abs().clamp(min=1.0)).max().item()
        assert rel < 1e-5, k


def test_folding_and_channels_last_stn():
    torch.manual_seed(2)
    net = _randomise_bn(STN(width=4, levels=3, num_outputs=2))
    fast = prepare_for_inference(net, torch.rand(1, 3, 16, 16))
    assert not any(isinstance(m, nn.BatchNorm2d) for m in fast.modules())
    x = torch.rand(1, 3, 24, 40)
    with torch.no_grad():
        a = net(x)
        b = fast(x.contiguous(memory_format=torch.channels_last))
    assert ((a - b).abs() / a.abs().clamp(min=1.0)).max().item() < 1e-5


def test_a_conv_output_read_twice_is_not_folded():
    class Twice(nn.Module):
        def __init__(self):
            super().__init__()
            self.conv = nn.Conv2d(1, 2, 3, padding=1)
            self.bn = nn.BatchNorm2d(2)
            self.act = nn.ReLU()

        def forward(self, x):
            y = self.conv(x)
            return self.bn(y) + self.act(y)

    net = _randomise_bn(Twice())
    folded = fold_batchnorm(net, torch.rand(1, 1, 8, 8))
    assert isinstance(folded.bn, nn.BatchNorm2d)


def test_fold_needs_running_statistics():
    bn = nn.BatchNorm2d(2, track_running_stats=False)
    with pytest.raises(NidarError, match="running statistics"):
        fold_conv_bn(nn.Conv2d(1, 2, 1), bn)


@pytest.fixture
def tf32_convolutions():
    """Every float32 2-D convolution computed as a GPU does by default on Ampere and Hopper:
    inputs and weights rounded to TF32, products accumulated in float32. Float64 is untouched."""
    with emulated_convolutions("tf32"):
        yield


def _irnet() -> nn.Module:
    torch.manual_seed(3)
    return _randomise_bn(
        IRNet("unet+deeplabv3", 1, width=16, unet_depth=2, output_stride=4, aspp_rates=(1, 2))
    )


def test_tf32_rounding_moves_float32_outputs_past_the_tolerance(tf32_convolutions):
    """The emulation is strong enough to matter: compared in float32 under TF32, the folded and the
    original network differ by more than FOLD_TOLERANCE (the check of earlier versions failed so)."""
    net = _irnet()
    folded = fold_batchnorm(net, torch.rand(1, 1, 16, 16))
    x = torch.rand(1, 1, 32, 48)
    with torch.no_grad():
        a, b = net(x), folded(x)
    rel = max(((a[k] - b[k]).abs() / a[k].abs().clamp(min=1.0)).max().item() for k in a)
    assert rel > 10 * FOLD_TOLERANCE


def test_folding_holds_under_tf32_convolutions(tf32_convolutions):
    net = _irnet()
    example = torch.rand(1, 1, 16, 16)
    folded = fold_batchnorm(net, example)  # raised "folding changed an output" before
    # in float64 only the float32 storage of the folded weights is left (2**-24 each)
    assert fold_error(net, folded, example) < 1e-6
    assert not any(isinstance(m, nn.BatchNorm2d) for m in folded.modules())


def test_a_wrong_fold_is_still_refused(monkeypatch):
    import nidar_mi.nidar.fold as fold

    right = fold.fold_conv_bn

    def off_by_1e_3(conv, bn):
        fused = right(conv, bn)
        with torch.no_grad():
            fused.bias += 1e-3
        return fused

    monkeypatch.setattr(fold, "fold_conv_bn", off_by_1e_3)
    with pytest.raises(NidarError, match="folding changed an output by"):
        fold_batchnorm(_irnet(), torch.rand(1, 1, 16, 16))


def test_round_mantissa_keeps_the_stated_bits():
    # 1 + 2**-11 is halfway between two TF32 numbers (10 bits): rounds up to 1 + 2**-10
    x = torch.tensor([1.0 + 2.0**-11, 1.0 + 2.0**-12, -3.0 - 2.0**-9, 1e-30], dtype=torch.float32)
    got = round_mantissa(x, 10)
    expected = torch.tensor([1.0 + 2.0**-10, 1.0, -3.0 - 2.0**-9, 1e-30], dtype=torch.float32)
    rel = ((got - expected).abs() / expected.abs()).max().item()
    assert rel < 2.0**-10
    assert got[:3].tolist() == expected[:3].tolist()
    r = torch.rand(10_000) * 100.0
    assert ((round_mantissa(r, 7) - r).abs() / r).max().item() <= 2.0**-8
