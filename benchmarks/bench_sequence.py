"""Sequence throughput: frames/s of an HDL-64E driving through the street scene, with intensity.

``python benchmarks/bench_sequence.py [--frames 20] [--cols 2048] [--camera-frames 10]
[--json out.json]``

The rig drives ``scenes/street.xml`` at 10 m/s along x while yawing at 0.1 rad/s (a TUM
trajectory written to a temporary folder); the scene's HDL-64E (raw intensity, noise,
threshold) sweeps at 10 Hz with per-column poses (motion distortion). Three sensor set-ups:

* ``uniform``: the preset's uniform table, ideal beams;
* ``per_laser``: the HDL-64E S2.1 per-laser table (beam origins, azimuth corrections, timing);
* ``per_laser + divergence``: the same with ``beam_divergence`` 3 mrad, ``beam_sample_quality`` 3
  (19 sub-rays per beam) and ``return_mode`` dual.

Three measurements per set-up, all after one warm-up frame (kernel compilation):

* **scan** (no files): :func:`nidar_mi.lidar.scan.scan` per frame (poses interpolated, cast,
  return model, read back to NumPy), wall time and process CPU time (all threads; less sensitive
  to other processes on a shared machine); the Dr.Jit kernels compiled after the warm-up are
  counted (0 expected: poses are data).
* **sequence with files**: :func:`nidar_mi.sequence.render_sequence` without cameras
  (``points.npz`` and the EXR range image per frame, written on the background writer while the
  next frame is cast; poses.txt, times.txt) without range previews, and with the previews of
  every frame (``previews="all"``, what every frame had before previews became optional):
  frames/s (median over the frames after the first, each frame's time in the render loop) and
  CPU seconds per frame.

And once, the **street sequence with its camera** (480 × 270, 16 spp, RGB and NIR; the default
point formats and previews, i.e. what ``render scenes/street.xml --trajectory T --rate 10
--frames N`` does): frames/s over all frames as the command reports it, the median after the
first frame, CPU seconds per frame, the time per stage, and the kernels compiled after a
warm-up sequence (kernel hashes not seen in the warm-up; 0 expected: camera poses are data).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import platform
import re
import statistics
import sys
import tempfile
import time

import numpy as np

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
STREET = os.path.join(REPO, "scenes", "street.xml")

SETUPS = {
    "uniform": '<string name="layout" value="uniform"/>',
    "per_laser": '<string name="layout" value="per_laser"/>',
    "per_laser + divergence": '<string name="layout" value="per_laser"/>'
    '<float name="beam_divergence" value="3"/><integer name="beam_sample_quality" value="3"/>'
    '<string name="return_mode" value="dual"/>',
}


def _scene(tmp: str, extra: str) -> str:
    with open(STREET, encoding="utf-8") as f:
        xml = f.read()
    xml = re.sub(
        r'(<sensor type="lidar" id="lidar_top">)', lambda m: m.group(1) + extra, xml, count=1
    )
    path = os.path.join(tmp, f"street_{abs(hash(extra))}.xml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(xml)
    return path


def _trajectory(tmp: str, seconds: float) -> str:
    from scipy.spatial.transform import Rotation

    t = np.arange(0.0, seconds + 1e-9, 0.05)
    yaw = 0.1 * t
    q = Rotation.from_euler("z", yaw[:, None]).as_quat()
    x, y = 10.0 * t - 20.0, np.zeros_like(t)
    path = os.path.join(tmp, "drive.txt")
    rows = [
        f"{a:.4f} {b:.4f} {c:.4f} 0 {' '.join(f'{v:.9f}' for v in qq)}"
        for a, b, c, qq in zip(t, x, y, q)
    ]
    with open(path, "w", encoding="utf-8") as f:
        f.write("\n".join(rows) + "\n")
    return path


def _scan_frames(scene: str, traj_path: str, frames: int, cols: int, variant: str) -> dict:
    """Scan ``frames`` + 1 frames without files: per-frame wall and CPU time, points, and the
    kernels compiled after the first frame."""
    import drjit as dr

    from nidar_mi.io.trajectory import read_trajectory
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene

    traj = read_trajectory(traj_path)
    loaded = load_scene(scene, variant=variant, params={"cols": str(cols)})
    sensor = loaded.lidars[0]
    mount = np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
    tc = sensor.config.pattern.column_time_s()
    secs, cpu, points = [], [], []
    for k in range(frames + 1):
        t0, c0 = time.perf_counter(), time.process_time()
        columns = traj.at(k / 10.0 + tc) @ mount
        if k == 1:
            dr.set_flag(dr.JitFlag.KernelHistory, True)
            dr.kernel_history()
        r = scan(loaded.scene, sensor, seed=k, to_world=columns[0], poses_per_column=columns)
        if k >= 1:
            secs.append(time.perf_counter() - t0)
            cpu.append(time.process_time() - c0)
            points.append(sum(int(layer.valid.sum()) for layer in r.returns))
    misses = sum(1 for h in dr.kernel_history() if "hash" in h and not h.get("cache_hit"))
    dr.set_flag(dr.JitFlag.KernelHistory, False)
    return {
        "rays_per_frame": sensor.config.rings * cols * sensor.config.subrays,
        "points_per_frame": float(np.mean(points)),
        "scan_median_s": statistics.median(secs),
        "scan_frames_per_s": 1.0 / statistics.median(secs),
        "scan_cpu_s_per_frame": statistics.median(cpu),
        "kernels_compiled_after_warmup": misses,
    }


def _sequence(options, out_dir: str) -> tuple[dict, dict]:
    """Render a sequence: its manifest, and frames/s (median after the first frame; all frames
    as the command reports them) with the process CPU seconds per frame."""
    from nidar_mi.sequence import render_sequence

    c0 = time.process_time()
    m = render_sequence(options, out_dir)
    cpu = time.process_time() - c0
    per_frame = [f["timings_s"]["frame_total"] for f in m["frames"][1:]] or [
        m["frames"][0]["timings_s"]["frame_total"]
    ]
    return m, {
        "median_s": statistics.median(per_frame),
        "frames_per_s": 1.0 / statistics.median(per_frame),
        "frames_per_s_all": m["frames_per_s"],
        "cpu_s_per_frame": cpu / len(m["frames"]),
        "first_frame_s": m["frames"][0]["timings_s"]["frame_total"],
    }


def _lidar_setup(tmp: str, scene: str, traj_path: str, frames: int, cols: int, variant: str):
    """One LiDAR set-up: the scan without files, the sequence with files with and without
    previews."""
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions

    out = _scan_frames(scene, traj_path, frames, cols, variant)
    frame = RenderOptions(scene, formats=("npz",), params={"cols": str(cols)}, cameras=False,
                          progress=False)  # fmt: skip
    for previews, key in (("none", "sequence"), ("all", "sequence_previews")):
        options = SequenceOptions(frame, traj_path, rate=10.0, frames=frames + 1,
                                  previews=previews)  # fmt: skip
        _, r = _sequence(options, tempfile.mkdtemp(dir=tmp))
        out |= {f"{key}_{k}": v for k, v in r.items()}
    return out


@contextlib.contextmanager
def _kernels_per_frame():
    """Record the hashes of the kernels each frame of a sequence launches (a list of sets, one
    per frame), by wrapping the sequence's frame render."""
    import drjit as dr

    from nidar_mi import sequence

    per_frame, render = [], sequence._render_frame

    def recorded(*args, **kwargs):
        dr.kernel_history()
        out = render(*args, **kwargs)
        per_frame.append({h["hash"] for h in dr.kernel_history() if "hash" in h})
        return out

    sequence._render_frame = recorded
    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        yield per_frame
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
        sequence._render_frame = render


def _camera_sequence(tmp: str, traj_path: str, frames: int, cols: int) -> dict:
    """The street sequence with its camera (the command's defaults): frames/s, CPU s per frame,
    seconds per stage, and the kernels compiled after its first frame (hashes frame 0 did not
    launch)."""
    from nidar_mi import render_folder as rf
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.sequence import SequenceOptions

    formats = tuple(f for f in rf.FORMATS if f != "laz")  # laz: an extra
    frame = RenderOptions(STREET, formats=formats, params={"cols": str(cols)}, progress=False)
    options = SequenceOptions(frame, traj_path, rate=10.0, frames=frames)
    with _kernels_per_frame() as hashes:
        m, r = _sequence(options, tempfile.mkdtemp(dir=tmp))
    stages = {"render": [], "write": []}
    for f in m["frames"][1:] or m["frames"]:
        for key in stages:
            stages[key].append(f["timings_s"][key])
    r["stage_median_s"] = {k: statistics.median(v) for k, v in stages.items()}
    r["kernels_compiled_after_warmup"] = len(set().union(*hashes[1:]) - hashes[0])
    r["frames"] = frames
    return r


def run_benchmark(*, frames: int, cols: int, variant: str, camera_frames: int = 10) -> dict:
    out = {"frames": frames, "cols": cols, "variant": variant, "setups": {}}
    with tempfile.TemporaryDirectory(prefix="nidar_seq_") as tmp:
        traj_path = _trajectory(tmp, (max(frames, camera_frames) + 2) / 10.0)
        for name, extra in SETUPS.items():
            scene = _scene(tmp, extra)
            out["setups"][name] = _lidar_setup(tmp, scene, traj_path, frames, cols, variant)
        if camera_frames:
            out["camera"] = _camera_sequence(tmp, traj_path, camera_frames, cols)
    out["machine"] = {
        "cpu": _cpu(),
        "cores": os.cpu_count(),
        "load_average_1min": os.getloadavg()[0],
        "python": platform.python_version(),
    }
    return out


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _report(r: dict) -> str:
    lines = [
        f"HDL-64E x {r['cols']} columns, {r['frames']} frames after one warm-up, {r['variant']}, "
        f"{r['machine']['cpu']} ({r['machine']['cores']} cores, load "
        f"{r['machine']['load_average_1min']:.1f})",
        "| set-up | rays/frame | points/frame | scan (no files) frames/s | scan CPU s/frame "
        "| sequence with files frames/s | CPU s/frame | with all previews frames/s "
        "| CPU s/frame | kernels compiled after warm-up |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in r["setups"].items():
        lines.append(
            f"| {name} | {s['rays_per_frame']} | {s['points_per_frame']:.0f} "
            f"| {s['scan_frames_per_s']:.2f} | {s['scan_cpu_s_per_frame']:.2f} "
            f"| {s['sequence_frames_per_s']:.2f} | {s['sequence_cpu_s_per_frame']:.2f} "
            f"| {s['sequence_previews_frames_per_s']:.2f} "
            f"| {s['sequence_previews_cpu_s_per_frame']:.2f} "
            f"| {s['kernels_compiled_after_warmup']} |"
        )
    c = r.get("camera")
    if c:
        lines += [
            "",
            f"street sequence with its camera, {c['frames']} frames: {c['frames_per_s_all']:.2f} "
            f"frames/s (all frames), {c['frames_per_s']:.2f} after the first, "
            f"{c['cpu_s_per_frame']:.2f} CPU s/frame; per frame render "
            f"{c['stage_median_s']['render']:.2f} s, write {c['stage_median_s']['write']:.2f} s "
            "(background); kernels compiled after warm-up: "
            f"{c['kernels_compiled_after_warmup']}",
        ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_sequence.py", description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=20, help="timed frames (after one warm-up)")
    p.add_argument("--cols", type=int, default=2048, help="columns per sweep")
    p.add_argument(
        "--camera-frames",
        type=int,
        default=10,
        help="frames of the street sequence with its camera (0: skip it)",
    )
    p.add_argument("--variant", default="llvm_ad_spectral", help="Mitsuba variant")
    p.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.errors import NidarError

    try:
        for name in ("frames", "cols"):
            if getattr(args, name) < 1:
                raise NidarError(f"--{name} must be >= 1 (got {getattr(args, name)})")
        from nidar_mi.backend import set_variant

        set_variant(args.variant)
        if args.camera_frames < 0:
            raise NidarError(f"--camera-frames must be >= 0 (got {args.camera_frames})")
        result = run_benchmark(
            frames=args.frames,
            cols=args.cols,
            variant=args.variant,
            camera_frames=args.camera_frames,
        )
        if args.json:
            from nidar_mi.io.atomic import atomic_write_json

            atomic_write_json(args.json, result)
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(_report(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
