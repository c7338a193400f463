"""DeepLabV3 parts: output strides, ASPP branches, full-resolution output."""

from __future__ import annotations

import pytest
import torch

from nidar_mi.nidar.aspp import ASPP, DeepLabV3, DilatedResNet


@pytest.mark.parametrize("os_", [4, 8, 16])
def test_encoder_output_stride(os_):
    enc = DilatedResNet(1, width=4, output_stride=os_)
    y = enc(torch.rand(2, 1, 64, 32))
    assert y.shape == (2, 32, 64 // os_, 32 // os_)


def test_encoder_dilates_instead_of_striding():
    enc = DilatedResNet(1, width=4, output_stride=4)
    dilations = [b.conv1.dilation[0] for b in enc.stages]
    strides = [b.conv1.stride[0] for b in enc.stages]
    assert strides == [1, 2, 1, 1]
    assert dilations == [1, 1, 2, 4]


def test_aspp_branches_and_image_pooling():
    aspp = ASPP(8, 6, rates=(1, 2, 3)).eval()
    assert len(aspp.branches) == 5  # 1x1, three atrous, image pooling
    x = torch.rand(2, 8, 5, 7)
    assert aspp(x).shape == (2, 6, 5, 7)
    pooled = aspp.branches[-1](x)
    torch.testing.assert_close(pooled, pooled[..., :1, :1].expand_as(pooled))
    assert [b[0].dilation[0] for b in aspp.branches[1:4]] == [1, 2, 3]


def test_deeplabv3_full_resolution_output():
    net = DeepLabV3(3, 2, width=4, output_stride=8, rates=(1, 2, 3))
    x = torch.rand(1, 3, 32, 40)
    assert net(x).shape == (1, 2, 32, 40)
    assert net.features(x).shape == (1, 4, 32, 40)
    assert net.stride == 8


def test_rejects_bad_output_stride():
    with pytest.raises(ValueError):
        DilatedResNet(1, 4, output_stride=6)
