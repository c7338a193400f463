"""Real-data evaluation on a KITTI-format folder written here (synthetic content)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.eval.kitti import (
    KITTI_METHODS,
    KITTI_UNAVAILABLE,
    evaluate_kitti,
    kitti_predictions,
)
from nidar_mi.io.images import write_png
from nidar_mi.io.points import write_kitti_bin
from nidar_mi.nidar.calibration import QuantileMap
from nidar_mi.nidar.config import TrainConfig
from nidar_mi.nidar.synthetic import write_synthetic_dataset

H, W, F = 48, 64, 50.0


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    from nidar_mi.nidar.dataset_calibration import fit_dataset_calibration
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.nidar.train import train

    data = write_synthetic_dataset(tmp_path_factory.mktemp("data"), height=H, width=W)
    out = tmp_path_factory.mktemp("run")
    train(dataclasses.replace(TrainConfig.reduced(), device="cpu"), data, out, progress=False)
    m = NidarModel.load(out, device="cpu")
    fit_dataset_calibration(m, data, "train").save_json(out / "calibration.json")
    return NidarModel.load(out, device="cpu")


def _numbers(a) -> str:
    return " ".join(f"{x:.12e}" for x in np.ravel(a))


@pytest.fixture(scope="module")
def kitti_dir(tmp_path_factory):
    root = tmp_path_factory.mktemp("kitti")
    for sub in ("velodyne", "image_2", "calib"):
        (root / sub).mkdir()
    P = np.array([[F, 0, W / 2, 0], [0, F, H / 2, 0], [0, 0, 1, 0]])
    Tr = np.array([[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0]], dtype=float)
    calib = f"P2: {_numbers(P)}\nR0_rect: {_numbers(np.eye(3))}\nTr_velo_to_cam: {_numbers(Tr)}\n"
    rng = np.random.default_rng(7)
    for k in range(3):
        fid = f"{k:06d}"
        n = 300
        x = rng.uniform(4.0, 40.0, n)
        xyz = np.stack([x, rng.uniform(-0.5, 0.5, n) * x, rng.uniform(-0.3, 0.3, n) * x], 1)
        xyz = np.concatenate([xyz, [[-5.0, 0.0, 0.0]]])  # behind the camera
        inten = rng.uniform(0.0, 1.0, n + 1)
        write_kitti_bin(root / "velodyne" / f"{fid}.bin", xyz.astype(np.float32), inten)
        write_png(root / "image_2" / f"{fid}.png", rng.integers(0, 256, (H, W, 3), np.uint8))
        (root / "calib" / f"{fid}.txt").write_text(calib)
    # an incomplete frame (no image, no calib) is not listed
    write_kitti_bin(root / "velodyne" / "000009.bin", np.zeros((1, 3), np.float32), np.zeros(1))
    return root


def test_rows_and_carla_by_hand(kitti_dir, model):
    from nidar_mi.datasets.kitti import load_frame

    res = evaluate_kitti(str(kitti_dir), model)
    assert res["frames"] == ["000000", "000001", "000002"]
    assert set(res["unavailable"]) == set(KITTI_UNAVAILABLE) == {"rgb_twin", "class_const"}
    methods = [k for k in KITTI_METHODS if k != "nidar_no_irnet"]  # no pseudo calibration
    assert [r["method"] for r in res["rows"] if r["scene"] == "000001"] == methods
    fr = load_frame(str(kitti_dir), "000001")
    f = kitti_predictions(fr.xyz, fr.intensity, fr.rgb, fr.camera, model)
    assert f["gt"].size < fr.xyz.shape[0]  # the point behind the camera is not evaluated
    d = np.exp(-0.004 * np.linalg.norm(f["xyz"], axis=1)) - f["gt"]
    row = next(r for r in res["rows"] if r["scene"] == "000001" and r["method"] == "carla")
    assert row["n_points"] == f["gt"].size
    assert row["point_rmse"] == pytest.approx(math.sqrt(np.mean(d**2)), rel=1e-6)
    assert row["point_mae"] == pytest.approx(np.mean(np.abs(d)), rel=1e-6)


def test_leave_one_out_uses_only_the_other_frames(kitti_dir, model):
    from nidar_mi.datasets.kitti import load_frame
    from nidar_mi.eval.kitti import loo_remap

    loaded = [load_frame(str(kitti_dir), f"{k:06d}") for k in range(3)]
    frames = [kitti_predictions(fr.xyz, fr.intensity, fr.rgb, fr.camera, model) for fr in loaded]
    loo_remap(frames, model.calibration)
    enc = [model.calibration.encode(f["raw"]["R"], f["range"]) for f in frames]
    qmap = QuantileMap.fit(np.concatenate(enc[1:]), np.concatenate([f["gt"] for f in frames[1:]]))
    np.testing.assert_allclose(frames[0]["pred"]["nidar_full_loo"], qmap(enc[0]))
    lum = [f["raw"]["luminance"] for f in frames]
    qlum = QuantileMap.fit(
        np.concatenate([lum[0], lum[2]]), np.concatenate([frames[0]["gt"], frames[2]["gt"]])
    )
    np.testing.assert_allclose(frames[1]["pred"]["luminance_loo"], qlum(lum[1]))


def test_no_frames_is_a_user_error(tmp_path, model):
    with pytest.raises(NidarError, match="no KITTI frame"):
        evaluate_kitti(str(tmp_path), model)
