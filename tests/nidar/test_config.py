"""Configuration: the paper's numbers, JSON round trip, validation."""

from __future__ import annotations

import json

import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import IRNET_VARIANTS, TrainConfig


def test_defaults_are_the_papers_settings():
    cfg = TrainConfig()
    lw = cfg.loss
    assert (lw.lambda_recon, lw.lambda_r, lw.lambda_s, lw.lambda_med, lw.lambda_int) == (
        1.0, 0.01, 0.0, 0.01, 0.5,
    )  # fmt: skip
    assert (lw.w1, lw.w2, lw.w_ssim) == (1.0, 0.5, 0.2)
    assert lw.scales == (1.0, 0.5, 0.25) and lw.m0 == 0.5
    o = cfg.irnet_optim
    assert (o.lr, o.weight_decay, o.batch_size, o.epochs) == (1e-4, 1e-5, 8, 10)
    assert cfg.irnet.variant == "unet+deeplabv3" and cfg.irnet.input == "pseudo_nir"
    assert len(IRNET_VARIANTS) == 10


def test_json_round_trip():
    for cfg in (TrainConfig(), TrainConfig.reduced()):
        cfg.validate()
        again = TrainConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
        assert again == cfg
        assert isinstance(again.irnet.aspp_rates, tuple)


def test_partial_dict_takes_defaults_and_unknown_keys_fail():
    cfg = TrainConfig.from_dict({"seed": 3, "irnet": {"variant": "deeplabv3+unet"}})
    assert cfg.seed == 3 and cfg.irnet.variant == "deeplabv3+unet" and cfg.irnet.width == 16
    with pytest.raises(NidarError, match=r"config.irnet: wdith"):
        TrainConfig.from_dict({"irnet": {"wdith": 3}})
    with pytest.raises(NidarError, match="must be a JSON object"):
        TrainConfig.from_dict({"loss": 3})


@pytest.mark.parametrize(
    "change,message",
    [
        ({"irnet": {"variant": "resnet"}}, "unknown IRNet variant"),
        ({"irnet": {"input": "nir"}}, "unknown IRNet input"),
        ({"crop_size": 0}, "crop_size"),
        ({"device": "tpu"}, "device"),
        ({"loss": {"scales": [1.0, 2.0]}}, "scales"),
    ],
)
def test_validate(change, message):
    with pytest.raises(NidarError, match=message):
        TrainConfig.from_dict(change).validate()
