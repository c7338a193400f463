"""Tests for nidar_mi.datasets.kitti_objects (calib files, frame ids, whole frames)."""

from __future__ import annotations

import os
import struct
from pathlib import Path

import numpy as np
import pytest

from nidar_mi.datasets.kitti_objects import KittiFrame, frame_ids, load_kitti_frame
from nidar_mi.errors import NidarError
from nidar_mi.geometry import in_image, project
from nidar_mi.io.images import write_png
from nidar_mi.io.kitti import KITTI_IMAGE_SIZE, load_kitti_calib, write_kitti_bin

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


# --- calib files ------------------------------------------------------------------------

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
        # a ~82 deg camera sees about 1/3 of the points in front of it: measured 30.5-36.3 %
        # on the six shared frames, full scans and front halves alike
        assert 0.25 < inside.sum() / in_front.sum() < 0.45, frame
        if pts[:, 0].min() > 0:
            # a KITTI raw frame whose cloud was cut to LiDAR x > 0 (see the data's README):
            # nothing is left behind the camera, so the share of the whole cloud in image_2
            # is the share of the points in front of it (33 % measured), twice a full scan's
            assert in_front.all(), frame
            assert 0.25 < inside.mean() < 0.45, frame
        else:
            # a full HDL-64E scan (360 deg): about half of it is in front of the camera
            # (46-53 % measured) and 15.5-17.6 % lands in image_2
            assert 0.4 < in_front.mean() < 0.6, frame
            assert 0.12 < inside.mean() < 0.22, frame
        # the points that land in the image are ahead of the car (LiDAR x > 0)
        assert (pts[inside, 0] > 0).all()
        # independent check against P2 . R0_rect . Tr_velo_to_cam
        sample = pts[rng.choice(len(pts), 2000, replace=False)]
        uv_s, depth_s, _ = project(sample, cam)
        uv_ref, w_ref = _direct_projection(calib.read_text(), "P2", sample)
        np.testing.assert_allclose(depth_s, w_ref, rtol=1e-9, atol=1e-9)
        ok = w_ref > 0.5
        np.testing.assert_allclose(uv_s[ok], uv_ref[ok], rtol=1e-9, atol=1e-6)


def test_kitti_real_frames_load_whole():
    root = _kitti_dir()
    ids = frame_ids(root)
    assert ids == sorted(p.stem for p in (root / "calib").glob("*.txt"))
    for fid in ids:
        frame = load_kitti_frame(root, fid)
        n = (root / "velodyne" / f"{fid}.bin").stat().st_size // 16
        assert frame.frame_id == fid and frame.camera.name == "P2"
        assert frame.xyz.shape == (n, 3) and frame.xyz.dtype == np.float32
        assert frame.intensity.shape == (n,) and frame.intensity.dtype == np.float32
        assert 0.0 <= frame.intensity.min() and frame.intensity.max() <= 1.0
        width, height = _png_size(root / "image_2" / f"{fid}.png")
        assert frame.rgb.shape == (height, width, 3) and frame.rgb.dtype == np.uint8
        assert (frame.camera.width, frame.camera.height) == (width, height)


# --- frames -----------------------------------------------------------------------------


@pytest.fixture()
def kitti_dir(tmp_path):
    """Two complete frames (images of other sizes than the default, as KITTI's odometry and
    object frames have), and three incomplete ones."""
    root = tmp_path / "kitti"
    for sub in ("velodyne", "image_2", "calib"):
        (root / sub).mkdir(parents=True)
    rng = np.random.default_rng(5)
    for fid, (h, w) in (("000004", (370, 1226)), ("000001", (374, 1238))):
        xyz = rng.uniform(-20.0, 20.0, (50, 3)).astype(np.float32)
        write_kitti_bin(root / "velodyne" / f"{fid}.bin", xyz, rng.uniform(0.0, 1.0, 50))
        write_png(root / "image_2" / f"{fid}.png", rng.integers(0, 256, (h, w, 3), np.uint8))
        (root / "calib" / f"{fid}.txt").write_text(_SYNTHETIC_KITTI)
    one = (np.zeros((1, 3), np.float32), np.zeros(1))
    write_kitti_bin(root / "velodyne" / "000002.bin", *one)  # no image, no calib
    write_kitti_bin(root / "velodyne" / "000003.bin", *one)  # no calib
    write_png(root / "image_2" / "000003.png", np.zeros((10, 16, 3), np.uint8))
    (root / "calib" / "000005.txt").write_text(_SYNTHETIC_KITTI)  # no scan
    (root / "velodyne" / "notes.txt").write_text("not a scan")
    return root


def test_frame_ids_lists_complete_frames_sorted(kitti_dir, tmp_path):
    assert frame_ids(kitti_dir) == ["000001", "000004"]
    assert frame_ids(str(kitti_dir)) == ["000001", "000004"]
    assert frame_ids(tmp_path / "absent") == []


def test_load_frame(kitti_dir):
    from nidar_mi.io.kitti import read_kitti_bin

    frame = load_kitti_frame(kitti_dir, "000004")
    assert isinstance(frame, KittiFrame) and frame.frame_id == "000004"
    xyz, intensity = read_kitti_bin(kitti_dir / "velodyne" / "000004.bin")
    np.testing.assert_array_equal(frame.xyz, xyz)
    np.testing.assert_array_equal(frame.intensity, intensity)
    assert frame.rgb.shape == (370, 1226, 3) and frame.rgb.dtype == np.uint8
    # camera P2 at the image's size, not the default KITTI size
    assert (frame.camera.width, frame.camera.height) == (1226, 370) != KITTI_IMAGE_SIZE
    reference = load_kitti_calib(kitti_dir / "calib" / "000004.txt", "P2", width=1226, height=370)
    np.testing.assert_array_equal(frame.camera.K, reference.K)
    np.testing.assert_array_equal(frame.camera.T_cam_lidar, reference.T_cam_lidar)


@pytest.mark.parametrize(
    ("frame_id", "message"),
    [("000002", "missing image file"), ("000003", "missing calib file"), ("000005", "velodyne")],
)
def test_load_frame_names_the_missing_file(kitti_dir, frame_id, message):
    with pytest.raises(NidarError, match=message) as info:
        load_kitti_frame(kitti_dir, frame_id)
    assert f"KITTI frame {frame_id}" in str(info.value) and "\n" not in str(info.value)


def test_an_image_that_does_not_match_the_calibration_is_refused(kitti_dir):
    """A resized image puts P2's principal point far from the image centre: the points would
    land on the wrong pixels (a half-size image left 1.8 % of them observed, status 0)."""
    write_png(kitti_dir / "image_2" / "000004.png", np.zeros((188, 621, 3), np.uint8))
    with pytest.raises(NidarError, match=r"000004.png is 621x188 but calib P2's principal point"):
        load_kitti_frame(kitti_dir, "000004")
