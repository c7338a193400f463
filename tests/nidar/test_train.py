"""The real training loop with the reduced configuration: outputs, determinism, resume, CLI."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from safetensors.numpy import load_file

from nidar_mi.cli.train import main
from nidar_mi.errors import NidarError
from nidar_mi.nidar.checkpoint import latest_checkpoint
from nidar_mi.nidar.config import TrainConfig
from nidar_mi.nidar.infer import predict
from nidar_mi.nidar.model_io import load_pipeline
from nidar_mi.nidar.training import train, train_irnet, train_stn
from nidar_mi.training_frames import list_frames, load_frame
from tests.helpers.synthetic_frames import write_synthetic_dataset


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("data"), height=48, width=64)


@pytest.fixture(scope="module")
def trained(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    cfg = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    paths = train(cfg, data_dir, out, progress=False)
    return cfg, out, paths


def _same_weights(a, b) -> bool:
    ta, tb = load_file(str(a)), load_file(str(b))
    return ta.keys() == tb.keys() and all(np.array_equal(ta[k], tb[k]) for k in ta)


def test_two_iteration_run_writes_everything(trained, data_dir):
    cfg, out, paths = trained
    assert paths == {"stn": out / "stn.safetensors", "irnet": out / "irnet.safetensors"}
    for name in ("stn.safetensors", "irnet.safetensors", "config.json", "train_log.json"):
        assert (out / name).is_file()
    log = json.loads((out / "train_log.json").read_text())
    for stage in ("stn", "irnet"):
        assert [s["step"] for s in log[stage]["steps"]] == [1, 2]
        assert log[stage]["done"] is True
        (epoch,) = log[stage]["epochs"]
        assert np.isfinite(epoch["val_loss"]) and np.isfinite(epoch["train_loss"])
    # lambda_int warm-up over one epoch of two steps: factors 1/2, then 1.
    assert [s["int_factor"] for s in log["irnet"]["steps"]] == [0.5, 1.0]
    assert set(log["irnet"]["epochs"][0]["val_terms"]) == {"recon", "R", "S", "med", "int"}
    record = json.loads((out / "config.json").read_text())
    assert TrainConfig.from_dict(record["train"]) == cfg
    assert record["data"]["intensity_scale"] == 255.0


def test_load_pipeline_and_predict_any_size(trained, data_dir):
    cfg, out, _ = trained
    stn, irnet, loaded = load_pipeline(out, device="cpu")
    assert loaded == cfg and not stn.training and not irnet.training
    rgb = load_frame(list_frames(data_dir, "test")[0], ("rgb",))["rgb"][:45, :61]
    result = predict(stn, irnet, rgb)
    assert set(result) == {"pseudo_nir", "R", "S", "I_hat"}
    for value in result.values():
        assert value.shape == (45, 61) and value.dtype == np.float32
        assert np.all(np.isfinite(value))
    assert 0 < result["R"].min() and result["R"].max() < 1


def test_same_seed_same_weights(trained, data_dir, tmp_path):
    cfg, out, _ = trained
    train(cfg, data_dir, tmp_path, progress=False)
    assert _same_weights(out / "stn.safetensors", tmp_path / "stn.safetensors")
    assert _same_weights(out / "irnet.safetensors", tmp_path / "irnet.safetensors")


def test_resume_continues_exactly(data_dir, tmp_path):
    base = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    four = dataclasses.replace(
        base, stn_optim=dataclasses.replace(base.stn_optim, epochs=2, max_steps=None)
    )
    train_stn(four, data_dir, tmp_path / "straight", progress=False)
    # Interrupted after 1 step (mid-epoch), then resumed to the end: same weights, same log.
    one = dataclasses.replace(four, stn_optim=dataclasses.replace(four.stn_optim, max_steps=1))
    train_stn(one, data_dir, tmp_path / "resumed", progress=False)
    with pytest.raises(NidarError, match="resume it"):
        train_stn(four, data_dir, tmp_path / "resumed", progress=False)
    train_stn(four, data_dir, tmp_path / "resumed", resume=True, progress=False)
    assert _same_weights(
        tmp_path / "straight/stn.safetensors", tmp_path / "resumed/stn.safetensors"
    )
    logs = [
        json.loads((tmp_path / d / "train_log.json").read_text())["stn"]
        for d in ("straight", "resumed")
    ]
    assert [s["loss"] for s in logs[0]["steps"]] == [s["loss"] for s in logs[1]["steps"]]
    assert len(logs[0]["steps"]) == 4
    # A different model in the same directory is refused.
    other = dataclasses.replace(four, seed=1)
    with pytest.raises(NidarError, match="different configuration"):
        train_stn(other, data_dir, tmp_path / "resumed", resume=True, progress=False)


def test_fresh_run_discards_stale_checkpoints(data_dir, tmp_path):
    stale = tmp_path / "checkpoints" / "stn_step00000099.json"
    stale.parent.mkdir(parents=True)
    stale.write_text("{}")
    cfg = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    train_stn(cfg, data_dir, tmp_path, progress=False)
    assert latest_checkpoint(tmp_path / "checkpoints", "stn").name == "stn_step00000002.json"


def test_rgb_variant_needs_no_stn(data_dir, tmp_path):
    base = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    cfg = dataclasses.replace(base, irnet=dataclasses.replace(base.irnet, input="rgb"))
    paths = train(cfg, data_dir, tmp_path, progress=False)
    assert set(paths) == {"irnet"} and not (tmp_path / "stn.safetensors").exists()
    stn, irnet, _ = load_pipeline(tmp_path, device="cpu")
    assert stn is None and irnet.in_channels == 3
    rgb = load_frame(list_frames(data_dir, "test")[0], ("rgb",))["rgb"]
    assert set(predict(None, irnet, rgb)) == {"R", "S", "I_hat"}


def test_pseudo_nir_irnet_without_stn_is_a_user_error(data_dir, tmp_path):
    cfg = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    with pytest.raises(NidarError, match="needs STN weights"):
        train_irnet(cfg, data_dir, tmp_path, progress=False)


def test_cli_reuses_a_trained_stn(trained, data_dir, tmp_path, capsys):
    _, out, _ = trained
    argv = [str(data_dir), str(tmp_path), "--reduced", "--device", "cpu", "--no-progress", "-q"]
    code = main(
        argv + ["--variant", "DeepLabV3+3Conv", "--stn-weights", str(out / "stn.safetensors")]
    )
    assert code == 0
    assert _same_weights(out / "stn.safetensors", tmp_path / "stn.safetensors")
    _, irnet, cfg = load_pipeline(tmp_path, device="cpu")
    assert cfg.irnet.variant == "deeplabv3+3conv" and irnet.head is not None


def test_cli_user_errors_are_one_line(tmp_path, capsys):
    code = main([str(tmp_path / "missing"), str(tmp_path / "out"), "--reduced", "-q"])
    err = capsys.readouterr().err
    assert (
        code == 2 and err.count("\n") == 1 and err.startswith("error:") and "Traceback" not in err
    )
    code = main([str(tmp_path), str(tmp_path / "out"), "--variant", "resnet", "-q"])
    err = capsys.readouterr().err
    assert code == 2 and "config.irnet.variant: must be one of unet, " in err
    assert err.count("\n") == 1 and err.rstrip().endswith("(got 'resnet')")
    assert not (tmp_path / "out").exists()


def test_cli_config_file_merges_over_the_reduced_config(tmp_path):
    from nidar_mi.cli.train import _parser, build_config

    path = tmp_path / "cfg.json"
    path.write_text(json.dumps({"irnet": {"variant": "unet+unet"}, "seed": 4}))
    args = _parser().parse_args(["d", "o", "--reduced", "--config", str(path), "--max-steps", "7"])
    cfg = build_config(args)
    reduced = TrainConfig.reduced()
    assert cfg.irnet.variant == "unet+unet" and cfg.seed == 4
    assert cfg.irnet.width == reduced.irnet.width and cfg.crop_size == reduced.crop_size
    assert cfg.stn_optim.max_steps == cfg.irnet_optim.max_steps == 7


def test_cli_config_file_errors_name_the_file_and_the_key(tmp_path, capsys):
    from nidar_mi.cli.train import main

    path = tmp_path / "cfg.json"
    path.write_text(json.dumps({"irnet": {"wdith": 4}, "seed": "one"}))
    code = main([str(tmp_path), str(tmp_path / "out"), "--config", str(path), "-q"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1
    assert str(path) in err and "config.irnet.wdith: unknown key" in err and "config.seed" in err
    assert not (tmp_path / "out").exists()


def test_cli_fits_calibration_and_pipeline_runs(trained, data_dir, tmp_path):
    """The CLI writes calibration.json; the whole pipeline then maps points to [0, 1]."""
    from nidar_mi.geometry import CameraModel
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.profiles import DistanceQuantileMap

    _, out, _ = trained
    argv = [str(data_dir), str(tmp_path), "--reduced", "--device", "cpu", "--no-progress", "-q"]
    assert main(argv + ["--stn-weights", str(out / "stn.safetensors")]) == 0
    calib = DistanceQuantileMap.load_json(tmp_path / "calibration.json")
    knots = calib.quantile_map.q_source
    assert np.all(np.diff(knots) > 0)  # strictly increasing knots
    model = NidarModel.load(tmp_path, device="cpu")
    (frame,) = list_frames(data_dir, "val")[:1]
    f = load_frame(frame)
    cam = CameraModel(f["K"], f["rgb"].shape[1], f["rgb"].shape[0], f["T_cam_lidar"])
    # points straight ahead of the camera at 5-20 m, and one behind the LiDAR (never observed)
    xyz = np.array([[5.0, 0.3, 0.0], [12.0, -0.5, 0.4], [20.0, 2.5, -0.3], [-5.0, 0.0, 0.0]])
    res = model.point_intensity(xyz, [cam], [f["rgb"]])
    assert res.observed.tolist() == [True, True, True, False]
    assert np.all((res.intensity >= 0) & (res.intensity <= 1)) and res.intensity[3] == 0
    # deterministic: the same inputs give the same output
    res2 = model.point_intensity(xyz, [cam], [f["rgb"]])
    np.testing.assert_array_equal(res.intensity, res2.intensity)


@pytest.mark.parametrize("verbose", [False, True])
def test_cli_epoch_lines_only_with_verbose(data_dir, tmp_path, capsys, verbose):
    """Training logs its start and end at INFO; one line per epoch only with ``-v`` (DEBUG)."""
    argv = [str(data_dir), str(tmp_path / "w"), "--reduced", "--device", "cpu", "--stage", "stn"]
    assert main(argv + (["-v"] if verbose else [])) == 0
    err = capsys.readouterr().err
    assert "steps of batch" in err and "weights written" in err
    assert ("epoch 0, step" in err) is verbose
    assert "%|" not in err  # stderr is not a terminal: no progress bar
