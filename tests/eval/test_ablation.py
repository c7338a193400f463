"""Ablations: shared settings, scores by hand, table structure, finished runs reused."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nidar_mi.eval.ablation import AblationSettings, ablation_config, map_scores, run_ablation
from tests.helpers.synthetic_frames import write_synthetic_dataset


def test_config_carries_the_settings():
    s = AblationSettings(width=6, crop_size=48, batch_size=4, epochs=3, lr=2e-3)
    cfg = ablation_config(s, "deeplabv3+unet", "rgb")
    assert (cfg.irnet.variant, cfg.irnet.input, cfg.irnet.width) == ("deeplabv3+unet", "rgb", 6)
    assert (cfg.crop_size, cfg.irnet_optim.batch_size, cfg.irnet_optim.epochs) == (48, 4, 3)
    assert cfg.irnet_optim.lr == 2e-3 and cfg.loss.int_warmup_epochs == s.int_warmup_epochs


def test_map_scores_by_hand():
    gt = np.array([[0.0, 0.2], [0.4, 1.0]])
    pred = np.array([[0.1, 0.2], [0.1, 1.5]])  # 1.5 is clipped to 1
    mask = np.array([[True, True], [True, False]])
    s = map_scores(pred, gt, mask)
    assert s["mae"] == pytest.approx((0.1 + 0.0 + 0.3) / 3)
    mse = (0.01 + 0.0 + 0.09) / 3
    assert s["rmse"] == pytest.approx(math.sqrt(mse))
    assert s["psnr"] == pytest.approx(10 * math.log10(1 / mse))
    assert map_scores(gt, gt, mask)["ssim"] == pytest.approx(1.0)


def test_tables_and_reuse(tmp_path):
    from nidar_mi.nidar.config import TrainConfig
    from nidar_mi.nidar.model_io import build_stn, save_stn

    counts = {"train": 2, "val": 1, "test": 1}
    data = write_synthetic_dataset(tmp_path / "data", counts, height=32, width=32)
    stn_path = tmp_path / "stn.safetensors"
    save_stn(stn_path, build_stn(TrainConfig.reduced().stn), TrainConfig.reduced().stn)
    s = AblationSettings(width=4, crop_size=32, batch_size=2, epochs=1)
    variants = ("unet+deeplabv3",)
    res = run_ablation(data, tmp_path / "abl", stn_path, s, variants=variants)
    assert [r["variant"] for r in res["structural"]] == list(variants)
    assert [(r["input"], r["output"], r["post"]) for r in res["input"]] == [
        (i, o, p)
        for i in ("pseudo-NIR", "RGB")
        for o, p in (("Î", "raw"), ("R", "raw"), ("R", "remapped"))
    ]
    for r in res["structural"] + res["input"]:
        assert np.isfinite(r["val_loss"]) and 0 <= r["mae"] <= r["rmse"] <= 1
    # the paper's variant is the same run in both tables
    paper = next(r for r in res["structural"] if r["variant"] == "unet+deeplabv3")
    assert paper["mae"] == res["input"][0]["mae"]
    weights = tmp_path / "abl" / "pseudo_nir__unet+deeplabv3" / "irnet.safetensors"
    stamp = weights.stat().st_mtime_ns
    again = run_ablation(data, tmp_path / "abl", stn_path, s, variants=variants)
    assert weights.stat().st_mtime_ns == stamp and again["structural"] == res["structural"]
