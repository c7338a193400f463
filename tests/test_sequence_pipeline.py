"""A sequence keeps up with its sensors: no kernel compiled after the first frame (LiDAR and
cameras), frames written on a background thread (errors reach the caller, nothing is left
behind), previews of the first frame only by default, and Ctrl-C / SIGTERM stop a long camera
render within about a render pass."""

import json
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from tests.helpers.signals import default_sigint

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STREET = os.path.join(REPO, "scenes", "street.xml")
SMALL = {"width": "32", "height": "18", "cols": "256"}


@pytest.fixture(scope="module")
def trajectory(tmp_path_factory):
    path = tmp_path_factory.mktemp("traj") / "drive.txt"
    rows = [f"{t:.3f} {8.0 * t:.6f} {0.3 * t:.6f} 0 0 0 {np.sin(0.05 * t):.9f} "
            f"{np.cos(0.05 * t):.9f}" for t in np.arange(0.0, 2.01, 0.25)]  # fmt: skip
    path.write_text("\n".join(rows) + "\n")
    return str(path)


def _options(trajectory, **kw):
    """Sequence options of the street; ``kw`` are fields of the sequence or of its frames."""
    from dataclasses import fields

    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions

    kw = {"rate": 10.0, "frames": 3, "formats": ("npz",), "spp": 1, "params": SMALL,
          "progress": False} | kw  # fmt: skip
    own = {f.name for f in fields(SequenceOptions)}
    frame = RenderOptions(STREET, **{k: v for k, v in kw.items() if k not in own})
    return SequenceOptions(frame, trajectory, **{k: v for k, v in kw.items() if k in own})


def test_no_kernel_compiled_after_the_first_frame(variant, trajectory, tmp_path, monkeypatch):
    """Poses (LiDAR columns, camera pose, depth's eye) and seeds enter every kernel as data:
    frames 1.. launch only kernels frame 0 launched (same hashes, whatever the disk cache)."""
    import drjit as dr

    from nidar_mi import sequence

    per_frame = []
    render = sequence._render_frame

    def recorded(shot, previews):
        dr.kernel_history()
        out = render(shot, previews)
        per_frame.append({h["hash"] for h in dr.kernel_history() if "hash" in h})
        return out

    monkeypatch.setattr(sequence, "_render_frame", recorded)
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        sequence.render_sequence(_options(trajectory, frames=4), str(tmp_path / "o"))
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    assert len(per_frame) == 4 and len(per_frame[0]) > 5
    for k, hashes in enumerate(per_frame[1:], 1):
        assert hashes <= per_frame[0], f"frame {k} compiled {len(hashes - per_frame[0])} kernels"


def test_previews_of_the_first_frame_only_by_default(variant, trajectory, tmp_path):
    from nidar_mi.sequence import render_sequence

    def pngs(out, k):
        return sorted(p.name for p in (out / "frames" / f"{k:06d}" / "lidar_top").glob("*.png"))

    out = tmp_path / "first"
    m = render_sequence(_options(trajectory, cameras=False), str(out))
    assert pngs(out, 0) == ["intensity.png", "range.png"] and pngs(out, 1) == pngs(out, 2) == []
    assert m["request"]["previews"] == "first"
    assert all((out / f).is_file() for f in m["files"])
    frame1 = json.loads((out / "frames/000001/manifest.json").read_text())
    assert not [f for f in frame1["files"] if f.endswith(".png")]
    for previews, expect in (("all", 2), ("none", 0)):
        out = tmp_path / previews
        render_sequence(_options(trajectory, cameras=False, previews=previews), str(out))
        assert [len(pngs(out, k)) for k in range(3)] == [expect] * 3


def test_frames_are_written_in_order_with_their_timings(variant, trajectory, tmp_path):
    from nidar_mi.sequence import render_sequence

    m = render_sequence(_options(trajectory, sequence_formats=("kitti",)), str(tmp_path / "o"))
    assert [f["frame"] for f in m["frames"]] == [0, 1, 2]
    loop = sum(f["timings_s"]["frame_total"] for f in m["frames"])
    assert m["timings_s"]["frames"] == pytest.approx(loop)
    assert loop <= m["timings_s"]["total"]
    for f in m["frames"]:
        assert f["timings_s"]["render"] > 0 and f["timings_s"]["write"] > 0
    assert sorted(os.listdir(tmp_path / "o" / "kitti" / "velodyne")) == [
        f"{k:06d}.bin" for k in range(3)
    ]


def test_a_write_failure_reaches_the_caller_and_leaves_nothing(
    variant, trajectory, tmp_path, monkeypatch
):
    from nidar_mi import render_folder as rf
    from nidar_mi.errors import NidarError
    from nidar_mi.sequence import render_sequence

    calls = []
    write = rf.write_lidar

    def failing(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise NidarError("disk full")
        return write(*args, **kwargs)

    monkeypatch.setattr(rf, "write_lidar", failing)
    out = tmp_path / "o"
    with pytest.raises(NidarError, match="disk full"):
        render_sequence(_options(trajectory, cameras=False, sequence_formats=("rosbag",)), str(out))
    assert not out.exists() and os.listdir(tmp_path) == []


def test_background_writer_order_errors_and_abort():
    from nidar_mi.io.background import BackgroundWriter

    done, aborted = [], []
    with BackgroundWriter(depth=2) as w:
        for i in range(5):
            w.submit(lambda i=i: (time.sleep(0.01), done.append(i)))
    assert done == [0, 1, 2, 3, 4]

    def boom():
        raise ValueError("boom")

    done.clear()
    with pytest.raises(ValueError, match="boom"):
        with BackgroundWriter(depth=1, on_abort=lambda: aborted.append(1)) as w:
            w.submit(boom)
            for i in range(100):
                time.sleep(0.01)
                w.submit(done.append, i)
    assert aborted == [1] and len(done) == 0

    with pytest.raises(KeyboardInterrupt):
        with BackgroundWriter(depth=2, on_abort=lambda: aborted.append(2)) as w:
            w.submit(time.sleep, 0.2)
            w.submit(done.append, "dropped")
            raise KeyboardInterrupt
    assert aborted == [1, 2] and done == []


def test_render_passes_split_large_renders_only():
    from nidar_mi.camera import render_passes

    assert render_passes(480 * 270, 16, 7, 2**21) == [(16, 7)]
    passes = render_passes(1000, 10, 5, 3000)
    assert [n for n, _ in passes] == [3, 3, 3, 1]
    assert passes[0][1] == 5 and len({s for _, s in passes}) == 4
    assert render_passes(10**7, 4, 0, 2**21) == [(1, s) for _, s in render_passes(10**7, 4, 0, 1)]


def test_render_in_passes_matches_in_expectation(variant, write_scene, monkeypatch):
    """A render split in passes is the spp-weighted mean of the passes: a uniform sky reads the
    same as in one pass (another noise pattern)."""
    from nidar_mi import camera
    from nidar_mi.scene import load_scene

    path = write_scene(
        '<emitter type="constant"><spectrum name="radiance" value="1"/></emitter>'
        '<sensor type="lidar" id="l"><integer name="horizontal_resolution" value="8"/></sensor>'
        '<sensor type="perspective" id="c"><film type="hdrfilm"><integer name="width" '
        'value="16"/><integer name="height" value="8"/></film></sensor>'
    )
    loaded = load_scene(path)
    one = camera.render_camera(loaded, loaded.cameras[0], wavelength=905.0, spp=6)
    monkeypatch.setattr(camera, "PASS_SAMPLES_CPU", 16 * 8 * 2)
    split = camera.render_camera(loaded, loaded.cameras[0], wavelength=905.0, spp=6)
    assert split.rgb.shape == one.rgb.shape and not np.array_equal(split.rgb, one.rgb)
    np.testing.assert_allclose(split.rgb.mean(axis=(0, 1)), one.rgb.mean(axis=(0, 1)), rtol=0.03)
    np.testing.assert_allclose(split.nir, 1.0, rtol=1e-3)  # a flat band: exact in every pass


SLOW_CAMERA = ["-D", "width=640", "-D", "height=480", "--spp", "1024", "-D", "cols=64"]


@pytest.mark.parametrize("sig, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_signal_stops_a_long_camera_render_quickly(tmp_path, sig, status):
    """The camera render (640 x 480 at 1024 spp: 150 passes of 2 M samples, minutes on 2 cores)
    stops within a few seconds of the signal; nothing is left behind."""
    out = tmp_path / "out"
    proc = subprocess.Popen(
        [sys.executable, "-m", "nidar_mi.render", STREET, "-o", str(out), "-q", *SLOW_CAMERA],
        cwd=REPO,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=default_sigint,
    )
    try:
        _wait_for_render(tmp_path)
        time.sleep(3.0)  # the LiDAR (64 columns) is scanned: inside the camera render
        t0 = time.monotonic()
        proc.send_signal(sig)
        rc = proc.wait(timeout=60)
        stopped = time.monotonic() - t0
    finally:
        proc.kill()
        proc.wait()
    err = proc.stderr.read()
    assert rc == status, err
    assert stopped < 6.0, f"took {stopped:.1f} s to stop"
    assert not out.exists() and os.listdir(tmp_path) == []


def _wait_for_render(folder, timeout=120.0):
    """Wait until the render's staging folder exists (the scene is loaded; sensing starts)."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if any(".partial-" in entry for entry in os.listdir(folder)):
            return
        time.sleep(0.1)
    raise AssertionError("the render did not start")


def test_without_motion_each_frame_is_a_scan_and_a_photo_from_its_start_pose(
    variant, trajectory, tmp_path
):
    """``motion`` off: frame k is the scan from the rig pose at t_k with seed + k, exactly, the
    camera at that pose; labels off reads none; the last frame starts at the trajectory's end;
    ensure_sequence reuses a current folder and renders another request again."""
    from nidar_mi.geometry.se3 import transform_matrix
    from nidar_mi.io.trajectory import read_trajectory
    from nidar_mi.lidar.scan import scan
    from nidar_mi.render_folder import read_render
    from nidar_mi.scene import load_scene
    from nidar_mi.sequence import ensure_sequence

    options = _options(trajectory, rate=4.0, frames=None, seed=5, motion=False, labels=False)
    out = tmp_path / "o"
    m = ensure_sequence(options, str(out))
    assert m["frame_count"] == 9 and m["request"]["motion"] is False  # 0 .. 2 s at 4 Hz
    assert m["request"]["labels"] is False
    loaded = load_scene(STREET, params=SMALL)
    lidar, camera = loaded.lidars[0], loaded.cameras[0]
    rig = read_trajectory(trajectory).at(np.array([2.0]))[0]
    pose = rig @ transform_matrix(lidar.world_transform())
    direct = scan(loaded.scene, lidar, seed=5 + 8, to_world=pose).points()
    last = read_render(out / "frames" / "000008")
    for key in ("xyz", "intensity", "range", "t"):
        np.testing.assert_array_equal(last.points[key], direct[key], err_msg=key)
    assert not last.points["label"].any()
    T_world_cam = np.asarray(last.manifest["cameras"][camera.id()]["T_world_cam"])
    mount = transform_matrix(camera.world_transform()) @ np.diag([-1.0, -1.0, 1.0, 1.0])
    np.testing.assert_allclose(T_world_cam, rig @ mount, atol=1e-5)
    stamp = (out / "manifest.json").stat().st_mtime_ns
    assert ensure_sequence(options, str(out)) == m
    assert (out / "manifest.json").stat().st_mtime_ns == stamp
    again = ensure_sequence(_options(trajectory, rate=4.0, frames=2, motion=False), str(out))
    assert again["frame_count"] == 2 and "labels" not in again["request"]
