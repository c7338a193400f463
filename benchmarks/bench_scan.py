"""Scan speed: nidar_mi's full LiDAR scan against the bare ray cast on the same rays.

``python benchmarks/bench_scan.py [--repeats 9] [--rings 128] [--cols 2048 8192]
[--variants llvm_ad_spectral cuda_ad_spectral] [--json out.json]``

The scene is :mod:`city_scene`'s procedural city (116 200 triangles by default: a height-field
terrain and box buildings), loaded through :func:`nidar_mi.scene.load_scene` with a diffuse
spectral material per mesh and a ``lidar`` sensor (the ``os1_128`` preset's uniform table for 128
rings, else uniform rings over the same ±22.5°; ``cols`` columns). For every variant and size,
in one run:

* **full scan**: :func:`nidar_mi.lidar.scan.scan` (beam pattern and pose, ray cast with the glass
  passes, monostatic BSDF at the laser wavelength, return model, noise and dropout draws,
  detection, material and shape look-ups, read back to NumPy). The noise σ are kernel inputs,
  so the kernels do the same work whatever their values; range noise is 0 here so that ranges
  can be compared with the bare cast's.
* **bare cast**: ``scene.ray_intersect_preliminary`` on the same rays (origin and unit world
  direction of every beam, from the sensor's pose), its distance, primitive, shape and
  barycentrics evaluated and the distance read back to NumPy.
* **Open3D** (optional, when importable): ``RaycastingScene.cast_rays`` on a prepared (N, 6)
  float32 tensor of the same rays.
* **weather** (``--weather``): the full scan of the same rays in fog (MOR 100 m), rain
  (20 mm/h) and snow (2 mm/h) (:mod:`nidar_mi.lidar.weather_returns`: extinction, soft return, sampled
  particles, their detection), reported as the ratio **weather / clear scan** (seconds).

Every method is warmed up (Dr.Jit compiles its kernels on the first call, Open3D builds its BVH
on the first cast), then timed ``repeats`` times, interleaved so that all see the same machine
load; medians are reported and the ratio **full scan / bare cast** (rays/s) is formed from the
medians of the same run. Sanity line: the scan's ranges against the bare cast's distances where
both hit.
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import numpy as np

try:  # python -m benchmarks.bench_scan
    from .city_scene import load_city, world_rays
except ImportError:  # python benchmarks/bench_scan.py
    from city_scene import load_city, world_rays

__all__ = ["run_benchmark", "run_all", "build_parser", "main"]


def _median(values: list[float]) -> float:
    return float(statistics.median(values))


def _kernel_ms(fn) -> float:
    """Milliseconds the Dr.Jit kernels launched by ``fn()`` spent executing."""
    import drjit as dr

    dr.set_flag(dr.JitFlag.KernelHistory, True)
    try:
        dr.kernel_history()  # drop older entries
        fn()
        history = dr.kernel_history()
    finally:
        dr.set_flag(dr.JitFlag.KernelHistory, False)
    return float(sum(k.get("execution_time", 0.0) for k in history))


def _open3d_caster(meshes: dict, rays_np: np.ndarray):
    """Open3D's ``cast_rays`` on the same triangles and rays, or None without Open3D."""
    try:
        import open3d as o3d
    except (ImportError, OSError):  # not installed, or a shared library missing
        return None
    o3d_scene = o3d.t.geometry.RaycastingScene()
    for v, f in meshes.values():
        o3d_scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f.astype(np.uint32)))
    o3d_rays = o3d.core.Tensor(rays_np)

    def run_o3d():
        return o3d_scene.cast_rays(o3d_rays)["t_hit"].numpy()

    return run_o3d


def _time_interleaved(methods: dict, repeats: int) -> tuple[dict, dict, dict]:
    """First-call seconds, the seconds of every timed run and the scan's stage timings."""
    first: dict[str, float] = {}
    for key, fn in methods.items():
        t0 = time.perf_counter()  # first call: kernel compilation (or cache load), BVH build
        fn()
        first[key] = time.perf_counter() - t0
    for fn in methods.values():
        fn()
    secs: dict[str, list[float]] = {key: [] for key in methods}
    stages: dict[str, list[float]] = {}
    for _ in range(repeats):
        for key, fn in methods.items():
            t0 = time.perf_counter()
            out = fn()
            secs[key].append(time.perf_counter() - t0)
            if key == "scan":
                for stage, t in out.timings.items():
                    stages.setdefault(stage, []).append(t)
    return first, secs, stages


#: The weather of ``--weather``: one condition of each kind.
WEATHER = {"fog": {"fog": 100.0}, "rain": {"rain": 20.0}, "snow": {"snow": 2.0}}


def run_benchmark(
    *,
    repeats: int = 9,
    rings: int = 128,
    cols: int = 2048,
    grid: int = 241,
    variant: str,
    weather: bool = False,
) -> dict:
    """Build the city, scan it and cast the same rays bare (and with Open3D when importable).

    Args:
        repeats: timed runs of each (median reported); >= 1.
        rings, cols: the LiDAR's beam grid.
        grid: terrain vertices per side (see :func:`city_mesh`).
        variant: Mitsuba variant for nidar_mi.
        weather: also time the scan in each of :data:`WEATHER` (the ratio weather / clear).

    Returns:
        A JSON-safe dict: rays, triangles, median seconds and rays/s of each method, the ratio
        full scan / bare cast (rays/s), median stage timings of the scan, the Dr.Jit kernel time
        of one scan, first-call times, hit fractions, the range agreement, and the machine.
    """
    import drjit as dr
    import mitsuba as mi

    from nidar_mi.lidar.scan import scan

    loaded, meshes = load_city(rings=rings, cols=cols, grid=grid, variant=variant)
    scene, sensor = loaded.scene, loaded.lidars[0]
    rays_np = world_rays(sensor)
    n = len(rays_np)
    mi_rays = mi.Ray3f(
        mi.Point3f(*(rays_np[:, k] for k in range(3))),
        mi.Vector3f(*(rays_np[:, k] for k in range(3, 6))),
    )

    def run_scan():
        return scan(scene, sensor)

    def run_bare():
        pi = scene.ray_intersect_preliminary(mi_rays)
        dr.eval(pi.t, pi.prim_index, pi.shape_index, pi.prim_uv)
        return pi.t.numpy()

    methods = {"scan": run_scan, "bare": run_bare}
    if weather:
        from nidar_mi.weather import Weather

        def in_weather(values: dict):
            w = Weather(**values)
            return lambda: scan(scene, sensor, weather=w)

        methods |= {name: in_weather(values) for name, values in WEATHER.items()}
    run_o3d = _open3d_caster(meshes, rays_np)
    if run_o3d is not None:
        methods["open3d"] = run_o3d
    first, secs, stages = _time_interleaved(methods, repeats)
    out = {
        "rays": n,
        "rings": rings,
        "cols": cols,
        "triangles": int(sum(len(f) for _, f in meshes.values())),
        "repeats": repeats,
        "variant": variant,
        **_summary(secs, n),
        "scan_stage_median_s": {k: _median(v) for k, v in stages.items()},
        "scan_kernel_s": _kernel_ms(run_scan) / 1e3,
        "first_call_s": first,
        "all_s": secs,
    }
    out.update(_agreement(run_scan(), run_bare(), run_o3d))
    return out


def _summary(secs: dict[str, list[float]], n: int) -> dict:
    """Medians, minima, rays/s and the ratios of the methods' timings."""
    med = {k: _median(v) for k, v in secs.items()}
    out = {
        "median_s": med,
        "min_s": {k: min(v) for k, v in secs.items()},
        "rays_per_s": {k: n / v for k, v in med.items()},
        "ratio_scan_over_bare": med["bare"] / med["scan"],
    }
    if "open3d" in med:
        out["ratio_scan_over_open3d"] = med["open3d"] / med["scan"]
    weather = {k: med[k] / med["scan"] for k in WEATHER if k in med}
    if weather:
        out["ratio_weather_over_clear"] = weather
    return out


def _agreement(res, t_bare: np.ndarray, run_o3d) -> dict:
    """Hit fractions and the scan's ranges against the bare cast's distances (and Open3D's)."""
    both = res.valid.reshape(-1) & np.isfinite(t_bare)
    diff = np.abs(res.range.reshape(-1)[both] - t_bare[both])
    agree = {
        "compared": int(both.sum()),
        "scan_vs_bare_median": float(np.median(diff)) if diff.size else None,
        "scan_vs_bare_max": float(diff.max()) if diff.size else None,
        "hit_mismatch": int((res.hit.reshape(-1) != np.isfinite(t_bare)).sum()),
    }
    if run_o3d is not None:
        t_o3d = run_o3d()
        o3d_both = np.isfinite(t_bare) & np.isfinite(t_o3d)
        o3d_diff = np.abs(t_bare[o3d_both] - t_o3d[o3d_both])
        agree["bare_vs_open3d_median"] = float(np.median(o3d_diff)) if o3d_diff.size else None
    hits = {
        "scan_hit": float(res.hit.mean()),
        "scan_valid": float(res.valid.mean()),
        "bare": float(np.isfinite(t_bare).mean()),
    }
    return {"hit_fraction": hits, "agreement_m": agree}


def run_all(*, variants: list[str], cols: list[int], **kwargs) -> dict:
    """:func:`run_benchmark` for every variant and column count; with the machine."""
    from nidar_mi.backend import set_variant

    runs = []
    for v in variants:
        set_variant(v)  # the benchmark is an entry point: it chooses the variant
        runs += [run_benchmark(variant=v, cols=c, **kwargs) for c in cols]
    return {"runs": runs, "machine": _machine()}


def _machine() -> dict:
    import drjit
    import mitsuba

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    try:
        import open3d

        o3d_version = open3d.__version__
    except (ImportError, OSError):
        o3d_version = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "mitsuba": mitsuba.__version__,
        "drjit": drjit.__version__,
        "open3d": o3d_version,
    }


_LABELS = {
    "scan": "full scan",
    "bare": "bare cast",
    "open3d": "Open3D cast_rays",
    "fog": "scan in fog",
    "rain": "scan in rain",
    "snow": "scan in snow",
}


def _report_run(r: dict) -> list[str]:
    rps, med = r["rays_per_s"], r["median_s"]
    agree = r["agreement_m"]
    lines = [
        f"{r['variant']}: {r['rings']}x{r['cols']} = {r['rays']} rays, "
        f"{r['triangles']} triangles, median of {r['repeats']}",
        "                      median ms  Mrays/s   (min ms)",
        *(
            f"  {_LABELS[k]:20s} {med[k] * 1e3:8.1f} {rps[k] / 1e6:8.2f}   ({r['min_s'][k] * 1e3:.1f})"
            for k in med
        ),
        f"  ratio full scan / bare cast (rays/s): {r['ratio_scan_over_bare']:.2f}",
    ]
    if "ratio_scan_over_open3d" in r:
        lines.append(f"  ratio full scan / Open3D (rays/s): {r['ratio_scan_over_open3d']:.2f}")
    for name, ratio in r.get("ratio_weather_over_clear", {}).items():
        lines.append(f"  ratio scan in {name} / clear scan (s): {ratio:.2f}")
    lines += [
        "  scan stages (median ms): "
        + ", ".join(f"{k} {v * 1e3:.1f}" for k, v in r["scan_stage_median_s"].items()),
        f"  scan Dr.Jit kernel execution: {r['scan_kernel_s'] * 1e3:.1f} ms",
        f"  hit fraction: scan {r['hit_fraction']['scan_hit']:.3f}, "
        f"bare {r['hit_fraction']['bare']:.3f}",
        f"  range |scan - bare| over {agree['compared']} returns: "
        f"median {agree['scan_vs_bare_median']:.2e} m, max {agree['scan_vs_bare_max']:.2e} m",
    ]
    return lines


def _report(result: dict) -> str:
    m = result["machine"]
    lines = [f"{m['cpu']} ({m['cores']} cores), Mitsuba {m['mitsuba']}, Dr.Jit {m['drjit']}"]
    for r in result["runs"]:
        lines += _report_run(r)
    lines.append("variant            rays      full ms   bare ms   full / bare")
    lines += [
        f"{r['variant']:18s} {r['rings']}x{r['cols']:<8d} {r['median_s']['scan'] * 1e3:8.1f} "
        f"{r['median_s']['bare'] * 1e3:9.1f}   {r['ratio_scan_over_bare']:.2f}"
        for r in result["runs"]
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bench_scan.py",
        description="Time nidar_mi's full LiDAR scan against the bare ray cast on the same rays.",
    )
    p.add_argument("--repeats", type=int, default=9, help="timed runs of each (median)")
    p.add_argument("--rings", type=int, default=128, help="LiDAR channels")
    p.add_argument(
        "--cols", type=int, nargs="+", default=[2048, 8192], help="columns per scan (sizes)"
    )
    p.add_argument("--grid", type=int, default=241, help="terrain vertices per side")
    p.add_argument(
        "--variants",
        nargs="+",
        default=["llvm_ad_spectral"],
        help="Mitsuba variants (default: llvm_ad_spectral)",
    )
    p.add_argument(
        "--weather",
        action="store_true",
        help="also time the scan in fog, rain and snow (ratio weather / clear)",
    )
    p.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    return p


def _check_args(args) -> None:
    from nidar_mi.errors import NidarError

    for name in ("repeats", "rings"):
        if getattr(args, name) < 1:
            raise NidarError(f"--{name} must be >= 1 (got {getattr(args, name)})")
    if min(args.cols) < 1:
        raise NidarError(f"--cols must be >= 1 (got {min(args.cols)})")
    if args.grid < 2:
        raise NidarError(f"--grid must be >= 2 (got {args.grid})")
    import mitsuba as mi

    for v in args.variants:
        if v not in mi.variants():
            raise NidarError(f"variant '{v}' is not available (have: {', '.join(mi.variants())})")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.errors import NidarError

    try:
        _check_args(args)
        result = run_all(
            variants=args.variants,
            cols=args.cols,
            repeats=args.repeats,
            rings=args.rings,
            grid=args.grid,
            weather=args.weather,
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
