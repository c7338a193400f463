"""Sequence throughput: frames/s of an HDL-64E driving through the street scene, with intensity.

``python benchmarks/bench_sequence.py [--frames 20] [--cols 2048] [--json out.json]``

The rig drives ``scenes/street.xml`` at 10 m/s along x while yawing at 0.1 rad/s (a TUM
trajectory written to a temporary folder); the scene's HDL-64E (raw intensity, noise,
threshold) sweeps at 10 Hz with per-column poses (motion distortion). Three sensor set-ups:

* ``uniform``: the preset's uniform table, ideal beams;
* ``per_laser``: the HDL-64E S2.1 per-laser table (beam origins, azimuth corrections, timing);
* ``per_laser + divergence``: the same with ``beam_divergence`` 3 mrad, ``beam_sample_quality`` 3
  (19 sub-rays per beam) and ``return_mode`` dual.

Two measurements per set-up, both after one warm-up frame (kernel compilation):

* **scan**: :func:`nidar_mi.lidar.scan.scan` per frame (poses interpolated, cast, return model,
  read back to NumPy), wall time and process CPU time (all threads; less sensitive to other
  processes on a shared machine); the Dr.Jit kernels compiled after the warm-up are counted
  (0 expected: poses are data).
* **sequence**: :func:`nidar_mi.sequence.render_sequence` without cameras (``points.npz``, range
  image and previews per frame, poses.txt, times.txt), frames/s from its manifest (first frame
  excluded).
"""

from __future__ import annotations

import argparse
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


def run_benchmark(*, frames: int, cols: int, variant: str) -> dict:
    import drjit as dr

    from nidar_mi.io.trajectory import read_trajectory
    from nidar_mi.lidar.scan import scan
    from nidar_mi.scene import load_scene
    from nidar_mi.sequence import SequenceOptions, render_sequence

    out = {"frames": frames, "cols": cols, "variant": variant, "setups": {}}
    with tempfile.TemporaryDirectory(prefix="nidar_seq_") as tmp:
        traj_path = _trajectory(tmp, (frames + 2) / 10.0)
        traj = read_trajectory(traj_path)
        for name, extra in SETUPS.items():
            scene = _scene(tmp, extra)
            loaded = load_scene(scene, variant=variant, params={"cols": str(cols)})
            sensor = loaded.lidars[0]
            mount = np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(
                4, 4
            )
            tc = sensor.config.pattern.column_time_s()
            secs, cpu, points, misses = [], [], [], 0
            for k in range(frames + 1):
                t0, c0 = time.perf_counter(), time.process_time()
                columns = traj.at(k / 10.0 + tc) @ mount
                if k == 1:
                    dr.set_flag(dr.JitFlag.KernelHistory, True)
                    dr.kernel_history()
                r = scan(
                    loaded.scene, sensor, seed=k, to_world=columns[0], poses_per_column=columns
                )
                if k >= 1:
                    secs.append(time.perf_counter() - t0)
                    cpu.append(time.process_time() - c0)
                    points.append(sum(int(layer.valid.sum()) for layer in r.returns))
            misses = sum(1 for h in dr.kernel_history() if "hash" in h and not h.get("cache_hit"))
            dr.set_flag(dr.JitFlag.KernelHistory, False)
            seq_dir = os.path.join(tmp, f"seq_{len(out['setups'])}")
            options = SequenceOptions(
                scene,
                traj_path,
                rate=10.0,
                frames=frames + 1,
                formats=("npz",),
                params={"cols": str(cols)},
                cameras=False,
                progress=False,
            )
            m = render_sequence(options, seq_dir)
            per_frame = [f["timings_s"]["frame_total"] for f in m["frames"][1:]]
            out["setups"][name] = {
                "rays_per_frame": sensor.config.rings * cols * sensor.config.subrays,
                "points_per_frame": float(np.mean(points)),
                "scan_median_s": statistics.median(secs),
                "scan_frames_per_s": 1.0 / statistics.median(secs),
                "scan_cpu_s_per_frame": statistics.median(cpu),
                "kernels_compiled_after_warmup": misses,
                "sequence_median_s": statistics.median(per_frame),
                "sequence_frames_per_s": 1.0 / statistics.median(per_frame),
                "first_frame_s": m["frames"][0]["timings_s"]["frame_total"],
            }
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
        "| set-up | rays/frame | points/frame | scan frames/s | scan CPU s/frame | sequence "
        "frames/s | kernels compiled after warm-up |",
        "|---|---:|---:|---:|---:|---:|---:|",
    ]
    for name, s in r["setups"].items():
        lines.append(
            f"| {name} | {s['rays_per_frame']} | {s['points_per_frame']:.0f} "
            f"| {s['scan_frames_per_s']:.2f} | {s['scan_cpu_s_per_frame']:.2f} "
            f"| {s['sequence_frames_per_s']:.2f} "
            f"| {s['kernels_compiled_after_warmup']} |"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_sequence.py", description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=20, help="timed frames (after one warm-up)")
    p.add_argument("--cols", type=int, default=2048, help="columns per sweep")
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
        result = run_benchmark(frames=args.frames, cols=args.cols, variant=args.variant)
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
