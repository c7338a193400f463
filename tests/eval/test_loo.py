"""The leave-one-frame-out protocol and the scan metrics, with methods of known behaviour."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.datasets.scans import ScanFrame
from nidar_mi.errors import NidarError
from nidar_mi.eval.loo import LooMethod, leave_one_out, profile_method, raw_method
from nidar_mi.eval.scan_metrics import binned_spearman, range_image, scan_metrics
from nidar_mi.geometry import CameraModel


def _camera():
    T = np.eye(4)
    T[:3, :3] = [[0, -1, 0], [0, 0, -1], [1, 0, 0]]
    K = np.array([[200.0, 0, 159.5], [0, 200.0, 59.5], [0, 0, 1]])
    return CameraModel(K=K, width=320, height=120, T_cam_lidar=T, name="cam")


def scan(name: str, seed: int) -> ScanFrame:
    """Returns on a wall 20 m ahead and the ground, 16 rings x 400 columns over ±35°."""
    rng = np.random.default_rng(seed)
    el = np.radians(np.linspace(2, -15, 16))
    az = np.radians(np.linspace(-35, 35, 400))
    e, a = np.meshgrid(el, az, indexing="ij")
    d = np.stack([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)], -1).reshape(-1, 3)
    t = np.full(len(d), 20.0 / np.maximum(d[:, 0], 1e-3))
    down = d[:, 2] < 0
    t[down] = np.minimum(t[down], 1.7 / -d[down, 2])
    xyz = d * t[:, None]
    ring = np.repeat(np.arange(16), 400).astype(np.int16)
    surface = (np.floor(a.reshape(-1) * 8) % 3) / 3 + 0.2  # vertical stripes
    inten = np.clip(surface * np.exp(-t / 30) + rng.normal(0, 0.01, len(t)), 0, 1)
    img = np.zeros((120, 320, 3), np.uint8)
    return ScanFrame(name, xyz, inten, ring, [_camera()], _images=lambda: [img])


def test_scan_metrics_of_the_truth_and_its_reverse():
    s = scan("a", 0)
    m = scan_metrics(s, s.intensity)
    assert m["spearman"] == pytest.approx(1.0) and m["rmse"] == 0.0
    assert m["ssim_cam"] == pytest.approx(1.0) and m["ssim_ri"] == pytest.approx(1.0)
    assert m["spearman_bin"] == pytest.approx(1.0)
    r = scan_metrics(s, 1.0 - s.intensity)
    assert r["spearman"] == pytest.approx(-1.0) and r["spearman_bin"] == pytest.approx(-1.0)
    with pytest.raises(NidarError, match="non-finite"):
        scan_metrics(s, np.full(len(s.intensity), np.nan))


def test_binned_spearman_separates_ranking_from_range_response():
    rng = np.random.default_rng(1)
    d = rng.uniform(0, 40, 5000)
    gt = rng.uniform(0, 1, 5000)
    pred = gt + 10 * np.floor(d / 2)  # right order within each 2 m bin, bins shifted apart
    pred_rev = -np.floor(d / 2) * 10 + gt  # ... and in reverse order of the bins
    assert binned_spearman(pred, gt, d) == pytest.approx(1.0)
    assert binned_spearman(pred_rev, gt, d) == pytest.approx(1.0)
    from nidar_mi.eval.metrics import spearman

    assert abs(spearman(pred_rev, gt)) < 0.2
    # bins with fewer than 50 returns do not count
    assert np.isnan(binned_spearman(pred[:40], gt[:40], d[:40] * 0))


def test_range_image_rows_are_rings_and_nearest_wins():
    s = scan("a", 0)
    imgs, mask = range_image(s.xyz, s.ring, {"v": s.intensity})
    assert mask.shape[0] == 16 and mask.sum() <= len(s.xyz)
    no_ring = range_image(s.xyz, np.full(len(s.xyz), -1), {"v": s.intensity})[1]
    assert no_ring.shape[0] == 64  # elevation rows when rings are unknown


def test_leave_one_out_never_scores_a_frame_a_method_was_fitted_on():
    scans = [scan(f"f{k}", k) for k in range(5)]
    seen = []

    def fit(train):
        seen.append(sorted(s.name for s in train))
        return lambda s: s.intensity  # an oracle

    methods = {
        "oracle": LooMethod("oracle", fit),
        "reverse": raw_method("reverse", lambda s: 1.0 - s.intensity),
    }
    res = leave_one_out(scans, ["f1", "f3"], methods, progress=False)
    assert seen == [["f0", "f2", "f3", "f4"], ["f0", "f1", "f2", "f4"]]
    mean = {m["method"]: m for m in res["mean"]}
    assert mean["oracle"]["spearman"] == pytest.approx(1.0) and mean["oracle"]["folds"] == 2
    assert mean["reverse"]["spearman"] == pytest.approx(-1.0)
    assert [(r["frame"], r["method"]) for r in res["rows"]] == [
        ("f1", "oracle"),
        ("f1", "reverse"),
        ("f3", "oracle"),
        ("f3", "reverse"),
    ]
    with pytest.raises(NidarError, match="not among"):
        leave_one_out(scans, ["x"], methods, progress=False)


@pytest.mark.parametrize("form", ["range_ring", "gbm"])
def test_a_profile_method_learns_the_range_response_from_the_other_frames(form):
    scans = [scan(f"f{k}", k) for k in range(4)]
    surface = {s.name: np.clip(s.intensity / np.exp(-s.range_m / 30), 0, 1) for s in scans}
    m = profile_method(
        f"true surface + {form}", lambda s: surface[s.name], form=form, input="truth"
    )
    res = leave_one_out(scans, ["f0", "f2"], {"p": m}, progress=False)
    (mean,) = res["mean"]
    assert mean["spearman"] > 0.95 and mean["rmse"] < 0.03


def test_a_geometry_only_gbm_profile_gets_the_range_response_but_not_the_surfaces():
    """The stripes' intensity depends on the surface, not only on the geometry: a profile of
    range and elevation alone predicts each return's mean over surfaces at its geometry."""
    scans = [scan(f"f{k}", k) for k in range(4)]
    m = profile_method(
        "geometry", lambda s: np.zeros(len(s.xyz)), form="gbm", input="constant", use_value=False
    )
    res = leave_one_out(scans, ["f1"], {"g": m}, progress=False)
    s = scans[1]
    pred = m.fit(scans[:1] + scans[2:])(s)
    mean_surface = np.mean([0.2, 0.2 + 1 / 3, 0.2 + 2 / 3])
    expected = mean_surface * np.exp(-s.range_m / 30)
    assert np.abs(pred - expected).mean() < 0.03
    (row,) = res["mean"]
    assert row["spearman"] < 0.95  # the surfaces' ranking within a range is not there
