"""Sensor profiles: the file format, its validation, both forms, the named profiles."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.pipeline import NidarModel
from nidar_mi.nidar.profile import PROFILE_SCHEMA, fit_profile, load_profile
from nidar_mi.nidar.profiles import model_identity, resolve_profile


def _data(n=20_000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.uniform(0, 1, n)
    d = rng.uniform(2, 60, n)
    ring = rng.integers(0, 8, n)
    el = -2.0 * ring
    ref = np.clip(v * np.exp(-d / 30) * (0.8 + 0.05 * ring), 0, 1)
    return v, d, ring, el, ref


@pytest.mark.parametrize("form", ["distance_quantile", "range_ring", "gbm"])
def test_round_trip_through_a_file(tmp_path, form):
    v, d, ring, el, ref = _data()
    p = fit_profile(
        v,
        d,
        ref,
        form=form,
        name="test-1",
        sensor="x",
        input="nidar:R",
        ring=ring,
        elevation_deg=el,
    )
    path = tmp_path / "p.json"
    p.save(path)
    data = json.loads(path.read_text())
    assert (
        data["schema"] == PROFILE_SCHEMA
        and data["form"] == form
        and "schema" not in data["mapping"]
    )
    q = load_profile(path)
    out = p.apply(v[:1000], d[:1000], ring[:1000], el[:1000])
    assert out.dtype == np.float32 and ((out >= 0) & (out <= 1)).all()
    np.testing.assert_array_equal(q.apply(v[:1000], d[:1000], ring[:1000], el[:1000]), out)
    assert q.branch == "R"


def test_distance_quantile_is_the_paper_calibration():
    from nidar_mi.nidar.calibration import fit_calibration

    v, d, _, _, ref = _data()
    p = fit_profile(v, d, ref, form="distance_quantile", name="p", sensor="", input="nidar:R")
    cal = fit_calibration(v, d, ref)
    np.testing.assert_allclose(p.apply(v, d), cal.apply(v, d)[0], rtol=1e-6)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d | {"schema": "other/1"}, "'schema' must be"),
        (lambda d: d | {"form": "cubic"}, "'form' must be one of"),
        (lambda d: {k: v for k, v in d.items() if k != "mapping"}, "missing field"),
        (lambda d: d | {"extra": 1}, "unknown field"),
        (lambda d: d | {"name": "has space"}, "profile name"),
        (lambda d: d | {"mapping": {"gains": [1]}}, "'mapping'"),
        (
            lambda d: (
                d | {"mapping": d["mapping"] | {"gains": [-1.0] * len(d["mapping"]["gains"])}}
            ),
            "gains",
        ),
        (lambda d: d | {"model": [1]}, "'model' must be"),
    ],
)
def test_invalid_files_are_one_line_errors(tmp_path, edit, message):
    v, d, ring, el, ref = _data(5000)
    good = fit_profile(
        v,
        d,
        ref,
        form="range_ring",
        name="g",
        sensor="",
        input="nidar:R",
        ring=ring,
        elevation_deg=el,
    )
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(edit(good.to_dict())))
    with pytest.raises(NidarError, match=message) as info:
        load_profile(path)
    assert str(path) in str(info.value) and "\n" not in str(info.value)


def test_unreadable_files(tmp_path):
    with pytest.raises(NidarError, match="no such profile"):
        load_profile(tmp_path / "none.json")
    (tmp_path / "x.json").write_text("{not json")
    with pytest.raises(NidarError, match="not valid JSON"):
        load_profile(tmp_path / "x.json")


def test_non_finite_values_are_an_error_not_nan():
    v, d, _, _, ref = _data(5000)
    p = fit_profile(v, d, ref, form="range_ring", name="p", sensor="", input="nidar:R")
    with pytest.raises(NidarError, match="finite"):
        p.apply([0.5, np.nan], [10.0, 10.0])


def test_sim_905_is_the_weights_profile_or_their_calibration(tmp_path):
    """The shipped weights carry ``profiles/sim-905.json`` (a gbm profile of R and the
    incidence, the form of the compensated intensity g·ρ·cos θ, which it ranks like ρ·cos θ
    over R's range); a weights folder without one maps R through its ``calibration.json``."""
    import shutil

    from scipy.stats import spearmanr

    model = NidarModel.load(device="cpu")
    p = resolve_profile("sim-905", model)
    assert p.form == "gbm" and p.branch == "R" and p.model == model_identity(model)
    assert p.uses_incidence and p.mapping.features == ("v", "cos_incidence")
    r, c = (g.ravel() for g in np.meshgrid(np.linspace(0.3, 0.6, 16), np.linspace(0.1, 1, 19)))
    assert spearmanr(p.apply(r, np.full(r.size, 10.0), None, None, c), r * c).statistic > 0.9
    plain = tmp_path / "w"
    shutil.copytree(model.weights_dir, plain, ignore=shutil.ignore_patterns("profiles"))
    other = NidarModel.load(plain, device="cpu")
    q = resolve_profile("sim-905", other)
    assert q.form == "distance_quantile" and other.default_profile() is None
    v = np.linspace(0, 1, 50)
    d = np.linspace(1, 80, 50)
    np.testing.assert_allclose(q.apply(v, d), other.calibration.apply(v, d)[0], rtol=1e-7)
    with pytest.raises(NidarError, match="unknown profile"):
        resolve_profile("kitti-hdl32", model)


def _wall_scene():
    """A camera looking along the LiDAR's +x at a wall tilted 50° about z, 10 m ahead, sampled
    on a 0.05 m grid, with a constant R map."""
    from nidar_mi.geometry import CameraModel

    cam = CameraModel(
        K=np.array([[50.0, 0, 31.5], [0, 50, 23.5], [0, 0, 1]]),
        width=64,
        height=48,
        T_cam_lidar=np.array([[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]]),
    )
    n = np.array([np.cos(np.radians(50)), np.sin(np.radians(50)), 0.0])
    t = np.array([-n[1], n[0], 0.0])
    s, h = np.meshgrid(np.arange(-3, 3, 0.05), np.arange(-1.5, 1.5, 0.05))
    xyz = 10.0 * np.array([1.0, 0, 0]) + s.reshape(-1, 1) * t + h.reshape(-1, 1) * [0, 0, 1.0]
    maps = {"R": np.full((48, 64), 0.4, np.float32), "I_hat": np.zeros((48, 64), np.float32)}
    return cam, xyz, n, maps


def test_default_point_intensity_uses_the_incidence_of_the_cloud():
    """With no profile given, R goes through the shipped sim-905 profile, and the incidence it
    reads is estimated from the cloud itself: on a flat wall the output equals the profile at
    the analytic |cos θ| = |n · x| / |x|, and the wall seen more obliquely comes out no brighter."""
    model = NidarModel.load(device="cpu")
    cam, xyz, n, maps = _wall_scene()
    res = model.point_intensity(xyz, [cam], [None], maps=[maps], occlusion=False)
    assert res.observed.sum() > 100
    cos = np.abs(xyz @ n) / np.linalg.norm(xyz, axis=1)
    given = model.point_intensity(
        xyz, [cam], [None], maps=[maps], occlusion=False, cos_incidence=cos
    )
    np.testing.assert_allclose(res.intensity, given.intensity, atol=1e-6)
    o = res.observed
    p = model.default_profile()
    el = np.degrees(np.arctan2(xyz[o, 2], np.hypot(xyz[o, 0], xyz[o, 1])))
    rng = np.linalg.norm(xyz[o], axis=1)
    np.testing.assert_allclose(
        res.intensity[o], p.apply(np.full(o.sum(), 0.4), rng, None, el, cos[o]), atol=1e-6
    )
    explicit = model.point_intensity(
        xyz, [cam], [None], maps=[maps], occlusion=False, profile=resolve_profile("sim-905", model)
    )
    np.testing.assert_array_equal(explicit.intensity, res.intensity)
    with pytest.raises(NidarError, match="incidence cosines for"):
        model.point_intensity(xyz, [cam], [None], maps=[maps], cos_incidence=cos[:3])
    with pytest.raises(NidarError, match="rings for"):
        model.point_intensity(xyz, [cam], [None], maps=[maps], ring=np.zeros(3, int))


def test_one_or_two_observed_points_are_assigned_head_on():
    """Too few observed points for a normal: the incidence is taken as head-on (a warning), and
    the output is the profile's at |cos θ| = 1."""
    model = NidarModel.load(device="cpu")
    cam, xyz, _, maps = _wall_scene()
    pts = np.array([[10.0, 0.2, 0.1], [12.0, -0.3, 0.0], [-5.0, 0, 0]])  # the last is behind
    with pytest.warns(UserWarning, match="too few for a surface normal"):
        res = model.point_intensity(pts, [cam], [None], maps=[maps], occlusion=False)
    assert res.observed.tolist() == [True, True, False]
    el = np.degrees(np.arctan2(pts[:2, 2], np.hypot(pts[:2, 0], pts[:2, 1])))
    expect = model.default_profile().apply(
        [0.4, 0.4], np.linalg.norm(pts[:2], axis=1), None, el, [1.0, 1.0]
    )
    np.testing.assert_allclose(res.intensity[:2], expect, atol=1e-6)


def test_a_default_profile_of_other_networks_is_ignored(tmp_path):
    """A weights folder whose profiles/sim-905.json was fitted for other networks (retrained
    into the same folder) warns and maps R through its calibration.json."""
    import shutil

    w = tmp_path / "w"
    shutil.copytree(NidarModel.load(device="cpu").weights_dir, w)
    path = w / "profiles" / "sim-905.json"
    data = json.loads(path.read_text())
    data["model"]["irnet_sha256"] = "0" * 64
    path.write_text(json.dumps(data))
    model = NidarModel.load(w, device="cpu")
    with pytest.warns(UserWarning, match="fitted for other networks"):
        assert model.default_profile() is None
    cam, xyz, _, maps = _wall_scene()
    res = model.point_intensity(xyz, [cam], [None], maps=[maps], occlusion=False)
    o = res.observed
    expect, _ = model.calibration.apply(
        np.full(o.sum(), 0.4), np.linalg.norm(xyz[o], axis=1), np.ones(o.sum(), bool)
    )
    np.testing.assert_allclose(res.intensity[o], expect, atol=1e-6)


def test_incidence_fit_survives_a_scan_with_too_few_returns():
    """Fitting with the incidence on scans one of which has two returns: that scan's incidence
    is head-on (a warning), the fit goes on."""
    from nidar_mi.datasets.scans import ScanFrame
    from nidar_mi.nidar.profiles import fit_values_profile

    rng = np.random.default_rng(0)
    scans = []
    for i, n in enumerate((4000, 2)):
        xyz = rng.uniform([2, -10, -2], [40, 10, 2], (n, 3))
        scans.append(
            ScanFrame(f"s{i}", xyz, rng.uniform(0, 1, n), np.full(n, -1, np.int16), cameras=[])
        )
    with pytest.warns(UserWarning, match="too few for a surface normal"):
        p = fit_values_profile(
            scans, lambda s: np.linspace(0, 1, len(s.xyz)), name="t", sensor="", input="nidar:R",
            form="gbm", incidence=True, trees=5,
        )  # fmt: skip
    assert p.uses_incidence and p.provenance["returns"] == 4002


def test_a_profile_of_other_weights_warns(tmp_path):
    model = NidarModel.load(device="cpu")
    v, d, _, _, ref = _data(5000)
    p = fit_profile(
        v,
        d,
        ref,
        form="range_ring",
        name="o",
        sensor="",
        input="nidar:R",
        model={"irnet_sha256": "0" * 64},
    )
    p.save(tmp_path / "o.json")
    with pytest.warns(UserWarning, match="fitted for other NIDAR weights"):
        resolve_profile(str(tmp_path / "o.json"), model)
    q = fit_profile(v, d, ref, form="range_ring", name="b", sensor="", input="luminance")
    q.save(tmp_path / "b.json")
    with pytest.raises(NidarError, match="not a NIDAR map"), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        resolve_profile(str(tmp_path / "b.json"), model)


def test_kitti_profile_is_fitted_at_first_use_and_cached(tmp_path, monkeypatch):
    from tests.helpers.synthetic_kitti import make_kitti

    make_kitti(tmp_path / "data" / "kitti", frames=2)
    monkeypatch.setenv("NIDAR_MI_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("NIDAR_MI_CACHE", str(tmp_path / "cache"))
    model = NidarModel.load(device="cpu")
    with pytest.warns(UserWarning, match="fitting the kitti-hdl64e profile"):
        p = resolve_profile("kitti-hdl64e", model, progress=False)
    assert p.form == "gbm" and p.model == model_identity(model) and p.uses_incidence
    assert p.provenance["frames"] == 2 and p.provenance["rings"] == "given"
    cached = list((tmp_path / "cache" / "profiles").glob("kitti-hdl64e-*.json"))
    assert len(cached) == 1
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no refit, no warning
        q = resolve_profile("kitti-hdl64e", model, progress=False)
    assert q.to_dict() == p.to_dict()
    monkeypatch.setenv("NIDAR_MI_DATA", str(tmp_path / "nothing"))
    monkeypatch.setenv("NIDAR_MI_CACHE", str(tmp_path / "cache2"))
    with pytest.raises(NidarError, match="not shipped"):
        resolve_profile("kitti-hdl64e", model)


def test_profile_in_point_intensity_uses_range_and_ring():
    model = NidarModel.load(device="cpu")
    v, d, ring, el, ref = _data()
    p = fit_profile(
        v,
        d,
        ref,
        form="range_ring",
        name="p",
        sensor="",
        input="nidar:R",
        ring=ring,
        elevation_deg=el,
    )
    from nidar_mi.geometry import CameraModel

    cam = CameraModel(
        K=np.array([[50.0, 0, 31.5], [0, 50, 23.5], [0, 0, 1]]),
        width=64,
        height=48,
        T_cam_lidar=np.array([[0, -1, 0, 0], [0, 0, -1, 0], [1, 0, 0, 0], [0, 0, 0, 1.0]]),
    )
    xyz = np.array([[5.0, 0.0, 0.0], [20.0, 1.0, -1.0], [-5.0, 0, 0]])
    maps = {"R": np.full((48, 64), 0.6, np.float32), "I_hat": np.zeros((48, 64), np.float32)}
    res = model.point_intensity(
        xyz, [cam], [None], maps=[maps], profile=p, ring=np.array([1, 6, 0])
    )
    assert res.observed.tolist() == [True, True, False] and res.intensity[2] == 0
    expect = p.apply([0.6, 0.6], np.linalg.norm(xyz[:2], axis=1), [1, 6])
    np.testing.assert_allclose(res.intensity[:2], expect, rtol=1e-6)
