"""Tests for nidar_mi.geometry.camera_returns (visible returns, splatting them to pixels)."""

from __future__ import annotations

import numpy as np

from nidar_mi.geometry import (
    CameraModel,
    camera_returns,
    project,
    splat_points,
    unproject,
    visible_mask,
)

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def _identity_cam(width=W, height=H, k=K) -> CameraModel:
    return CameraModel(k, width, height, np.eye(4), "opencv")


def test_camera_returns_are_the_projected_visible_points(wall_scene):
    pts, _ = wall_scene
    cam = _identity_cam()
    values = {"z": pts[:, 2], "i": np.arange(len(pts))}
    r = camera_returns(pts, cam, values)
    uv, depth, front = project(pts, cam)
    seen = np.flatnonzero(front & visible_mask(uv, depth, cam))
    assert r.index.dtype == np.int64 and 0 < len(r.index) < len(pts)
    np.testing.assert_array_equal(r.index, seen)
    np.testing.assert_array_equal(r.uv, uv[seen])
    np.testing.assert_array_equal(r.depth, depth[seen])
    maps, mask = splat_points(pts, values, cam)
    np.testing.assert_array_equal(r.mask, mask)
    assert set(r.maps) == set(values)
    for name in values:
        np.testing.assert_array_equal(r.maps[name], maps[name])
    # every occupied pixel holds one of the visible returns
    assert set(r.maps["i"][r.mask].astype(int)) <= set(seen.tolist())


def test_camera_returns_without_values_give_the_mask_only():
    cam = _identity_cam()
    pts = np.array([[0.3, -0.2, 20.0], [0.0, 0.0, -5.0]])
    r = camera_returns(pts, cam, depth_image=np.full((H, W), 30.0))
    assert r.maps == {} and r.index.tolist() == [0] and r.mask.sum() == 1
    hidden = camera_returns(pts, cam, depth_image=np.full((H, W), 10.0))
    assert hidden.index.size == 0 and hidden.uv.shape == (0, 2) and not hidden.mask.any()


def test_splat_points_nearest_point_wins_each_pixel():
    cam = _identity_cam(width=8, height=6, k=[[4.0, 0, 3.5], [0, 4.0, 2.5], [0, 0, 1]])
    centres = np.array([[1, 1], [1, 1], [6, 4], [6, 4]], dtype=float)  # (column, row)
    pts = unproject(centres, np.array([5.2, 5.0, 5.0, 5.0]), cam)
    pts = np.concatenate([pts, [[0.0, 0.0, -5.0], [50.0, 0.0, 5.0]]])  # behind, outside
    values = {"a": np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]), "b": np.arange(6)}
    maps, mask = splat_points(pts, values, cam)
    assert mask.shape == (6, 8) and mask.dtype == bool
    assert np.flatnonzero(mask).tolist() == [1 * 8 + 1, 4 * 8 + 6]
    assert maps["a"].dtype == np.float32 and maps["a"].shape == (6, 8)
    # pixel (1, 1): the nearer second point; pixel (4, 6): equal depths, the first in order
    assert maps["a"][1, 1] == 2.0 and maps["a"][4, 6] == 3.0
    assert maps["b"][1, 1] == 1.0 and maps["b"][4, 6] == 2.0
    assert not maps["a"][~mask].any() and not maps["b"][~mask].any()


def test_splat_points_honours_the_depth_image():
    cam = _identity_cam()
    point = np.array([[0.3, -0.2, 20.0]])
    _, alone = splat_points(point, {}, cam)
    assert alone.sum() == 1  # nothing in the cloud hides it
    _, behind = splat_points(point, {}, cam, depth_image=np.full((H, W), 10.0))
    assert not behind.any()  # the rendered surface at 10 m does
    _, no_surface = splat_points(point, {}, cam, depth_image=np.zeros((H, W)))
    np.testing.assert_array_equal(no_surface, alone)
