"""Tests for nidar_mi.geometry.camera_model (validation, conventions)."""

from __future__ import annotations

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import R_OPENCV_FROM_WAYMO, CameraModel, project

K = np.array([[500.0, 0.0, 319.5], [0.0, 480.0, 239.5], [0.0, 0.0, 1.0]])
W, H = 640, 480


def test_camera_model_validation(rot, rigid):
    with pytest.raises(NidarError, match="convention"):
        CameraModel(K, W, H, np.eye(4), "ros")
    with pytest.raises(NidarError, match="K must"):
        CameraModel(np.eye(4), W, H, np.eye(4))
    with pytest.raises(NidarError, match="last row"):
        CameraModel(K, W, H, np.ones((4, 4)))
    with pytest.raises(NidarError, match="positive"):
        CameraModel(K, 0, H, np.eye(4))
    cam = CameraModel(K, W, H, rigid(rot("x", 10.0), [1, 2, 3]), name="front")
    np.testing.assert_allclose(cam.T_lidar_cam @ cam.T_cam_lidar, np.eye(4), atol=1e-12)
    assert cam.to_opencv() is not cam and cam.to_opencv().name == "front"


def test_camera_model_arrays_are_read_only():
    cam = CameraModel(K, W, H, np.eye(4), "waymo")
    for arr in (cam.K, cam.T_cam_lidar, cam.R_opencv_cam, cam.to_opencv().R_opencv_cam):
        with pytest.raises(ValueError):
            arr[0, 0] = 2.0
    np.testing.assert_array_equal(cam.R_opencv_cam, R_OPENCV_FROM_WAYMO)
    np.testing.assert_array_equal(cam.to_opencv().R_opencv_cam, np.eye(3))


def test_conventions_agree_for_the_same_physical_camera(rot, rigid):
    rng = np.random.default_rng(3)
    # A camera 1.5 m up, yawed 30 degrees left, in a LiDAR frame x fwd / y left / z up.
    R_lidar_cam_waymo = rot("z", 30.0)  # waymo camera axes coincide with LiDAR axes, yawed
    T_lidar_cam = rigid(R_lidar_cam_waymo, [0.2, 0.1, 1.5])
    waymo = CameraModel(K, W, H, np.linalg.inv(T_lidar_cam), "waymo")
    # The same camera written by hand in OpenCV axes (right, down, forward).
    R_lidar_cam_cv = R_lidar_cam_waymo @ R_OPENCV_FROM_WAYMO.T
    opencv = CameraModel(K, W, H, np.linalg.inv(rigid(R_lidar_cam_cv, [0.2, 0.1, 1.5])))
    np.testing.assert_allclose(waymo.to_opencv().T_cam_lidar, opencv.T_cam_lidar, atol=1e-12)
    pts = rng.uniform([-5, -40, -3], [60, 40, 8], size=(1000, 3))
    uv_w, d_w, f_w = project(pts, waymo)
    uv_c, d_c, f_c = project(pts, opencv)
    np.testing.assert_array_equal(f_w, f_c)
    np.testing.assert_allclose(d_w, d_c, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(uv_w[f_w], uv_c[f_c], rtol=1e-10, atol=1e-9)
    # A point straight ahead of the camera, 1 m to its left and up, lands up-left of centre.
    p = (T_lidar_cam @ [10.0, 1.0, 1.0, 1.0])[:3]
    ((u, v),) = project(p[None], waymo)[0]
    assert u == pytest.approx(319.5 - 50.0) and v == pytest.approx(239.5 - 48.0)
