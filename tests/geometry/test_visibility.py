"""Tests for nidar_mi.geometry.visibility (the occlusion test)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import CameraModel, project, visible_mask

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def _identity_cam(width=W, height=H, k=K) -> CameraModel:
    return CameraModel(k, width, height, np.eye(4), "opencv")


# --- occlusion --------------------------------------------------------------------------


def _render_wall_depth(cam: CameraModel, kind: str) -> np.ndarray:
    rows, cols = np.mgrid[0 : cam.height, 0 : cam.width]
    xn = (cols - cam.K[0, 2]) / cam.K[0, 0]
    yn = (rows - cam.K[1, 2]) / cam.K[1, 1]
    hit = (np.abs(10.0 * xn) <= 2.0) & (np.abs(10.0 * yn) <= 2.0)
    z = np.where(hit, 10.0, np.inf)
    return z if kind == "z" else z * np.sqrt(xn**2 + yn**2 + 1.0)


def test_point_behind_wall_hidden_by_cloud_zbuffer(wall_scene):
    pts, n_wall = wall_scene
    cam = _identity_cam()
    uv, depth, _ = project(pts, cam)
    vis = visible_mask(uv, depth, cam)
    assert vis[:n_wall].all()
    assert vis[n_wall:].tolist() == [False, True, True, True]


@pytest.mark.parametrize("kind", ["z", "range"])
def test_point_behind_wall_hidden_by_depth_image(kind, wall_scene):
    pts, n_wall = wall_scene
    cam = _identity_cam()
    uv, depth, _ = project(pts, cam)
    vis = visible_mask(uv, depth, cam, depth_image=_render_wall_depth(cam, kind), depth_kind=kind)
    assert vis[:n_wall].all()
    assert vis[n_wall:].tolist() == [False, True, True, True]
    # a zero-depth ("no hit") image hides nothing; a tight tolerance hides the 3 % point
    none = visible_mask(uv, depth, cam, depth_image=np.zeros((H, W)))
    assert none.all()
    tight = visible_mask(
        uv, depth, cam, depth_image=_render_wall_depth(cam, "z"), rel_tol=0.0, abs_tol=0.0
    )
    assert not tight[-1]


def test_visible_mask_rejects_bad_arguments():
    cam = _identity_cam()
    uv, depth = np.zeros((2, 2)), np.ones(2)
    with pytest.raises(NidarError, match="depth image"):
        visible_mask(uv, depth, cam, depth_image=np.ones((3, 3)))
    with pytest.raises(NidarError, match="depth_kind"):
        visible_mask(uv, depth, cam, depth_image=np.ones((H, W)), depth_kind="disparity")
    with pytest.raises(NidarError, match="zbuffer_cell"):
        visible_mask(uv, depth, cam, zbuffer_cell=0)
