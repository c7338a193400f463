"""Tests for nidar_mi.nidar.cameras (YAML/JSON camera files, KITTI calib files)."""

from __future__ import annotations

import json
import os
import struct
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.nidar.cameras import load_calib, load_kitti_calib, save_calib
from nidar_mi.nidar.projection import CameraModel, in_image, project

REPO = Path(__file__).resolve().parents[2]


def _kitti_dir() -> Path:
    env = os.environ.get("NIDAR_KITTI_DIR")
    path = Path(env) if env else REPO.parent / "shared" / "data" / "kitti"
    if not (path / "calib").is_dir():
        pytest.skip(f"KITTI frames not found at {path} (set NIDAR_KITTI_DIR)")
    return path


def _png_size(path: Path) -> tuple[int, int]:
    header = path.read_bytes()[:24]
    assert header[:8] == b"\x89PNG\r\n\x1a\n" and header[12:16] == b"IHDR"
    return struct.unpack(">II", header[16:24])


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


# --- KITTI ------------------------------------------------------------------------------

_SYNTHETIC_KITTI = """P0: 7.0e+02 0 6.0e+02 0 0 7.0e+02 1.8e+02 0 0 0 1 0
P1: 7.0e+02 0 6.0e+02 -3.8e+02 0 7.0e+02 1.8e+02 0 0 0 1 0
P2: 7.0e+02 0 6.0e+02 4.5e+01 0 7.0e+02 1.8e+02 -3.0e-01 0 0 1 5.0e-03
P3: 7.0e+02 0 6.0e+02 -3.3e+02 0 7.0e+02 1.8e+02 2.3e+00 0 0 1 3.0e-03
R0_rect: 0.9999 0.0101 -0.0085 -0.0101 0.9999 -0.0040 0.0085 0.0041 0.9999
Tr_velo_to_cam: 0.0069 -0.9999 -0.0028 -0.0246 -0.0012 0.0027 -0.9999 -0.0613 0.9999 0.0069 -0.0011 -0.3321
Tr_imu_to_velo: 1 0 0 -0.8 0 1 0 0.3 0 0 1 -0.8
"""


def _direct_projection(calib_text: str, camera: str, pts: np.ndarray):
    """x_img ~ P R0_rect Tr_velo_to_cam x_velo, written out with plain numpy."""
    rows = {}
    for line in calib_text.splitlines():
        if ":" in line:
            key, vals = line.split(":", 1)
            rows[key.strip()] = np.array(vals.split(), dtype=float)
    P = rows[camera].reshape(3, 4)
    R0 = np.eye(4)
    R0[:3, :3] = rows["R0_rect"].reshape(3, 3)
    Tr = np.vstack([rows["Tr_velo_to_cam"].reshape(3, 4), [0, 0, 0, 1]])
    x = P @ R0 @ Tr @ np.vstack([pts.T, np.ones(len(pts))])
    return (x[:2] / x[2]).T, x[2]


@pytest.mark.parametrize("camera", ["P0", "P2", "P3"])
def test_kitti_projection_equals_direct_product(tmp_path, camera):
    path = tmp_path / "000000.txt"
    path.write_text(_SYNTHETIC_KITTI)
    cam = load_kitti_calib(path, camera)
    assert (cam.width, cam.height, cam.name) == (1242, 375, camera)
    rng = np.random.default_rng(1)
    pts = rng.uniform([2, -20, -3], [80, 20, 3], size=(500, 3))
    uv, depth, in_front = project(pts, cam)
    uv_ref, w_ref = _direct_projection(_SYNTHETIC_KITTI, camera, pts)
    assert in_front.all()
    np.testing.assert_allclose(uv, uv_ref, rtol=1e-10, atol=1e-8)
    np.testing.assert_allclose(depth, w_ref, rtol=1e-12)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (_SYNTHETIC_KITTI.replace("Tr_velo_to_cam", "Tr_other"), "missing 'Tr_velo_to_cam'"),
        (_SYNTHETIC_KITTI.replace("R0_rect: 0.9999", "R0_rect:"), "R0_rect has 8 numbers"),
        (_SYNTHETIC_KITTI.replace("P2: 7.0e+02", "P2: seven"), "non-numeric"),
        (_SYNTHETIC_KITTI + "garbage line\n", "expected 'KEY: numbers'"),
        (_SYNTHETIC_KITTI.replace("0 0 1 5.0e-03", "0 0 2 5.0e-03"), r"\[K \| p\]"),
    ],
)
def test_kitti_errors_are_one_line(tmp_path, text, message):
    path = tmp_path / "calib.txt"
    path.write_text(text)
    with pytest.raises(NidarError, match=message) as info:
        load_kitti_calib(path)
    assert "\n" not in str(info.value) and str(path) in str(info.value)
    with pytest.raises(NidarError, match="P0..P3"):
        load_kitti_calib(path, camera="P5")


def test_kitti_aliases_in_raw_calib_files(tmp_path):
    path = tmp_path / "calib.txt"
    text = _SYNTHETIC_KITTI.replace("R0_rect", "R_rect").replace("Tr_velo_to_cam", "Tr_velo_cam")
    path.write_text(text)
    a = load_kitti_calib(path)
    path.write_text(_SYNTHETIC_KITTI)
    np.testing.assert_array_equal(a.T_cam_lidar, load_kitti_calib(path).T_cam_lidar)


def test_kitti_real_frames_project_into_image_2():
    root = _kitti_dir()
    frames = sorted(p.stem for p in (root / "calib").glob("*.txt"))
    assert frames
    rng = np.random.default_rng(2)
    for frame in frames:
        width, height = _png_size(root / "image_2" / f"{frame}.png")
        calib = root / "calib" / f"{frame}.txt"
        cam = load_kitti_calib(calib, width=width, height=height)
        scan = np.fromfile(root / "velodyne" / f"{frame}.bin", dtype=np.float32).reshape(-1, 4)
        pts = scan[:, :3].astype(np.float64)
        uv, depth, in_front = project(pts, cam)
        inside = in_image(uv, cam) & in_front
        # HDL-64E (360 deg) vs a ~82 deg camera: measured 15.5-17.6 % of a scan lands in
        # image_2, i.e. about 1/3 of the points in front of the camera.
        assert 0.12 < inside.mean() < 0.22, frame
        assert 0.25 < inside.sum() / in_front.sum() < 0.45, frame
        # the points that land in the image are ahead of the car (LiDAR x > 0)
        assert (pts[inside, 0] > 0).all()
        # independent check against P2 . R0_rect . Tr_velo_to_cam
        sample = pts[rng.choice(len(pts), 2000, replace=False)]
        uv_s, depth_s, _ = project(sample, cam)
        uv_ref, w_ref = _direct_projection(calib.read_text(), "P2", sample)
        np.testing.assert_allclose(depth_s, w_ref, rtol=1e-9, atol=1e-9)
        ok = w_ref > 0.5
        np.testing.assert_allclose(uv_s[ok], uv_ref[ok], rtol=1e-9, atol=1e-6)
