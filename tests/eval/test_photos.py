"""The held-out photo table: scores of known predictions, the linear map on synthetic pairs."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.datasets.rgbnir import list_pairs, split_pairs
from nidar_mi.eval.baselines import LinearNIR
from nidar_mi.eval.photos import image_scores, photo_table, standard_photo_methods
from nidar_mi.io.images import linear_to_srgb, srgb_to_linear, write_png

W_TRUE = np.array([0.6, -0.2, 0.5, 0.1])  # nir = 0.6 r - 0.2 g + 0.5 b + 0.1 (linear, in (0, 1))


def test_image_scores_of_affine_and_unrelated_predictions():
    rng = np.random.default_rng(0)
    t = rng.uniform(0, 1, (40, 50))
    s = image_scores(3.0 * t + 2.0, t)
    assert s["r"] == pytest.approx(1.0) and s["ssim"] == pytest.approx(1.0)
    s = image_scores(-t, t)  # the gain may be negative: r tells the sign
    assert s["r"] == pytest.approx(-1.0) and s["ssim"] == pytest.approx(1.0)
    s = image_scores(rng.uniform(0, 1, (40, 50)), t)
    assert abs(s["r"]) < 0.1 and s["ssim"] < 0.2


@pytest.fixture()
def photos(tmp_path):
    rng = np.random.default_rng(1)
    for cat in ("a", "b", "c"):
        (tmp_path / cat).mkdir()
        for i in range(5):
            lin = rng.uniform(0.1, 0.8, (30, 40, 3))
            nir = np.clip(lin @ W_TRUE[:3] + W_TRUE[3], 0, 1)
            write_png(
                tmp_path / cat / f"{i:04d}_rgb.png",
                np.round(linear_to_srgb(lin) * 255).astype(np.uint8),
            )
            write_png(
                tmp_path / cat / f"{i:04d}_nir.png",
                np.round(linear_to_srgb(nir) * 255).astype(np.uint8),
            )
    return tmp_path


def test_linear_map_is_recovered_and_wins_the_table(photos):
    from nidar_mi.datasets.rgbnir import load_pair

    pairs = list_pairs(photos)
    split = split_pairs(pairs)
    by = {p.name: p for p in pairs}
    lin = LinearNIR.fit(load_pair(by[n]) for n in split["train"] + split["val"])
    np.testing.assert_allclose(lin.weights, W_TRUE, atol=0.01)  # 8-bit quantisation
    res = photo_table(pairs, split["test"], standard_photo_methods(lin), progress=False)
    mean = {m["method"]: m for m in res["mean"]}
    assert mean["linear"]["images"] == 3 and mean["linear"]["r"] > 0.99
    assert mean["luminance"]["r"] < mean["linear"]["r"] - 0.3
    assert set(res["per_category"]["linear"]) == {"a", "b", "c"}
    rgb, nir = load_pair(by[split["test"][0]])
    direct = image_scores(lin(rgb), srgb_to_linear(nir / 255.0))
    row = next(r for r in res["rows"] if r["method"] == "linear" and r["image"] == split["test"][0])
    assert row["r"] == pytest.approx(direct["r"])
