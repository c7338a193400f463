"""Render a scene into a render folder: scan every LiDAR, render every camera, write it all.

:func:`render_scene` reads as its algorithm: load the scene -> scan each LiDAR -> render each
camera -> (optionally) NIDAR's intensity from those cameras -> write the LiDAR files -> write
the manifest -> publish the folder. Everything is written into a staging folder that replaces
``OUT`` whole only when every step succeeded (:func:`nidar_mi.io.atomic.staged_directory`).
:func:`ensure_rendered` is the cached form used by the dataset builder and the evaluation: it
renders only when the folder does not already hold the same request
(:func:`nidar_mi.render_folder.is_current`).
"""

from __future__ import annotations

import contextlib
import os
import platform
import re
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import render_folder as rf
from .errors import NidarError, check_seed

__all__ = ["INTENSITY_SOURCES", "render_scene", "render_request", "ensure_rendered"]

#: ``physics``: only the simulated intensity; ``nidar``: also NIDAR's prediction from the cameras.
INTENSITY_SOURCES = ("physics", "nidar")
#: NIDAR branches a render can assign.
NIDAR_BRANCHES = ("R", "I_hat")


def _profile_key(profile) -> str | None:
    """``<name>@<sha256 of its JSON, 16 digits>``: what a render's request records of a profile."""
    if profile is None:
        return None
    import hashlib
    import json

    text = json.dumps(profile.to_dict(), sort_keys=True)
    return f"{profile.name}@{hashlib.sha256(text.encode('utf-8')).hexdigest()[:16]}"


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


def _check_request(req: rf.RenderRequest) -> None:
    if req.spp < 1:
        raise NidarError(f"--spp must be >= 1 (got {req.spp})")
    if req.intensity not in INTENSITY_SOURCES:
        raise NidarError(
            f"--intensity must be one of {', '.join(INTENSITY_SOURCES)} (got '{req.intensity}')"
        )
    if req.intensity == "nidar" and not req.cameras:
        raise NidarError("--intensity nidar needs the camera renders (drop --no-cameras)")
    if req.intensity == "nidar" and req.nidar_branch not in NIDAR_BRANCHES:
        raise NidarError(f"--nidar-branch must be one of {', '.join(NIDAR_BRANCHES)}")
    if req.seed is not None:
        check_seed(req.seed)
    if req.bin_intensity not in rf.BIN_INTENSITY:
        raise NidarError(
            f"--bin-intensity must be one of {', '.join(rf.BIN_INTENSITY)} "
            f"(got '{req.bin_intensity}')"
        )
    bad = [f for f in req.formats if f not in rf.FORMATS]
    if bad or not req.formats:
        raise NidarError(
            f"--formats: unknown '{','.join(bad)}' (choose from {', '.join(rf.FORMATS)})"
        )


def _load(req: rf.RenderRequest, variant: str | None):
    from .scene import load_scene

    loaded = load_scene(req.scene, variant=variant, rgb_twin=req.rgb_twin, params=req.params)
    if not loaded.lidars:
        raise NidarError(f'{req.scene}: no lidar sensor (add <sensor type="lidar">)')
    names = [s.id() for s in loaded.lidars + loaded.cameras]
    dup = {n for n in names if names.count(n) > 1 or not n}
    if dup:
        raise NidarError(f"{req.scene}: every sensor needs a unique id (offending: {sorted(dup)})")
    return loaded


@dataclass
class _Run:
    """What the steps of one render hand to each other."""

    stage: str
    results: dict = field(default_factory=dict)  # lidar id -> ScanResult
    renders: dict = field(default_factory=dict)  # camera id -> (CameraRender, calib)
    lidars: dict = field(default_factory=dict)  # lidar id -> manifest entry
    cameras: dict = field(default_factory=dict)  # camera id -> manifest entry
    written: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)


def _check_memory(loaded, cameras: bool, spp: int, max_memory: int | None) -> None:
    """Refuse, before any work, a scan or render estimated to need more than ``max_memory``."""
    from .camera import check_render_memory
    from .lidar.memory import check_scan_memory

    for sensor in loaded.lidars:
        check_scan_memory(sensor.config, max_memory)
    for cam in loaded.cameras if cameras else []:
        check_render_memory(cam, spp, max_memory)


_RGB_ONLY = re.compile(r"lidar '(?P<lidar>.*)': material '(?P<name>.*)' is RGB-only; (?P<rest>.*)")


@contextlib.contextmanager
def _rgb_only_summary():
    """Collect the scan's per-material "is RGB-only" warnings into one line per LiDAR (the
    RGB twin makes every material RGB-only); other warnings pass through unchanged."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    groups: dict[str, list[str]] = {}
    rest: dict[str, str] = {}
    for w in caught:
        m = _RGB_ONLY.fullmatch(str(w.message))
        if m is None:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            continue
        groups.setdefault(m["lidar"], []).append(m["name"])
        rest[m["lidar"]] = m["rest"].replace("its reflectance", "their reflectance")
    for lidar, names in groups.items():
        if len(names) == 1:
            text = f"lidar '{lidar}': material '{names[0]}' is RGB-only; " + rest[lidar].replace(
                "their reflectance", "its reflectance"
            )
        else:
            text = f"lidar '{lidar}': {len(names)} materials are RGB-only ({', '.join(names)}); "
            text += rest[lidar].replace(" is not physical", " are not physical")
        warnings.warn(text, RuntimeWarning, stacklevel=3)


def _scan_lidars(run: _Run, loaded, seed: int | None, bar, max_memory: int | None = None) -> None:
    from .lidar.scan import scan

    for sensor in loaded.lidars:
        bar.set_postfix_str(f"lidar {sensor.id()}")
        t0 = time.perf_counter()
        with _rgb_only_summary():
            result = scan(
                loaded.scene, sensor, seed=seed, max_memory=max_memory, labels=loaded.labels
            )
        run.results[sensor.id()] = result
        run.lidars[sensor.id()] = {
            "parameters": result.config.to_dict() | ({"seed": seed} if seed is not None else {}),
            "to_world": result.to_world.tolist(),
            "rays": int(result.valid.size),
            "hits": int(result.hit.sum()),
            "returns": int(sum(layer.valid.sum() for layer in result.returns)),
            "materials": result.material_names,
            "timings_s": result.timings | {"scan_total": time.perf_counter() - t0},
        }
        bar.update(1)


def nir_wavelengths(loaded) -> list[float]:
    """The NIR bands a render gives each camera: every distinct LiDAR wavelength, that of the
    first LiDAR by id first (``nir.exr``; the others are ``nir_<λ>nm.exr``)."""
    return list(dict.fromkeys(float(s.config.wavelength) for s in loaded.lidars))


def _render_cameras(run: _Run, loaded, spp: int, seed: int | None, bar) -> None:
    from .camera import render_camera

    poses = {lid: r.to_world for lid, r in run.results.items()}
    wavelengths = nir_wavelengths(loaded)
    for cam in loaded.cameras:
        bar.set_postfix_str(f"camera {cam.id()}")
        t0 = time.perf_counter()
        r = render_camera(
            loaded,
            cam,
            wavelength=wavelengths[0],
            other_wavelengths=wavelengths[1:],
            spp=spp,
            seed=0 if seed is None else seed,
        )
        t_render = time.perf_counter() - t0
        t0 = time.perf_counter()
        calib, written = rf.write_camera(run.stage, r, poses)
        run.written += written
        run.renders[cam.id()] = (r, calib)
        run.cameras[cam.id()] = calib | {
            "spp": spp,
            "timings_s": r.timings | {"render_total": t_render, "write": time.perf_counter() - t0},
        }
        bar.update(1)


def _nidar_columns(run: _Run, weights: str | None, branch: str, profile=None) -> dict[str, dict]:
    """``intensity_nidar`` and ``nidar_observed`` per LiDAR from every rendered camera."""
    from .io.calib import render_camera
    from .nidar.pipeline import NidarModel

    if not run.renders:
        raise NidarError("--intensity nidar needs at least one perspective camera in the scene")
    model = NidarModel.load(weights)
    maps = {cid: model.predict_image(r.srgb8()) for cid, (r, _) in run.renders.items()}
    out = {}
    for lid, result in run.results.items():
        cams, depth, cam_maps = [], [], []
        for cid, (r, calib) in run.renders.items():
            cams.append(render_camera(calib, cid, lid))
            depth.append(r.depth)
            cam_maps.append(maps[cid])
        pts = result.points()
        res = model.point_intensity(
            pts["xyz"],
            cams,
            [None] * len(cams),
            depth_images=depth,
            maps=cam_maps,
            branch=branch,
            profile=profile,
            ring=pts["ring"].astype(np.int64),
        )
        out[lid] = {"intensity_nidar": res.intensity, "nidar_observed": res.observed}
    return out


def _write_lidars(
    run: _Run, formats, extra: dict[str, dict], bin_intensity: str, deskew: bool = False
) -> None:
    for lid, result in run.results.items():
        t0 = time.perf_counter()
        run.written += rf.write_lidar(
            run.stage, result, formats, extra.get(lid), bin_intensity, deskew=deskew
        )
        entry = run.lidars[lid]
        entry["timings_s"]["write"] = time.perf_counter() - t0
        if lid in extra:
            entry["nidar_observed"] = int(extra[lid]["nidar_observed"].sum())


def render_scene(
    scene_path: str,
    out_dir: str,
    *,
    formats=rf.DEFAULT_FORMATS,
    seed: int | None = None,
    spp: int = 16,
    variant: str | None = None,
    rgb_twin: bool = False,
    params: dict[str, str] | None = None,
    cameras: bool = True,
    progress: bool = True,
    intensity: str = "physics",
    weights: str | None = None,
    nidar_branch: str | None = None,
    profile=None,
    overwrite: bool = False,
    bin_intensity: str = "unit",
    max_memory: int | None = None,
    deskew: bool = False,
) -> dict:
    """Render a scene into ``out_dir`` (layout: :mod:`nidar_mi.render_folder`).

    Args:
        scene_path: scene XML.
        out_dir: the render folder; a non-empty folder that is not an earlier render folder is
            refused unless ``overwrite``; an earlier render folder is replaced whole.
        formats: point-cloud formats.
        seed: overrides every LiDAR's seed; the camera sampler seed (None: each LiDAR's own
            seed and sampler seed 0; the manifest records the seeds used), in [0, 2**32).
        spp: camera samples per pixel.
        variant: Mitsuba variant (None: CUDA if available, else LLVM).
        rgb_twin: load the RGB-only twin of the scene.
        params: values for the scene's ``<default>`` parameters.
        cameras: render the cameras.
        progress: show a progress bar on stderr.
        intensity: ``physics``, or ``nidar`` to add NIDAR's intensity from the cameras.
        weights: NIDAR weights folder (None: the shipped model); ``nidar`` only.
        nidar_branch: ``R`` (None: the default) or ``I_hat``; ``nidar`` only (without a
            profile).
        profile: a :class:`~nidar_mi.profiles.SensorProfile` for NIDAR's intensity
            (:func:`nidar_mi.datasets.sensor_profiles.resolve_profile` makes one of a name or file);
            None: the weights' own ``sim-905`` (``profiles/sim-905.json``, else
            ``calibration.json``); ``nidar`` only.
        overwrite: replace a non-empty ``out_dir``.
        bin_intensity: ``unit`` (KITTI's [0, 1]) or ``raw``: see
            :func:`nidar_mi.render_folder.write_lidar`.
        max_memory: bytes a scan or camera render may use (None:
            :func:`nidar_mi.lidar.memory.default_limit`); larger requests are refused before
            anything runs.
        deskew: add ``xyz_deskewed`` to the points (equal to ``xyz`` for a scan from one pose).

    Returns:
        The manifest (also written to ``out_dir/manifest.json``).

    Raises:
        NidarError: bad scene or parameter; ``out_dir`` is then left untouched.
    """
    from tqdm.auto import tqdm

    from .io.atomic import staged_directory

    if intensity != "nidar" and weights is not None:
        raise NidarError("--weights is used only with --intensity nidar")
    if intensity != "nidar" and nidar_branch is not None:
        raise NidarError("--nidar-branch is used only with --intensity nidar")
    nidar_branch = nidar_branch or "R"
    req = rf.RenderRequest.of(
        scene_path,
        params=params,
        seed=seed,
        spp=spp,
        formats=tuple(formats),
        cameras=cameras,
        rgb_twin=rgb_twin,
        intensity=intensity,
        weights=weights,
        nidar_branch=nidar_branch,
        profile=_profile_key(profile),
        bin_intensity=bin_intensity,
    )
    _check_request(req)
    t_start = time.perf_counter()
    t0 = time.perf_counter()
    loaded = _load(req, variant)
    load_s = time.perf_counter() - t0
    _check_memory(loaded, cameras, spp, max_memory)
    steps = len(loaded.lidars) + (len(loaded.cameras) if cameras else 0)
    with staged_directory(out_dir, overwrite=overwrite, marker=rf.MANIFEST) as stage:
        run = _Run(stage=str(stage), timings={"load": load_s})
        bar = tqdm(total=steps, desc="render", unit="sensor", disable=not progress, file=sys.stderr)
        try:
            _scan_lidars(run, loaded, seed, bar, max_memory)
            if cameras:
                _render_cameras(run, loaded, spp, seed, bar)
        finally:
            bar.close()
        extra = {}
        if intensity == "nidar":
            t0 = time.perf_counter()
            extra = _nidar_columns(run, weights, nidar_branch, profile)
            run.timings["nidar"] = time.perf_counter() - t0
        _write_lidars(run, formats, extra, bin_intensity, deskew)
        manifest = {
            "request": req.to_dict(),
            "scene": req.scene,
            "scene_sha256": req.scene_sha256,
            "variant": loaded.variant,
            "rgb_twin": rgb_twin,
            "params": dict(req.params),
            "versions": _versions(),
            "seed": 0 if seed is None else seed,
            "seed_source": "default" if seed is None else "--seed",
            "spp": spp,
            "nir_wavelengths_nm": nir_wavelengths(loaded) if cameras else [],
            "bin_intensity": bin_intensity,
            "formats": list(formats),
            "intensity": intensity,
            "nidar_weights": req.weights,
            "nidar_branch": req.nidar_branch,
            "nidar_profile": req.profile,
            "lidars": run.lidars,
            "cameras": run.cameras,
            "timings_s": run.timings | {"total": time.perf_counter() - t_start},
            "files": sorted(os.path.relpath(p, stage) for p in run.written) + [rf.MANIFEST],
        }
        rf.write_manifest(stage, manifest)
    return manifest


def render_request(scene_path: str, **options) -> rf.RenderRequest:
    """The cache key of :func:`render_scene` called with ``options`` (its keyword arguments)."""
    keys = ("params", "seed", "spp", "formats", "cameras", "rgb_twin", "intensity", "weights")
    keys += ("bin_intensity",)
    return rf.RenderRequest.of(
        scene_path,
        **{k: options[k] for k in keys if k in options},
        nidar_branch=options.get("nidar_branch") or "R",
        profile=_profile_key(options.get("profile")),
    )


def ensure_rendered(scene_path: str, out_dir: str, **options) -> dict:
    """The manifest of ``out_dir`` when it already holds this render, else :func:`render_scene`.

    ``options`` are :func:`render_scene`'s keyword arguments; every one of them (and the scene
    file's hash) is part of the cache key (:func:`render_request`), so a folder rendered with
    other parameters is rendered again (replaced whole).
    """
    if rf.is_current(out_dir, render_request(scene_path, **options)):
        return rf.read_manifest(out_dir)
    return render_scene(scene_path, out_dir, overwrite=True, **options)
