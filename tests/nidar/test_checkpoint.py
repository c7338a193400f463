"""Weights and checkpoints: round trips, exact resumption of Adam, no pickle."""

from __future__ import annotations

import json
import pickle
import struct

import pytest
import torch

from nidar_mi.errors import NidarError
from nidar_mi.nidar.checkpoint import (
    latest_checkpoint,
    load_checkpoint,
    load_weights,
    prune_checkpoints,
    read_weights_metadata,
    save_checkpoint,
    save_weights,
)
from nidar_mi.nidar.unet import UNet


def _net(seed=0):
    torch.manual_seed(seed)
    return UNet(1, 1, width=4, depth=1)


def _step(net, opt, seed):
    g = torch.Generator().manual_seed(seed)
    x = torch.rand(2, 1, 8, 8, generator=g)
    loss = (net(x) - x).abs().mean()
    opt.zero_grad()
    loss.backward()
    opt.step()


def test_weights_round_trip_with_metadata(tmp_path):
    a, b = _net(0), _net(1)
    path = save_weights(tmp_path / "w.safetensors", a, {"config": '{"width": 4}'})
    assert read_weights_metadata(path) == {"config": '{"width": 4}'}
    load_weights(path, b)
    for (ka, va), (kb, vb) in zip(a.state_dict().items(), b.state_dict().items()):
        assert ka == kb and torch.equal(va, vb)
    with pytest.raises(NidarError, match="does not fit"):
        load_weights(path, UNet(1, 1, width=8, depth=1))


def test_files_are_safetensors_not_pickle(tmp_path):
    path = save_weights(tmp_path / "w.safetensors", _net())
    raw = path.read_bytes()
    (header_len,) = struct.unpack("<Q", raw[:8])
    assert json.loads(raw[8 : 8 + header_len])  # a JSON header, no pickle opcode
    evil = tmp_path / "evil.safetensors"
    evil.write_bytes(pickle.dumps({"x": 1}))
    with pytest.raises(NidarError, match="cannot read"):
        load_weights(evil, _net())


def test_checkpoint_resumes_adam_exactly(tmp_path):
    net = _net()
    opt = torch.optim.Adam(net.parameters(), lr=1e-2, weight_decay=1e-5)
    _step(net, opt, 0)
    state = {"step": 1, "epoch": 0, "batch_in_epoch": 1, "log": {"steps": [1]}}
    sidecar = save_checkpoint(tmp_path, "irnet", net, opt, state)
    assert sidecar.name == "irnet_step00000001.json"
    _step(net, opt, 1)  # the uninterrupted run continues

    net2 = _net(7)
    opt2 = torch.optim.Adam(net2.parameters(), lr=0.5)
    side = load_checkpoint(sidecar, net2, opt2)
    assert side["epoch"] == 0 and side["log"] == {"steps": [1]}
    assert opt2.param_groups[0]["lr"] == 1e-2
    _step(net2, opt2, 1)
    for va, vb in zip(net.state_dict().values(), net2.state_dict().values()):
        assert torch.equal(va, vb)


def test_checkpoint_restores_the_torch_rng(tmp_path):
    net = _net()
    opt = torch.optim.Adam(net.parameters())
    torch.manual_seed(123)
    sidecar = save_checkpoint(tmp_path, "stn", net, opt, {"step": 4})
    expected = torch.rand(3)
    torch.manual_seed(0)
    load_checkpoint(sidecar, _net(), None)
    assert torch.equal(torch.rand(3), expected)


def test_latest_and_prune(tmp_path):
    net = _net()
    opt = torch.optim.Adam(net.parameters())
    for step in (3, 10, 7):
        save_checkpoint(tmp_path, "stn", net, opt, {"step": step})
    save_checkpoint(tmp_path, "irnet", net, opt, {"step": 99})
    assert latest_checkpoint(tmp_path, "stn").name == "stn_step00000010.json"
    prune_checkpoints(tmp_path, "stn", keep=1)
    assert sorted(p.name for p in tmp_path.glob("stn_*")) == [
        "stn_step00000010.json",
        "stn_step00000010.safetensors",
    ]
    assert latest_checkpoint(tmp_path, "irnet").name == "irnet_step00000099.json"
    assert latest_checkpoint(tmp_path / "none", "stn") is None


def test_mismatched_tensor_file_is_detected(tmp_path):
    net = _net()
    opt = torch.optim.Adam(net.parameters())
    a = save_checkpoint(tmp_path, "stn", net, opt, {"step": 1})
    b = save_checkpoint(tmp_path, "stn", net, opt, {"step": 2})
    b.with_suffix(".safetensors").replace(a.with_suffix(".safetensors"))
    with pytest.raises(NidarError, match="step mismatch"):
        load_checkpoint(a, net, opt)
