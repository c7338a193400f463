"""Tests for nidar_mi.geometry.fusion (per-point values from several cameras)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import CameraModel, in_image, project, sample_cameras, unproject

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def _identity_cam(width=W, height=H, k=K) -> CameraModel:
    return CameraModel(k, width, height, np.eye(4), "opencv")


def test_sample_cameras_occlusion_changes_the_hidden_point(wall_scene):
    pts, n_wall = wall_scene
    cam = _identity_cam()
    img = np.full((H, W), 0.25)
    vals, obs, idx = sample_cameras(pts, [cam], [img])
    assert obs[:n_wall].all() and obs[n_wall:].tolist() == [False, True, True, True]
    assert vals[n_wall] == 0.0 and idx[n_wall] == -1
    assert vals.dtype == np.float32 and idx.dtype == np.int64
    vals2, obs2, idx2 = sample_cameras(pts, [cam], [img], occlusion=False)
    assert obs2.all() and vals2[n_wall] == np.float32(0.25) and idx2[n_wall] == 0


# --- fusion -----------------------------------------------------------------------------


def _two_cameras(rot, rigid):
    """Camera 0 at the origin looking +z; camera 1 yawed 20 deg to the right, 1 m behind."""
    cam0 = _identity_cam()
    R_lidar_cam1 = rot("y", 20.0)  # rotates +z (forward) towards +x (right)
    T1 = np.linalg.inv(rigid(R_lidar_cam1, R_lidar_cam1 @ [0.0, 0.0, -1.0]))
    return cam0, CameraModel(K, W, H, T1, "opencv")


def test_fusion_rules_pick_as_documented(rot, rigid):
    cam0, cam1 = _two_cameras(rot, rigid)
    ang = np.deg2rad([15.0, -20.0, 80.0])  # 15 deg right, 20 deg left of cam0 axis; outside
    pts = np.stack([10 * np.sin(ang), np.zeros(3), 10 * np.cos(ang)], 1)
    images = [np.full((H, W), 0.25), np.full((H, W), 0.75)]
    # nearest_center: the 15 deg point is 5 deg off cam1's axis, 15 deg off cam0's
    vals, obs, idx = sample_cameras(pts, [cam0, cam1], images, occlusion=False)
    assert obs.tolist() == [True, True, False]
    assert idx.tolist() == [1, 0, -1]
    np.testing.assert_array_equal(vals, np.float32([0.75, 0.25, 0.0]))
    # min_depth: cam1 stands 1 m behind, so cam0 is always nearer
    vals, _, idx = sample_cameras(pts, [cam0, cam1], images, occlusion=False, fusion="min_depth")
    assert idx.tolist() == [0, 0, -1]
    np.testing.assert_array_equal(vals, np.float32([0.25, 0.25, 0.0]))
    # mean over the cameras that see the point (the -20 deg point is outside cam1's view)
    uv1, _, f1 = project(pts, cam1)
    assert not (in_image(uv1, cam1) & f1)[1]
    vals, _, idx = sample_cameras(pts, [cam0, cam1], images, occlusion=False, fusion="mean")
    np.testing.assert_array_equal(vals, np.float32([0.5, 0.25, 0.0]))
    assert idx.tolist() == [1, 0, -1]


def test_fusion_ties_go_to_the_lowest_index_and_nan_pixels_do_not_count():
    cam = _identity_cam()
    pts = np.array([[0.0, 0.0, 5.0], [1.0, 0.0, 5.0]])
    img0 = np.full((H, W), 0.1)
    img0[:, W // 2 + 20 :] = np.nan  # camera 0 has no value at the second point
    vals, obs, idx = sample_cameras(pts, [cam, cam], [img0, np.full((H, W), 0.9)], occlusion=False)
    assert obs.all() and idx.tolist() == [0, 1]
    np.testing.assert_array_equal(vals, np.float32([0.1, 0.9]))


def test_sample_cameras_rejects_mismatched_inputs():
    cam = _identity_cam()
    pts = np.zeros((1, 3))
    with pytest.raises(NidarError, match="images"):
        sample_cameras(pts, [cam], [])
    with pytest.raises(NidarError, match="image 0"):
        sample_cameras(pts, [cam], [np.zeros((2, 2))])
    with pytest.raises(NidarError, match="fusion"):
        sample_cameras(pts, [cam], [np.zeros((H, W))], fusion="max")
    with pytest.raises(NidarError, match=r"\(N, 3\)"):
        sample_cameras(np.zeros((4, 2)), [cam], [np.zeros((H, W))])
    with pytest.raises(NidarError, match="no cameras"):
        sample_cameras(pts, [], [])
    with pytest.raises(NidarError, match="^sample_cameras: 1 cameras but 2 depth images"):
        sample_cameras(pts, [cam], [np.zeros((H, W))], depth_images=[None, None])
    from nidar_mi.geometry import locate_in_cameras

    with pytest.raises(NidarError, match="^locate_in_cameras: 1 cameras but 2 depth images"):
        locate_in_cameras(pts, [cam], depth_images=[None, None])
    with pytest.raises(NidarError, match="^locate_in_cameras: no cameras"):
        locate_in_cameras(pts, [])


# --- what occlusion changes: an analytic street -----------------------------------------

_BOXES = [  # (min corner, max corner, image value); LiDAR frame x fwd, y left, z up
    ((10.0, -1.0, -1.8), (11.0, 1.0, 0.5), 0.9),
    ((15.0, 2.0, -1.8), (16.0, 4.0, 1.0), 0.7),
    ((20.0, -5.0, -1.8), (21.0, -3.0, 2.0), 0.3),
]
_SURFACE_VALUE = np.array([0.2, 0.5] + [b[2] for b in _BOXES])  # ground, wall, boxes


def _cast(origin, dirs):
    """First hit (distance, surface id) of unit rays with ground z=-1.8, wall x=30, boxes."""
    t = np.full(len(dirs), np.inf)
    sid = np.full(len(dirs), -1)
    with np.errstate(divide="ignore", invalid="ignore"):
        for k, tk in enumerate([(-1.8 - origin[2]) / dirs[:, 2], (30.0 - origin[0]) / dirs[:, 0]]):
            m = (tk > 1e-6) & (tk < t)
            t[m], sid[m] = tk[m], k
        for k, (lo, hi, _) in enumerate(_BOXES):
            t1, t2 = (np.array(lo) - origin) / dirs, (np.array(hi) - origin) / dirs
            tn = np.nanmax(np.minimum(t1, t2), axis=1)
            tf = np.nanmin(np.maximum(t1, t2), axis=1)
            m = (tn <= tf) & (tn > 1e-6) & (tn < t)
            t[m], sid[m] = tn[m], 2 + k
    return t, sid


def test_occlusion_on_an_analytic_street(rigid):
    el, az = np.meshgrid(
        np.deg2rad(np.linspace(-24.8, 2.0, 64)), np.deg2rad(np.arange(-60, 60, 0.1))
    )
    dirs = np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], -1)
    t, sid = _cast(np.zeros(3), dirs.reshape(-1, 3))
    keep = t < 80.0
    pts, truth = dirs.reshape(-1, 3)[keep] * t[keep, None], _SURFACE_VALUE[sid[keep]]
    # camera 1.2 m from the LiDAR, waymo axes = LiDAR axes
    width, height, offset = 800, 300, np.array([0.5, 1.0, -0.3])
    k = np.array([[400.0, 0, width / 2 - 0.5], [0, 400.0, height / 2 - 0.5], [0, 0, 1]])
    cam = CameraModel(k, width, height, rigid(np.eye(3), -offset), "waymo")
    rows, cols = np.mgrid[0:height, 0:width]
    uv = np.stack([cols.ravel(), rows.ravel()], 1).astype(float)
    rays = unproject(uv, np.ones(len(uv)), cam) - offset
    t_pix, sid_pix = _cast(offset, rays / np.linalg.norm(rays, axis=1, keepdims=True))
    img = _SURFACE_VALUE[sid_pix].reshape(height, width)
    zimg = (t_pix * rays[:, 0] / np.linalg.norm(rays, axis=1)).reshape(height, width)

    def wrong_fraction(**kw):
        vals, obs, _ = sample_cameras(pts, [cam], [img], **kw)
        return np.mean(np.abs(vals[obs] - truth[obs]) > 1e-6), obs.sum()

    none, n_none = wrong_fraction(occlusion=False)
    with_depth, n_depth = wrong_fraction(depth_images=[zimg])
    with_zbuf, n_zbuf = wrong_fraction()
    # measured 3.2 % / 0.8 % / 0.8 % (visibility module docstring); the rest is silhouette
    # blending
    assert none > 0.025
    assert with_depth < 0.01 and with_zbuf < 0.01
    assert n_depth > 0.97 * n_none and n_zbuf > 0.97 * n_none


def test_located_sightings_sample_as_sample_cameras_does(rot, rigid, wall_scene):
    """The geometric half computed first (:func:`locate_in_cameras`, no image needed) and then
    sampled gives what sample_cameras gives in one call, for two cameras with occlusion; the
    points it reports as seen are those a finite image gives a value to."""
    from nidar_mi.geometry import locate_in_cameras

    pts, _ = wall_scene
    cam0, cam1 = _two_cameras(rot, rigid)
    rng = np.random.default_rng(3)
    images = [rng.uniform(0, 1, (H, W)), rng.uniform(0, 1, (H, W))]
    for fusion in ("nearest_center", "mean", "min_depth"):
        ref = sample_cameras(pts, [cam0, cam1], images, fusion=fusion)
        sightings = locate_in_cameras(pts, [cam0, cam1])
        got = sample_cameras(pts, [cam0, cam1], images, fusion=fusion, sightings=sightings)
        for a, b in zip(got, ref, strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(sightings.seen, ref[1])
    with pytest.raises(NidarError, match="sightings of another"):
        sample_cameras(pts[:5], [cam0, cam1], images, sightings=sightings)
    with pytest.raises(NidarError, match="sightings of another"):
        sample_cameras(pts, [cam0], images[:1], sightings=sightings)
