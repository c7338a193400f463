"""Tests of nidar_mi.io.point_cloud: the reader chosen by extension."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.kitti import write_kitti_bin
from nidar_mi.io.las import write_las
from nidar_mi.io.point_cloud import read_point_cloud
from nidar_mi.io.points import write_npz, write_ply


@pytest.mark.parametrize("suffix", [".npz", ".ply", ".las", ".bin", ".PLY"])
def test_read_point_cloud_dispatch(tmp_path, points, suffix):
    path = tmp_path / f"scan{suffix}"
    if suffix == ".bin":
        write_kitti_bin(path, points["xyz"], points["intensity"])
    elif suffix == ".las":
        write_las(path, points)
    else:
        (write_npz if suffix == ".npz" else write_ply)(path, points)
    got = read_point_cloud(path)
    np.testing.assert_allclose(got["xyz"], points["xyz"], atol=1e-4)
    np.testing.assert_allclose(got["intensity"], points["intensity"], atol=1e-5)
    assert got["xyz"].dtype == np.float32


def test_read_point_cloud_errors(tmp_path):
    with pytest.raises(NidarError, match=r"scan\.xyz.*unknown point cloud extension '\.xyz'"):
        read_point_cloud(tmp_path / "scan.xyz")
    with pytest.raises(NidarError, match=r"missing\.ply: no such file"):
        read_point_cloud(tmp_path / "missing.ply")
    np.savez(tmp_path / "noxyz.npz", intensity=np.zeros(3))
    with pytest.raises(NidarError, match=r"noxyz\.npz: no \(N,3\) 'xyz'"):
        read_point_cloud(tmp_path / "noxyz.npz")
