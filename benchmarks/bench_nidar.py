"""NIDAR inference speed: seconds per frame for pseudo-NIR, IRNet and the point assignment.

``python benchmarks/bench_nidar.py [--threads 2] [--repeats 5] [--sizes 1242x375,1600x900]
[--weights DIR] [--configs before,fold,fold+cl,fold+cl+half] [--devices auto]
[--profile FILE|context-gbm|context-mlp] [--json out.json]``

Per frame, image size and device, the stages are timed separately, and the whole frame (after one warm-up call per
configuration, size and device, ``repeats`` rounds that run every cell in turn, so that all see
the same machine load; medians of the wall time and of the process CPU time):

* ``pseudo_nir``: 8-bit sRGB -> linear exposure-normalised RGB -> STN -> pseudo-NIR
  (:func:`nidar_mi.nidar.infer.pseudo_nir`, on the device: the image is uploaded as 8 bits);
* ``irnet``: pseudo-NIR -> R, S, Î (:func:`nidar_mi.nidar.infer.run_irnet`; the maps stay on
  the device);
* ``end_to_end``: :meth:`nidar_mi.nidar.pipeline.NidarModel.point_intensity` on the image
  and the cloud, as ``assign`` and ``render --intensity nidar`` run it: the networks compute
  only the maps it samples, and on the CPU they run beside the assignment's geometry
  (locating the points in the camera, their incidence); the figure a frame costs;
* ``assign``: :meth:`nidar_mi.nidar.pipeline.NidarModel.point_intensity` with precomputed maps,
  timed in its stages (``assign`` is their sum): ``sampling`` (R brought to the host, the
  point cloud projected into the camera, the occlusion test against the cloud's own z-buffer
  and bilinear sampling of R: :func:`nidar_mi.geometry.sample_cameras`), ``normals`` (the
  incidence cosines of the observed points, :func:`nidar_mi.geometry.incidence_cosine`; for a
  ``context`` profile their whole local geometry,
  :func:`nidar_mi.geometry.local_features.local_geometry`), ``image`` (a ``context`` profile's
  image inputs and NIDAR's maps at the observed points,
  :func:`nidar_mi.profiles.inputs.camera_inputs`; 0 for another profile) and ``profile`` (the
  profile at the observed points).

``--profile``: the profile applied (default: the weights' own): a profile file, or
``context-gbm`` / ``context-mlp``, a ``context`` profile of its default inputs (its trees, or its small
head) with the form's own settings, fitted on the benchmark's procedural frame (an intensity
made up from the range, the incidence and the image; the time a profile takes depends on its
size and inputs, not on what it learnt).

``--devices``: ``cpu``, ``cuda`` or both, comma-separated; ``auto`` (default): the CPU, and
CUDA when torch sees a GPU. The networks and the assignment run on that device.

Inputs are procedural and need no data: a textured street-like image of the given size and an
HDL-64E-like cloud (64 rings x 2048 columns over a ground plane at -1.73 m and a wall 30 m
ahead, 131 072 points) seen by a KITTI-like camera (focal length 0.58 x width).

Configurations (``--configs``):

* ``before``: the networks as :func:`nidar_mi.nidar.model_io.load_pipeline` loads them;
* ``fold``: BatchNorm folded into the convolutions (:func:`nidar_mi.nidar.fold.fold_batchnorm`);
* ``fold+cl``: and channels-last memory;
* ``fold+cl+half`` (any ``+s<scale>``, e.g. ``+s0.5``, or ``+half``): and inference at that
  fraction of the image resolution (:mod:`nidar_mi.nidar.infer`).

torch uses ``--threads`` threads (2 by default, the CI machine's cores).
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time

import numpy as np

__all__ = ["build_parser", "main", "run_benchmark", "street_image", "hdl64e_cloud"]

DEFAULT_SIZES = ((1242, 375), (1600, 900))
DEFAULT_CONFIGS = ("before", "fold", "fold+cl", "fold+cl+half")
STEPS = ("pseudo_nir", "irnet", "sampling", "normals", "image", "profile")
#: The stages of the point assignment, summed as ``assign``.
ASSIGN = ("sampling", "normals", "image", "profile")
#: The context profiles ``--profile`` can fit on the procedural frame, by name -> model kind.
SYNTHETIC_PROFILES = {"context-gbm": "gbm", "context-mlp": "mlp"}


def street_image(width: int, height: int, seed: int = 0) -> np.ndarray:
    """(H, W, 3) uint8 procedural street image: sky, façade blocks, road, noise texture."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:height, 0:width].astype(np.float64)
    img = np.empty((height, width, 3))
    img[:] = [0.55, 0.65, 0.85]
    horizon = int(0.45 * height)
    img[horizon:] = [0.3, 0.3, 0.32]
    for _ in range(12):
        w = int(rng.uniform(0.03, 0.15) * width) + 1
        x0 = int(rng.uniform(0, width - w))
        top = int(rng.uniform(0.05, 0.4) * height)
        img[top:horizon, x0 : x0 + w] = rng.uniform(0.1, 0.9, 3)
    img += 0.05 * np.sin(x[..., None] / 7.0) * np.cos(y[..., None] / 5.0)
    img += rng.normal(0.0, 0.02, img.shape)
    return np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)


def hdl64e_cloud(cols: int = 2048) -> np.ndarray:
    """(64 * cols, 3) float64 points: HDL-64E beams hitting a ground plane and a wall at x = 30 m."""
    from nidar_mi.lidar.pattern import beam_directions, elevation_table

    d = beam_directions(elevation_table("hdl64e"), cols).reshape(-1, 3).astype(np.float64)
    t = np.full(len(d), 80.0)
    down = d[:, 2] < -1e-6
    t[down] = np.minimum(t[down], 1.73 / -d[down, 2])
    ahead = d[:, 0] > 1e-6
    t[ahead] = np.minimum(t[ahead], 30.0 / d[ahead, 0])
    return d * t[:, None]


def kitti_like_camera(width: int, height: int):
    """A forward camera 0.27 m ahead of the LiDAR (KITTI's axes), focal length 0.58 x width."""
    from nidar_mi.geometry import CameraModel

    f = 0.58 * width
    K = np.array([[f, 0.0, width / 2 - 0.5], [0.0, f, height / 2 - 0.5], [0.0, 0.0, 1.0]])
    T = np.eye(4)
    T[:3, :3] = [[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]  # x fwd -> z, y left -> -x
    T[:3, 3] = [0.0, -0.08, -0.27]
    return CameraModel(K=K, width=width, height=height, T_cam_lidar=T, name="cam")


def _parse_config(name: str) -> dict:
    parts = name.split("+")
    cfg = {"fold": False, "channels_last": False, "scale": 1.0}
    if parts[0] != "before":
        for p in parts:
            if p == "fold":
                cfg["fold"] = True
            elif p == "cl":
                cfg["channels_last"] = True
            elif p == "half":
                cfg["scale"] = 0.5
            elif p.startswith("s"):
                cfg["scale"] = float(p[1:])
            else:
                raise ValueError(f"unknown configuration part {p!r} in {name!r}")
    return cfg


def _time(fn, sync=None) -> tuple[float, float, object]:
    """Wall and process CPU seconds of one call (until ``sync()`` returns, when given: a CUDA
    device's work is asynchronous), and its result."""
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    if sync is not None:
        sync()
    return time.perf_counter() - t0, time.process_time() - c0, out


def _assign_stages(model, xyz, cam, maps, out: dict, profile=None, rgb=None):
    """:meth:`NidarModel.point_intensity` of ``profile`` (None: the default one), stage by
    stage, timed into ``out``; ``maps`` on the networks' device (``sampling`` brings R to the
    host; with ``pseudo_nir``; ``rgb`` the image, for a ``context`` profile). Returns the number
    of observed points."""
    from nidar_mi.geometry import incidence_cosine, sample_cameras

    profile = profile or model.default_profile()
    if profile.reads_context:
        return _context_stages(xyz, cam, maps, out, profile, rgb)

    def sample():
        r = maps["R"]
        r = r.detach().cpu().numpy() if hasattr(r, "detach") else r
        return sample_cameras(xyz, [cam], [r])

    wall, cpu, (values, observed, _) = _time(sample)
    out["sampling"] = (wall, cpu)
    observed = observed & np.isfinite(values)
    p = xyz[observed]
    wall, cpu, cos = _time(lambda: incidence_cosine(p))
    out["normals"] = (wall, cpu)
    out["image"] = (0.0, 0.0)
    el = np.degrees(np.arctan2(p[:, 2], np.hypot(p[:, 0], p[:, 1])))
    rng = np.linalg.norm(p, axis=1)
    out["profile"] = _time(
        lambda: profile(values[observed], rng, elevation_deg=el, cos_incidence=cos)
    )[:2]
    return int(observed.sum())


def _context_stages(xyz, cam, maps, out: dict, profile, rgb) -> int:
    """:func:`_assign_stages` of a ``context`` profile (on the CPU, as it runs): sampling, the
    observed points' local geometry, their image inputs and maps, the profile."""
    from nidar_mi.geometry import locate_in_cameras, sample_cameras
    from nidar_mi.geometry.local_features import local_geometry
    from nidar_mi.profiles.inputs import NIDAR_MAPS, camera_inputs, return_inputs, scales_read

    scales = scales_read(profile.mapping.features)
    host = [
        {k: np.asarray(v.detach().cpu() if hasattr(v, "detach") else v) for k, v in maps.items()}
    ]

    def sample():
        sightings = locate_in_cameras(xyz, [cam])
        return sightings, sample_cameras(xyz, [cam], [host[0]["R"]], sightings=sightings)

    wall, cpu, (sightings, (values, observed, cam_idx)) = _time(sample)
    out["sampling"] = (wall, cpu)
    p = xyz[observed]
    wall, cpu, geo = _time(lambda: local_geometry(p, scales, notes=[]))
    out["normals"] = (wall, cpu)
    keys = [{k: host[0][k] for k in NIDAR_MAPS}]
    run = lambda: camera_inputs(sightings, [rgb], np.where(observed, cam_idx, -1), keys)  # noqa: E731
    wall, cpu, pics = _time(run)
    out["image"] = (wall, cpu)
    named = return_inputs(p, None, geo, scales) | {k: v[observed] for k, v in pics.items()}
    out["profile"] = _time(lambda: profile(values[observed], named["range_m"], context=named))[:2]
    return int(observed.sum())


def synthetic_profile(model, kind: str, width: int = 1242, height: int = 375):
    """A ``context`` profile of its default inputs (``kind`` ``gbm`` or ``mlp``, the form's own
    settings) fitted on the procedural frame of that size: its intensity made up from the
    range, the incidence and the image's luminance, with noise (seeded)."""
    from nidar_mi.geometry import locate_in_cameras, sample_cameras
    from nidar_mi.profiles import SensorProfile, fit
    from nidar_mi.profiles.inputs import NIDAR_MAPS, camera_inputs, return_inputs

    rgb, cam, xyz = street_image(width, height), kitti_like_camera(width, height), hdl64e_cloud()
    sightings = locate_in_cameras(xyz, [cam])
    maps = [model.predict_image(rgb, outputs=NIDAR_MAPS)]
    _, seen, cam_idx = sample_cameras(xyz, [cam], [maps[0]["R"]], sightings=sightings)
    named = return_inputs(xyz[seen]) | {
        k: v[seen]
        for k, v in camera_inputs(sightings, [rgb], np.where(seen, cam_idx, -1), maps).items()
    }
    rng = np.random.default_rng(0)
    y = 0.4 * np.exp(-named["range_m"] / 40.0) * named["cos_incidence"] + 0.3 * named["r_lin"]
    y = np.clip(y + rng.normal(0.0, 0.05, y.size), 0.0, 1.0)
    ctx = named | {"frame": np.arange(y.size) % 8}  # 8 frames' worth of draws
    mapping = fit("context", named["R"], named["range_m"], y, context=ctx, kind=kind, threads=2)
    return SensorProfile("bench-" + kind, "procedural", "context", "nidar:R", mapping)


def _devices(spec: str) -> list[str]:
    import torch

    if spec == "auto":
        return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])
    return [d.strip() for d in spec.split(",") if d.strip()]


def run_benchmark(
    sizes=DEFAULT_SIZES,
    configs=DEFAULT_CONFIGS,
    *,
    repeats: int = 5,
    threads: int = 2,
    weights: str | None = None,
    cols: int = 2048,
    devices: str = "auto",
    profile: str | None = None,
) -> dict:
    """Time the stages per configuration, size and device; returns a JSON-safe dict
    (``profile``: the ``--profile`` applied, None: the weights' own).

    Every cell is warmed up once; then the timed rounds run them all in turn, ``repeats``
    times, so that every cell sees the same machine load. Medians are reported, of the wall
    time and of the process CPU time (all threads).
    """
    import torch

    torch.set_num_threads(int(threads))
    xyz = hdl64e_cloud(cols)
    cells = []
    for device in _devices(devices):
        base = _model(weights, device)
        prof = _profile(profile, base)
        for name in configs:
            cells += _cells(base, name, sizes, xyz, device, prof)
    for cell in cells:  # warm-up
        cell["observed"] = cell["run"]()[1]
    for _ in range(int(repeats)):
        for cell in cells:
            cell["t"].append(cell["run"]()[0])
    results = [_summary(cell, len(xyz)) for cell in cells]
    return {
        "threads": int(threads),
        "repeats": int(repeats),
        "weights": str(base.weights_dir),
        "profile": profile,
        "load_average": list(os.getloadavg()),
        "machine": {
            "cpu": _cpu_name(),
            "cores": os.cpu_count(),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
            "python": platform.python_version(),
            "torch": torch.__version__,
        },
        "results": results,
    }


def _model(weights, device: str):
    from nidar_mi.nidar.pipeline import NidarModel

    return NidarModel.load(weights, device=device, optimize=False)


def _profile(spec: str | None, model):
    """The profile of ``--profile`` (module docstring), None for the weights' own."""
    if spec is None:
        return None
    if spec in SYNTHETIC_PROFILES:
        return synthetic_profile(model, SYNTHETIC_PROFILES[spec])
    from nidar_mi.profiles import load_profile

    return load_profile(spec)


def _cells(base, name: str, sizes, xyz, device: str, profile=None) -> list[dict]:
    """One timed cell per size for a configuration of the networks on a device."""
    import torch

    from nidar_mi.nidar.fold import prepare_for_inference
    from nidar_mi.nidar.infer import pseudo_nir, run_irnet
    from nidar_mi.nidar.pipeline import NidarModel
    from nidar_mi.nidar.preprocess import colour_from_prepared, prepare_rgb_tensor

    cfg = _parse_config(name)
    stn, irnet = base.stn, base.irnet
    if cfg["fold"] or cfg["channels_last"]:
        s = 2 * max(stn.stride, irnet.stride)
        opts = {"fold": cfg["fold"], "channels_last": cfg["channels_last"]}
        stn = prepare_for_inference(stn, torch.rand(1, 3, s, s, device=device), **opts)
        x = torch.rand(1, irnet.in_channels, s, s, device=device)
        irnet = prepare_for_inference(irnet, x, **opts)
    sync = torch.cuda.synchronize if torch.device(device).type == "cuda" else None
    cells = []
    for width, height in sizes:
        rgb = street_image(width, height)
        cam = kitti_like_camera(width, height)

        # the configuration's networks as a model (its profile read once, as a command does)
        model = NidarModel(stn, irnet, base.config, base._calibration_map, base.weights_dir)
        model.scale = cfg["scale"]
        model.default_profile()

        def steps(stn=stn, irnet=irnet, rgb=rgb, cam=cam, scale=cfg["scale"], model=model):
            out = {}
            run = lambda: pseudo_nir(stn, rgb, scale=scale, as_tensors=True)  # noqa: E731
            wall, cpu, p = _time(run, sync)
            out["pseudo_nir"] = (wall, cpu)
            x = p[None, None]
            if irnet.in_channels == 4:  # colour channels stacked before the pseudo-NIR
                prepared = prepare_rgb_tensor(rgb, device)
                x = torch.cat((colour_from_prepared(prepared, irnet.input_mode)[None], x), 1)
            run = lambda: run_irnet(irnet, x, scale=scale, as_tensors=True)  # noqa: E731
            wall, cpu, maps = _time(run, sync)
            out["irnet"] = (wall, cpu)
            maps = {**maps, "pseudo_nir": p}
            observed = _assign_stages(base, xyz, cam, maps, out, profile, rgb)
            run = lambda: model.point_intensity(xyz, [cam], [rgb], profile=profile)  # noqa: E731
            out["end_to_end"] = _time(run, sync)[:2]
            return out, observed

        size = f"{width}x{height}"
        cells.append({"config": name, "size": size, "device": device, "run": steps, "t": []})
    return cells


def _summary(cell: dict, points: int) -> dict:
    """Medians of one cell's timed rounds."""
    t = cell["t"]
    wall = {k: float(statistics.median(r[k][0] for r in t)) for k in STEPS}
    cpu = {k: float(statistics.median(r[k][1] for r in t)) for k in STEPS}
    wall["assign"] = float(statistics.median(sum(r[k][0] for k in ASSIGN) for r in t))
    cpu["assign"] = float(statistics.median(sum(r[k][1] for k in ASSIGN) for r in t))
    wall["end_to_end"] = float(statistics.median(r["end_to_end"][0] for r in t))
    cpu["end_to_end"] = float(statistics.median(r["end_to_end"][1] for r in t))
    return {
        "config": cell["config"],
        "size": cell["size"],
        "device": cell["device"],
        "seconds": wall,
        "cpu_seconds": cpu,
        "total_s": float(statistics.median(sum(r[k][0] for k in STEPS) for r in t)),
        "points": int(points),
        "observed": cell["observed"],
    }


def _cpu_name() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def markdown(result: dict) -> str:
    """The results as a Markdown table (seconds per frame)."""
    lines = [
        "| configuration | size | device | pseudo-NIR (s) | IRNet (s) | sampling (s) | normals (s) "
        "| image (s) | profile (s) | assignment (s) | stages' sum (s) | stages' CPU (s) "
        "| end to end (s) | end to end CPU (s) |",
        "| --- | --- | --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: "
        "| ---: |",
    ]
    for r in result["results"]:
        s, c = r["seconds"], r["cpu_seconds"]
        stages = " | ".join(f"{s[k]:.4f}" for k in (*STEPS, "assign"))
        lines.append(
            f"| {r['config']} | {r['size']} | {r['device']} | {stages} | "
            f"{r['total_s']:.3f} | {sum(c[k] for k in STEPS):.3f} | "
            f"**{s['end_to_end']:.3f}** | {c['end_to_end']:.3f} |"
        )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="bench_nidar.py", description="NIDAR inference speed per frame and step."
    )
    p.add_argument("--sizes", default="1242x375,1600x900", help="WxH,WxH,...")
    p.add_argument("--configs", default=",".join(DEFAULT_CONFIGS), help="comma-separated")
    p.add_argument("--repeats", type=int, default=5, help="timed calls per step (median)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    p.add_argument("--cols", type=int, default=2048, help="LiDAR columns of the cloud")
    p.add_argument("--weights", help="NIDAR weights folder (default: the shipped model)")
    p.add_argument(
        "--devices", default="auto", help="cpu, cuda or both; auto: cpu and cuda if available"
    )
    p.add_argument(
        "--profile",
        help="the profile applied: a file, or context-gbm / context-mlp (fitted on the "
        "procedural frame); default: the weights' own",
    )
    p.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    return p


def main(argv=None) -> int:
    from nidar_mi.cli._common import run

    args = build_parser().parse_args(argv)

    def work():
        from nidar_mi.errors import NidarError

        try:
            sizes = [tuple(int(v) for v in s.lower().split("x")) for s in args.sizes.split(",")]
            configs = [c.strip() for c in args.configs.split(",") if c.strip()]
            for c in configs:
                _parse_config(c)
        except ValueError as e:
            raise NidarError(f"--sizes/--configs: {e}") from None
        if any(
            d != "auto" and d.split(":")[0] not in ("cpu", "cuda") for d in args.devices.split(",")
        ):
            raise NidarError(f"--devices: cpu, cuda or auto (got {args.devices})")
        if args.repeats < 1 or args.threads < 1 or any(len(s) != 2 for s in sizes):
            raise NidarError("--repeats and --threads must be >= 1; sizes are WxH")
        result = run_benchmark(
            sizes,
            configs,
            repeats=args.repeats,
            threads=args.threads,
            weights=args.weights,
            cols=args.cols,
            devices=args.devices,
            profile=args.profile,
        )
        gpu = result["machine"]["gpu"]
        print(f"{result['machine']['cpu']}, {result['threads']} torch threads, GPU: {gpu}")
        print(markdown(result))
        if args.json:
            from nidar_mi.io.atomic import atomic_write_json

            os.makedirs(os.path.dirname(os.path.abspath(args.json)), exist_ok=True)
            atomic_write_json(args.json, result)

    return run(work)


if __name__ == "__main__":
    sys.exit(main())
