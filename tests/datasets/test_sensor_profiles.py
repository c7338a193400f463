"""The named sensor profiles: sim-905 from the weights, kitti-hdl64e fitted at first use and
cached, profile files of other weights."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nidar_mi.datasets.sensor_profiles import resolve_profile
from nidar_mi.errors import NidarError
from nidar_mi.nidar.pipeline import NidarModel
from nidar_mi.profiles import DistanceQuantileMap
from tests.helpers.profiles import fitted_profile


def _data(n=20_000, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.uniform(0, 1, n)
    d = rng.uniform(2, 60, n)
    ring = rng.integers(0, 8, n)
    el = -2.0 * ring
    ref = np.clip(v * np.exp(-d / 30) * (0.8 + 0.05 * ring), 0, 1)
    return v, d, ring, el, ref


def test_sim_905_is_the_weights_profile_or_their_calibration(tmp_path):
    """The shipped weights carry ``profiles/sim-905.json`` (a gbm profile of R and the
    incidence, the form of the compensated intensity g·ρ·cos θ, which it ranks like ρ·cos θ
    over R's range); a weights folder without one maps R through its ``calibration.json``."""
    import shutil

    from scipy.stats import spearmanr

    model = NidarModel.load(device="cpu")
    p = resolve_profile("sim-905", model)
    assert p.form == "gbm" and p.branch == "R" and p.model == model.identity()
    assert p.uses_incidence and p.mapping.features == ("v", "cos_incidence")
    r, c = (g.ravel() for g in np.meshgrid(np.linspace(0.3, 0.6, 16), np.linspace(0.1, 1, 19)))
    assert spearmanr(p(r, np.full(r.size, 10.0), cos_incidence=c), r * c).statistic > 0.9
    plain = tmp_path / "w"
    shutil.copytree(model.weights_dir, plain, ignore=shutil.ignore_patterns("profiles"))
    other = NidarModel.load(plain, device="cpu")
    q = resolve_profile("sim-905", other)
    assert q.form == "distance_quantile" and other.default_profile() is q is other.calibration
    v = np.linspace(0, 1, 50)
    d = np.linspace(1, 80, 50)
    calibration = DistanceQuantileMap.load_json(plain / "calibration.json")
    np.testing.assert_allclose(q(v, d), calibration(v, d), rtol=1e-7)
    with pytest.raises(NidarError, match="unknown profile"):
        resolve_profile("kitti-hdl32", model)


def test_a_profile_of_other_weights_warns(tmp_path):
    model = NidarModel.load(device="cpu")
    v, d, _, _, ref = _data(5000)
    p = fitted_profile(
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
    q = fitted_profile(v, d, ref, form="range_ring", name="b", sensor="", input="luminance")
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
    assert p.form == "context" and p.model == model.identity() and p.uses_incidence
    assert p.needs_image and p.mapping.groups == ("return", "ring", "geometry", "image", "nidar")
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


def test_generic_profiles_are_closed_forms():
    """generic-compensated is R·|cos θ|, generic-raw k·R·|cos θ|/d² with a 10 %-reflective
    target head-on at 10 m reading GENERIC_RAW_LEVEL; neither is tied to weights or data."""
    from nidar_mi.datasets.sensor_profiles import GENERIC_RAW_LEVEL, PROFILE_NAMES

    model = NidarModel.load(device="cpu")
    assert {"generic-raw", "generic-compensated"} <= set(PROFILE_NAMES)
    rng = np.random.default_rng(0)
    v, d, c = rng.uniform(0, 1, 500), rng.uniform(1, 80, 500), rng.uniform(0, 1, 500)
    comp = resolve_profile("generic-compensated", model)
    assert comp.form == "physical" and comp.branch == "R" and comp.model is None
    np.testing.assert_allclose(comp(v, d, cos_incidence=c), v * c, rtol=1e-6)
    raw = resolve_profile("generic-raw", model)
    k = GENERIC_RAW_LEVEL * 100 / 0.1
    np.testing.assert_allclose(
        raw(v, d, cos_incidence=c), np.clip(k * v * c / d**2, 0, 1), rtol=1e-6
    )
    assert raw([0.1], [10.0], cos_incidence=[1.0])[0] == pytest.approx(GENERIC_RAW_LEVEL)


def test_default_profiles_and_the_unknown_sensor_warning():
    from nidar_mi.datasets.sensor_profiles import (
        default_profile,
        profile_line,
        warn_unknown_sensor,
    )

    assert default_profile(kitti=True) == "kitti-hdl64e"
    assert default_profile(simulator=True) is None
    assert default_profile() == "generic-compensated"
    with pytest.warns(UserWarning, match=r"unknown sensor.*python -m nidar_mi\.calibrate"):
        warn_unknown_sensor()
    assert profile_line(None).startswith("profile: sim-905 (")
    assert profile_line(None, branch="I_hat") == "profile: none (the I_hat head, raw)"
    assert profile_line("generic-raw").startswith("profile: generic-raw (a raw LiDAR")
    assert profile_line("kitti-hdl64e").startswith("profile: kitti-hdl64e (")
    assert "\n" not in profile_line("generic-compensated")
