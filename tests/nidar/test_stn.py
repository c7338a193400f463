"""STN: shapes, the channel-combination formula, initialisation, and that it learns."""

from __future__ import annotations

import pytest
import torch

from nidar_mi.nidar.losses import stn_loss
from nidar_mi.nidar.stn import STN, image_pyramid


@pytest.fixture()
def stn():
    torch.manual_seed(0)
    return STN(width=4, levels=3, num_outputs=2)


def test_shapes(stn):
    x = torch.rand(2, 3, 32, 48)
    assert stn.stride == 8
    assert stn(x).shape == (2, 1, 32, 48)
    assert [tuple(w.shape) for w in stn.channel_weights(x)] == [(2, 3, 32, 48), (2, 3, 16, 24)]
    assert [tuple(p.shape) for p in stn.forward_pyramid(x)] == [(2, 1, 32, 48), (2, 1, 16, 24)]


def test_pseudo_nir_is_the_weighted_channel_sum(stn):
    stn.eval()
    x = torch.rand(2, 3, 16, 16)
    w = stn.channel_weights(x)
    expected = (x * w[0]).sum(1, keepdim=True)
    torch.testing.assert_close(stn(x), expected)
    torch.testing.assert_close(stn(x, 2.5), 2.5 * expected)
    ratio = torch.tensor([1.0, 3.0])
    torch.testing.assert_close(stn(x, ratio), expected * ratio.view(2, 1, 1, 1))
    coarse = stn.forward_pyramid(x)[1]
    torch.testing.assert_close(coarse, (image_pyramid(x, 2)[1] * w[1]).sum(1, keepdim=True))


def test_untrained_stn_averages_the_channels():
    # cs-stereo initialisation: output bias 1, ELU(1) / 3 = 1/3 per channel.
    torch.manual_seed(0)
    stn = STN(width=4, levels=3, num_outputs=2)
    for m in stn.modules():
        if isinstance(m, torch.nn.Conv2d) and m.bias is not None:
            torch.nn.init.zeros_(m.weight)
    w = stn.channel_weights(torch.rand(1, 3, 16, 16))
    for level in w:
        torch.testing.assert_close(level, torch.full_like(level, 1 / 3))


def test_image_pyramid_is_2x2_means():
    x = torch.arange(16.0).reshape(1, 1, 4, 4)
    half, quarter = image_pyramid(x, 3)[1:]
    torch.testing.assert_close(half, torch.tensor([[[[2.5, 4.5], [10.5, 12.5]]]]))
    torch.testing.assert_close(quarter, torch.tensor([[[[7.5]]]]))


def test_rejects_bad_input(stn):
    with pytest.raises(ValueError, match="multiples of 8"):
        stn(torch.rand(1, 3, 20, 16))
    with pytest.raises(ValueError, match=r"\(B, 3, H, W\)"):
        stn(torch.rand(1, 1, 16, 16))
    with pytest.raises(ValueError):
        STN(levels=2, num_outputs=3)


def test_learns_a_fixed_channel_mix(stn):
    torch.manual_seed(1)
    mix = torch.tensor([0.7, 0.2, 0.1]).view(1, 3, 1, 1)
    x = torch.rand(4, 3, 16, 16)
    target = (x * mix).sum(1, keepdim=True)
    targets = image_pyramid(target, 2)
    opt = torch.optim.Adam(stn.parameters(), lr=3e-3)
    first = None
    for _ in range(40):
        loss = stn_loss(stn.forward_pyramid(x), targets)
        first = first if first is not None else float(loss.detach())
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert float(loss.detach()) < 0.3 * first
