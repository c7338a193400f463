"""Rig and sun geometry of the scene records against hand-computed poses."""

import numpy as np

from nidar_mi.scenegen.primitives import Layout, Patch, Rig, Sky, Sun, rotate_z


def _rig(**kw) -> Rig:
    base = dict(
        lidar_preset="vlp16",
        lidar_position=(1.0, 2.0, 1.8),
        lidar_yaw_deg=0.0,
        camera_position=(1.2, 2.0, 1.7),
        camera_yaw_deg=0.0,
        camera_pitch_deg=0.0,
        camera_fov_deg=80.0,
    )
    return Rig(**(base | kw))


def test_camera_looking_along_x_has_opencv_axes():
    T = _rig().T_world_cam()
    # OpenCV: x right (= -y world when facing +x with z up), y down, z forward.
    expected = np.array(
        [[0.0, 0.0, 1.0, 1.2], [-1.0, 0.0, 0.0, 2.0], [0.0, -1.0, 0.0, 1.7], [0, 0, 0, 1]]
    )
    np.testing.assert_allclose(T, expected, atol=1e-12)


def test_camera_yaw_90_looks_along_y():
    T = _rig(camera_yaw_deg=90.0).T_world_cam()
    np.testing.assert_allclose(T[:3, 2], [0.0, 1.0, 0.0], atol=1e-12)  # forward
    np.testing.assert_allclose(T[:3, 0], [1.0, 0.0, 0.0], atol=1e-12)  # right


def test_pitch_tilts_the_optical_axis_down():
    d = _rig(camera_pitch_deg=-30.0).camera_direction
    np.testing.assert_allclose(d, [np.cos(np.pi / 6), 0.0, -0.5], atol=1e-12)


def test_T_cam_lidar_by_hand():
    # LiDAR at the origin of its frame; the camera 0.2 m ahead (+x) and 0.1 m lower.
    # A point 10 m ahead of the LiDAR at LiDAR height is 0.1 m above the camera: x = 0,
    # y = -0.1 (y points down), z = 9.8 forward.
    T = _rig().T_cam_lidar()
    np.testing.assert_allclose(T @ [10.0, 0.0, 0.0, 1.0], [0.0, -0.1, 9.8, 1.0], atol=1e-12)
    # a point 1 m to the LiDAR's left is 1 m to the camera's left (negative x)
    np.testing.assert_allclose(T @ [0.2, 1.0, -0.1, 1.0], [-1.0, 0.0, 0.0, 1.0], atol=1e-12)


def test_T_world_lidar_applies_yaw_then_position():
    T = _rig(lidar_yaw_deg=90.0).T_world_lidar()
    np.testing.assert_allclose(T @ [1.0, 0.0, 0.0, 1.0], [1.0, 3.0, 1.8, 1.0], atol=1e-12)


def test_sun_direction_points_from_the_sun():
    np.testing.assert_allclose(Sun(90.0, 0.0, 1.0).direction, [0.0, 0.0, -1.0], atol=1e-12)
    np.testing.assert_allclose(Sun(0.0, 90.0, 1.0).direction, [0.0, -1.0, 0.0], atol=1e-12)
    d = Sun(30.0, 180.0, 1.0).direction
    np.testing.assert_allclose(d, [np.cos(np.pi / 6), 0.0, -0.5], atol=1e-12)


def test_rotate_z_quarter_turn():
    np.testing.assert_allclose(rotate_z(90.0) @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-12)


def test_layout_materials_are_sorted_and_unique():
    shapes = (
        Patch("a", "grass", (0.0, 0.0, 0.0), (1.0, 1.0)),
        Patch("b", "asphalt_old", (0.0, 0.0, 0.0), (1.0, 1.0)),
        Patch("c", "grass", (5.0, 0.0, 0.0), (1.0, 1.0)),
    )
    layout = Layout("urban", shapes, Sun(45.0, 0.0, 1.0), Sky(1.0), _rig())
    assert layout.materials() == ["asphalt_old", "grass"]
