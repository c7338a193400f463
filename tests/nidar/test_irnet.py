"""IRNet: every ablation variant, output ranges, variant parsing, RGB target, gradients."""

from __future__ import annotations

import pytest
import torch

from nidar_mi.io.images import REC709_LUMA
from nidar_mi.nidar.config import IRNET_VARIANTS
from nidar_mi.nidar.heads import ConvHead
from nidar_mi.nidar.irnet import IRNet, parse_variant

KW = {"width": 4, "unet_depth": 2, "output_stride": 4, "aspp_rates": (1, 2)}


@pytest.mark.parametrize("variant", IRNET_VARIANTS)
@pytest.mark.parametrize("cin", [1, 3])
def test_every_variant_shapes_and_ranges(variant, cin):
    torch.manual_seed(0)
    net = IRNet(variant, cin, **KW)
    with torch.no_grad():
        out = net(torch.rand(2, cin, 16, 24))
    assert set(out) == {"R", "S", "I_hat"}
    for v in out.values():
        assert v.shape == (2, 1, 16, 24)
    assert float(out["R"].min()) > 0 and float(out["R"].max()) < 1
    assert float(out["S"].min()) >= 0 and float(out["I_hat"].min()) >= 0


def test_variant_structure():
    assert parse_variant("U-Net+DeepLabV3") == ("unet", "deeplabv3")
    assert parse_variant("DeepLabV3") == ("deeplabv3", None)
    assert parse_variant("deeplabv3+4conv") == ("deeplabv3", "4conv")
    with pytest.raises(ValueError, match="unknown IRNet variant"):
        parse_variant("unet+resnet")
    single = IRNet("unet", 1, **KW)
    assert single.head is None and single.backbone.head.out_channels == 3
    net = IRNet("unet+3conv", 1, **KW)
    assert isinstance(net.head, ConvHead)
    assert sum(isinstance(m, torch.nn.Conv2d) for m in net.head.body) == 3
    # The head sees the backbone features plus R and S.
    assert net.head.body[0].in_channels == 4 + 2
    four = IRNet("unet+4conv", 1, **KW).head.body
    assert sum(isinstance(m, torch.nn.Conv2d) for m in four) == 4


def test_intrinsic_target():
    net = IRNet("unet", 3, **KW)
    rgb = torch.zeros(1, 3, 4, 4)
    rgb[:, 0] = 1.0
    torch.testing.assert_close(net.intrinsic_target(rgb), torch.full((1, 1, 4, 4), REC709_LUMA[0]))
    grey = IRNet("unet", 1, **KW)
    x = torch.rand(1, 1, 4, 4)
    assert grey.intrinsic_target(x) is x


def test_gradients_reach_every_parameter():
    torch.manual_seed(0)
    net = IRNet("unet+deeplabv3", 1, **KW)
    out = net(torch.rand(2, 1, 16, 16))
    sum(v.mean() for v in out.values()).backward()
    missing = [n for n, p in net.named_parameters() if p.grad is None or not p.grad.abs().sum() > 0]
    assert missing == []


def test_stride_and_input_checks():
    assert IRNet("unet+deeplabv3", 1, **KW).stride == 4
    assert IRNet("deeplabv3+3conv", 1, width=4, output_stride=8).stride == 8
    net = IRNet("unet", 1, **KW)
    with pytest.raises(ValueError, match="multiples"):
        net(torch.rand(1, 1, 10, 16))
    with pytest.raises(ValueError, match=r"\(B, 1, H, W\)"):
        net(torch.rand(1, 3, 16, 16))
