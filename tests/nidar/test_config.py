"""Configuration: the paper's numbers, JSON round trip, validation."""

from __future__ import annotations

import dataclasses
import json

import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import IRNET_VARIANTS, IRNetConfig, LossConfig, STNConfig, TrainConfig


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
    with pytest.raises(NidarError, match=r"^config\.irnet\.wdith: unknown key$"):
        TrainConfig.from_dict({"irnet": {"wdith": 3}})
    with pytest.raises(NidarError, match=r"^config\.loss: must be a JSON object$"):
        TrainConfig.from_dict({"loss": 3})
    with pytest.raises(NidarError, match="config must be a JSON object"):
        TrainConfig.from_dict([1, 2])


@pytest.mark.parametrize(
    "data,where",
    [
        ({"crop_size": "64"}, "config.crop_size"),
        ({"crop_size": 2.5}, "config.crop_size"),
        ({"seed": True}, "config.seed"),
        ({"irnet": {"aspp_rates": "6,12"}}, "config.irnet.aspp_rates"),
        ({"loss": {"scales": [1.0, "half"]}}, "config.loss.scales.1"),
        ({"stn_optim": {"lr": None}}, "config.stn_optim.lr"),
        ({"device": 0}, "config.device"),
    ],
)
def test_values_of_the_wrong_type_fail_with_their_key(data, where):
    with pytest.raises(NidarError, match=f"^{where}: should be") as info:
        TrainConfig.from_dict(data)
    assert "\n" not in str(info.value)


def test_every_offending_key_is_named_on_one_line():
    with pytest.raises(NidarError) as info:
        TrainConfig.from_dict({"seed": "x", "irnet": {"wdith": 3}})
    msg = str(info.value)
    assert "config.seed: should be" in msg and "config.irnet.wdith: unknown key" in msg
    assert "\n" not in msg


def test_json_numbers_fit_float_fields_and_lists_fit_tuples():
    cfg = TrainConfig.from_dict({"loss": {"gamma": 5, "scales": [1, 0.5]}})
    assert cfg.loss.gamma == 5.0 and isinstance(cfg.loss.gamma, float)
    assert cfg.loss.scales == (1.0, 0.5)
    assert TrainConfig.from_dict({"irnet_optim": {"max_steps": None}}).irnet_optim.max_steps is None


def test_from_dict_over_a_base_merges_nested_objects():
    base = TrainConfig.reduced()
    cfg = TrainConfig.from_dict({"irnet": {"variant": "unet+unet"}, "seed": 9}, base=base)
    assert cfg.irnet.variant == "unet+unet" and cfg.seed == 9
    assert cfg.irnet.width == base.irnet.width and cfg.stn == base.stn
    assert TrainConfig.from_dict({}, base=base) == base
    with pytest.raises(NidarError, match=r"config\.stn\.wdith: unknown key"):
        TrainConfig.from_dict({"stn": {"wdith": 1}}, base=base)


def test_shipped_config_json_loads():
    from nidar_mi.nidar.pipeline import shipped_weights_dir

    record = json.loads((shipped_weights_dir() / "config.json").read_text())
    cfg = TrainConfig.from_dict(record["train"])
    cfg.validate()
    written = json.loads(json.dumps(cfg.to_dict()))
    default = json.loads(json.dumps(TrainConfig().to_dict()))

    def check(written, recorded, default):
        # the recorded settings are kept; settings added after the shipped model was trained
        # (at any depth) take their defaults
        for k, v in written.items():
            if k not in recorded:
                assert v == default[k], k
            elif isinstance(v, dict):
                check(v, recorded[k], default[k])
            else:
                assert v == recorded[k], k
        assert set(recorded) <= set(written)

    check(written, record["train"], default)


@pytest.mark.parametrize(
    "change,message",
    [
        # a choice: every allowed value and the one given
        (
            {"irnet": {"variant": "resnet"}},
            "config.irnet.variant: must be one of " + ", ".join(IRNET_VARIANTS) + " (got 'resnet')",
        ),
        (
            {"irnet": {"input": "nir"}},
            "config.irnet.input: must be one of pseudo_nir, rgb, rgb+pseudo_nir, "
            "chroma+pseudo_nir (got 'nir')",
        ),
        (
            {"stn": {"kind": "nope"}},
            "config.stn.kind: must be one of cs_stereo, lowres (got 'nope')",
        ),
        (
            {"loss": {"r_target": "albedo"}},
            "config.loss.r_target: must be one of monostatic, surface, colour (got 'albedo')",
        ),
        (
            {"irnet_optim": {"schedule": "cosine"}},
            "config.irnet_optim.schedule: must be one of constant, onecycle (got 'cosine')",
        ),
        (
            {"irnet": {"output_stride": 3}},
            "config.irnet.output_stride: must be one of 2, 4, 8, 16, 32 (got 3)",
        ),
        # an interval: both bounds, open or closed, and the value given
        ({"scale": 1.5}, r"config.scale: must lie in (0, 1] (got 1.5)"),
        ({"render_scale": 0.0}, r"config.render_scale: must lie in (0, 1] (got 0)"),
        ({"photos": {"zoom_min": 0}}, r"config.photos.zoom_min: must lie in (0, 1] (got 0)"),
        (
            {"photos": {"render_fraction": 2}},
            "config.photos.render_fraction: must lie in [0, 1] (got 2)",
        ),
        ({"loss": {"scales": [1.0, 2.0]}}, "config.loss.scales.1: must lie in (0, 1] (got 2)"),
        ({"seed": -1}, "config.seed: must lie in [0, 4294967295] (got -1)"),
        # one bound
        ({"crop_size": 0}, "config.crop_size: must be >= 1 (got 0)"),
        ({"crop_width": 0}, "config.crop_width: must be >= 1 (got 0)"),
        ({"stn_optim": {"max_steps": 0}}, "config.stn_optim.max_steps: must be >= 1 (got 0)"),
        ({"irnet_optim": {"lr": 0}}, "config.irnet_optim.lr: must be > 0 (got 0)"),
        ({"loss": {"lambda_s_true": -0.1}}, "config.loss.lambda_s_true: must be >= 0 (got -0.1)"),
        # a pattern
        ({"device": "tpu"}, r"config.device: must match ^(auto|cpu|cuda(:\d+)?)$ (got 'tpu')"),
        # a rule between two fields
        (
            {"stn": {"levels": 3, "num_outputs": 4}},
            "config.stn: num_outputs must lie in [1, levels] = [1, 3] (got 4)",
        ),
    ],
)
def test_a_bad_value_is_one_line_naming_key_allowed_values_and_value(change, message):
    with pytest.raises(NidarError) as info:
        TrainConfig.from_dict(change)
    assert str(info.value) == message


@pytest.mark.parametrize(
    "change",
    [
        {"scale": 1.5},
        {"irnet": IRNetConfig(variant="resnet")},
        {"stn": STNConfig(levels=2, num_outputs=3)},
        {"loss": LossConfig(scales=(1.0, 0.0))},
        {"seed": 2**32},
    ],
)
def test_validate_checks_a_config_built_in_python_as_from_dict_does(change):
    cfg = dataclasses.replace(TrainConfig(), **change)
    with pytest.raises(NidarError) as built:
        cfg.validate()
    with pytest.raises(NidarError) as read:
        TrainConfig.from_dict(json.loads(json.dumps(cfg.to_dict())))
    assert str(built.value) == str(read.value) and "\n" not in str(built.value)


def test_validate_refuses_what_json_cannot_carry():
    with pytest.raises(
        NidarError, match=r"^config\.loss\.gamma: should be a finite number \(got nan\)$"
    ):
        dataclasses.replace(TrainConfig(), loss=LossConfig(gamma=float("nan"))).validate()
    with pytest.raises(
        NidarError, match=r"^config\.crop_size: should be a valid integer \(got 2\.5\)$"
    ):
        dataclasses.replace(TrainConfig(), crop_size=2.5).validate()
