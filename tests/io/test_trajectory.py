"""Trajectory files: KITTI odometry, TUM and CSV read the same poses; bad files give one line."""

import numpy as np
import pytest

from nidar_mi.errors import NidarError
from nidar_mi.io.kitti import write_kitti_poses
from nidar_mi.io.trajectory import read_trajectory


def _poses():
    from scipy.spatial.transform import Rotation

    out = []
    for k in range(4):
        T = np.eye(4)
        T[:3, :3] = Rotation.from_euler("zyx", [0.1 * k, 0.02 * k, -0.01 * k]).as_matrix()
        T[:3, 3] = [2.0 * k, 0.3 * k, 0.05]
        out.append(T)
    return np.stack(out)


def test_three_formats_same_poses(tmp_path):
    from scipy.spatial.transform import Rotation

    P = _poses()
    write_kitti_poses(tmp_path / "poses.txt", P)
    q = Rotation.from_matrix(P[:, :3, :3]).as_quat()  # x, y, z, w
    t = np.arange(4) * 0.1 + 100.0
    tum = "\n".join(
        f"{ti} {' '.join(map(str, T[:3, 3]))} {' '.join(map(str, qi))}"
        for ti, T, qi in zip(t, P, q)
    )
    (tmp_path / "t.txt").write_text("# timestamp tx ty tz qx qy qz qw\n" + tum + "\n")
    csv = "qw,qx,qy,qz,x,y,z,timestamp,extra\n" + "\n".join(
        ",".join(map(str, [qi[3], *qi[:3], *T[:3, 3], ti, 7])) for ti, T, qi in zip(t, P, q)
    )
    (tmp_path / "c.csv").write_text(csv + "\n")
    kitti = read_trajectory(tmp_path / "poses.txt", rate=10.0)
    assert kitti.format == "kitti"
    np.testing.assert_allclose(kitti.times, [0, 0.1, 0.2, 0.3])
    for path in ("t.txt", "c.csv"):
        tr = read_trajectory(tmp_path / path)
        np.testing.assert_allclose(tr.times, t)
        np.testing.assert_allclose(tr.poses, P, atol=1e-9)
    np.testing.assert_allclose(kitti.poses, P, atol=1e-8)


@pytest.mark.parametrize(
    "name, content, kwargs, needle",
    [
        ("a.txt", "1 2 3\n", {}, "3 values per line"),
        ("b.txt", " ".join(["1"] * 12) + "\n", {}, "carry no time"),
        ("c.txt", "0 0 0 0 0 0 0 1\n0 1 0 0 0 0 0 1\n", {}, "times must increase"),
        ("d.txt", "0 0 0 0 0 0 0 0\n", {}, "quaternion is zero"),
        ("e.csv", "t,x,y\n0,1,2\n", {}, "no column z, qx, qy, qz, qw"),
        ("f.txt", "0 0 0 nan 0 0 0 1\n", {}, "not finite"),
        ("g.txt", "2 0 0 0 0 1 0 0 0 0 1 0\n", {"rate": 10}, "not a rotation matrix"),
        ("h.txt", "0 0 0 0 0 0 0 1\n1 x 0 0 0 0 0 1\n", {}, "h.txt:2: not a number"),
        ("i.txt", "", {}, "no poses"),
    ],
)
def test_bad_trajectories_one_line(tmp_path, name, content, kwargs, needle):
    (tmp_path / name).write_text(content)
    with pytest.raises(NidarError, match=needle) as e:
        read_trajectory(tmp_path / name, **kwargs)
    assert "\n" not in str(e.value)


def test_missing_file(tmp_path):
    with pytest.raises(NidarError, match="no such file"):
        read_trajectory(tmp_path / "none.txt")
