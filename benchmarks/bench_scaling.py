"""Cost of training data per scene and per frame, and what Ray workers buy (docs/SCALING.md).

``python benchmarks/bench_scaling.py [--scenes 6] [--repeats 3] [--spp 16] [--json out.json]``

Scenes are procedural (``nidar_mi.scenegen``, seed 0, their default 480 × 270 camera and the
preset's columns unless ``--width/--height/--cols`` say otherwise); one camera per scene, so one
training frame per scene. Five measurements, all in one run so that their ratios see the same
machine load (the machine is shared: read ratios within a run, not absolute seconds across runs):

1. **stages** (this process, kernels warm after the first scene): per scene the render's own
   timings (scene load, LiDAR scan, camera RGB / NIR / depth, file writing), the frame step
   (read the render folder, project the returns, write the frame), and NIDAR on the frame
   (networks on the RGB image, intensity at the points); wall and CPU seconds (all threads);
   bytes of the render folder and of the frame (also written with ``np.savez_compressed``).
2. **kernel cache**: the first scene rendered in a fresh process, with Dr.Jit's kernel cache
   (``~/.drjit``) empty (a temporary ``HOME``) and warm.
3. **modes**: the dataset command's work (:func:`nidar_mi.render_dataset.build_dataset`) from scratch
   in a fresh process, serially, with ``workers=1`` and ``workers=2``; ``repeats`` rounds, the
   order rotated every round. Wall time of the whole process (start-up, Ray included), the time
   the first scene finished, and the steady rate after the first wave (each worker's first
   scene pays its process start-up); speed-ups against serial in the same round.
4. **Ray**: ``import ray`` in a fresh interpreter against ``import nidar_mi.render_dataset``; starting
   and stopping the local runtime; per-task overhead (no-op tasks through
   :func:`nidar_mi.tasks.run_tasks`, Ray against serial); a worker's first set-up
   (``prepare_worker``: imports, variant, plugins) and later ones; the installed size of Ray.
5. **sizing**: CPU core-hours and storage for 10**6 frames from (1).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

__all__ = ["build_parser", "main", "run_benchmark", "sizing"]

PY = sys.executable


def _median(values) -> float:
    return float(statistics.median(values))


def _folder_bytes(path: str) -> int:
    return sum(
        os.path.getsize(os.path.join(root, f)) for root, _, files in os.walk(path) for f in files
    )


def _defines(args) -> list[str]:
    out = []
    for name in ("width", "height", "cols"):
        value = getattr(args, name)
        if value is not None:
            out += ["-D", f"{name}={value}"]
    return out


def _params(args) -> dict[str, str]:
    return {k: str(getattr(args, k)) for k in ("width", "height", "cols") if getattr(args, k)}


# --------------------------------------------------------------------------- 1. stages


def _stages(scene_files: list[str], work: str, args) -> dict:
    """Render each scene, build its frame and run NIDAR on it, in this process."""
    import numpy as np

    from nidar_mi.backend import prepare_worker
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.render_dataset import frames_of_render
    from nidar_mi.render_folder import read_render
    from nidar_mi.render_session import RenderOptions
    from nidar_mi.simulate import render_scene

    prepare_worker(None, args.variant)
    t0 = time.perf_counter()
    model = NidarModel.load(None, device="cpu")
    model_load_s = time.perf_counter() - t0
    rows = []
    for i, path in enumerate(scene_files):
        rdir = os.path.join(work, "renders", f"s{i}")
        w0, c0 = time.perf_counter(), time.process_time()
        options = RenderOptions(
            path, formats=("npz",), seed=0, spp=args.spp, params=_params(args), progress=False
        )
        manifest = render_scene(options, rdir, overwrite=True)
        render = (time.perf_counter() - w0, time.process_time() - c0)
        lidar = next(iter(manifest["lidars"].values()))
        cams = list(manifest["cameras"].values())
        w0, c0 = time.perf_counter(), time.process_time()
        frames = list(frames_of_render(rdir))
        project = (time.perf_counter() - w0, time.process_time() - c0)
        w0, c0 = time.perf_counter(), time.process_time()
        frame_bytes = 0
        for cam_id, frame, _ in frames:
            fpath = os.path.join(work, "frames", f"s{i}__{cam_id}.npz")
            os.makedirs(os.path.dirname(fpath), exist_ok=True)
            with open(fpath, "wb") as f:
                np.savez(f, **frame)
            frame_bytes += os.path.getsize(fpath)
        write = (time.perf_counter() - w0, time.process_time() - c0)
        w0, c0 = time.perf_counter(), time.process_time()
        packed_bytes = 0
        for cam_id, frame, _ in frames:
            fpath = os.path.join(work, "frames", f"s{i}__{cam_id}.packed.npz")
            with open(fpath, "wb") as f:
                np.savez_compressed(f, **frame)
            packed_bytes += os.path.getsize(fpath)
        packed = (time.perf_counter() - w0, time.process_time() - c0)
        r = read_render(rdir)
        w0, c0 = time.perf_counter(), time.process_time()
        for cam in r.cameras:
            model.point_intensity(
                r.points["xyz"], [cam.model], [cam.rgb8()], depth_images=[cam.depth]
            )
        nidar = (time.perf_counter() - w0, time.process_time() - c0)
        t = manifest["timings_s"]
        rows.append(
            {
                "scene": os.path.basename(path),
                "returns": lidar["returns"],
                "rays": lidar["rays"],
                "frames": len(frames),
                "load_s": t["load"],
                "scan_s": lidar["timings_s"]["scan_total"],
                "lidar_write_s": lidar["timings_s"]["write"],
                "camera_rgb_s": sum(c["timings_s"]["rgb"] for c in cams),
                "camera_nir_s": sum(c["timings_s"]["nir"] for c in cams),
                "camera_depth_s": sum(c["timings_s"]["depth"] for c in cams),
                "camera_write_s": sum(c["timings_s"]["write"] for c in cams),
                "render_wall_s": render[0],
                "render_cpu_s": render[1],
                "frame_project_wall_s": project[0],
                "frame_project_cpu_s": project[1],
                "frame_write_wall_s": write[0],
                "frame_write_cpu_s": write[1],
                "frame_write_compressed_wall_s": packed[0],
                "frame_write_compressed_cpu_s": packed[1],
                "frame_compressed_bytes": packed_bytes,
                "nidar_wall_s": nidar[0],
                "nidar_cpu_s": nidar[1],
                "render_bytes": _folder_bytes(rdir),
                "frame_bytes": frame_bytes,
            }
        )
    steady = rows[1:] or rows
    keys = [k for k in rows[0] if k.endswith(("_s", "_bytes")) or k in ("returns", "frames")]
    return {
        "model_load_s": model_load_s,
        "first_scene": rows[0],
        "median_after_first": {k: _median([r[k] for r in steady]) for k in keys},
        "scenes": rows,
    }


# --------------------------------------------------------------------------- 2. kernel cache

_FIRST_RENDER = """
import json, sys, time
t0 = time.perf_counter()
from nidar_mi.backend import set_variant
from nidar_mi.render_session import RenderOptions
from nidar_mi.simulate import render_scene
set_variant(sys.argv[5])
m = render_scene(RenderOptions(sys.argv[1], formats=("npz",), seed=0, spp=int(sys.argv[3]),
                               params=json.loads(sys.argv[4]), progress=False),
                 sys.argv[2], overwrite=True)
print(json.dumps({"process_s": time.perf_counter() - t0, "render_s": m["timings_s"]["total"]}))
"""


def _first_render(scene: str, out: str, args, home: str | None) -> dict:
    env = dict(os.environ)
    if home is not None:
        env["HOME"] = home
    cmd = [PY, "-c", _FIRST_RENDER, scene, out, str(args.spp), json.dumps(_params(args))]
    t0 = time.perf_counter()
    proc = subprocess.run(
        cmd + [args.variant], env=env, capture_output=True, text=True, check=True, timeout=900
    )
    return json.loads(proc.stdout) | {"wall_s": time.perf_counter() - t0}


def _kernel_cache(scene: str, work: str, args) -> dict:
    rounds = []
    for r in range(args.repeats):
        home = tempfile.mkdtemp(prefix="home-", dir=work)
        cold = _first_render(scene, os.path.join(work, f"kc{r}"), args, home)
        warm = _first_render(scene, os.path.join(work, f"kc{r}"), args, None)
        shutil.rmtree(home, ignore_errors=True)
        rounds.append({"cold": cold, "warm": warm})
    return {
        "cold_render_s": _median([x["cold"]["render_s"] for x in rounds]),
        "warm_render_s": _median([x["warm"]["render_s"] for x in rounds]),
        "cold_process_s": _median([x["cold"]["wall_s"] for x in rounds]),
        "warm_process_s": _median([x["warm"]["wall_s"] for x in rounds]),
        "rounds": rounds,
    }


# --------------------------------------------------------------------------- 3. modes

MODES = {"serial": None, "workers_1": 1, "workers_2": 2}

#: ``python -m nidar_mi.dataset`` in a fresh process (the same call as the command), with the
#: time each scene finished taken from the job's progress bar.
_DATASET_JOB = """
import json, sys, time
t0 = time.perf_counter()
import nidar_mi.tasks as tasks
from nidar_mi.render_dataset import build_dataset
done = []
original = tasks._Progress.done
def stamp(self, failure):
    done.append(time.perf_counter() - t0)
    original(self, failure)
tasks._Progress.done = stamp
scenes, out, spp, params, workers = sys.argv[1:6]
build_dataset(scenes, out, spp=int(spp), params=json.loads(params), progress=False,
              workers=None if workers == "None" else int(workers))
print(json.dumps({"done_s": done, "total_s": time.perf_counter() - t0}))
"""


def _job(scene_dir: str, out: str, args, workers) -> dict:
    cmd = [PY, "-c", _DATASET_JOB, scene_dir, out, str(args.spp), json.dumps(_params(args))]
    t0 = time.perf_counter()
    proc = subprocess.run(
        cmd + [str(workers)], capture_output=True, text=True, check=True, timeout=3600
    )
    wall = time.perf_counter() - t0
    job = json.loads(proc.stdout.strip().splitlines()[-1])
    done, k = job["done_s"], workers or 1
    # after the first wave (each worker's first scene: process start-up, imports, kernels)
    steady = (done[-1] - done[k - 1]) / (len(done) - k) if len(done) > k else float("nan")
    return {"wall_s": wall, "first_done_s": done[0], "steady_s_per_scene": steady, "done_s": done}


def _modes(scene_dir: str, work: str, args) -> dict:
    rounds = []
    names = list(MODES)
    for r in range(args.repeats):
        order = names[r % len(names) :] + names[: r % len(names)]
        jobs = {}
        for mode in order:
            out = os.path.join(work, f"data_{mode}_{r}")
            jobs[mode] = _job(scene_dir, out, args, MODES[mode])
            shutil.rmtree(out, ignore_errors=True)
        rounds.append({"order": order, "jobs": jobs})

    def med(key, mode):
        return _median([x["jobs"][mode][key] for x in rounds])

    def ratio(key, mode):
        return _median([x["jobs"]["serial"][key] / x["jobs"][mode][key] for x in rounds])

    return {
        "median_wall_s": {m: med("wall_s", m) for m in names},
        "median_steady_s_per_scene": {m: med("steady_s_per_scene", m) for m in names},
        "median_first_done_s": {m: med("first_done_s", m) for m in names},
        "speedup_vs_serial": {m: ratio("wall_s", m) for m in names},
        "steady_speedup_vs_serial": {m: ratio("steady_s_per_scene", m) for m in names},
        "rounds": rounds,
    }


# --------------------------------------------------------------------------- 4. Ray


def _import_time(module: str, repeats: int) -> float:
    code = f"import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"
    return _median(
        [
            float(subprocess.run([PY, "-c", code], capture_output=True, text=True).stdout)
            for _ in range(repeats)
        ]
    )


def _noop(i: int) -> int:
    return i


def _timed_setup(threads, variant):
    """prepare_worker, returning how long it took (first call in a worker: imports and all)."""
    t0 = time.perf_counter()
    from nidar_mi.backend import prepare_worker

    prepare_worker(threads, variant)
    return time.perf_counter() - t0


def _ray(args) -> dict:
    import importlib.metadata

    import ray

    from nidar_mi.tasks import Task, run_tasks

    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    n = args.noop_tasks
    tasks = [Task(f"t{i}", _noop, (i,)) for i in range(n)]
    t0 = time.perf_counter()
    run_tasks(tasks, progress=False)
    serial_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    ray.init(
        num_cpus=2,
        num_gpus=0,
        include_dashboard=False,
        object_store_memory=128 * 1024**2,
        logging_level="ERROR",
        log_to_driver=False,
    )
    init_s = time.perf_counter() - t0
    try:
        run_tasks(tasks[:4], workers=2, progress=False)  # workers started
        per_task = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            run_tasks(tasks, workers=2, progress=False)
            per_task.append((time.perf_counter() - t0 - serial_s) / n)
        setup = ray.remote(_timed_setup).options(num_cpus=1)
        first = ray.get([setup.remote(1, args.variant) for _ in range(2)])
        again = ray.get([setup.remote(1, args.variant) for _ in range(4)])
    finally:
        t0 = time.perf_counter()
        ray.shutdown()
        shutdown_s = time.perf_counter() - t0
    files = importlib.metadata.files("ray") or []
    size = sum(f.locate().stat().st_size for f in files if f.locate().is_file())
    return {
        "import_ray_s": _import_time("ray", args.repeats),
        "import_nidar_mi_render_dataset_s": _import_time("nidar_mi.render_dataset", args.repeats),
        "ray_version": ray.__version__,
        "ray_installed_bytes": size,
        "init_s": init_s,
        "shutdown_s": shutdown_s,
        "noop_tasks": n,
        "overhead_per_task_ms": 1e3 * _median(per_task),
        "worker_first_setup_s": _median(first),
        "worker_setup_again_s": _median(again),
    }


# --------------------------------------------------------------------------- 5. sizing


def sizing(stages: dict, frames: float = 1e6) -> dict:
    """CPU core-hours and storage for ``frames`` training frames from the per-scene medians.

    One frame per scene (one camera), as in the measured scenes: every frame is a render.
    """
    m = stages["median_after_first"]
    per_frame_cpu = (m["render_cpu_s"] + m["frame_project_cpu_s"] + m["frame_write_cpu_s"]) / max(
        m["frames"], 1
    )
    per_frame_bytes = (m["render_bytes"] + m["frame_bytes"]) / max(m["frames"], 1)
    return {
        "frames": frames,
        "cpu_s_per_frame": per_frame_cpu,
        "core_hours": frames * per_frame_cpu / 3600.0,
        "nidar_core_hours": frames * m["nidar_cpu_s"] / max(m["frames"], 1) / 3600.0,
        "bytes_per_frame": per_frame_bytes,
        "terabytes": frames * per_frame_bytes / 1e12,
        "frame_only_terabytes": frames * m["frame_bytes"] / max(m["frames"], 1) / 1e12,
    }


# --------------------------------------------------------------------------- command line


def run_benchmark(args) -> dict:
    from nidar_mi.scenegen import generate

    work = tempfile.mkdtemp(prefix="bench_scaling-")
    try:
        scene_dir = os.path.join(work, "scenes")
        generate(scene_dir, args.scenes, 0, progress=False)
        files = sorted(
            os.path.join(scene_dir, f) for f in os.listdir(scene_dir) if f.endswith(".xml")
        )
        result = {
            "settings": {
                k: getattr(args, k)
                for k in ("scenes", "repeats", "spp", "width", "height", "cols", "variant")
            },
            "machine": {
                "cpus": len(os.sched_getaffinity(0)),
                "load_avg_start": os.getloadavg(),
                "python": platform.python_version(),
                "platform": platform.platform(),
            },
        }
        print("stages ...", file=sys.stderr)
        result["stages"] = _stages(files, os.path.join(work, "stages"), args)
        print("kernel cache ...", file=sys.stderr)
        result["kernel_cache"] = _kernel_cache(files[0], work, args)
        print("modes ...", file=sys.stderr)
        result["modes"] = _modes(scene_dir, work, args)
        print("ray ...", file=sys.stderr)
        result["ray"] = _ray(args)
        result["sizing"] = sizing(result["stages"])
        result["machine"]["load_avg_end"] = os.getloadavg()
        return result
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _report(r: dict) -> str:
    m = r["stages"]["median_after_first"]
    lines = [
        f"per scene (median of {len(r['stages']['scenes']) - 1} after the first; wall s):",
        f"  load {m['load_s']:.2f}  scan {m['scan_s']:.2f}  rgb {m['camera_rgb_s']:.2f}  "
        f"nir {m['camera_nir_s']:.2f}  depth {m['camera_depth_s']:.2f}  "
        f"write {m['lidar_write_s'] + m['camera_write_s']:.2f}  render total {m['render_wall_s']:.2f}"
        f" (CPU {m['render_cpu_s']:.2f})",
        f"  frame: project {m['frame_project_wall_s']:.3f}  write {m['frame_write_wall_s']:.3f}"
        f"   NIDAR {m['nidar_wall_s']:.3f} (CPU {m['nidar_cpu_s']:.3f}; model load "
        f"{r['stages']['model_load_s']:.2f})",
        f"  bytes: render folder {m['render_bytes'] / 1e6:.2f} MB, frame "
        f"{m['frame_bytes'] / 1e6:.2f} MB ({m['frame_compressed_bytes'] / 1e6:.2f} MB compressed,"
        f" {m['frame_write_compressed_wall_s']:.3f} s to write)",
        f"first scene in this process: render {r['stages']['first_scene']['render_wall_s']:.2f} s",
        f"kernel cache, first scene in a fresh process: cold {r['kernel_cache']['cold_render_s']:.2f}"
        f" s, warm {r['kernel_cache']['warm_render_s']:.2f} s (render only)",
        "dataset command from scratch (median wall s; speed-up vs serial, same round):",
    ]
    md = r["modes"]
    for mode, wall in md["median_wall_s"].items():
        lines.append(
            f"  {mode:10s} {wall:7.1f} s  x{md['speedup_vs_serial'][mode]:.2f};  first scene done "
            f"at {md['median_first_done_s'][mode]:.1f} s; then {md['median_steady_s_per_scene'][mode]:.2f}"
            f" s per scene  x{md['steady_speedup_vs_serial'][mode]:.2f}"
        )
    ray = r["ray"]
    lines += [
        f"ray {ray['ray_version']}: import {ray['import_ray_s']:.2f} s (nidar_mi.render_dataset "
        f"{ray['import_nidar_mi_render_dataset_s']:.2f} s), {ray['ray_installed_bytes'] / 1e6:.0f} MB "
        f"installed, init {ray['init_s']:.1f} s, shutdown {ray['shutdown_s']:.1f} s, "
        f"{ray['overhead_per_task_ms']:.2f} ms per task, worker set-up first "
        f"{ray['worker_first_setup_s']:.2f} s / again {ray['worker_setup_again_s'] * 1e3:.1f} ms",
    ]
    s = r["sizing"]
    lines.append(
        f"10^6 frames: {s['core_hours']:.0f} core-hours (+{s['nidar_core_hours']:.0f} for NIDAR), "
        f"{s['terabytes']:.2f} TB ({s['frame_only_terabytes']:.2f} TB frames only)"
    )
    lines.append(
        f"load average: start {r['machine']['load_avg_start']}, end {r['machine']['load_avg_end']}"
    )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="bench_scaling.py", description=__doc__.splitlines()[0])
    p.add_argument("--scenes", type=int, default=6, help="generated scenes (default 6)")
    p.add_argument("--repeats", type=int, default=3, help="rounds of each timing (default 3)")
    p.add_argument("--spp", type=int, default=16, help="camera samples per pixel (default 16)")
    p.add_argument("--width", type=int, default=None, help="camera width (scene default 480)")
    p.add_argument("--height", type=int, default=None, help="camera height (scene default 270)")
    p.add_argument("--cols", type=int, default=None, help="LiDAR columns (preset default)")
    p.add_argument("--noop-tasks", type=int, default=200, help="no-op tasks for Ray's overhead")
    p.add_argument("--variant", default="llvm_ad_spectral", help="Mitsuba variant")
    p.add_argument("--json", default=None, help="write the results here")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    for name in ("scenes", "repeats", "spp", "noop_tasks"):
        if getattr(args, name) < 1:
            print(f"error: --{name.replace('_', '-')} must be >= 1", file=sys.stderr)
            return 2
    if args.scenes < 2:
        print("error: --scenes must be >= 2 (the first scene warms the kernels)", file=sys.stderr)
        return 2
    try:
        import ray  # noqa: F401
    except ImportError:
        print("error: Ray is not importable: pip install -e '.[ray]'", file=sys.stderr)
        return 2
    result = run_benchmark(args)
    print(_report(result))
    if args.json:
        os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(result, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
