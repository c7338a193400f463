"""Scan speed: nidar_mi's full LiDAR scan against Open3D's bare ``RaycastingScene.cast_rays``.

``python benchmarks/bench_scan.py [--repeats 5] [--rings 128 --cols 2048] [--json out.json]``

The scene is :mod:`city_scene`'s procedural city (116 200 triangles by default: a height-field
terrain and box buildings), loaded through :func:`nidar_mi.scene.load_scene` with a diffuse
spectral material per mesh and a ``lidar`` sensor (the ``os1_128`` preset's uniform table for 128
rings, else uniform rings over the same ±22.5°; ``cols`` columns). Open3D gets the same vertex and
index arrays and the same rays (origin and unit world direction of every beam, from the sensor's
pose).

Both sides are warmed up (Dr.Jit compiles its kernels on the first call, Open3D builds its BVH
on the first cast), then timed ``repeats`` times, interleaved so that both see the same machine
load; the median is reported. Timed work:

* nidar_mi full scan: :func:`nidar_mi.lidar.scan.scan` (ray cast with the glass passes,
  monostatic BSDF at the laser wavelength, return model, detection and noise draws, read back to
  NumPy). The noise σ are opaque kernel inputs, so the kernels do the same work whatever their
  values; range noise is 0 here so that ranges can be compared with Open3D's.
* nidar_mi bare cast (for reference): ``scene.ray_intersect_preliminary`` on the same rays, read
  back to NumPy.
* Open3D: ``cast_rays`` on a prepared (N, 6) float32 tensor (its results are host tensors).

Sanity line: median and maximum absolute difference of the hit distances where both hit.
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

__all__ = ["run_benchmark", "build_parser", "main"]


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


def run_benchmark(
    *, repeats: int = 5, rings: int = 128, cols: int = 2048, grid: int = 241, variant: str
) -> dict:
    """Build the city, run both ray casters, time them.

    Args:
        repeats: timed runs of each (median reported); >= 1.
        rings, cols: the LiDAR's beam grid.
        grid: terrain vertices per side (see :func:`city_mesh`).
        variant: Mitsuba variant for nidar_mi.

    Returns:
        A JSON-safe dict: rays, triangles, rays/s and median seconds of each method, the ratio
        (full scan rays/s over Open3D's), median stage timings of the scan, the Dr.Jit kernel
        time of one scan, first-call times, hit fractions, the hit-distance agreement, and the
        machine and versions.
    """
    import drjit as dr
    import mitsuba as mi
    import open3d as o3d

    from nidar_mi.lidar.scan import scan

    loaded, meshes = load_city(rings=rings, cols=cols, grid=grid, variant=variant)
    scene, sensor = loaded.scene, loaded.lidars[0]
    rays_np = world_rays(sensor)
    n = len(rays_np)

    o3d_scene = o3d.t.geometry.RaycastingScene()
    for v, f in meshes.values():
        o3d_scene.add_triangles(o3d.core.Tensor(v), o3d.core.Tensor(f.astype(np.uint32)))
    o3d_rays = o3d.core.Tensor(rays_np)
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

    def run_o3d():
        return o3d_scene.cast_rays(o3d_rays)["t_hit"].numpy()

    first: dict[str, float] = {}
    for key, fn in (("scan", run_scan), ("bare", run_bare), ("open3d", run_o3d)):
        t0 = time.perf_counter()  # first call: kernel compilation (or cache load), BVH build
        fn()
        first[key] = time.perf_counter() - t0
    res, t_bare, t_o3d = run_scan(), run_bare(), run_o3d()

    secs: dict[str, list[float]] = {"scan": [], "bare": [], "open3d": []}
    stages: dict[str, list[float]] = {}
    for _ in range(repeats):
        for key, fn in (("scan", run_scan), ("bare", run_bare), ("open3d", run_o3d)):
            t0 = time.perf_counter()
            out = fn()
            secs[key].append(time.perf_counter() - t0)
            if key == "scan":
                for stage, t in out.timings.items():
                    stages.setdefault(stage, []).append(t)

    kernel_ms = _kernel_ms(run_scan)

    # ------------------------------------------------------------------ agreement
    rng_scan = res.range.reshape(-1)
    both = res.valid.reshape(-1) & np.isfinite(t_o3d)
    diff = np.abs(rng_scan[both] - t_o3d[both])
    bare_both = np.isfinite(t_bare) & np.isfinite(t_o3d)
    bare_diff = np.abs(t_bare[bare_both] - t_o3d[bare_both])
    med = {k: _median(v) for k, v in secs.items()}
    return {
        "rays": n,
        "rings": rings,
        "cols": cols,
        "triangles": int(sum(len(f) for _, f in meshes.values())),
        "repeats": repeats,
        "variant": variant,
        "median_s": med,
        "min_s": {k: min(v) for k, v in secs.items()},
        "rays_per_s": {k: n / v for k, v in med.items()},
        "ratio_scan_over_open3d": med["open3d"] / med["scan"],
        "ratio_bare_over_open3d": med["open3d"] / med["bare"],
        "ratio_scan_over_open3d_min": min(secs["open3d"]) / min(secs["scan"]),
        "scan_stage_median_s": {k: _median(v) for k, v in stages.items()},
        "scan_kernel_s": kernel_ms / 1e3,
        "first_call_s": first,
        "all_s": secs,
        "hit_fraction": {
            "scan_hit": float(res.hit.mean()),
            "scan_valid": float(res.valid.mean()),
            "open3d": float(np.isfinite(t_o3d).mean()),
        },
        "agreement_m": {
            "compared": int(both.sum()),
            "scan_vs_open3d_median": float(np.median(diff)) if diff.size else None,
            "scan_vs_open3d_max": float(diff.max()) if diff.size else None,
            "bare_vs_open3d_median": float(np.median(bare_diff)) if bare_diff.size else None,
            "hit_mismatch": int((res.hit.reshape(-1) != np.isfinite(t_o3d)).sum()),
        },
        "machine": _machine(),
    }


def _machine() -> dict:
    import drjit
    import mitsuba
    import open3d

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "mitsuba": mitsuba.__version__,
        "drjit": drjit.__version__,
        "open3d": open3d.__version__,
    }


def _report(r: dict) -> str:
    rps, med = r["rays_per_s"], r["median_s"]
    agree = r["agreement_m"]
    lines = [
        f"{r['rings']}x{r['cols']} = {r['rays']} rays, {r['triangles']} triangles, "
        f"median of {r['repeats']}, {r['variant']}, {r['machine']['cpu']} "
        f"({r['machine']['cores']} cores)",
        "                      median ms  Mrays/s   (min ms)",
        *(
            f"  {label:20s} {med[k] * 1e3:8.1f} {rps[k] / 1e6:8.2f}   ({r['min_s'][k] * 1e3:.1f})"
            for k, label in (
                ("scan", "nidar_mi full scan"),
                ("bare", "nidar_mi bare cast"),
                ("open3d", "Open3D cast_rays"),
            )
        ),
        f"  ratio full scan / Open3D (rays/s): {r['ratio_scan_over_open3d']:.2f} (target >= 1: "
        f"{'met' if r['ratio_scan_over_open3d'] >= 1.0 else 'not met'}); "
        f"of the fastest runs: {r['ratio_scan_over_open3d_min']:.2f}",
        "  scan stages (median ms): "
        + ", ".join(f"{k} {v * 1e3:.1f}" for k, v in r["scan_stage_median_s"].items()),
        f"  scan Dr.Jit kernel execution: {r['scan_kernel_s'] * 1e3:.1f} ms "
        f"(the rest of the scan is host-side work)",
        f"  hit fraction: scan {r['hit_fraction']['scan_hit']:.3f}, "
        f"Open3D {r['hit_fraction']['open3d']:.3f}",
        f"  hit distance |scan - Open3D| over {agree['compared']} returns: "
        f"median {agree['scan_vs_open3d_median']:.2e} m, max {agree['scan_vs_open3d_max']:.2e} m",
    ]
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bench_scan.py",
        description="Time nidar_mi's full LiDAR scan against Open3D's bare cast_rays.",
    )
    p.add_argument("--repeats", type=int, default=5, help="timed runs of each (median)")
    p.add_argument("--rings", type=int, default=128, help="LiDAR channels")
    p.add_argument("--cols", type=int, default=2048, help="columns per scan")
    p.add_argument("--grid", type=int, default=241, help="terrain vertices per side")
    p.add_argument(
        "--variant", default="llvm_ad_spectral", help="Mitsuba variant (default: llvm_ad_spectral)"
    )
    p.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    from nidar_mi.errors import NidarError

    try:
        for name in ("repeats", "rings", "cols"):
            if getattr(args, name) < 1:
                raise NidarError(f"--{name} must be >= 1 (got {getattr(args, name)})")
        if args.grid < 2:
            raise NidarError(f"--grid must be >= 2 (got {args.grid})")
        try:
            import open3d  # noqa: F401
        except (ImportError, OSError) as e:  # not installed, or a shared library missing
            raise NidarError(
                f"Open3D is not importable ({e}); install it with: pip install -e '.[bench]'"
            ) from None
        from nidar_mi.backend import set_variant

        set_variant(args.variant)
        result = run_benchmark(
            repeats=args.repeats,
            rings=args.rings,
            cols=args.cols,
            grid=args.grid,
            variant=args.variant,
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
