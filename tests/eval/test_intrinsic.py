"""Scores of a decomposition against the true reflectance and shading (analytic cases)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.eval.intrinsic import intrinsic_frame_scores, intrinsic_scores


def _maps(seed=0, shape=(20, 30)):
    rng = np.random.default_rng(seed)
    r_true = rng.uniform(0.05, 0.9, shape).astype(np.float32)
    r_true[:3] = 0.0  # sky rows: left out
    s_true = rng.uniform(0.1, 2.0, shape).astype(np.float32)
    return r_true, s_true


def test_true_reflectance_as_prediction():
    r_true, s_true = _maps()
    image = r_true * s_true
    maps = {"R": r_true, "S": s_true, "pseudo_nir": image}
    out = intrinsic_frame_scores(maps, r_true, s_true)
    valid = r_true >= 1e-3
    assert out["pixels"] == valid.sum() == 17 * 30
    assert out["r_R_reflectance"] == pytest.approx(1.0)
    assert out["spearman_R_reflectance"] == pytest.approx(1.0)
    # a perfect R correlates with the shading exactly as the true maps do
    expected = np.corrcoef(r_true[valid], s_true[valid])[0, 1]
    assert out["r_R_shading"] == pytest.approx(expected, abs=1e-9)
    assert out["r_true_shading"] == pytest.approx(expected, abs=1e-9)
    assert out["r_input_shading"] == pytest.approx(
        np.corrcoef(image[valid], s_true[valid])[0, 1], abs=1e-9
    )


def test_reflectance_that_carries_the_shading():
    r_true, s_true = _maps(1)
    maps = {"R": s_true * 0.1, "S": np.ones_like(s_true), "pseudo_nir": s_true}
    out = intrinsic_frame_scores(maps, r_true, s_true)
    assert out["r_R_shading"] == pytest.approx(1.0)
    assert np.isnan(out["r_R_S"])  # a constant S has no correlation
    assert abs(out["r_R_reflectance"]) < 0.1  # independent draws


def test_retroreflectors_are_clipped_like_in_training():
    r_true, s_true = _maps(2)
    hot = r_true.copy()
    hot[5, 5] = 400.0
    maps = {"R": np.clip(hot, 0, 1), "S": s_true, "pseudo_nir": s_true}
    assert intrinsic_frame_scores(maps, hot, s_true)["r_R_reflectance"] == pytest.approx(1.0)


def test_shape_mismatch_and_empty_frames_are_errors():
    r_true, s_true = _maps()
    with pytest.raises(NidarError, match="shape"):
        intrinsic_frame_scores({"R": r_true[1:], "S": s_true, "pseudo_nir": s_true}, r_true, s_true)
    zero = np.zeros_like(r_true)
    with pytest.raises(NidarError, match="no pixel"):
        intrinsic_frame_scores({"R": r_true, "S": s_true, "pseudo_nir": s_true}, zero, s_true)


def test_scores_over_frame_files(tmp_path):
    from nidar_mi.training_frames import list_frames, load_frame
    from tests.helpers.synthetic_frames import write_synthetic_dataset

    data = write_synthetic_dataset(tmp_path / "d", height=24, width=32)
    frames = list_frames(data, "test")

    class Oracle:  # predicts the frame's own true maps
        scale = 1.0

        def __init__(self):
            self.arrays = {}

        def predict_image(self, rgb, scale=None):
            key = rgb.tobytes()
            return self.arrays[key]

    oracle = Oracle()
    for f in frames:
        a = load_frame(f, ("rgb", "R_true", "S_true"))
        oracle.arrays[a["rgb"].tobytes()] = {
            "R": np.clip(a["R_true"], 0, 1),
            "S": a["S_true"],
            "pseudo_nir": a["R_true"] * a["S_true"],
        }
    out = intrinsic_scores(oracle, frames)
    assert [r["frame"] for r in out["rows"]] == [f.stem for f in frames]
    assert out["mean"]["r_R_reflectance"] == pytest.approx(1.0)
    assert out["mean"]["r_R_shading"] == pytest.approx(out["mean"]["r_true_shading"])
    assert out["scale"] == 1.0
