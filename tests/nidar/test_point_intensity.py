"""NidarModel.point_intensity through a sensor profile: the weights' own by default (sim-905, else
calibration.json), or one given, with the points' range, ring, elevation and incidence."""

from __future__ import annotations

import json

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
        res.intensity[o],
        p(np.full(o.sum(), 0.4), rng, elevation_deg=el, cos_incidence=cos[o]),
        atol=1e-6,
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
    expect = model.default_profile()(
        [0.4, 0.4], np.linalg.norm(pts[:2], axis=1), elevation_deg=el, cos_incidence=[1.0, 1.0]
    )
    np.testing.assert_allclose(res.intensity[:2], expect, atol=1e-6)


def test_the_incidence_warns_once_for_the_points_it_is_used_on():
    """The incidence estimated beside the networks (every point the camera sees) is discarded
    when a map leaves some of them unobserved; its warning goes with it, and only that of the
    estimate the profile reads (the observed points) is given."""
    import warnings

    model = NidarModel.load(device="cpu")
    cam, _, _, maps = _wall_scene()
    pts = np.array([[10.0, 0.2, 0.1], [12.0, -0.3, 0.0]])  # pixels (30.5, 23) and (32.75, 23.5)
    for hole, expect in ((False, "2 point(s): too few"), (True, "1 point(s): too few")):
        m = {k: v.copy() for k, v in maps.items()}
        if hole:
            m["R"][:, :32] = np.nan  # the first point's bilinear sample is not finite
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            res = model.point_intensity(pts, [cam], [None], maps=[m], occlusion=False)
        assert res.observed.tolist() == [not hole, True]
        found = [w for w in caught if "surface normal" in str(w.message)]
        assert len(found) == 1 and str(found[0].message).startswith(expect), found
        assert found[0].filename.endswith("pipeline.py")  # the same place either way


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
        assert model.default_profile() is model.calibration
    assert model.calibration.form == "distance_quantile"
    cam, xyz, _, maps = _wall_scene()
    res = model.point_intensity(xyz, [cam], [None], maps=[maps], occlusion=False)
    o = res.observed
    calibration = DistanceQuantileMap.load_json(w / "calibration.json")
    expect = calibration(np.full(o.sum(), 0.4), np.linalg.norm(xyz[o], axis=1))
    np.testing.assert_allclose(res.intensity[o], expect, atol=1e-6)


def test_profile_in_point_intensity_uses_range_and_ring():
    model = NidarModel.load(device="cpu")
    v, d, ring, el, ref = _data()
    p = fitted_profile(
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
    expect = p([0.6, 0.6], np.linalg.norm(xyz[:2], axis=1), ring=[1, 6])
    np.testing.assert_allclose(res.intensity[:2], expect, rtol=1e-6)


def test_maps_kept_as_tensors_give_the_intensities_of_arrays():
    """Maps a model keeps on its device (tensors, as on a GPU) are sampled on the host: the
    benchmark scan through a KITTI-like camera and the shipped profile, the same as arrays."""
    import torch

    from benchmarks.bench_nidar import hdl64e_cloud, kitti_like_camera

    model = NidarModel.load(device="cpu")
    xyz, cam = hdl64e_cloud(512), kitti_like_camera(621, 188)
    rng = np.random.default_rng(0)
    maps = {b: rng.uniform(0, 1, (188, 621)).astype(np.float32) for b in ("R", "I_hat")}
    ref = model.point_intensity(xyz, [cam], [None], maps=[maps])
    tensors = {b: torch.from_numpy(m) for b, m in maps.items()}
    got = model.point_intensity(xyz, [cam], [None], maps=[tensors])
    assert ref.observed.sum() > 1000
    np.testing.assert_array_equal(got.observed, ref.observed)
    np.testing.assert_array_equal(got.camera_index, ref.camera_index)
    np.testing.assert_array_equal(got.raw_R, ref.raw_R)
    np.testing.assert_array_equal(got.intensity, ref.intensity)


def _synthetic_view():
    """The shipped model, a synthetic frame's camera, image and returns (tests/helpers)."""
    from nidar_mi.geometry import CameraModel
    from tests.helpers.synthetic_frames import synthetic_frame

    f = synthetic_frame(np.random.default_rng(7), height=48, width=64)
    cam = CameraModel(K=f["K"], width=64, height=48, T_cam_lidar=f["T_cam_lidar"])
    return NidarModel.load(device="cpu"), cam, f["rgb"], f["points_xyz"].astype(np.float64)


@pytest.mark.parametrize("branch", ["R", "I_hat"])
def test_the_overlapped_assignment_equals_the_stages_in_turn(branch):
    """The networks run on a second thread while the points are located in the camera and
    their incidence estimated; the result is, bit for bit, the stages in turn: the
    maps first, then sampling, then the incidence of the observed points."""
    from nidar_mi.geometry import incidence_cosine

    model, cam, rgb, xyz = _synthetic_view()
    got = model.point_intensity(xyz, [cam], [rgb], branch=branch)
    maps = model.predict_image(rgb)
    ref_maps = model.point_intensity(xyz, [cam], [None], maps=[maps], branch=branch)
    o = ref_maps.observed
    assert o.sum() > 100
    cos = np.zeros(len(xyz))
    cos[o] = incidence_cosine(xyz[o])
    ref = model.point_intensity(xyz, [cam], [None], maps=[maps], branch=branch, cos_incidence=cos)
    for r in (ref_maps, ref):
        for key in ("intensity", "observed", "raw_R", "camera_index", "reflectance"):
            np.testing.assert_array_equal(getattr(got, key), getattr(r, key))


def test_points_on_pixels_without_a_value_leave_the_incidence_of_the_others():
    """Where the map is not finite the points go unobserved; the incidence of the others is
    then estimated from the observed points alone, as the profile was fitted (not from every
    point the camera sees)."""
    from nidar_mi.geometry import incidence_cosine

    model, cam, rgb, xyz = _synthetic_view()
    maps = model.predict_image(rgb)
    maps["R"][:, :20] = np.nan
    got = model.point_intensity(xyz, [cam], [None], maps=[maps])
    all_seen = model.point_intensity(xyz, [cam], [None], maps=[model.predict_image(rgb)])
    o = got.observed
    assert 50 < o.sum() < all_seen.observed.sum()
    cos = np.zeros(len(xyz))
    cos[o] = incidence_cosine(xyz[o])
    ref = model.point_intensity(xyz, [cam], [None], maps=[maps], cos_incidence=cos)
    np.testing.assert_array_equal(got.intensity, ref.intensity)
