"""Held-out evaluation: per-frame predictions and tables against hand-computed references.

A reduced NIDAR model is trained here on synthetic frames (two steps per stage); the frame
under test is built by hand so that every point lands on its own pixel and its own range-image
cell, which makes the map metrics equal to hand-computed point formulas.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest
from scipy.stats import spearmanr

from nidar_mi.datasets.profile_fitting import fit_split_calibration
from nidar_mi.errors import NidarError
from nidar_mi.eval.baselines import ClassConstant
from nidar_mi.eval.heldout import twin_prediction
from nidar_mi.eval.rendered import (
    METHODS,
    FrameData,
    evaluate_frame,
    mean_table,
    predict_frame,
    result_rows,
)
from nidar_mi.eval.tables import goal_check, markdown_table, write_csv, write_json
from nidar_mi.geometry import CameraModel, bilinear_sample, project
from nidar_mi.io.images import REC709_LUMA, srgb_to_linear
from nidar_mi.nidar.config import TrainConfig
from tests.helpers.synthetic_frames import write_synthetic_dataset


@pytest.fixture(scope="module")
def data_dir(tmp_path_factory):
    return write_synthetic_dataset(tmp_path_factory.mktemp("data"), height=48, width=64)


@pytest.fixture(scope="module")
def model(data_dir, tmp_path_factory):
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.nidar.training import train

    out = tmp_path_factory.mktemp("run")
    train(dataclasses.replace(TrainConfig.reduced(), device="cpu"), data_dir, out, progress=False)
    m = NidarModel.load(out, device="cpu")
    fit_split_calibration(m, data_dir, "train").mapping.save_json(out / "calibration.json")
    return NidarModel.load(out, device="cpu")


def _frame(seed: int = 0, n: int = 40) -> FrameData:
    """Points at the centres of distinct pixels, each in its own range-image cell."""
    rng = np.random.default_rng(seed)
    H, W = 48, 64
    f = 0.8 * W
    K = np.array([[f, 0, W / 2], [0, f, H / 2], [0, 0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]  # LiDAR x forward -> camera z forward
    cam = CameraModel(K, W, H, T)
    pix = rng.choice(H * W, size=n, replace=False)
    rows, cols = pix // W, pix % W
    z = rng.uniform(3.0, 60.0, n)
    p_cam = np.stack([(cols - K[0, 2]) / f * z, (rows - K[1, 2]) / f * z, z], axis=1)
    xyz = p_cam @ T[:3, :3]  # camera -> LiDAR (T has no translation)
    uv = project(xyz, cam)[0]
    rgb = rng.integers(0, 256, size=(H, W, 3), dtype=np.uint8)
    return FrameData(
        scene=f"s{seed}",
        camera="cam",
        xyz=xyz,
        range_m=np.linalg.norm(xyz, axis=1),
        gt=rng.uniform(0.0, 1.0, n),
        ring=np.arange(n) % 4,
        column=np.arange(n) // 4,
        material=np.array(["a", "b", "c", "zz"])[rng.integers(0, 4, n)],
        uv=uv,
        rgb=rgb,
        depth=np.zeros((H, W), dtype=np.float32),  # no surface: nothing hidden
        camera_model=cam,
        grid_shape=(4, 16),
    )


@pytest.fixture(scope="module")
def evaluated(model, data_dir):
    frame = _frame()
    cc = ClassConstant.fit(np.array(["a", "a", "b", "c"]), np.array([0.2, 0.4, 0.9, 0.1]))
    pcal = fit_split_calibration(model, str(data_dir), branch="pseudo_nir")
    twin = np.linspace(0.0, 1.0, frame.gt.size)
    pred = predict_frame(frame, model, class_const=cc, pseudo_calibration=pcal, twin_pred=twin)
    return frame, pred, evaluate_frame(frame, pred), pcal


def test_every_method_in_the_listed_order(evaluated):
    frame, pred, _, _ = evaluated
    assert tuple(pred) == METHODS
    for v in pred.values():
        assert v.shape == frame.gt.shape and np.all((v >= 0) & (v <= 1))


def test_baselines_by_hand(evaluated):
    frame, pred, _, _ = evaluated
    np.testing.assert_allclose(pred["carla"], np.exp(-0.004 * frame.range_m), rtol=1e-12)
    # points at pixel centres: luminance is the pixel's own Rec. 709 luminance
    r, c = np.rint(frame.uv[:, 1]).astype(int), np.rint(frame.uv[:, 0]).astype(int)
    lum = srgb_to_linear(frame.rgb[r, c].astype(np.float64) / 255.0) @ np.asarray(REC709_LUMA)
    np.testing.assert_allclose(pred["luminance"], lum, rtol=1e-9, atol=1e-12)
    expect = {"a": 0.3, "b": 0.9, "c": 0.1, "zz": 0.4}  # unseen class: global mean 1.6 / 4
    np.testing.assert_allclose(pred["class_const"], [expect[m] for m in frame.material])


def test_nidar_rows_are_the_model_outputs(evaluated, model):
    frame, pred, _, pcal = evaluated
    maps = model.predict_image(frame.rgb)
    R = bilinear_sample(maps["R"], frame.uv)
    expect = model.calibration(R, frame.range_m)
    np.testing.assert_allclose(pred["nidar_full"], expect, rtol=1e-6)
    np.testing.assert_allclose(
        pred["nidar_ihat"], np.clip(bilinear_sample(maps["I_hat"], frame.uv), 0, 1), rtol=1e-6
    )
    pn = bilinear_sample(maps["pseudo_nir"], frame.uv)
    np.testing.assert_allclose(pred["nidar_no_irnet"], pcal(pn, frame.range_m), rtol=1e-6)
    assert pcal.branch == "pseudo_nir"


@pytest.mark.parametrize("branch", ["R", "pseudo_nir"])
def test_dataset_calibration_pools_the_named_map_at_masked_pixels(model, data_dir, branch):
    from nidar_mi.profiles import fit
    from nidar_mi.training_frames import list_frames, load_meta

    scale = load_meta(data_dir)["intensity_scale"]
    preds, dists, refs = [], [], []
    for path in list_frames(data_dir, "train"):
        with np.load(path) as z:
            m = z["mask"]
            preds.append(model.predict_image(z["rgb"])[branch][m])
            dists.append(z["range"][m])
            refs.append(np.clip(z["intensity"][m].astype(np.float64) / scale, 0.0, 1.0))
    v, d, y = np.concatenate(preds), np.concatenate(dists), np.concatenate(refs)
    expect = fit("distance_quantile", v, d, y, input=branch)
    got = fit_split_calibration(model, data_dir, branch=branch)
    assert got.mapping.to_dict() == expect.to_dict() and got.branch == branch


def test_dataset_calibration_rejects_an_unknown_branch(model, data_dir):
    with pytest.raises(NidarError, match="calibration branch"):
        fit_split_calibration(model, data_dir, branch="S")


def test_carla_row_recomputed_by_hand(evaluated):
    frame, _, res, _ = evaluated
    d = np.exp(-0.004 * frame.range_m) - frame.gt
    mse = np.mean(d**2)
    rho = spearmanr(np.exp(-0.004 * frame.range_m), frame.gt).statistic
    assert res.point["carla"]["rmse"] == pytest.approx(math.sqrt(mse), rel=1e-12)
    assert res.point["carla"]["mae"] == pytest.approx(np.mean(np.abs(d)), rel=1e-12)
    assert res.point["carla"]["spearman"] == pytest.approx(rho, rel=1e-9)
    # one point per pixel and per range-image cell: map RMSE/PSNR are the point values
    assert res.camera_map["carla"]["n"] == frame.gt.size
    assert res.camera_map["carla"]["rmse"] == pytest.approx(math.sqrt(mse), rel=1e-6)
    assert res.camera_map["carla"]["medae"] == pytest.approx(np.median(np.abs(d)), rel=1e-5)
    assert res.camera_map["carla"]["psnr"] == pytest.approx(10 * math.log10(1 / mse), rel=1e-5)
    assert res.range_image["carla"]["psnr"] == pytest.approx(10 * math.log10(1 / mse), rel=1e-9)


def test_perfect_prediction_scores_perfectly(model):
    frame = _frame(1)
    pred = {"oracle": frame.gt.copy()}
    res = evaluate_frame(frame, pred)
    assert res.point["oracle"]["rmse"] == 0.0
    assert res.camera_map["oracle"]["ssim"] == pytest.approx(1.0, abs=1e-6)
    assert res.range_image["oracle"]["ssim"] == pytest.approx(1.0, abs=1e-12)
    assert res.camera_map["oracle"]["psnr"] == float("inf")


def test_twin_prediction_compensates_like_the_ground_truth():
    frame = _frame(2, n=8)
    rings, cols = (4, 16)
    twin = type(
        "Twin",
        (),
        {
            "valid": np.ones((rings, cols), bool),
            "intensity": np.full((rings, cols), 0.01, np.float32),
            "range": np.full((rings, cols), 5.0, np.float32),
            "config": type("C", (), {"intensity_mode": "raw"})(),
        },
    )()
    twin.valid[frame.ring[0], frame.column[0]] = False
    p = twin_prediction(frame, twin, intensity_scale=0.5)
    expect = np.full(8, min(0.01 * 25.0 / 0.5, 1.0))  # raw * d^2 / scale, clipped
    expect[0] = 0.0  # no twin return there
    np.testing.assert_allclose(p, expect, rtol=1e-6)


def test_tables_structure_and_means(evaluated, model, tmp_path):
    frame, pred, res, _ = evaluated
    frame2 = _frame(3)
    res2 = evaluate_frame(frame2, {k: np.clip(frame2.gt + 0.1, 0, 1) for k in ("carla", "x")})
    rows = result_rows([res, res2], "g")
    assert len(rows) == len(METHODS) + 2
    assert {r["method"] for r in rows} == set(METHODS) | {"x"}
    assert all(r["group"] == "g" and r["n_points"] == 40 for r in rows)
    mean = {r["method"]: r for r in mean_table(rows)}
    c1 = res.camera_map["carla"]["ssim"]
    c2 = res2.camera_map["carla"]["ssim"]
    assert mean["carla"]["frames"] == 2
    assert mean["carla"]["map_ssim"] == pytest.approx((c1 + c2) / 2)
    assert mean["x"]["frames"] == 1
    assert mean["carla"]["map_lpips"] is None
    # the files carry the same numbers
    write_csv(tmp_path / "r.csv", rows)
    write_json(tmp_path / "r.json", {"rows": rows, "bad": float("nan")})
    data = json.loads((tmp_path / "r.json").read_text())
    assert data["bad"] is None and data["rows"][0]["map_rmse"] == rows[0]["map_rmse"]
    header = (tmp_path / "r.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["group", "scene", "camera", "method"]


def test_markdown_and_goal_check():
    rows = [
        {"method": "nidar_full", "map_ssim": 0.5, "map_rmse": 0.2},
        {"method": "carla", "map_ssim": 0.6, "map_rmse": 0.3},
    ]
    md = markdown_table(
        rows, [("method", "m", 0), ("map_ssim", "SSIM", 3)], bold_best={"map_ssim": "max"}
    )
    assert md.splitlines()[0] == "| m | SSIM |"
    assert "| carla | **0.600** |" in md
    ssim_line, rmse_line = goal_check(rows, "nidar_full", ["carla"])
    assert "NOT ahead of carla 0.6000" in ssim_line
    assert "ahead of every baseline" in rmse_line
