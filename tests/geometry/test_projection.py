"""Tests for nidar_mi.geometry.projection (pinhole projection, pixel convention, sampling)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import CameraModel, bilinear_sample, in_image, project, unproject
from nidar_mi.geometry.projection import project_in_image

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def _identity_cam(width=W, height=H, k=K) -> CameraModel:
    return CameraModel(k, width, height, np.eye(4), "opencv")


# --- projection -------------------------------------------------------------------------


@pytest.mark.parametrize("convention", ["opencv", "waymo"])
def test_project_unproject_round_trip(convention, random_rigid):
    rng = np.random.default_rng(0)
    T = random_rigid(rng)
    cam = CameraModel(K, W, H, T, convention)
    uv = rng.uniform([-100, -50], [W + 100, H + 50], size=(500, 2))
    depth = rng.uniform(0.5, 80.0, 500)
    pts = unproject(uv, depth, cam)
    uv2, depth2, in_front = project(pts, cam)
    assert in_front.all()
    np.testing.assert_allclose(uv2, uv, rtol=0, atol=1e-8)
    np.testing.assert_allclose(depth2, depth, rtol=1e-12)
    np.testing.assert_allclose(unproject(uv2, depth2, cam), pts, rtol=0, atol=1e-10)


@pytest.mark.parametrize("convention", ["opencv", "waymo"])
def test_project_in_image_is_project_restricted_to_the_image(convention, random_rigid):
    """The in-image points, their pixels and depths equal project()'s, bit for bit, and the
    (N, 3) x (3, 3) products equal the one-matrix computation within rounding."""
    rng = np.random.default_rng(3)
    cam = CameraModel(K, W, H, random_rigid(rng), convention)
    pts = rng.normal(0.0, 30.0, (20_000, 3)) * rng.choice([1e-3, 1.0, 1e3], (20_000, 1))
    uv, depth, in_front = project(pts, cam)
    index, uv_in, depth_in = project_in_image(pts, cam)
    keep = np.flatnonzero(in_front & in_image(uv, cam))
    assert len(keep) > 100
    np.testing.assert_array_equal(index, keep)
    np.testing.assert_array_equal(uv_in, uv[keep])
    np.testing.assert_array_equal(depth_in, depth[keep])
    rot = cam.R_opencv_cam @ cam.T_cam_lidar[:3, :3]
    p_cv = pts @ rot.T + cam.R_opencv_cam @ cam.T_cam_lidar[:3, 3]
    np.testing.assert_allclose(depth, p_cv[:, 2], rtol=1e-12, atol=1e-9)


def test_project_waymo_matches_paper_equation(random_rigid):
    rng = np.random.default_rng(1)
    T = random_rigid(rng)
    cam = CameraModel(K, W, H, T, "waymo")
    pts = rng.normal(size=(200, 3)) * 10
    pc = pts @ T[:3, :3].T + T[:3, 3]
    X, Y, Z = pc.T
    front = X > 1e-6
    u = K[0, 0] * (-Y / X) + K[0, 2]
    v = K[1, 1] * (-Z / X) + K[1, 2]
    uv, depth, in_front = project(pts, cam)
    np.testing.assert_array_equal(in_front, front)
    np.testing.assert_allclose(depth, X, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv[front], np.stack([u, v], 1)[front], rtol=1e-10)
    assert np.isnan(uv[~front]).all()


def test_project_opencv_matches_pinhole_equation(random_rigid):
    rng = np.random.default_rng(2)
    k = K.copy()
    k[0, 1] = 3.0  # skew is honoured
    T = random_rigid(rng)
    cam = CameraModel(k, W, H, T, "opencv")
    pts = rng.normal(size=(200, 3)) * 10
    X, Y, Z = (pts @ T[:3, :3].T + T[:3, 3]).T
    front = Z > 1e-6
    u = k[0, 0] * X / Z + k[0, 1] * Y / Z + k[0, 2]
    v = k[1, 1] * Y / Z + k[1, 2]
    uv, depth, in_front = project(pts, cam)
    np.testing.assert_array_equal(in_front, front)
    np.testing.assert_allclose(depth, Z, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv[front], np.stack([u, v], 1)[front], rtol=1e-10)


def test_pixel_convention_centre_and_bounds():
    cam = _identity_cam(width=8, height=6, k=[[4.0, 0, 3.5], [0, 4.0, 2.5], [0, 0, 1]])
    ((u, v),) = project(np.array([[0.0, 0.0, 5.0]]), cam)[0]
    assert (u, v) == (3.5, 2.5)  # the optical axis hits the image centre ((W-1)/2, (H-1)/2)
    uv = np.array([[-0.5, 0.0], [-0.5001, 0.0], [7.4999, 5.4999], [7.5, 0.0], [0.0, 5.5]])
    assert in_image(uv, cam).tolist() == [True, False, True, False, False]
    # unprojecting pixel (c, r)'s centre and sampling there returns img[r, c] exactly
    img = np.arange(48, dtype=float).reshape(6, 8)
    cr = np.array([[0, 0], [7, 5], [3, 2], [6, 1]], dtype=float)
    pts = unproject(cr, np.full(4, 3.0), cam)
    uv, _, _ = project(pts, cam)
    np.testing.assert_allclose(bilinear_sample(img, uv), img[[0, 5, 2, 1], [0, 7, 3, 6]])


def test_behind_camera_is_not_in_front():
    uv, depth, in_front = project(np.array([[0.0, 0.0, -2.0], [0.0, 0.0, 0.0]]), _identity_cam())
    assert not in_front.any() and np.isnan(uv).all()
    assert depth.tolist() == [-2.0, 0.0]
    assert not in_image(uv, _identity_cam()).any()


def test_shape_errors():
    cam = _identity_cam()
    with pytest.raises(NidarError, match=r"\(N, 3\)"):
        project(np.zeros((4, 2)), cam)
    with pytest.raises(NidarError, match=r"\(N, 2\)"):
        in_image(np.zeros(4), cam)
    with pytest.raises(NidarError, match="2 pixels but 3 depths"):
        unproject(np.zeros((2, 2)), np.ones(3), cam)


# --- sampling ---------------------------------------------------------------------------


def test_bilinear_sample_exact_on_linear_ramp():
    rows, cols = np.mgrid[0:7, 0:9]
    img = 2.0 * cols - 3.0 * rows + 1.0
    rng = np.random.default_rng(4)
    uv = rng.uniform([0, 0], [8, 6], size=(300, 2))
    np.testing.assert_allclose(
        bilinear_sample(img, uv), 2.0 * uv[:, 0] - 3.0 * uv[:, 1] + 1.0, rtol=0, atol=1e-12
    )
    # integer coordinates hit pixel centres
    assert bilinear_sample(img, np.array([[8.0, 6.0], [2.0, 3.0]])).tolist() == [
        img[6, 8],
        img[3, 2],
    ]


def test_bilinear_sample_edges_and_outside():
    img = np.array([[1.0, 2.0], [3.0, 4.0]])
    uv = np.array([[-0.5, -0.5], [-0.2, 0.0], [1.4, 1.0], [1.5, 0.0], [0.0, -0.6], [np.nan, 0]])
    out = bilinear_sample(img, uv)
    np.testing.assert_array_equal(out[:3], [1.0, 1.0, 4.0])  # outer half pixel: edge value
    assert np.isnan(out[3:]).all()
    assert bilinear_sample(img, uv[3:], fill=-1.0).tolist() == [-1.0, -1.0, -1.0]
    single = bilinear_sample(np.array([[5.0]]), np.array([[0.3, -0.2]]))
    assert single.tolist() == [5.0]
    with pytest.raises(NidarError, match=r"\(H, W\)"):
        bilinear_sample(np.zeros((2, 2, 3)), uv)
