"""Tests for nidar_mi.io.calib (the YAML/JSON camera schema and the renderer's calib.json)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.geometry import CameraModel, in_image, project
from nidar_mi.io.calib import load_calib, save_calib

REPO = Path(__file__).resolve().parents[2]


def _rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


# --- YAML / JSON ------------------------------------------------------------------------


def test_load_calib_yaml_with_matrices(tmp_path):
    path = tmp_path / "rig.yaml"
    path.write_text(
        """
cameras:
  - name: front
    K: [[700, 0, 640], [0, 710, 360], [0, 0, 1]]
    width: 1280
    height: 720
    T_cam_lidar: [[0, -1, 0, 0.1], [0, 0, -1, 0.2], [1, 0, 0, 0.3], [0, 0, 0, 1]]
"""
    )
    (cam,) = load_calib(path)
    assert (cam.name, cam.width, cam.height, cam.convention) == ("front", 1280, 720, "opencv")
    assert cam.K[1, 1] == 710.0 and cam.K[0, 2] == 640.0
    # a point 10 m ahead of the LiDAR: camera coordinates (0.1, 0.2, 10.3)
    uv, depth, _ = project(np.array([[10.0, 0.0, 0.0]]), cam)
    assert depth[0] == pytest.approx(10.3)
    np.testing.assert_allclose(uv[0], [640 + 700 * 0.1 / 10.3, 360 + 710 * 0.2 / 10.3])


def test_load_calib_json_intrinsics_and_inverse_extrinsic(tmp_path):
    R = _rot_z(30.0)
    T_lidar_cam = np.eye(4)
    T_lidar_cam[:3, :3], T_lidar_cam[:3, 3] = R, [1.5, -0.2, 2.0]
    data = [
        {
            "fx": 2000.0,
            "fy": 2001.0,
            "cx": 960.0,
            "cy": 640.0,
            "width": 1920,
            "height": 1280,
            "T_lidar_cam": T_lidar_cam[:3].ravel().tolist(),  # flat 3x4
            "convention": "waymo",
        }
    ]
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(data))
    (cam,) = load_calib(path)
    assert cam.convention == "waymo" and cam.name == ""
    np.testing.assert_allclose(cam.K, [[2000, 0, 960], [0, 2001, 640], [0, 0, 1]])
    np.testing.assert_allclose(cam.T_cam_lidar @ T_lidar_cam, np.eye(4), atol=1e-12)
    # the camera centre sits at the translation of T_lidar_cam: depth of a point 10 m
    # along the camera's forward axis (LiDAR x rotated by 30 deg) is 10 m
    p = T_lidar_cam[:3, 3] + 10.0 * R[:, 0]
    uv, depth, _ = project(p[None], cam)
    assert depth[0] == pytest.approx(10.0)
    np.testing.assert_allclose(uv[0], [960.0, 640.0], atol=1e-9)


@pytest.mark.parametrize("suffix", [".yaml", ".json"])
def test_save_load_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(0)
    cams = []
    for k, conv in enumerate(["opencv", "waymo"]):
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = _rot_z(rng.uniform(0, 360)), rng.normal(size=3)
        K = [[rng.uniform(300, 900), 0.5, 320.25], [0, rng.uniform(300, 900), 240.75], [0, 0, 1]]
        cams.append(CameraModel(K, 640 + k, 480, T, conv, f"cam{k}"))
    path = tmp_path / f"rig{suffix}"
    save_calib(path, cams)
    back = load_calib(path)
    assert [c.name for c in back] == ["cam0", "cam1"]
    for a, b in zip(cams, back, strict=True):
        np.testing.assert_array_equal(a.K, b.K)
        np.testing.assert_array_equal(a.T_cam_lidar, b.T_cam_lidar)
        assert (a.width, a.height, a.convention) == (b.width, b.height, b.convention)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            "cameras: [{K: [[1,0,0],[0,1,0],[0,0,1]], height: 2, T_cam_lidar: "
            "[[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]}]",
            "missing 'width'",
        ),
        (
            "- {fx: 1, fy: 1, cx: 0, width: 2, height: 2, T_cam_lidar: [1,0,0,0,0,1,0,0,0,0,1,0]}",
            "missing cy",
        ),
        ("- {fx: 1, fy: 1, cx: 0, cy: 0, width: 2, height: 2}", "exactly one"),
        (
            "- {fx: 1, fy: 1, cx: 0, cy: 0, width: 2, height: 2, T_cam_lidar: [1, 2, 3]}",
            "4x4 or 3x4",
        ),
        (
            "- {fx: 1, fy: 1, cx: 0, cy: 0, width: 2, height: 2, convention: ros, "
            "T_cam_lidar: [1,0,0,0,0,1,0,0,0,0,1,0]}",
            "convention",
        ),
        ("cameras: {front: 1}", "non-empty list"),
        ("cameras: [\n  {a: 1\n", "cannot parse"),
    ],
)
def test_load_calib_errors_are_one_line(tmp_path, text, message):
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    with pytest.raises(NidarError, match=message) as info:
        load_calib(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_load_calib_missing_file(tmp_path):
    with pytest.raises(NidarError, match="cannot read"):
        load_calib(tmp_path / "nope.yaml")


def test_lidar_argument_needs_a_renderer_calib(tmp_path):
    path = tmp_path / "rig.yaml"
    save_calib(path, [CameraModel(np.eye(3), 4, 3, np.eye(4))])
    with pytest.raises(NidarError, match="renderer calib.json only"):
        load_calib(path, lidar="front")


# --- the renderer's own calib.json ------------------------------------------------------

_TWO_LIDARS_ONE_CAMERA = """<scene version="3.0.0">
    <sensor type="lidar" id="front"><string name="preset" value="vlp16"/>
        <integer name="horizontal_resolution" value="360"/>
        <transform name="to_world"><translate x="1" z="1.5"/></transform></sensor>
    <sensor type="lidar" id="rear"><string name="elevation_angles" value="0, -5, -10"/>
        <integer name="horizontal_resolution" value="360"/>
        <transform name="to_world"><rotate z="1" angle="180"/><translate x="-1" z="0.5"/></transform>
    </sensor>
    <sensor type="perspective" id="cam">
        <float name="fov" value="90"/><string name="fov_axis" value="x"/>
        <transform name="to_world"><lookat origin="0, 0.5, 1.2" target="10, 2, 0.5" up="0, 0, 1"/>
        </transform>
        <sampler type="independent"><integer name="sample_count" value="1"/></sampler>
        <film type="hdrfilm"><integer name="width" value="40"/><integer name="height" value="30"/></film>
    </sensor>
    <bsdf type="diffuse" id="grey"><spectrum name="reflectance" value="360:0.3, 1700:0.6"/></bsdf>
    <shape type="sphere" id="dome"><float name="radius" value="20"/><ref id="grey"/>
        <boolean name="flip_normals" value="true"/></shape>
</scene>
"""


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """A render folder of a tiny scene: LiDARs ``front`` and ``rear``, camera ``cam``."""
    root = tmp_path_factory.mktemp("render")
    scene = root / "two_lidars.xml"
    scene.write_text(_TWO_LIDARS_ONE_CAMERA)
    out = root / "out"
    r = subprocess.run(
        [sys.executable, "-m", "nidar_mi.render", str(scene), "-o", str(out), "-q"]
        + ["--formats", "npz"],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
    )
    assert r.returncode == 0, r.stderr
    return out


@pytest.mark.parametrize("lidar", ["front", "rear"])
def test_render_calib_gives_the_named_lidars_extrinsic(rendered, lidar):
    from nidar_mi.io.images import read_exr
    from nidar_mi.io.points import read_npz

    path = rendered / "cam" / "calib.json"
    raw = json.loads(path.read_text())
    (cam,) = load_calib(path, lidar=lidar)
    assert (cam.name, cam.width, cam.height, cam.convention) == ("cam", 40, 30, "opencv")
    np.testing.assert_array_equal(cam.K, raw["K"])
    np.testing.assert_array_equal(cam.T_cam_lidar, raw["T_cam_lidar"][lidar])
    # the LiDAR-frame points land where their world positions do, seen from the camera
    pts = read_npz(rendered / lidar / "points.npz")
    T_cam_world = np.linalg.inv(np.array(raw["T_world_cam"]))
    want = pts["xyz_world"].astype(np.float64) @ T_cam_world[:3, :3].T + T_cam_world[:3, 3]
    T = cam.T_cam_lidar
    got = pts["xyz"].astype(np.float64) @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)  # float32 points, 20 m away
    # and their projected depth is the rendered depth at their pixel
    (depth,) = read_exr(rendered / "cam" / "depth.exr").values()
    uv, z, in_front = project(pts["xyz"], cam)
    inside = in_front & in_image(uv, cam)
    col, row = np.floor(uv[inside] + 0.5).astype(int).T
    assert inside.sum() > 200
    np.testing.assert_allclose(depth[row, col], z[inside], rtol=0.02, atol=0.05)


def test_render_calib_with_several_lidars_needs_one_named(rendered):
    path = rendered / "cam" / "calib.json"
    with pytest.raises(NidarError, match=r"2 LiDARs \(front, rear\); choose one") as info:
        load_calib(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    with pytest.raises(NidarError, match=r"no LiDAR 'side' in T_cam_lidar \(has front, rear\)"):
        load_calib(path, lidar="side")


def test_render_calib_with_one_lidar_needs_no_name(rendered, tmp_path):
    raw = json.loads((rendered / "cam" / "calib.json").read_text())
    raw["T_cam_lidar"] = {"rear": raw["T_cam_lidar"]["rear"]}
    path = tmp_path / "left" / "calib.json"
    os.makedirs(path.parent)
    path.write_text(json.dumps(raw))
    (cam,) = load_calib(path)
    assert cam.name == "left"
    np.testing.assert_array_equal(cam.T_cam_lidar, raw["T_cam_lidar"]["rear"])
    raw["T_cam_lidar"] = {}
    path.write_text(json.dumps(raw))
    with pytest.raises(NidarError, match=r"0 LiDARs \(none\)"):
        load_calib(path)
