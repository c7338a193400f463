"""UNet: shapes, a hand-counted parameter total, locality of the receptive field."""

from __future__ import annotations

import pytest
import torch

from nidar_mi.nidar.unet import UNet


@pytest.mark.parametrize("depth", [1, 2, 3])
@pytest.mark.parametrize("cin,cout", [(1, 2), (3, 3)])
def test_shapes(depth, cin, cout):
    net = UNet(cin, cout, width=4, depth=depth)
    x = torch.rand(2, cin, 8 * 2**depth, 4 * 2**depth)
    assert net.stride == 2**depth
    assert net(x).shape == (2, cout, *x.shape[-2:])
    assert net.features(x).shape == (2, 4, *x.shape[-2:])
    assert net.feature_channels == 4


def test_parameter_count_by_hand():
    # down0: 1->4 conv (36) + BN (8) + 4->4 conv (144) + BN (8)        = 196
    # down1: 4->8 conv (288) + BN (16) + 8->8 conv (576) + BN (16)     = 896
    # up0:   12->4 conv (432) + BN (8) + 4->4 conv (144) + BN (8)      = 592
    # head:  4->2 1x1 conv with bias                                   = 10
    net = UNet(1, 2, width=4, depth=1)
    assert sum(p.numel() for p in net.parameters()) == 196 + 896 + 592 + 10


def test_receptive_field_is_local():
    # depth 1: two 3x3 convs (radius 2), pool, two 3x3 convs at half resolution (radius 4 +
    # pool/upsample slack), two 3x3 convs (radius 2): nothing beyond ~12 px reaches a pixel.
    torch.manual_seed(0)
    net = UNet(1, 1, width=4, depth=1).eval()
    x = torch.rand(1, 1, 48, 48, requires_grad=True)
    net(x)[0, 0, 24, 24].backward()
    g = x.grad[0, 0].abs()
    assert float(g[24, 24]) > 0
    assert float(g[:, :10].sum() + g[:, 39:].sum() + g[:10].sum() + g[39:].sum()) == 0.0


def test_rejects_indivisible_input():
    with pytest.raises(ValueError, match="multiples of 4"):
        UNet(1, 1, width=4, depth=2)(torch.rand(1, 1, 10, 8))
