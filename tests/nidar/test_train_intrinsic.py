"""IRNet trained with the rendered frames' true reflectance and shading, and started from
given weights (pretraining on renders, fine-tuning on real frames)."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest
from safetensors.numpy import load_file

from nidar_mi.cli.train import main
from nidar_mi.errors import NidarError
from nidar_mi.nidar.config import LossConfig, TrainConfig
from nidar_mi.nidar.training import train_irnet
from nidar_mi.training_frames import list_frames
from tests.helpers.synthetic_frames import write_synthetic_dataset


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("data"), height=48, width=64)


def _cfg(**loss) -> TrainConfig:
    cfg = dataclasses.replace(TrainConfig.reduced(), device="cpu")
    cfg = dataclasses.replace(cfg, irnet=dataclasses.replace(cfg.irnet, input="rgb"))
    return dataclasses.replace(cfg, loss=dataclasses.replace(cfg.loss, **loss))


@pytest.fixture(scope="module")
def supervised(data_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("sup")
    cfg = _cfg(lambda_r_true=1.0, lambda_s_true=0.2)
    train_irnet(cfg, data_dir, out, progress=False)
    return cfg, out


def test_supervised_terms_are_logged_and_finite(supervised):
    _, out = supervised
    log = json.loads((out / "train_log.json").read_text())["irnet"]
    for step in log["steps"]:
        assert {"R_true", "S_true"} <= set(step)
        assert np.isfinite(step["R_true"]) and np.isfinite(step["S_true"])
        # R in (0, 1) and R_true clipped to [0, 1]: the mean absolute error lies in [0, 1]
        assert 0.0 <= step["R_true"] <= 1.0
    assert {"R_true", "S_true"} <= set(log["epochs"][0]["val_terms"])


def test_unsupervised_runs_log_no_supervised_terms(data_dir, tmp_path):
    train_irnet(_cfg(), data_dir, tmp_path, progress=False)
    log = json.loads((tmp_path / "train_log.json").read_text())["irnet"]
    assert not {"R_true", "S_true"} & set(log["steps"][0])


def _without_true_maps(data_dir, real):
    """A copy of the dataset whose frames carry no R_true / S_true (as real frames)."""
    for split in ("train", "val", "test"):
        (real / split).mkdir(parents=True)
        for f in list_frames(data_dir, split):
            with np.load(f) as npz:
                keep = {k: npz[k] for k in npz.files if k not in ("R_true", "S_true")}
            np.savez(real / split / f.name, **keep)
    (real / "meta.json").write_text((data_dir / "meta.json").read_text())
    return real


def test_frames_without_true_maps_are_refused(data_dir, tmp_path):
    real = _without_true_maps(data_dir, tmp_path / "real")
    with pytest.raises(NidarError, match="real frames carry no true reflectance"):
        train_irnet(_cfg(lambda_r_true=1.0), real, tmp_path / "out", progress=False)


def test_a_reflectance_target_the_frames_lack_is_refused(data_dir, tmp_path):
    old = tmp_path / "old"
    for split in ("train", "val", "test"):
        (old / split).mkdir(parents=True)
        for f in list_frames(data_dir, split):
            with np.load(f) as npz:
                keep = {k: npz[k] for k in npz.files if k != "A_true"}
            np.savez(old / split / f.name, **keep)
    (old / "meta.json").write_text((data_dir / "meta.json").read_text())
    with pytest.raises(
        NidarError, match="loss.r_target 'colour' needs rendered frames with A_true"
    ):
        train_irnet(
            _cfg(lambda_r_true=1.0, r_target="colour"), old, tmp_path / "out", progress=False
        )
    assert not (tmp_path / "out").exists()
    with pytest.raises(
        NidarError, match=r"^config\.loss\.r_target: must be one of .* \(got 'albedo'\)$"
    ):
        _cfg(lambda_r_true=1.0, r_target="albedo").validate()


def test_negative_weight_is_a_config_error():
    with pytest.raises(NidarError, match="lambda_s_true"):
        _cfg(lambda_s_true=-0.1).validate()


def test_init_weights_start_the_run_and_are_recorded(supervised, data_dir, tmp_path):
    cfg, out = supervised
    init = out / "irnet.safetensors"
    # a learning rate of 1e-30 leaves every weight where it started (Adam's steps are ~lr)
    tiny = dataclasses.replace(cfg, irnet_optim=dataclasses.replace(cfg.irnet_optim, lr=1e-30))
    tiny = dataclasses.replace(tiny, loss=LossConfig(int_warmup_epochs=1.0))
    train_irnet(tiny, data_dir, tmp_path, progress=False, init_weights=init)
    a, b = load_file(str(init)), load_file(str(tmp_path / "irnet.safetensors"))
    params = [k for k in a if "running" not in k and "num_batches" not in k]
    assert params and all(np.allclose(a[k], b[k], rtol=0, atol=1e-20) for k in params)
    record = json.loads((tmp_path / "config.json").read_text())
    assert record["data"]["init"]["sha256"] == hashlib.sha256(init.read_bytes()).hexdigest()


def test_init_weights_of_another_network_are_refused(supervised, data_dir, tmp_path):
    cfg, out = supervised
    other = dataclasses.replace(cfg, irnet=dataclasses.replace(cfg.irnet, width=6))
    with pytest.raises(NidarError, match="different network"):
        train_irnet(
            other, data_dir, tmp_path, progress=False, init_weights=out / "irnet.safetensors"
        )


def test_cli_init_irnet_needs_the_irnet_stage(supervised, data_dir, tmp_path, capsys):
    _, out = supervised
    code = main(
        [
            str(data_dir),
            str(tmp_path / "o"),
            "--reduced",
            "--init-irnet",
            str(out / "irnet.safetensors"),
        ]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "--stage irnet" in err[0]
    assert not (tmp_path / "o").exists()


def test_mixed_dataset_gives_renders_true_maps_and_real_frames_intensity(data_dir, tmp_path):
    from nidar_mi.nidar.data import IntrinsicTargets, IRNetDataset, MixedDataset

    real = _without_true_maps(data_dir, tmp_path / "real")
    real_frames, renders = list_frames(real, "train"), list_frames(data_dir, "train")
    common = dict(crop_size=16, intrinsic=IntrinsicTargets(missing_zero=True))
    a = IRNetDataset(real_frames, 255.0, **common)
    b = IRNetDataset(renders, 255.0, supervise_intensity=False, **common)
    mixed = MixedDataset(a, b)
    assert len(mixed) == len(real_frames) + len(renders)
    first, last = mixed[0], mixed[len(mixed) - 1]
    assert first.keys() == last.keys() >= {"x", "intensity", "mask", "R_true", "S_true"}
    assert float(first["R_true"].abs().max()) == 0.0  # real: no true maps
    assert float(first["mask"].sum()) > 0  # ... but its intensity
    assert float(last["R_true"].max()) > 0  # render: true maps
    assert float(last["mask"].sum()) == 0 and float(last["intensity"].sum()) == 0
    mixed.set_epoch(3)
    assert a.epoch == b.epoch == 3


def test_joint_run_with_renders(data_dir, tmp_path):
    real = _without_true_maps(data_dir, tmp_path / "real")
    renders = list_frames(data_dir, "train")
    with pytest.raises(NidarError, match="lambda_r_true"):
        train_irnet(_cfg(), real, tmp_path / "no", progress=False, render_frames=renders)
    cfg = _cfg(lambda_r_true=1.0, lambda_s_true=0.2)
    out = tmp_path / "joint"
    train_irnet(cfg, real, out, progress=False, render_frames=renders)
    record = json.loads((out / "config.json").read_text())
    assert record["data"]["renders"] == sorted(str(f) for f in renders)
    step = json.loads((out / "train_log.json").read_text())["irnet"]["steps"][-1]
    assert np.isfinite(step["R_true"]) and np.isfinite(step["int"])
    # renders must carry the true maps
    with pytest.raises(NidarError, match="real frames carry no true reflectance"):
        train_irnet(
            cfg, real, tmp_path / "x", progress=False, render_frames=list_frames(real, "train")
        )


def test_a_run_continues_only_with_the_same_inputs(supervised, data_dir, tmp_path):
    cfg, out = supervised
    init = out / "irnet.safetensors"
    run = tmp_path / "run"
    train_irnet(cfg, data_dir, run, progress=False, init_weights=init)
    # resuming without the initial weights, or with others, is refused; the record stays
    with pytest.raises(NidarError, match="other initial IRNet weights"):
        train_irnet(cfg, data_dir, run, progress=False, resume=True)
    other = tmp_path / "other.safetensors"
    other.write_bytes((run / "irnet.safetensors").read_bytes())
    with pytest.raises(NidarError, match="other initial IRNet weights"):
        train_irnet(cfg, data_dir, run, progress=False, resume=True, init_weights=other)
    record = json.loads((run / "config.json").read_text())
    assert record["data"]["init"]["sha256"] == hashlib.sha256(init.read_bytes()).hexdigest()


def test_failed_input_checks_write_nothing(data_dir, tmp_path):
    out = tmp_path / "out"
    with pytest.raises(NidarError, match="lambda_r_true"):
        train_irnet(
            _cfg(), data_dir, out, progress=False, render_frames=list_frames(data_dir, "train")
        )
    assert not out.exists()


def test_renders_smaller_than_the_crops_are_refused(data_dir, tmp_path):
    cfg = dataclasses.replace(_cfg(lambda_r_true=1.0), render_scale=0.25)  # 12 x 16 < 32 x 32
    with pytest.raises(NidarError, match="smaller than the 32x32 training crops"):
        train_irnet(
            cfg,
            data_dir,
            tmp_path / "o",
            progress=False,
            render_frames=list_frames(data_dir, "train"),
        )


def test_cli_renders_mixed_into_a_real_run(data_dir, tmp_path, capsys):
    real = _without_true_maps(data_dir, tmp_path / "real")
    config = tmp_path / "cfg.json"
    config.write_text(json.dumps({"loss": {"lambda_r_true": 1.0, "lambda_s_true": 0.2}}))
    out = tmp_path / "out"
    args = [str(real), str(out), "--reduced", "--stage", "irnet", "--input", "rgb"]
    args += ["--config", str(config), "--renders", str(data_dir), "--no-progress", "-q"]
    assert main(args) == 0
    record = json.loads((out / "config.json").read_text())
    assert record["data"]["renders"] == sorted(str(f) for f in list_frames(data_dir, "train"))
    assert (out / "irnet.safetensors").is_file() and (out / "calibration.json").is_file()
    # a folder without rendered frames: one line, status 2, nothing written
    bad = [str(real), str(tmp_path / "no"), "--reduced", "--stage", "irnet", "--input", "rgb"]
    bad += ["--config", str(config), "--renders", str(tmp_path / "none"), "-q"]
    assert main(bad) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"error: --renders: no frames in {tmp_path / 'none' / 'train'}"]
    assert not (tmp_path / "no").exists()
