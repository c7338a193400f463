"""Building networks from configuration and loading weights files."""

from __future__ import annotations

import json

import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import IRNetConfig, STNConfig, TrainConfig
from nidar_mi.nidar.model_io import (
    build_irnet,
    build_stn,
    load_irnet,
    load_pipeline,
    load_stn,
    resolve_device,
    save_irnet,
    save_stn,
)


def test_build_from_config():
    cfg = TrainConfig.reduced()
    stn, irnet = build_stn(cfg.stn), build_irnet(cfg.irnet)
    assert stn.stride == 2**cfg.stn.levels and stn.num_outputs == cfg.stn.num_outputs
    assert irnet.variant == "unet+deeplabv3" and irnet.in_channels == 1
    rgb = build_irnet(IRNetConfig(input="rgb", width=4, unet_depth=1))
    assert rgb.in_channels == 3


def test_weights_files_carry_their_configuration(tmp_path):
    torch.manual_seed(0)
    scfg = STNConfig(width=4, levels=3, num_outputs=2)
    save_stn(tmp_path / "stn.safetensors", build_stn(scfg), scfg)
    stn = load_stn(tmp_path / "stn.safetensors", device="cpu")
    assert stn.levels == 3 and not stn.training
    icfg = IRNetConfig(variant="deeplabv3+unet", width=4, unet_depth=1, output_stride=4)
    save_irnet(tmp_path / "irnet.safetensors", build_irnet(icfg), icfg)
    assert load_irnet(tmp_path / "irnet.safetensors", "cpu").variant == "deeplabv3+unet"
    with pytest.raises(NidarError, match="does not hold IRNET weights"):
        load_irnet(tmp_path / "stn.safetensors", "cpu")


def test_load_pipeline_errors(tmp_path):
    with pytest.raises(NidarError, match="config.json not found"):
        load_pipeline(tmp_path)
    (tmp_path / "config.json").write_text(json.dumps({"train": TrainConfig.reduced().to_dict()}))
    with pytest.raises(NidarError, match="irnet.safetensors not found"):
        load_pipeline(tmp_path)


def test_resolve_device():
    assert resolve_device("cpu") == torch.device("cpu")
    expected = "cuda" if torch.cuda.is_available() else "cpu"
    assert resolve_device("auto").type == expected and resolve_device(None).type == expected
    if not torch.cuda.is_available():
        with pytest.raises(NidarError, match="CUDA is not available"):
            resolve_device("cuda")
