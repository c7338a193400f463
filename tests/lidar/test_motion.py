"""Per-point time and motion distortion against closed forms, and kernel reuse across frames.

A sensor moving at v along +x towards a wall at x = X fires column j at t_j: the point it
reports (in its own frame at t_j) lies at x = X - v·t_j, so the wall appears sheared by
dx/dt = -v; de-skewed (expressed in the frame at the sweep's start) it is back at x = X, and in
the world it is at x = X. A sensor yawing at ω sees the same wall rotated by -ω·t_j.
"""

import gc

import numpy as np
import pytest

WALL_X = 10.0


def _scene(cols=720, extra=""):
    return f"""
    <sensor type="lidar" id="lidar">
        <string name="elevation_angles" value="3, 0, -3"/>
        <integer name="horizontal_resolution" value="{cols}"/>
        <float name="rotation_rate" value="10"/>
        {extra}
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.5, 1700:0.5"/></bsdf>
    <shape type="rectangle" id="wall"><transform name="to_world"><scale value="40"/>
        <rotate y="1" angle="-90"/><translate x="{WALL_X}"/></transform><ref id="grey"/></shape>
    """


def _moving_poses(times, v=0.0, omega=0.0):
    P = np.tile(np.eye(4), (len(times), 1, 1))
    P[:, 0, 3] = v * times
    c, s = np.cos(omega * times), np.sin(omega * times)
    P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = c, -s, s, c
    return P


@pytest.mark.parametrize("v", [5.0, 30.0])
def test_translation_shears_the_wall(variant, write_scene, v):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(_scene()))
    sensor = L.lidars[0]
    tc = sensor.config.pattern.column_time_s()
    r = scan(L.scene, sensor, to_world=np.eye(4), poses_per_column=_moving_poses(tc, v=v))
    p = r.points(deskew=True)
    assert len(p["t"]) > 500
    np.testing.assert_allclose(p["t"], tc[p["column"]], atol=1e-7)
    # raw points: x = X - v t (the shear), deskewed and world points on the wall
    np.testing.assert_allclose(p["xyz"][:, 0], WALL_X - v * p["t"], atol=2e-5)
    np.testing.assert_allclose(p["xyz_deskewed"][:, 0], WALL_X, atol=2e-5)
    np.testing.assert_allclose(p["xyz_world"][:, 0], WALL_X, atol=2e-5)
    # the range is the path from where the sensor stood when the column fired
    d = p["xyz"] / np.linalg.norm(p["xyz"], axis=1, keepdims=True)
    np.testing.assert_allclose(p["range"], (WALL_X - v * p["t"]) / d[:, 0], rtol=1e-5)


def test_rotation_turns_the_wall(variant, write_scene):
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    omega = np.radians(90.0)  # rad/s
    L = load_scene(write_scene(_scene()))
    sensor = L.lidars[0]
    tc = sensor.config.pattern.column_time_s()
    r = scan(L.scene, sensor, to_world=np.eye(4), poses_per_column=_moving_poses(tc, omega=omega))
    p = r.points()
    a = omega * p["t"]  # the sensor frame at t is yawed by a: raw = R(-a) · world
    world = np.stack(
        [np.cos(a) * p["xyz"][:, 0] - np.sin(a) * p["xyz"][:, 1],
         np.sin(a) * p["xyz"][:, 0] + np.cos(a) * p["xyz"][:, 1]], -1
    )  # fmt: skip
    np.testing.assert_allclose(world[:, 0], WALL_X, atol=3e-5)
    np.testing.assert_allclose(p["xyz_world"][:, :2], world, atol=3e-5)


def test_static_scan_times_follow_the_spin(variant, write_scene):
    """Clockwise from 180°: the column at azimuth a fires at ((180 - a) mod 360) / 360 / rate."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(_scene(cols=360)))
    r = scan(L.scene, L.lidars[0])
    az = (np.arange(360) + 0.5) * 1.0
    np.testing.assert_allclose(r.time[1], np.mod(180.0 - az, 360.0) / 360.0 / 10.0, atol=1e-7)
    L = load_scene(write_scene(_scene(cols=360, extra='<string name="spin" value="ccw"/>')))
    r = scan(L.scene, L.lidars[0])
    np.testing.assert_allclose(r.time[1], np.mod(az - 180.0, 360.0) / 360.0 / 10.0, atol=1e-7)


def test_bad_poses_per_column_one_line(variant, write_scene):
    from nidar_mi.errors import NidarError
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    L = load_scene(write_scene(_scene(cols=16)))
    with pytest.raises(NidarError, match=r"poses per column must be a finite \(16, 4, 4\)"):
        scan(L.scene, L.lidars[0], poses_per_column=np.zeros((15, 4, 4)))
    bad = np.tile(np.eye(4), (16, 1, 1))
    bad[3, 0, 3] = np.nan
    with pytest.raises(NidarError, match="finite"):
        scan(L.scene, L.lidars[0], poses_per_column=bad)


@pytest.mark.parametrize("divergence", [0.0, 3.0])
def test_moving_frames_reuse_kernels(variant, write_scene, divergence):
    """Per-column poses are data: frame after frame launches the same kernels."""
    import drjit as dr

    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    extra = f'<float name="beam_divergence" value="{divergence}"/>'
    extra += '<string name="layout" value="uniform"/><float name="noise_range_std" value="0.01"/>'
    L = load_scene(write_scene(_scene(cols=90, extra=extra)))
    sensor = L.lidars[0]
    tc = sensor.config.pattern.column_time_s()
    gc.collect()
    gc.disable()
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        for _ in range(2):
            scan(L.scene, sensor, seed=5, poses_per_column=_moving_poses(tc, v=1.0))
        hashes = []
        for i in range(3):
            dr.kernel_history()
            P = _moving_poses(tc + 0.1 * i, v=3.0 + i, omega=0.2 * i)
            scan(L.scene, sensor, seed=i, to_world=P[0], poses_per_column=P)
            hashes.append(sorted(k["hash"] for k in dr.kernel_history() if "hash" in k))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        gc.enable()
    assert hashes[0] and hashes[1] == hashes[2] == hashes[0]
