"""The KITTI odometry layout of a synthetic sequence, read back by hand."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.kitti_odometry import read_poses, semantic_kitti_labels, write_sequence
from nidar_mi.io.points import read_kitti_bin


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
    rel = read_poses(out / "poses.txt")
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
    cam = read_poses(tmp_path / "s" / "poses.txt")
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
