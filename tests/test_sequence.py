"""``render SCENE --trajectory FILE``: one render folder per frame, KITTI poses and times, per-point
time, cameras at their trigger times; bad requests refused with one line and nothing written."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STREET = os.path.join(REPO, "scenes", "street.xml")
SMALL = ["-D", "width=32", "-D", "height=18", "-D", "cols=256", "--spp", "1"]
SPEED = 8.0  # m/s along x


def run_cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "nidar_mi.render", *args],
        capture_output=True,
        text=True,
        cwd=REPO,
        timeout=600,
    )


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory):
    path = tmp_path_factory.mktemp("traj") / "drive.txt"
    rows = [f"{t:.3f} {SPEED * t:.6f} 0 0 0 0 0 1" for t in (10.0, 10.5, 11.0)]
    path.write_text("# t x y z qx qy qz qw (TUM)\n" + "\n".join(rows) + "\n")
    return str(path)


@pytest.fixture(scope="module")
def sequence_out(tmp_path_factory, trajectory):
    out = tmp_path_factory.mktemp("seq") / "drive"
    r = run_cli(STREET, "-o", str(out), "--trajectory", trajectory, "--frames", "3",
                "--formats", "npz,bin", "--deskew", "--seed", "2", "-q",
                "--sequence-formats", "kitti,rosbag", *SMALL)  # fmt: skip
    assert r.returncode == 0, r.stderr
    return out


def test_layout_poses_and_times(sequence_out):
    from nidar_mi.io.trajectory import read_trajectory

    m = json.loads((sequence_out / "manifest.json").read_text())
    assert m["frame_count"] == 3 and m["rate_hz"] == 10.0 and m["poses_lidar"] == "lidar_top"
    for f in m["files"]:
        assert (sequence_out / f).is_file(), f
    for k in range(3):
        assert (sequence_out / "frames" / f"{k:06d}" / "lidar_top" / "points.npz").is_file()
    np.testing.assert_allclose(np.loadtxt(sequence_out / "times.txt"), [0.0, 0.1, 0.2])
    poses = read_trajectory(sequence_out / "poses.txt", rate=10.0).poses
    np.testing.assert_allclose(poses[:, 0, 3], [0.0, 0.8, 1.6], atol=1e-6)  # v · k / rate
    np.testing.assert_allclose(poses[:, :3, :3], np.tile(np.eye(3), (3, 1, 1)), atol=1e-9)


def test_frames_are_render_folders_with_time(sequence_out):
    from nidar_mi.lidar.layouts import preset_table
    from nidar_mi.render_folder import read_render

    for k in range(3):
        scan = read_render(sequence_out / "frames" / f"{k:06d}")
        p = scan.points
        assert scan.manifest["time_s"] == pytest.approx(10.0 + 0.1 * k)
        assert p["t"].dtype == np.float32 and 0.0 <= p["t"].min() and p["t"].max() < 0.1
        # the column facing forward fires half a sweep in (clockwise from 180 deg)
        fwd = np.abs(np.arctan2(p["xyz"][:, 1], p["xyz"][:, 0])) < np.radians(1.0)
        np.testing.assert_allclose(p["t"][fwd], 0.05, atol=0.001)
        # de-skewed: the frame at the sweep's start, which lies v·t behind the firing pose (the
        # column's pose: a laser fires up to its firing offset, < 46 µs, after its column)
        shift = p["xyz_deskewed"][:, 0] - p["xyz"][:, 0]
        late = max(preset_table("hdl64e").firing_offset_s)
        assert 40e-6 < late < 46e-6
        np.testing.assert_allclose(shift, SPEED * p["t"], atol=2e-4 + SPEED * late)
        cam = scan.manifest["cameras"]["cam_front"]
        assert cam["time_s"] == pytest.approx(10.0 + 0.1 * k + 0.05, abs=1e-3)
        pose = np.array(scan.manifest["lidars"]["lidar_top"]["to_world"])
        assert pose[0, 3] == pytest.approx(SPEED * (10.0 + 0.1 * k), abs=1e-5)


def test_kitti_and_rosbag_sequence_outputs(sequence_out):
    from rosbags.highlevel import AnyReader

    from nidar_mi.io.kitti import read_kitti_bin
    from nidar_mi.io.points import read_npz

    kitti = sequence_out / "kitti"
    np.testing.assert_allclose(
        np.loadtxt(kitti / "poses.txt"), np.loadtxt(sequence_out / "poses.txt")
    )
    np.testing.assert_allclose(np.loadtxt(kitti / "times.txt"), [0.0, 0.1, 0.2], atol=1e-9)
    for k in range(3):
        xyz, _ = read_kitti_bin(kitti / "velodyne" / f"{k:06d}.bin")
        p = read_npz(sequence_out / "frames" / f"{k:06d}" / "lidar_top" / "points.npz")
        np.testing.assert_array_equal(xyz, p["xyz"])
        assert (kitti / "labels" / f"{k:06d}.label").stat().st_size == 4 * len(xyz)
    with AnyReader([sequence_out / "rosbag"]) as reader:
        topics = {c.topic: c.msgcount for c in reader.connections}
        stamps = [t / 1e9 for c, t, _ in reader.messages() if c.topic == "/lidar_top/points"]
    assert topics["/lidar_top/points"] == 3 and topics["/cam_front/image_raw"] == 3
    np.testing.assert_allclose(stamps, [10.0, 10.1, 10.2], atol=1e-6)


def test_noise_differs_between_frames(sequence_out):
    from nidar_mi.io.points import read_npz

    a = read_npz(sequence_out / "frames/000000/lidar_top/points.npz")
    b = read_npz(sequence_out / "frames/000001/lidar_top/points.npz")
    m0 = json.loads((sequence_out / "frames/000000/manifest.json").read_text())
    m1 = json.loads((sequence_out / "frames/000001/manifest.json").read_text())
    assert m0["lidars"]["lidar_top"]["parameters"]["seed"] == 2
    assert m1["lidars"]["lidar_top"]["parameters"]["seed"] == 3
    assert len(a["range"]) > 1000 and len(b["range"]) > 1000


@pytest.mark.parametrize(
    "extra, needle",
    [
        (["--frames", "20"], "holds 10 frames"),
        (["--rate", "0"], "--rate must be > 0"),
        (["--frames", "0"], "--frames must be >= 1"),
        (["--sequence-formats", "kitti,mcap"], "unknown 'mcap'"),
    ],
)
def test_bad_sequence_requests(tmp_path, trajectory, extra, needle):
    out = tmp_path / "out"
    r = run_cli(STREET, "-o", str(out), "--trajectory", trajectory, "--no-cameras", *SMALL, *extra)
    assert r.returncode == 2 and r.stderr.startswith("error:") and needle in r.stderr, r.stderr
    assert r.stderr.count("\n") == 1 and not out.exists()


def test_rate_without_trajectory(tmp_path):
    r = run_cli(STREET, "-o", str(tmp_path / "o"), "--rate", "5", *SMALL)
    assert r.returncode == 2 and "need --trajectory" in r.stderr
    r = run_cli(STREET, "-o", str(tmp_path / "o"), "--sequence-formats", "kitti", *SMALL)
    assert r.returncode == 2 and "need --trajectory" in r.stderr


def test_memory_limit_refuses_with_one_line(tmp_path):
    out = tmp_path / "big"
    r = run_cli(STREET, "-o", str(out), "--max-memory", "64M", *SMALL[:4], "-D", "cols=2000000")
    assert r.returncode == 2 and r.stderr.count("\n") == 1
    assert "lidar 'lidar_top': the scan needs about" in r.stderr and "--max-memory" in r.stderr
    assert not out.exists() and not [p for p in tmp_path.iterdir() if ".partial-" in p.name]
    r = run_cli(STREET, "-o", str(out), "--max-memory", "lots", *SMALL)
    assert r.returncode == 2 and "not a size in bytes" in r.stderr


@pytest.fixture(scope="module")
def long_trajectory(tmp_path_factory):
    """100 s along x: room for more frames than any bound allows."""
    path = tmp_path_factory.mktemp("traj") / "long.txt"
    rows = [f"{t:.3f} {SPEED * t:.6f} 0 0 0 0 0 1" for t in (10.0, 60.0, 110.0)]
    path.write_text("# t x y z qx qy qz qw (TUM)\n" + "\n".join(rows) + "\n")
    return str(path)


@pytest.mark.parametrize(
    "extra, pattern",
    [
        (  # the frame count asked for
            ["--rate", "1e9", "--frames", "100000000"],
            r"--frames 100000000 is more than the limit of 100000 frames \(--max-frames\)",
        ),
        (  # all that fit
            ["--rate", "1e9"],
            r"holds \d+ frames at 1e\+09 Hz, more than the limit of 100000 frames \(--max-frames\)",
        ),
        (  # the free space of OUT's filesystem
            ["--rate", "1e9", "--frames", "10000000", "--max-frames", "10000000"],
            r"needs about [\d.]+ TiB \(10000000 frames x [\d.]+ MiB\), more than the [\d.]+ \w+ "
            r"free on /",
        ),
        (
            ["--frames", "500", "--max-disk", "1G"],
            r"needs about [\d.]+ GiB \(500 frames x [\d.]+ MiB\), more than the limit of 1.0 GiB "
            r"\(--max-disk\)",
        ),
    ],
    ids=["frames", "all-that-fit", "free-space", "max-disk"],
)
def test_unbounded_sequences_are_refused_before_any_work(tmp_path, long_trajectory, extra, pattern):
    import re

    out = tmp_path / "out"
    r = run_cli(STREET, "-o", str(out), "--trajectory", long_trajectory, *SMALL, *extra)
    assert r.returncode == 2 and r.stderr.startswith("error:") and r.stderr.count("\n") == 1
    assert re.search(pattern, r.stderr), r.stderr
    assert not out.exists() and list(tmp_path.iterdir()) == []


def test_max_frames_and_max_disk_need_a_trajectory(tmp_path):
    for flag, value in (("--max-frames", "5"), ("--max-disk", "1G")):
        r = run_cli(STREET, "-o", str(tmp_path / "o"), flag, value, *SMALL)
        assert r.returncode == 2 and f"{flag}" in r.stderr and "need --trajectory" in r.stderr


def test_sequence_estimate_bounds_what_is_written(sequence_out):
    """The disk estimate of a frame folder is an upper bound of what is written."""
    from types import SimpleNamespace

    from nidar_mi.render_folder import folder_bytes

    m = json.loads((sequence_out / "frames" / "000000" / "manifest.json").read_text())
    params, cam = m["lidars"]["lidar_top"]["parameters"], m["cameras"]["cam_front"]
    cfg = SimpleNamespace(rings=64, horizontal_resolution=params["horizontal_resolution"])
    cfg.max_returns = 1
    need = folder_bytes([cfg], [(cam["width"], cam["height"])], ("npz", "bin"), deskew=True)
    for k in range(3):
        folder = sequence_out / "frames" / f"{k:06d}"
        size = sum(p.stat().st_size for p in folder.rglob("*") if p.is_file())
        assert size < need < 10 * size


def _compensated_street(tmp_path) -> str:
    """The street with a compensated-mode LiDAR of gain 0.5: its full scale is 0.5."""
    text = open(STREET, encoding="utf-8").read()
    old = '<string name="intensity_mode" value="raw"/>'
    assert old in text
    new = '<string name="intensity_mode" value="compensated"/><float name="gain" value="0.5"/>'
    path = tmp_path / "street_compensated.xml"
    path.write_text(text.replace(old, new))
    return str(path)


@pytest.mark.parametrize("convention", ["unit", "raw"])
def test_kitti_sequence_intensity_is_that_of_each_frames_bin(tmp_path, trajectory, convention):
    """The KITTI export holds the intensity of each frame's points.bin: KITTI's [0, 1] (the
    sensor's full scale, clipped) by default, the simulated intensity with --bin-intensity raw."""
    from nidar_mi.io.kitti import read_kitti_bin
    from nidar_mi.io.points import read_npz

    out = tmp_path / "seq"
    r = run_cli(_compensated_street(tmp_path), "-o", str(out), "--trajectory", trajectory,
                "--frames", "2", "--formats", "npz,bin", "--no-cameras", "-q",
                "--sequence-formats", "kitti", "--bin-intensity", convention, *SMALL)  # fmt: skip
    assert r.returncode == 0, r.stderr
    for k in range(2):
        _, exported = read_kitti_bin(out / "kitti" / "velodyne" / f"{k:06d}.bin")
        _, frame_bin = read_kitti_bin(out / "frames" / f"{k:06d}" / "lidar_top" / "points.bin")
        raw = read_npz(out / "frames" / f"{k:06d}" / "lidar_top" / "points.npz")["intensity"]
        np.testing.assert_array_equal(exported, frame_bin)
        if convention == "unit":
            np.testing.assert_allclose(exported, np.clip(raw / 0.5, 0, 1), rtol=1e-6)
            assert exported.max() <= 1.0 and exported.max() > raw.max()
        else:
            np.testing.assert_array_equal(exported, raw)


@settings(deadline=None, max_examples=50)
@given(frames=st.integers(1, 10**12), max_frames=st.integers(1, 10**12))
def test_the_frame_bound_refuses_exactly_the_frames_above_it(trajectory, frames, max_frames):
    from nidar_mi.errors import NidarError
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions, check_sequence

    options = SequenceOptions(
        RenderOptions(STREET), trajectory, frames=frames, max_frames=max_frames
    )
    if frames <= max_frames:
        check_sequence(options)
        return
    with pytest.raises(NidarError, match=rf"`frames` {frames} is more than the limit of "):
        check_sequence(options)
