"""eval.heldout.render_scenes: cached renders of scene files, a failing scene named."""

from __future__ import annotations

import os
import shutil

import numpy as np
import pytest

from nidar_mi.eval.heldout import render_scenes
from nidar_mi.tasks import TasksFailed

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
TINY = {"width": "48", "height": "32", "cols": "128"}


def test_render_scenes_names_the_failing_scene_and_renders_the_others(variant, tmp_path, capsys):
    scenes = tmp_path / "scenes"
    scenes.mkdir()
    shutil.copy(os.path.join(REPO, "scenes", "street.xml"), scenes / "street.xml")
    (scenes / "empty.xml").write_text('<scene version="3.0.0"/>\n', encoding="utf-8")
    files = [str(scenes / "empty.xml"), str(scenes / "street.xml")]
    cache = tmp_path / "renders"
    with pytest.raises(TasksFailed, match=r"^1 of 2 scenes failed \(empty\)"):
        render_scenes(files, str(cache), params=TINY, spp=1)
    err = capsys.readouterr().err
    assert err.startswith("error: empty: ") and "no lidar sensor" in err
    assert (cache / "street" / "manifest.json").is_file() and not (cache / "empty").exists()
    stamp = (cache / "street" / "manifest.json").stat().st_mtime
    dirs = render_scenes(files[1:], str(cache), params=TINY, spp=1)  # cached: not rendered again
    assert dirs == [str(cache / "street")]
    assert (cache / "street" / "manifest.json").stat().st_mtime == stamp


def test_noise_free_physics_of_a_render_is_the_reference_up_to_the_receiver_noise(
    variant, tmp_path
):
    """The street LiDAR (raw mode, intensity noise σ = 2e-4 per m² of the raw value): the
    compensated reference minus ``g·ρ·cos θ`` (α = 0) is the noise scaled by d², so
    within a few σ·d² at every return and unbiased."""
    from nidar_mi.eval.rendered import load_render_frames

    (d,) = render_scenes(
        [os.path.join(REPO, "scenes", "street.xml")], str(tmp_path), params=TINY, spp=1
    )
    frames = load_render_frames(d, intensity_scale=1.0)
    assert frames and all(f.physics is not None for f in frames)
    f = max(frames, key=lambda f: len(f.gt))
    assert f.physics.shape == f.gt.shape and len(f.gt) > 50
    sigma = 2e-4 * f.range_m**2
    unclipped = (f.gt > 0) & (f.gt < 1)
    resid = (f.gt - f.physics)[unclipped] / sigma[unclipped]
    assert np.all(np.abs(resid) < 6.0)
    assert abs(resid.mean()) < 4.0 / np.sqrt(resid.size)  # the noise is zero-mean
    assert 0.5 < resid.std() < 1.5


def _result(seed: int, physics: bool):
    from nidar_mi.eval.rendered import FrameData, FrameResult

    rng = np.random.default_rng(seed)
    n = 200
    truth = rng.uniform(0.0, 1.0, n)
    gt = truth + rng.normal(0.0, 0.2, n)
    frame = FrameData(
        scene=f"s{seed}", camera="cam", xyz=np.zeros((n, 3)), range_m=np.ones(n), gt=gt,
        ring=np.zeros(n, int), column=np.arange(n), material=np.array(["seen", "new"] * (n // 2)),
        uv=np.zeros((n, 2)), rgb=np.zeros((2, 2, 3), np.uint8), depth=np.zeros((2, 2)),
        camera_model=None, grid_shape=(1, n), physics=truth if physics else None,
    )  # fmt: skip
    pred = {"half": 0.5 * truth, "random": rng.uniform(0.0, 1.0, n)}
    return FrameResult(frame, pred, {}, {}, {}, {})


def test_heldout_scores_report_the_noise_free_ceiling_apart_from_the_methods():
    from scipy.stats import spearmanr

    from nidar_mi.eval.heldout import heldout_material_scores

    res = [_result(0, True), _result(1, True)]
    h = heldout_material_scores(res, ["seen"])
    assert h["materials"] == ["new"]
    assert [m["method"] for m in h["mean"]] == ["half", "random"]
    assert {r["method"] for r in h["rows"]} == {"half", "random"}
    held = [r.frame.material == "new" for r in res]
    per = [spearmanr(r.frame.physics[k], r.frame.gt[k]).statistic for r, k in zip(res, held)]
    c = h["ceiling"]
    assert c["spearman"] == pytest.approx(np.mean(per), abs=1e-12)
    # a prediction monotone in the truth ranks exactly as the ceiling does
    half = next(m for m in h["mean"] if m["method"] == "half")
    assert half["spearman"] == pytest.approx(c["spearman"], abs=1e-12)
    assert c["n_points"] == 200 and 0.5 < c["pooled_spearman"] < 0.95
    assert (
        heldout_material_scores([_result(0, True), _result(1, False)], ["seen"])["ceiling"] is None
    )
