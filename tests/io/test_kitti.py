"""KITTI files: .bin scans, poses and times, and the odometry layout of a synthetic sequence,
read back by hand."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.kitti import (
    read_kitti_bin,
    read_kitti_poses,
    read_kitti_times,
    semantic_kitti_labels,
    write_kitti_bin,
    write_kitti_poses,
    write_kitti_times,
    write_sequence,
)

# --- .bin ----------------------------------------------------------------------------------


def test_kitti_bin_layout_and_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    xyz = rng.normal(size=(100, 3)).astype(np.float32)
    intensity = rng.uniform(size=100).astype(np.float32)
    write_kitti_bin(tmp_path / "000000.bin", xyz, intensity)
    raw = np.fromfile(tmp_path / "000000.bin", dtype=np.float32).reshape(-1, 4)
    np.testing.assert_array_equal(raw, np.column_stack([xyz, intensity]))
    assert (tmp_path / "000000.bin").stat().st_size == 100 * 16
    got_xyz, got_i = read_kitti_bin(tmp_path / "000000.bin")
    np.testing.assert_array_equal(got_xyz, xyz)
    np.testing.assert_array_equal(got_i, intensity)
    assert got_xyz.shape == (100, 3) and got_i.shape == (100,) and got_i.dtype == np.float32


def test_kitti_bin_errors(tmp_path):
    with pytest.raises(NidarError, match="xyz"):
        write_kitti_bin(tmp_path / "a.bin", np.zeros((3, 3)), np.zeros(2))
    (tmp_path / "b.bin").write_bytes(b"\0" * 20)
    with pytest.raises(NidarError, match=r"b\.bin: size 20 B"):
        read_kitti_bin(tmp_path / "b.bin")


def test_a_scan_ending_inside_a_point_is_refused(tmp_path):
    """A truncated download: 8 whole points and 7 bytes of a ninth."""
    rows = np.arange(32, dtype="<f4").reshape(8, 4)
    path = tmp_path / "cut.bin"
    path.write_bytes(rows.tobytes() + b"\x00" * 7)
    with pytest.raises(NidarError, match=r"cut\.bin: size 135 B is not a multiple of 16 B") as e:
        read_kitti_bin(path)
    assert "\n" not in str(e.value)


# --- poses.txt, times.txt ------------------------------------------------------------------


def test_poses_and_times_round_trip_at_full_precision(tmp_path):
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(4)
    poses = np.tile(np.eye(4), (5, 1, 1))
    poses[:, :3, :3] = Rotation.from_rotvec(rng.normal(size=(5, 3))).as_matrix()
    poses[:, :3, 3] = rng.normal(scale=100.0, size=(5, 3))
    write_kitti_poses(tmp_path / "poses.txt", poses)
    lines = (tmp_path / "poses.txt").read_text().splitlines()
    assert len(lines) == 5 and all(len(ln.split()) == 12 for ln in lines)
    assert lines[0].split()[0] == f"{poses[0, 0, 0]:.12e}"
    np.testing.assert_allclose(read_kitti_poses(tmp_path / "poses.txt"), poses, rtol=1e-12)
    write_kitti_times(tmp_path / "times.txt", [0.0, 0.1, 0.25])
    np.testing.assert_allclose(np.loadtxt(tmp_path / "times.txt"), [0.0, 0.1, 0.25])
    np.testing.assert_array_equal(read_kitti_times(tmp_path / "times.txt"), [0.0, 0.1, 0.25])
    (tmp_path / "bad.txt").write_text("1 2 3\n")
    with pytest.raises(NidarError, match="bad.txt:1: expected 12 numbers per line, got 3"):
        read_kitti_poses(tmp_path / "bad.txt")
    # comments and blank lines are skipped; a line is named by its number
    (tmp_path / "c.txt").write_text("# header\n\n" + lines[0] + "\n2 0 0 0 0 1 0 0 0 0 1 0\n")
    with pytest.raises(NidarError, match="c.txt:4: the 3x3 part is not a rotation matrix"):
        read_kitti_poses(tmp_path / "c.txt")
    (tmp_path / "c.txt").write_text("# header\n\n" + lines[0] + "\n")
    np.testing.assert_allclose(read_kitti_poses(tmp_path / "c.txt"), poses[:1], rtol=1e-12)
    with pytest.raises(NidarError, match="absent.txt: not a times file"):
        read_kitti_times(tmp_path / "absent.txt")


# --- the odometry layout -------------------------------------------------------------------


def test_sequence_files_and_poses(tmp_path, synthetic_sequence):
    clouds, poses, times = synthetic_sequence
    out = tmp_path / "seq"
    written = write_sequence(out, clouds, poses, times)
    names = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
    assert names == sorted(
        [f"velodyne/00000{k}.bin" for k in range(3)]
        + [f"labels/00000{k}.label" for k in range(3)]
        + ["poses.txt", "times.txt", "calib.txt"]
    )
    assert len(written) == len(names)
    for k, cloud in enumerate(clouds):
        xyz, intensity = read_kitti_bin(out / "velodyne" / f"{k:06d}.bin")
        np.testing.assert_array_equal(xyz, cloud["xyz"])
        np.testing.assert_array_equal(intensity, cloud["intensity"])
        words = np.fromfile(out / "labels" / f"{k:06d}.label", dtype="<u4")
        np.testing.assert_array_equal(words & 0xFFFF, cloud["label"])
        np.testing.assert_array_equal(words >> 16, cloud["instance"])
    np.testing.assert_allclose(np.loadtxt(out / "times.txt"), times)
    rows = np.loadtxt(out / "poses.txt")
    assert rows.shape == (3, 12)
    np.testing.assert_allclose(rows[0], np.eye(4)[:3].ravel(), atol=1e-12)
    # T_{0 <- k} maps frame k's points into frame 0: the road lands on z = -1.5 there and the
    # box's points of every frame agree (a static world seen from a moving sensor)
    rel = read_kitti_poses(out / "poses.txt")
    for k, cloud in enumerate(clouds):
        p0 = cloud["xyz"].astype(np.float64) @ rel[k][:3, :3].T + rel[k][:3, 3]
        road = cloud["label"] == 40
        np.testing.assert_allclose(p0[road, 2], -1.5, atol=1e-4)
        box = cloud["label"] == 10
        assert box.sum() > 0
        world = p0[box] + [0.0, 0.0, 1.5]  # frame 0 sits at (0, 0, 1.5), unrotated
        assert np.all(np.abs(world - [8.0, 3.0, 1.0]).max(axis=1) <= 1.0 + 1e-4)
    assert (out / "calib.txt").read_text().startswith("Tr: 1.0")


def test_camera_reference_frame(tmp_path, synthetic_sequence):
    """With a camera ``Tr``, poses are the camera's: ``Tr · T_{l0<-lk} · Tr⁻¹``."""
    clouds, poses, times = synthetic_sequence
    Tr = np.array([[0, -1, 0, 0.1], [0, 0, -1, -0.2], [1, 0, 0, -0.3], [0, 0, 0, 1.0]])
    write_sequence(tmp_path / "s", clouds, poses, times, calib={"P0": np.eye(4)[:3], "Tr": Tr})
    cam = read_kitti_poses(tmp_path / "s" / "poses.txt")
    lidar_rel = np.linalg.inv(poses[0]) @ poses
    # the camera moves with the LiDAR: its pose change is the LiDAR's seen through Tr
    np.testing.assert_allclose(cam, Tr @ lidar_rel @ np.linalg.inv(Tr), atol=1e-9)
    lines = (tmp_path / "s" / "calib.txt").read_text().splitlines()
    assert [ln.split(":")[0] for ln in lines] == ["P0", "Tr"]


def test_semantic_kitti_word_and_bad_input(tmp_path, synthetic_sequence):
    assert semantic_kitti_labels(np.array([40]), np.array([3]))[0] == (3 << 16) + 40
    with pytest.raises(NidarError, match="16 bits"):
        semantic_kitti_labels(np.array([40]), np.array([70000]))
    clouds, poses, times = synthetic_sequence
    with pytest.raises(NidarError, match="need 3 poses"):
        write_sequence(tmp_path / "a", clouds, poses[:2], times)
    bad = poses.copy()
    bad[1, 0, 0] = 2.0
    with pytest.raises(NidarError, match="orthonormal"):
        write_sequence(tmp_path / "b", clouds, bad, times)
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
