"""Render a scene into a render folder: scan every LiDAR, render every camera, write it all.

:func:`render_scene` reads as its algorithm: open the session (check the options, load the
scene: :class:`nidar_mi.render_session.RenderSession`) -> scan each LiDAR -> render each camera
-> (optionally) NIDAR's intensity from those cameras -> write the LiDAR files -> write the
manifest -> publish the folder. Everything is written into a staging folder that replaces
``OUT`` whole only when every step succeeded (:func:`nidar_mi.io.atomic.staged_directory`).
:func:`ensure_rendered` is the cached form used by the dataset builder and the evaluation: it
renders only when the folder does not already hold the same request
(:func:`nidar_mi.render_folder.is_current`).
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from . import render_folder as rf
from .errors import NidarError
from .render_session import RenderOptions, RenderSession, profile_key

__all__ = ["render_scene", "ensure_rendered", "nidar_columns"]

log = logging.getLogger("nidar_mi.render")


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
    profile: str | None = None  # the sensor profile NIDAR applied (render_session.profile_key)


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


def _scan_lidars(run: _Run, session: RenderSession, bar) -> None:
    from .lidar.scan import scan

    seed, loaded = session.options.seed, session.loaded
    for sensor in session.lidars:
        bar.set_postfix_str(f"lidar {sensor.id()}")
        t0 = time.perf_counter()
        with _rgb_only_summary():
            result = scan(
                loaded.scene,
                sensor,
                seed=seed,
                max_memory=session.options.max_memory,
                labels=loaded.labels,
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
        if result.weather is not None:
            run.lidars[sensor.id()]["weather"] = result.weather.to_dict()
        bar.update(1)


def _render_cameras(run: _Run, session: RenderSession, bar) -> None:
    from .camera import render_camera

    spp, seed = session.options.spp, session.options.seed
    poses = {lid: r.to_world for lid, r in run.results.items()}
    wavelengths = session.nir_wavelengths
    for cam in session.cameras:
        bar.set_postfix_str(f"camera {cam.id()}")
        t0 = time.perf_counter()
        r = render_camera(
            session.loaded,
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


def _sense(run: _Run, session: RenderSession) -> None:
    """Scan every LiDAR, then render every camera, under one progress bar."""
    from .progress import progress_bar

    steps = len(session.lidars) + len(session.cameras)
    bar = progress_bar(total=steps, show=session.options.progress, desc="render", unit="sensor")
    try:
        _scan_lidars(run, session, bar)
        if session.options.cameras:
            _render_cameras(run, session, bar)
    finally:
        bar.close()


def nidar_columns(model, results: dict, renders: dict, branch: str, profile=None) -> dict:
    """NIDAR's intensity of every LiDAR's returns from every rendered camera.

    Args:
        model: the loaded :class:`~nidar_mi.nidar.pipeline.NidarModel`.
        results: LiDAR id -> its :class:`~nidar_mi.lidar.scan.ScanResult`.
        renders: camera id -> (its :class:`~nidar_mi.camera.CameraRender`, its ``calib.json``
            dict); at least one.
        branch: ``R`` or ``I_hat``.
        profile: a sensor profile, or None for the weights' own.

    Returns:
        LiDAR id -> ``{"intensity_nidar": (N,) float, "reflectance_nidar": (N,) float,
        "nidar_observed": (N,) bool}``, one value
        per valid return.
    """
    from .io.calib import render_calib_model

    rgbs = {cid: r.srgb8() for cid, (r, _) in renders.items()}
    maps = {cid: model.predict_image(rgb) for cid, rgb in rgbs.items()}
    out = {}
    for lid, result in results.items():
        cams, depth, cam_maps = [], [], []
        for cid, (r, calib) in renders.items():
            cams.append(render_calib_model(calib, cid, lid))
            depth.append(r.depth)
            cam_maps.append(maps[cid])
        pts = result.points()
        res = model.point_intensity(
            pts["xyz"],
            cams,
            list(rgbs.values()),  # read by a profile of the image context
            depth_images=depth,
            maps=cam_maps,
            branch=branch,
            profile=profile,
            ring=pts["ring"].astype(np.int64),
        )
        out[lid] = {
            "intensity_nidar": res.intensity,
            "reflectance_nidar": res.reflectance,
            "nidar_observed": res.observed,
        }
    return out


def _nidar_step(run: _Run, options: RenderOptions) -> dict[str, dict]:
    """``--intensity nidar``: load the NIDAR model, then :func:`nidar_columns`."""
    if not run.renders:
        raise NidarError("`intensity` nidar needs at least one perspective camera in the scene")
    from .nidar.pipeline import NidarModel

    model = NidarModel.load(options.weights)
    branch = options.branch()
    applied = options.profile or (model.default_profile() if branch == "R" else None)
    run.profile = profile_key(applied)
    return nidar_columns(model, run.results, run.renders, branch, options.profile)


def _write_lidars(run: _Run, options: RenderOptions, extra: dict[str, dict]) -> None:
    for lid, result in run.results.items():
        t0 = time.perf_counter()
        run.written += rf.write_lidar(
            run.stage,
            result,
            options.formats,
            extra.get(lid),
            options.bin_intensity,
            deskew=options.deskew,
        )
        entry = run.lidars[lid]
        entry["timings_s"]["write"] = time.perf_counter() - t0
        if lid in extra:
            entry["nidar_observed"] = int(extra[lid]["nidar_observed"].sum())


def _manifest(session: RenderSession, run: _Run, total_s: float) -> dict:
    """The render folder's ``manifest.json``: request, provenance, sensors, timings, files."""
    opts, req = session.options, session.request
    weather = session.loaded.weather
    return {
        **({} if weather is None else {"weather": weather.to_dict()}),
        "request": req.to_dict(),
        "scene": req.scene,
        "scene_sha256": req.scene_sha256,
        "variant": session.variant,
        "rgb_twin": opts.rgb_twin,
        "params": dict(req.params),
        "versions": session.versions,
        "seed": 0 if opts.seed is None else opts.seed,
        "seed_source": "default" if opts.seed is None else "--seed",
        "spp": opts.spp,
        "nir_wavelengths_nm": session.nir_wavelengths if opts.cameras else [],
        "bin_intensity": opts.bin_intensity,
        "formats": list(opts.formats),
        "intensity": opts.intensity,
        "nidar_weights": req.weights,
        "nidar_branch": req.nidar_branch,
        "nidar_profile": run.profile,
        "lidars": run.lidars,
        "cameras": run.cameras,
        "timings_s": run.timings | {"total": total_s},
        "files": sorted(os.path.relpath(p, run.stage) for p in run.written) + [rf.MANIFEST],
    }


def render_scene(
    options: RenderOptions, out_dir: str, *, overwrite: bool = False, nested: bool = False
) -> dict:
    """Render a scene into ``out_dir`` (layout: :mod:`nidar_mi.render_folder`), in the active
    Mitsuba variant (:func:`nidar_mi.backend.set_variant`).

    Args:
        options: what to render (:class:`~nidar_mi.render_session.RenderOptions`).
        out_dir: the render folder; an earlier render folder is replaced whole, any other
            folder as :func:`nidar_mi.io.ownership.check_owner` says.
        overwrite: the user passed ``overwrite`` (:func:`~nidar_mi.io.ownership.check_owner`).
        nested: ``out_dir`` is a cache inside the caller's own output (a dataset's renders).

    Returns:
        The manifest (also written to ``out_dir/manifest.json``).

    Raises:
        NidarError: bad scene or option; ``out_dir`` is then left untouched.
    """
    from .io.atomic import staged_directory

    t_start = time.perf_counter()
    session = RenderSession.open(options)
    session.check_memory()
    publish = dict(owner=rf.RENDER_OWNER, overwrite=overwrite, nested=nested)
    with staged_directory(out_dir, **publish) as stage:
        run = _Run(stage=str(stage), timings={"load": session.load_s})
        _sense(run, session)
        extra = {}
        if options.intensity == "nidar":
            t0 = time.perf_counter()
            extra = _nidar_step(run, options)
            run.timings["nidar"] = time.perf_counter() - t0
        _write_lidars(run, options, extra)
        manifest = _manifest(session, run, time.perf_counter() - t_start)
        rf.write_manifest(stage, manifest)
    for name, e in manifest["lidars"].items():
        t = e["timings_s"]["scan_total"]
        log.debug("lidar %s: %d rays, %d returns, %.2f s", name, e["rays"], e["returns"], t)
    for name, e in manifest["cameras"].items():
        t = e["timings_s"]["render_total"]
        log.debug("camera %s: %dx%d pixels, %.2f s", name, e["width"], e["height"], t)
    return manifest


def ensure_rendered(options: RenderOptions, out_dir: str) -> dict:
    """The manifest of ``out_dir`` when it already holds this render, else :func:`render_scene`
    (replacing ``out_dir`` whole).

    Every option of the cache key (:meth:`RenderOptions.key`, with the scene file's hash) is
    compared, so a folder rendered with other options is rendered again.
    """
    if rf.is_current(out_dir, options.key()):
        return rf.read_manifest(out_dir)
    return render_scene(options, out_dir, overwrite=True, nested=True)
