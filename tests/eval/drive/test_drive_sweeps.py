"""Drive sweeps: the sequence-folder reader, mid-sweep poses, per-source values, the sweeps of a
drive rendered by the sequence renderer."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from nidar_mi.errors import NidarError
from nidar_mi.eval.drive.drive_sweeps import SweepRequest, read_sequence, render_sweeps
from nidar_mi.eval.drive.study import SOURCES, gt_at_mid_sweep, source_values
from nidar_mi.io.points import write_npz


def _write_sequence(folder, n=3):
    """A sequence folder as ``render --trajectory`` writes it (SEQUENCES.md)."""
    poses = np.tile(np.eye(4), (n, 1, 1))
    poses[:, 0, 3] = np.arange(n) * 1.5
    np.savetxt(folder / "poses.txt", poses[:, :3, :].reshape(n, 12))
    np.savetxt(folder / "times.txt", np.arange(n) * 0.1)
    for k in range(n):
        d = folder / "frames" / f"{k:06d}" / "lidar_top"
        d.mkdir(parents=True)
        write_npz(
            d / "points.npz",
            {
                "xyz": np.full((4, 3), k, np.float32),
                "intensity": np.full(4, 0.5, np.float32),
                "range": np.full(4, 2.0, np.float32),
                "t": np.linspace(0, 0.099, 4).astype(np.float32),
            },
        )
    return poses


def test_read_sequence(tmp_path):
    poses = _write_sequence(tmp_path)
    got, times, load = read_sequence(str(tmp_path))
    np.testing.assert_allclose(got, poses)
    np.testing.assert_allclose(times, [0, 0.1, 0.2])
    f = load(2)
    np.testing.assert_array_equal(f.xyz, np.full((4, 3), 2, np.float32))
    np.testing.assert_allclose(f.t, np.linspace(0, 0.099, 4), rtol=1e-6)


def test_read_sequence_refuses_a_mismatch(tmp_path):
    _write_sequence(tmp_path)
    np.savetxt(tmp_path / "times.txt", [0.0, 0.1])
    with pytest.raises(NidarError, match="3 poses, 2 times and 3 frame folders"):
        read_sequence(str(tmp_path))
    (tmp_path / "poses.txt").write_text("1 2 3\n")
    with pytest.raises(NidarError, match="12 numbers"):
        read_sequence(str(tmp_path))


def test_gt_at_mid_sweep_of_a_constant_turn():
    # a car turning at a constant rate: 2 m and 0.1 rad of yaw per 0.1 s frame, T_k = exp(k ξ);
    # half a frame later it is at exp((k + 1/2) ξ), the last frame's extrapolated too
    from nidar_mi.geometry.se3 import se3_exp

    n = 5
    xi = np.array([2.0, 0.0, 0.0, 0.0, 0.0, 0.1])
    poses = se3_exp(np.arange(n)[:, None] * xi)
    mid = gt_at_mid_sweep(poses, np.arange(n) * 0.1, 0.1)
    np.testing.assert_allclose(mid, se3_exp((np.arange(n) + 0.5)[:, None] * xi), atol=1e-12)
    yaw = Rotation.from_matrix(mid[:, :3, :3]).as_euler("zyx")[:, 0]
    np.testing.assert_allclose(yaw, 0.1 * np.arange(n) + 0.05, atol=1e-12)
    # the arc of radius 20 m: the middle of the first frame is 20 sin(0.05) ahead
    np.testing.assert_allclose(mid[0, :2, 3], [20 * np.sin(0.05), 20 * (1 - np.cos(0.05))])


def test_source_values():
    xyz = np.array([[10.0, 0, -1.73], [0, 5.0, 1.0]])
    intensity = np.array([0.004, 0.02])
    rng = np.array([10.0, 5.0])
    np.testing.assert_allclose(source_values("physics", xyz, intensity, rng), [0.4, 0.5])
    np.testing.assert_allclose(source_values("carla", xyz, intensity, rng), np.exp(-0.004 * rng))
    np.testing.assert_allclose(source_values("none", xyz, intensity, rng), [0.0, 2.73])
    np.testing.assert_allclose(
        source_values("nidar", xyz, intensity, rng, np.array([0.3, 0])), [0.3, 0]
    )
    with pytest.raises(NidarError, match="NIDAR"):
        source_values("nidar", xyz, intensity, rng)
    assert set(SOURCES) == {"physics", "nidar", "rgb_twin", "carla", "none"}


def test_render_sweeps_scans_from_each_pose_and_reuses_the_sequence(tmp_path, variant):
    """One instantaneous sweep per pose of the trajectory, the scan from that pose with seed
    + k exactly; the same request renders nothing again, another renders again."""
    from nidar_mi.geometry.se3 import transform_matrix
    from nidar_mi.io.trajectory import write_tum
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    rig = np.tile(np.eye(4), (3, 1, 1))
    rig[:, 0, 3] = [0.0, 0.5, 1.0]
    write_tum(tmp_path / "d.tum", np.arange(3) * 0.1, rig)
    scene = "scenes/target.xml"
    params = {"cols": "64"}
    request = SweepRequest(scene, str(tmp_path / "d.tum"), 10.0, 3, params=params, seed=3)
    folder = render_sweeps(request, str(tmp_path / "f"), progress=False)
    poses, times, load = read_sequence(folder)
    np.testing.assert_allclose(times, [0.0, 0.1, 0.2])
    loaded = load_scene(scene, params=params, labels=False)
    lidar = loaded.lidars[0]
    pose = rig[1] @ transform_matrix(lidar.world_transform())
    direct = scan(loaded.scene, lidar, seed=4, to_world=pose).points()
    np.testing.assert_array_equal(load(1).xyz, direct["xyz"])
    np.testing.assert_array_equal(load(1).intensity, direct["intensity"])
    np.testing.assert_allclose(poses[1][:3, 3], [0.5, 0, 0], atol=1e-6)
    stamp = (tmp_path / "f" / "manifest.json").stat().st_mtime_ns
    render_sweeps(request, str(tmp_path / "f"), progress=False)
    assert (tmp_path / "f" / "manifest.json").stat().st_mtime_ns == stamp
    render_sweeps(replace(request, frames=2), str(tmp_path / "f"), progress=False)
    assert len(read_sequence(folder)[0]) == 2


def test_loading_without_labels_scans_the_same_returns(tmp_path, variant):
    """``load_scene(labels=False)`` lets Mitsuba merge meshes: the returns do not change."""
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene
    from nidar_mi.scenegen.city import sample_city
    from nidar_mi.scenegen.xml import scene_xml

    layout, _ = sample_city(np.random.default_rng(3), "city", (2, 1))
    path = tmp_path / "c.xml"
    path.write_text(scene_xml(layout))
    pts = {}
    for labels in (True, False):
        loaded = load_scene(str(path), params={"cols": "256"}, labels=labels)
        pts[labels] = scan(loaded.scene, loaded.lidars[0], seed=1, labels=loaded.labels).points()
    np.testing.assert_array_equal(pts[True]["xyz"], pts[False]["xyz"])
    np.testing.assert_array_equal(pts[True]["intensity"], pts[False]["intensity"])
    assert (pts[True]["label"] > 0).mean() > 0.95 and not pts[False]["label"].any()
