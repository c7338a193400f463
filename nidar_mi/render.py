"""``python -m nidar_mi.render SCENE.xml -o OUT``: scan every LiDAR and render every camera.

Outputs (every file written atomically; on any error nothing is left in OUT)::

    OUT/manifest.json                      scene, variant, versions, resolved parameters, seed,
                                           timings, counts
    OUT/<lidar_id>/points.npz|.ply|.las|.bin   valid returns (schema: nidar_mi.io.points)
    OUT/<lidar_id>/range_image.exr         rows = rings (ring 0 highest), columns = azimuth;
                                           channels range, intensity, reflectance, valid
    OUT/<lidar_id>/range.png, intensity.png   colour-mapped previews
    OUT/<camera_id>/rgb.png|exr, nir.png|exr, depth.exr, calib.json
"""

from __future__ import annotations

import argparse
import hashlib
import os
import platform
import shutil
import sys
import tempfile
import time
import warnings

import numpy as np

from .errors import NidarError

__all__ = ["main", "render_scene", "FORMATS"]

FORMATS = ("npz", "ply", "las", "bin")
#: ``physics``: only the simulated intensity; ``nidar``: also NIDAR's prediction from the cameras.
INTENSITY_SOURCES = ("physics", "nidar")


def _parse_formats(text: str) -> list[str]:
    fmts = [f.strip().lower() for f in text.split(",") if f.strip()]
    bad = [f for f in fmts if f not in FORMATS]
    if bad or not fmts:
        raise NidarError(
            f"--formats: unknown format '{','.join(bad)}' (choose from {', '.join(FORMATS)})"
        )
    return fmts


def _parse_params(items: list[str]) -> dict[str, str]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name.strip():
            raise NidarError(f"-D expects NAME=VALUE (got '{item}')")
        out[name.strip()] = value.strip()
    return out


def _versions() -> dict[str, str]:
    import drjit
    import mitsuba

    from . import __version__

    return {
        "nidar_mi": __version__,
        "mitsuba": mitsuba.__version__,
        "drjit": drjit.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def _sha256(path: str) -> str:
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def _write_lidar(stage: str, result, formats, written: list[str], extra=None) -> None:
    from .io import images
    from .io import points as pio
    from .io.las import write_las

    name = result.config.name
    d = os.path.join(stage, name)
    os.makedirs(d, exist_ok=True)
    pts = result.points() | dict(extra or {})
    writers = {
        "npz": lambda p: pio.write_npz(p, pts),
        "ply": lambda p: pio.write_ply(p, pts),
        "las": lambda p: write_las(p, pts),
        "bin": lambda p: pio.write_kitti_bin(p, pts["xyz"], pts["intensity"]),
    }
    ext = {"npz": "npz", "ply": "ply", "las": "las", "bin": "bin"}
    for fmt in formats:
        path = os.path.join(d, f"points.{ext[fmt]}")
        writers[fmt](path)
        written.append(path)
    valid = result.valid
    channels = {
        "range": np.where(valid, result.range, 0.0).astype(np.float32),
        "intensity": np.where(valid, result.intensity, 0.0).astype(np.float32),
        "reflectance": result.reflectance.astype(np.float32),
        "valid": valid.astype(np.float32),
    }
    path = os.path.join(d, "range_image.exr")
    images.write_exr(path, channels)
    written.append(path)
    for key in ("range", "intensity"):
        path = os.path.join(d, f"{key}.png")
        images.write_colormap_png(path, channels[key], invalid=~valid, cmap="turbo")
        written.append(path)


def _write_camera(stage: str, cam, lidar_poses: dict, written: list[str]) -> dict:
    from .io import atomic, images

    d = os.path.join(stage, cam.name)
    os.makedirs(d, exist_ok=True)
    exposure = cam.exposure()
    outputs = {
        "rgb.png": lambda p: images.write_png(p, cam.srgb8()),
        "rgb.exr": lambda p: images.write_exr(
            p, {"R": cam.rgb[..., 0], "G": cam.rgb[..., 1], "B": cam.rgb[..., 2]}
        ),
        "nir.png": lambda p: images.write_png(p, _gray8(cam.nir * exposure)),
        "nir.exr": lambda p: images.write_exr(p, {"Y": cam.nir}),
        "depth.exr": lambda p: images.write_exr(p, {"Z": cam.depth}),
    }
    for fname, fn in outputs.items():
        path = os.path.join(d, fname)
        fn(path)
        written.append(path)
    T_cam_world = np.linalg.inv(cam.T_world_cam)
    calib = {
        "convention": "opencv",
        "width": int(cam.rgb.shape[1]),
        "height": int(cam.rgb.shape[0]),
        "K": cam.K.tolist(),
        "T_world_cam": cam.T_world_cam.tolist(),
        "T_cam_lidar": {k: (T_cam_world @ T).tolist() for k, T in lidar_poses.items()},
        "nir_wavelength_nm": cam.wavelength,
        "png_exposure": exposure,
    }
    path = os.path.join(d, "calib.json")
    atomic.atomic_write_json(path, calib)
    written.append(path)
    return calib


def _nidar_columns(results: dict, renders: dict, weights: str | None, branch: str = "R") -> dict:
    """``intensity_nidar`` and ``nidar_observed`` per LiDAR from every rendered camera."""
    from .geometry import CameraModel
    from .nidar.pipeline import NidarModel

    if not renders:
        raise NidarError("--intensity nidar needs at least one perspective camera in the scene")
    model = NidarModel.load(weights)
    maps = {cid: model.predict_image(r.srgb8()) for cid, (r, _) in renders.items()}
    out = {}
    for lid, result in results.items():
        pts = result.points()
        cams, depth, cam_maps = [], [], []
        for cid, (r, calib) in renders.items():
            T = np.array(calib["T_cam_lidar"][lid])
            cams.append(CameraModel(r.K, calib["width"], calib["height"], T, name=cid))
            depth.append(r.depth)
            cam_maps.append(maps[cid])
        res = model.point_intensity(
            pts["xyz"], cams, [None] * len(cams), depth_images=depth, maps=cam_maps, branch=branch
        )
        out[lid] = {"intensity_nidar": res.intensity, "nidar_observed": res.observed}
    return out


def _gray8(img: np.ndarray) -> np.ndarray:
    from .io.images import linear_to_srgb

    return np.round(linear_to_srgb(np.clip(img, 0.0, 1.0)) * 255.0).astype(np.uint8)


def render_scene(
    scene_path: str,
    out_dir: str,
    *,
    formats=FORMATS,
    seed: int | None = None,
    spp: int = 16,
    variant: str | None = None,
    rgb_twin: bool = False,
    params: dict[str, str] | None = None,
    cameras: bool = True,
    progress: bool = True,
    intensity: str = "physics",
    weights: str | None = None,
    nidar_branch: str = "R",
) -> dict:
    """Render a scene into ``out_dir`` (see the module docstring for the layout).

    Returns:
        The manifest (also written to ``out_dir/manifest.json``).

    Raises:
        NidarError: bad scene or parameter; ``out_dir`` is then left untouched.
    """
    from tqdm.auto import tqdm

    from .camera import render_camera
    from .io.atomic import atomic_write_json
    from .lidar.raycast import scan
    from .scene import load_scene

    if spp < 1:
        raise NidarError(f"--spp must be >= 1 (got {spp})")
    if intensity not in INTENSITY_SOURCES:
        raise NidarError(
            f"--intensity must be one of {', '.join(INTENSITY_SOURCES)} (got '{intensity}')"
        )
    if intensity == "nidar" and not cameras:
        raise NidarError("--intensity nidar needs the camera renders (drop --no-cameras)")
    if seed is not None and seed < 0:
        raise NidarError(f"--seed must be >= 0 (got {seed})")
    t_start = time.perf_counter()
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    loaded = load_scene(scene_path, variant=variant, rgb_twin=rgb_twin, params=params)
    timings["load"] = time.perf_counter() - t0
    if not loaded.lidars:
        raise NidarError(f'{scene_path}: no lidar sensor (add <sensor type="lidar">)')
    names = [s.id() for s in loaded.lidars + loaded.cameras]
    dup = {n for n in names if names.count(n) > 1 or not n}
    if dup:
        raise NidarError(f"{scene_path}: every sensor needs a unique id (offending: {sorted(dup)})")

    parent = os.path.dirname(os.path.abspath(out_dir)) or "."
    os.makedirs(parent, exist_ok=True)
    stage = tempfile.mkdtemp(
        prefix=f".{os.path.basename(os.path.abspath(out_dir))}.partial-", dir=parent
    )
    written: list[str] = []
    steps = len(loaded.lidars) + (len(loaded.cameras) if cameras else 0)
    bar = tqdm(total=steps, desc="render", unit="sensor", disable=not progress, file=sys.stderr)
    try:
        lidar_entries, poses, results = {}, {}, {}
        for sensor in loaded.lidars:
            bar.set_postfix_str(f"lidar {sensor.id()}")
            t0 = time.perf_counter()
            result = scan(loaded.scene, sensor, seed=seed)
            results[sensor.id()] = result
            poses[sensor.id()] = result.to_world
            lidar_entries[sensor.id()] = {
                "parameters": result.config.to_dict()
                | ({"seed": seed} if seed is not None else {}),
                "to_world": result.to_world.tolist(),
                "rays": int(result.valid.size),
                "hits": int(result.hit.sum()),
                "returns": int(result.valid.sum()),
                "materials": result.material_names,
                "timings_s": result.timings | {"scan_total": time.perf_counter() - t0},
            }
            bar.update(1)
        camera_entries, renders = {}, {}
        if cameras:
            wavelength = loaded.lidars[0].config.wavelength
            for cam in loaded.cameras:
                bar.set_postfix_str(f"camera {cam.id()}")
                t0 = time.perf_counter()
                r = render_camera(loaded, cam, wavelength=wavelength, spp=spp, seed=seed or 0)
                t_render = time.perf_counter() - t0
                t0 = time.perf_counter()
                calib = _write_camera(stage, r, poses, written)
                renders[cam.id()] = (r, calib)
                camera_entries[cam.id()] = calib | {
                    "spp": spp,
                    "timings_s": r.timings
                    | {"render_total": t_render, "write": time.perf_counter() - t0},
                }
                bar.update(1)
        extra_columns = {}
        if intensity == "nidar":
            t0 = time.perf_counter()
            extra_columns = _nidar_columns(results, renders, weights, nidar_branch)
            timings["nidar"] = time.perf_counter() - t0
        for lid, result in results.items():
            t0 = time.perf_counter()
            _write_lidar(stage, result, formats, written, extra_columns.get(lid, {}))
            lidar_entries[lid]["timings_s"]["write"] = time.perf_counter() - t0
            if lid in extra_columns:
                obs = extra_columns[lid]["nidar_observed"]
                lidar_entries[lid]["nidar_observed"] = int(obs.sum())
        bar.close()
        manifest = {
            "scene": os.path.abspath(scene_path),
            "scene_sha256": _sha256(scene_path),
            "variant": loaded.variant,
            "rgb_twin": rgb_twin,
            "params": dict(params or {}),
            "versions": _versions(),
            "seed": seed,
            "spp": spp,
            "formats": list(formats),
            "intensity": intensity,
            "nidar_weights": str(weights) if intensity == "nidar" and weights else None,
            "nidar_branch": nidar_branch if intensity == "nidar" else None,
            "lidars": lidar_entries,
            "cameras": camera_entries,
            "timings_s": timings | {"total": time.perf_counter() - t_start},
            "files": sorted(os.path.relpath(p, stage) for p in written) + ["manifest.json"],
        }
        atomic_write_json(os.path.join(stage, "manifest.json"), manifest)
        _publish(stage, out_dir)
    except BaseException:
        bar.close()
        shutil.rmtree(stage, ignore_errors=True)
        raise
    return manifest


def _publish(stage: str, out_dir: str) -> None:
    """Move every staged file into ``out_dir`` (each move is an atomic rename)."""
    for root, _, files in os.walk(stage):
        rel = os.path.relpath(root, stage)
        dest = os.path.normpath(os.path.join(out_dir, rel))
        os.makedirs(dest, exist_ok=True)
        for f in files:
            os.replace(os.path.join(root, f), os.path.join(dest, f))
    shutil.rmtree(stage, ignore_errors=True)


def _summary(manifest: dict, out_dir: str) -> str:
    rows = [("sensor", "kind", "rays/pixels", "returns", "time (s)")]
    for name, e in manifest["lidars"].items():
        rows.append(
            (
                name,
                "lidar",
                str(e["rays"]),
                str(e["returns"]),
                f"{e['timings_s']['scan_total']:.2f}",
            )
        )
    for name, e in manifest["cameras"].items():
        rows.append(
            (
                name,
                "camera",
                str(e["width"] * e["height"]),
                "-",
                f"{e['timings_s']['render_total']:.2f}",
            )
        )
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    lines.insert(1, "  ".join("-" * w for w in widths))
    lines.append(
        f"wrote {len(manifest['files'])} files to {out_dir} in {manifest['timings_s']['total']:.1f} s"
    )
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m nidar_mi.render",
        description="Scan every lidar sensor of a scene (points with NIR intensity) and render every "
        "camera (RGB, NIR band at the LiDAR wavelength, depth).",
    )
    p.add_argument("scene", help="scene XML file")
    p.add_argument("-o", "--out", help="output directory (default: out/<scene name>)")
    p.add_argument("--formats", default=",".join(FORMATS), help="point formats: npz,ply,las,bin")
    p.add_argument(
        "--seed", type=int, default=None, help="overrides every lidar's seed; camera sampler seed"
    )
    p.add_argument("--spp", type=int, default=16, help="camera samples per pixel (default 16)")
    p.add_argument(
        "--variant",
        default=None,
        help="Mitsuba variant (default: cuda_ad_spectral if CUDA works, else llvm_ad_spectral)",
    )
    p.add_argument(
        "-D",
        dest="params",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a scene parameter (<default name=...>), e.g. -D cols=512; repeatable",
    )
    p.add_argument(
        "--intensity",
        default="physics",
        choices=INTENSITY_SOURCES,
        help="nidar: also predict intensity_nidar / nidar_observed from the cameras with NIDAR",
    )
    p.add_argument(
        "--weights", default=None, help="NIDAR weights folder (default: the shipped model)"
    )
    p.add_argument(
        "--nidar-branch",
        default="R",
        choices=("R", "I_hat"),
        help="R: calibrated reflectance branch (the paper's, default); I_hat: dense intensity head",
    )
    p.add_argument("--rgb-twin", action="store_true", help="load the scene's RGB-only twin")
    p.add_argument("--no-cameras", action="store_true", help="skip the camera renders")
    p.add_argument("-q", "--quiet", action="store_true", help="no progress bar or summary")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    out = args.out or os.path.join("out", os.path.splitext(os.path.basename(args.scene))[0])
    try:
        formats = _parse_formats(args.formats)
        params = _parse_params(args.params)
        with warnings.catch_warnings():
            warnings.simplefilter("default")
            manifest = render_scene(
                args.scene,
                out,
                formats=formats,
                seed=args.seed,
                spp=args.spp,
                variant=args.variant,
                rgb_twin=args.rgb_twin,
                params=params,
                cameras=not args.no_cameras,
                progress=not args.quiet,
                intensity=args.intensity,
                weights=args.weights,
                nidar_branch=args.nidar_branch,
            )
    except NidarError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; nothing written", file=sys.stderr)
        return 130
    if not args.quiet:
        print(_summary(manifest, out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
