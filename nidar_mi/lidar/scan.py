"""One LiDAR scan: beam pattern → cast through glass → monostatic ρ at λ → return model →
detection and noise → read back.

:func:`scan` casts every beam at once in Dr.Jit (in blocks of bounded memory for very large
scans, :mod:`.memory`); the physics is :mod:`.return_model`'s, the ray casting :mod:`.raycast`'s,
the rays (pose per column, beam origins, sub-rays) :mod:`.rays`'s. What stays on the device:

* the beam pattern, uploaded once per pattern and block (cached);
* every scalar parameter, the single pose and the PCG32 seed state: one upload and one width-1
  kernel per scan, read by the scan's kernels as data (never literals), so scanning again with
  another pose, other per-column poses or another seed reuses the compiled kernels; a dropout
  probability or noise σ of 0 leaves its draw's transform out of that sensor's kernels (the
  random stream advances as before, so every other draw keeps its value);
* the material and shape indices, looked up from the hit's BSDF and shape pointers in the scene's
  tables (:mod:`.scene_tables`, cached per scene).

An ideal-beam block is **one kernel** (rays, cast, BSDF, return model, draws, detection, look-ups)
followed by one synchronisation and the read-back of its per-beam columns (zero-copy views on
the CPU). On the host remain the checks of the materials found non-finite or RGB-only (rare
paths), building :class:`ScanResult`, and, for diverging beams, the grouping of the sub-rays'
contributions into echoes and the choice of returns (:mod:`.echoes`, NumPy over the block).

Two paths, one per beam model:

* **ideal beam** (``beam_divergence`` 0): one ray per beam, detection and noise in Dr.Jit.
* **diverging beam**: ``N`` sub-rays per beam (:mod:`.footprint`), each carrying its footprint
  weight ``w`` of the pulse: a surface hit contributes ``w · g·ρ·T²·a(d, θ)``, and the first glass
  pane a beam meets contributes its specular echo ``w · g · R_F · exp(-8 α² / θ_w²) / (2 θ_w²) ·
  a'(d)`` (a mirror of Fresnel reflectance ``R_F`` tilted by ``α`` from the beam axis returns a
  Gaussian beam of divergence ``θ_w`` centred ``2α`` off the receiver, over twice the range;
  ``a'`` is ``a`` without the cosine). The contributions are grouped into echoes and the returns
  selected per ``return_mode`` (:mod:`.echoes`) by the receiver's output (each echo with its
  own receiver noise); further noise per return.

A scan names the materials (:func:`material_table`) and the shapes (``scene.shapes()``
order), and warns once per material whose reflectance is not finite (Mitsuba's conductor presets
past ~886 nm: its returns are dropped) or comes from RGB upsampling (not physical past 830 nm).
"""

from __future__ import annotations

import contextlib
import time
import warnings
from typing import Any, NamedTuple

import numpy as np

from ..geometry.se3 import transform_matrix
from ..labels import SceneLabels, shape_labels
from .config import LidarConfig
from .echoes import group_echoes, select_returns
from .footprint import subray_offsets
from .memory import check_scan_memory, chunk_beams
from .raycast import cast, monostatic_reflectance
from .rays import block_rays, column_poses, jit_float, jit_scalars, static_pose
from .result import ReturnLayer, ScanResult
from .return_model import (
    add_noise,
    attenuation,
    box_muller,
    detect,
    expected_intensity,
    range_response,
    received,
)
from .scene_tables import SceneTables, material_table, scene_tables, shape_table
from .weather_returns import device_tables, range_jitter, weather_model

__all__ = ["ScanResult", "ReturnLayer", "scan", "material_table", "shape_table"]


def scan(
    scene,
    sensor,
    *,
    seed: int | None = None,
    to_world=None,
    poses_per_column=None,
    max_memory: int | None = None,
    labels: SceneLabels | None = None,
    weather=None,
) -> ScanResult:
    """Cast every beam of ``sensor`` and compute its returns.

    Args:
        scene: a loaded ``mi.Scene`` (spectral variant).
        sensor: a ``lidar`` sensor of that scene.
        seed: overrides the sensor's ``seed`` for the noise and dropout draws.
        to_world: optional (4,4) pose overriding the sensor's ``to_world``: the pose at the
            sweep's start.
        poses_per_column: optional (C, 4, 4) world pose at each column's firing time (a moving
            sensor: every column is cast from its own pose; motion distortion).
        max_memory: bytes the scan may use (None: :func:`.memory.default_limit`).
        labels: the scene's label declaration (:attr:`nidar_mi.scene.LoadedScene.labels`);
            None: every point ``unlabeled``, every shape its own instance.
        weather: a :class:`nidar_mi.weather.Weather` overriding the sensor's own (its XML
            ``fog``, ``rain``, ``snow``); None: the sensor's. Clear weather scans exactly as
            without (:mod:`.weather`).

    Returns:
        The scan on the (ring, column) grid.

    Raises:
        NidarError: the scan would need more memory than ``max_memory``, or the per-column
            poses do not match the columns.
    """
    cfg: LidarConfig = sensor.config
    check_scan_memory(cfg, max_memory)
    timings: dict[str, float] = {}
    pose = _pose(sensor, to_world)
    poses_per_column = _check_column_poses(cfg, poses_per_column)
    model = _weather_model(sensor, cfg, weather, timings)
    with _timed(timings, "pattern"):
        inputs, poses = _kernel_inputs(
            cfg,
            cfg.seed if seed is None else int(seed),
            pose if poses_per_column is None else None,
            0.0 if model is None else model.alpha,
        )
        ctx = _Context(
            scene,
            cfg,
            inputs,
            poses if poses_per_column is None else column_poses(poses_per_column),
            scene_tables(scene),
            _Outputs(cfg.rings * cfg.horizontal_resolution, cfg.max_returns),
            timings,
            None if model is None else (model, device_tables(model, _float_type())),
        )
    for start, stop in chunk_beams(cfg):
        _scan_block(ctx, start, stop)
    with _timed(timings, "readback"):
        return _result(ctx, pose, poses_per_column, labels)


def _check_column_poses(cfg: LidarConfig, poses):
    """(C, 4, 4) float64 per-column poses, or None; NidarError when they do not fit."""
    from ..errors import NidarError

    if poses is None:
        return None
    poses = np.asarray(poses, dtype=np.float64)
    if poses.shape != (cfg.horizontal_resolution, 4, 4) or not np.all(np.isfinite(poses)):
        raise NidarError(
            f"lidar '{cfg.name}': poses per column must be a finite "
            f"({cfg.horizontal_resolution}, 4, 4) array (got {poses.shape})"
        )
    return poses


def _weather_model(sensor, cfg: LidarConfig, weather, timings: dict):
    """The scan's :class:`.weather.WeatherModel` (timed as ``weather``), or None in clear
    weather."""
    w = weather if weather is not None else getattr(sensor, "weather", None)
    if w is None or w.clear:
        return None
    with _timed(timings, "weather"):
        return weather_model(w, cfg)


def _float_type():
    import mitsuba as mi

    return mi.Float


def _result(ctx, pose, poses_per_column, labels) -> ScanResult:
    """The scan's :class:`ScanResult` from the read-back outputs (warnings, dropped materials)."""
    cfg, out, tables = ctx.cfg, ctx.out, ctx.tables
    shape = (cfg.rings, cfg.horizontal_resolution)
    names = tables.material_names
    bad = _warn_nonfinite(cfg, names, np.concatenate(out.nonfinite))
    layers = [
        ReturnLayer(
            valid=layer["valid"].reshape(shape),
            range=layer["range"].reshape(shape),
            intensity=layer["intensity"].reshape(shape),
            reflectance=layer["reflectance"].reshape(shape),
            cos_incidence=layer["cos"].reshape(shape),
            material=layer["material"].reshape(shape),
            shape_index=layer["shape"].reshape(shape),
            scatterer=layer["scatterer"].reshape(shape) if "scatterer" in layer else None,
        )
        for layer in out.layers
    ]
    directions, origins = _pattern_arrays(cfg, 0, cfg.rings * cfg.horizontal_resolution)
    shadow = shadowed_beams(cfg, directions.reshape(*shape, 3))
    for layer in layers:
        _drop_materials(layer, bad)
        if shadow is not None:
            _drop(layer, shadow & layer.valid)
        _offset_ranges(layer, cfg)
    _warn_rgb_materials(tables, cfg, np.unique(np.concatenate(out.materials_hit)))
    first = layers[0]
    return ScanResult(
        config=cfg,
        valid=first.valid,
        range=first.range,
        intensity=first.intensity,
        reflectance=first.reflectance,
        cos_incidence=first.cos_incidence,
        material=first.material,
        directions=directions.reshape(*shape, 3),
        to_world=pose,
        material_names=list(names),
        hit=out.hit.reshape(shape),
        timings=ctx.timings,
        shape_index=first.shape_index,
        shape_labels=shape_labels(ctx.scene, labels),
        shape_names=list(tables.shape_names),
        time=_firing_times(cfg).reshape(shape),
        origins=None if origins is None else origins.reshape(*shape, 3),
        column_poses=poses_per_column,
        further=layers[1:],
        scatterer=first.scatterer,
        weather=None if ctx.weather is None else ctx.weather[0].weather,
    )


def shadowed_beams(cfg: LidarConfig, directions: np.ndarray) -> np.ndarray | None:
    """(R, C) bool: the beams in the sensor's ``laser_shadow`` (laser r, azimuth of its
    sensor-frame direction ``atan2(y, x)`` in degrees, read in [-180, 180), within [from, to)),
    which return nothing; None without a shadow. ``directions``: (R, C, 3) the pattern's."""
    if cfg.laser_shadow is None:
        return None
    az = np.degrees(np.arctan2(directions[..., 1], directions[..., 0]))  # (R, C), (-180, 180]
    az = np.where(az >= 180.0, az - 360.0, az)  # [-180, 180): straight back starts the circle
    out = np.zeros(az.shape, bool)
    for ring, a0, a1 in cfg.laser_shadow:
        out[ring] |= (az[ring] >= a0) & (az[ring] < a1)
    return out


# ---------------------------------------------------------------- one block of beams


class _Context(NamedTuple):
    """What every block of a scan needs."""

    scene: Any
    cfg: LidarConfig
    inputs: Any
    poses: Any
    tables: SceneTables
    out: Any
    timings: dict
    weather: Any = None  # (WeatherModel, its tables on the device) or None: clear


class _Outputs:
    """Flat (R·C,) per-beam outputs, one dict per return (keys: ``valid``, ``range``,
    ``intensity``, ``reflectance``, ``cos``, ``material``, ``shape``), filled block by block;
    a block covering the whole scan hands its arrays over without a copy."""

    _DTYPES = {
        "valid": bool,
        "range": np.float32,
        "intensity": np.float32,
        "reflectance": np.float32,
        "cos": np.float32,
        "material": np.int32,
        "shape": np.int32,
        "scatterer": np.uint8,
    }

    def __init__(self, beams: int, returns: int) -> None:
        self.beams = beams
        self.layers: list[dict[str, np.ndarray]] = [{} for _ in range(returns)]
        self.hit = np.zeros(beams, dtype=bool)
        self.nonfinite: list[np.ndarray] = [np.zeros(0, dtype=np.int64)]  # material indices
        self.materials_hit: list[np.ndarray] = [np.zeros(0, dtype=np.int64)]

    def put(self, m: int, start: int, stop: int, **values: np.ndarray) -> None:
        """Store return ``m``'s columns of beams ``start..stop``."""
        layer = self.layers[m]
        for key, v in values.items():
            v = np.asarray(v).astype(self._DTYPES[key], copy=False)
            if start == 0 and stop == self.beams:
                layer[key] = v
                continue
            if key not in layer:
                layer[key] = np.zeros(self.beams, dtype=self._DTYPES[key])
            layer[key][start:stop] = v


def _scan_block(ctx: _Context, start: int, stop: int) -> None:
    """Scan beams ``start..stop`` and write their outputs into ``ctx.out``."""
    import drjit as dr
    import mitsuba as mi

    cfg, inputs = ctx.cfg, ctx.inputs
    with _timed(ctx.timings, "pattern"):
        directions, origins = _pattern_jit(cfg, start, stop)
        first = dr.opaque(mi.UInt32, start)
        subrays = subray_offsets(cfg.beam_sample_quality) if cfg.beam_divergence > 0 else None
        rays = block_rays(
            ctx.poses,
            directions,
            origins,
            first_beam=first,
            cols=cfg.horizontal_resolution,
            subrays=subrays,
            half_angle=inputs.half_angle,
        )
    with _timed(ctx.timings, "raycast"):
        beams = cast(ctx.scene, rays.ray, inputs.wavelength, glass_front=subrays is not None)
    with _timed(ctx.timings, "bsdf"):
        rho, cos_t, bsdf = monostatic_reflectance(beams, inputs.wavelength)
        d = dr.select(beams.hit, beams.path_m, 1.0)
        expected = expected_intensity(
            inputs.gain,
            rho,
            d,
            cos_t,
            inputs.alpha,
            cfg.intensity_mode,
            beams.two_way_transmittance,
        )
        ring = _ring(cfg, first, stop - start, 1 if subrays is None else cfg.subrays)
        laser = _laser_gain(cfg, ring)
        expected = expected * laser * _range_factor(cfg, d, ring)
    draws = _draws(cfg, stop - start, inputs, first)
    shading = _Shading(rho, cos_t, bsdf, d, expected, laser, ring)
    if subrays is None and ctx.weather is not None:
        _ideal_weather_block(ctx, beams, shading, draws, (start, stop, first))
    elif subrays is None:
        _ideal_block(ctx, beams, shading, draws, start, stop)
    else:
        _echo_block(ctx, rays, beams, shading, draws, start, stop)


class _Shading(NamedTuple):
    """Per-ray Dr.Jit values of a block: ρ, cos θ, the BSDF, the range (1 where no hit) and
    the expected intensity."""

    rho: Any
    cos_t: Any
    bsdf: Any
    d: Any
    expected: Any
    laser_gain: Any = 1.0
    ring: Any = None


def _ring(cfg: LidarConfig, first_beam, beams: int, per_beam: int):
    """Each ray's laser (``mi.UInt32``), or None when the sensor reads nothing per laser.

    Args:
        first_beam: opaque ``mi.UInt32`` flat index of the block's first beam.
        beams: beams in the block; per_beam: rays per beam (sub-rays).
    """
    if cfg.laser_gains is None and cfg.laser_range_response is None and cfg.laser_offsets is None:
        return None
    import drjit as dr
    import mitsuba as mi

    beam = dr.arange(mi.UInt32, beams * per_beam) // per_beam + first_beam
    return beam // cfg.horizontal_resolution


def _laser_gain(cfg: LidarConfig, ring):
    """Each ray's per-laser gain (``laser_gains`` of its ``ring``; 1.0 when the sensor has
    none)."""
    if cfg.laser_gains is None:
        return 1.0
    import drjit as dr
    import mitsuba as mi

    gains = _cached(
        _jit_cache,
        ("laser_gains", cfg.laser_gains, mi.variant()),
        lambda: jit_float(np.asarray(cfg.laser_gains, dtype=np.float32)),
    )
    return dr.gather(mi.Float, gains, ring)


def _offset(cfg: LidarConfig, ring):
    """The intensity offset of each ray of laser ``ring`` (``mi.UInt32`` or NumPy): the
    sensor's ``intensity_offset`` plus, where it has ``laser_offsets``, the ring's own."""
    if cfg.laser_offsets is None or ring is None:
        return cfg.intensity_offset
    if isinstance(ring, np.ndarray):
        return cfg.intensity_offset + np.asarray(cfg.laser_offsets)[ring]
    import drjit as dr
    import mitsuba as mi

    table = _cached(
        _jit_cache,
        ("laser_offsets", cfg.laser_offsets, mi.variant()),
        lambda: jit_float(np.asarray(cfg.laser_offsets, dtype=np.float32)),
    )
    return cfg.intensity_offset + dr.gather(mi.Float, table, ring)


def _range_factor(cfg: LidarConfig, d, ring=None):
    """The sensor's ``range_response`` at range ``d`` times, where the sensor has a
    ``laser_range_response``, its ``ring``'s own factor there (1.0 when it has neither)."""
    if cfg.range_response is None:
        return 1.0
    knots, values = zip(*cfg.range_response)
    factor = range_response(d, knots, values)
    if cfg.laser_range_response is None or ring is None:
        return factor
    import drjit as dr
    import mitsuba as mi

    k = len(knots)
    table = _cached(
        _jit_cache,
        ("laser_range_response", cfg.laser_range_response, mi.variant()),
        lambda: jit_float(np.asarray(cfg.laser_range_response, dtype=np.float32).ravel()),
    )
    own = [dr.gather(mi.Float, table, ring * k + i) for i in range(k)]
    return factor * range_response(d, knots, own)


def _ideal_block(ctx: _Context, beams, sh: _Shading, draws, start: int, stop: int) -> None:
    """One ray per beam: detection, noise, the material and shape indices and the per-beam
    columns in one kernel, then one synchronisation and the columns' read-back."""
    import drjit as dr

    inputs, tables, cfg = ctx.inputs, ctx.tables, ctx.cfg
    with _timed(ctx.timings, "detect"):
        u_dropout, normal_intensity, normal_range = draws.returns[0]
        valid = detect(
            sh.expected,
            sh.d,
            hit=beams.hit,
            threshold=inputs.threshold,
            range_min=inputs.range_min,
            range_max=inputs.range_max,
            dropout=inputs.dropout,
            u=u_dropout,
            noise=inputs.receiver_noise,
            normal=draws.receiver,
        )
        output = received(sh.expected, inputs.receiver_noise, draws.receiver)
        intensity = add_noise(
            output - _offset(cfg, sh.ring), inputs.noise_intensity, normal_intensity
        )
        range_m = add_noise(sh.d, inputs.noise_range, normal_range)
        hit = beams.hit
        material = dr.select(hit, tables.material_index(sh.bsdf), -1)
        columns = {
            "range": dr.select(valid, range_m, 0.0),
            "intensity": dr.select(valid, intensity, 0.0),
            "reflectance": dr.select(dr.isfinite(sh.rho), sh.rho, 0.0),
            "cos": dr.select(hit, sh.cos_t, 0.0),
            "material": material,
            "shape": dr.select(hit, tables.shape_index(beams.si.shape), -1),
            "valid": valid,
            "hit": hit,
        }
        columns["nonfinite"] = hit & ~dr.isfinite(sh.expected)  # its material is dropped
        dr.eval(columns)  # one kernel
    with _timed(ctx.timings, "readback"):
        _store_ideal(ctx, {key: value.numpy() for key, value in columns.items()}, start, stop)


def _ideal_weather_block(ctx: _Context, beams, sh: _Shading, draws, span) -> None:
    """:func:`_ideal_block` in weather: the hard target (attenuated, occluded by the particles
    in the beam), the soft return and the sampled particles are candidates, each detected in
    its own receiver noise; the return mode picks one (:mod:`.weather`). One kernel, as in
    clear weather."""
    import drjit as dr

    from .weather_returns import candidates, choose, detect_candidates, range_jitter

    (model, tables), inputs, cfg = ctx.weather, ctx.inputs, ctx.cfg
    start, stop, first = span
    with _timed(ctx.timings, "detect"):
        u_dropout, normal_intensity, normal_range = draws.returns[0]
        uniform, normal = _weather_draws(inputs, stop - start, first, cfg.receiver_noise_std > 0)
        limit = dr.select(beams.hit, sh.d, cfg.range_max + model.receiver.pulse_length)
        cands = candidates(model, limit, tables, uniform)
        hard = dr.select(beams.hit, sh.expected * cands.occlusion, 0.0)
        gates = {"threshold": inputs.threshold, "noise": inputs.receiver_noise}
        gates |= {"range_min": inputs.range_min, "range_max": inputs.range_max}
        valid = [detect(hard, sh.d, hit=beams.hit, normal=draws.receiver, **gates)]
        output = [received(hard, inputs.receiver_noise, draws.receiver)]
        more_valid, more_output = detect_candidates(cands, normals=normal, **gates)
        ranges = [sh.d, *cands.range_m]
        pick = choose(cfg.return_mode, valid + more_valid, output + more_output, ranges)

        def picked(values, default):
            out = default
            for i, v in enumerate(values):
                out = dr.select(pick == i, v, out)
            return out

        clear = sh.expected * dr.exp(2.0 * tables["alpha"] * sh.d)  # the same return, clear air
        energy = picked([hard, *cands.energy], 0.0)
        jitter = range_jitter(model, energy, picked([clear], float("inf"))) * normal()
        surface = pick <= 0
        hit = beams.hit
        columns = {
            "range": dr.select(
                pick >= 0,
                add_noise(picked(ranges, 0.0) + jitter, inputs.noise_range, normal_range),
                0.0,
            ),
            "intensity": dr.select(
                pick >= 0,
                add_noise(
                    picked(output + more_output, 0.0) - _offset(cfg, sh.ring),
                    inputs.noise_intensity,
                    normal_intensity,
                ),
                0.0,
            ),
            "reflectance": dr.select(
                surface,
                dr.select(dr.isfinite(sh.rho), sh.rho, 0.0),
                picked([0.0, *cands.reflectance], 0.0),
            ),
            "cos": dr.select(
                surface, dr.select(hit, sh.cos_t, 0.0), dr.select(pick >= 2, 1.0, 0.0)
            ),
            "material": dr.select(surface & hit, ctx.tables.material_index(sh.bsdf), -1),
            "shape": dr.select(surface & hit, ctx.tables.shape_index(beams.si.shape), -1),
            "scatterer": picked([0, *cands.scatterer], 0),
            "valid": (pick >= 0) & (u_dropout >= inputs.dropout),
            "hit": hit,
            "nonfinite": hit & ~dr.isfinite(sh.expected),
        }
        columns["range"] = dr.select(columns["valid"], columns["range"], 0.0)
        columns["intensity"] = dr.select(columns["valid"], columns["intensity"], 0.0)
        dr.eval(columns)  # one kernel
    with _timed(ctx.timings, "readback"):
        _store_ideal(ctx, {key: value.numpy() for key, value in columns.items()}, start, stop)


def _store_ideal(ctx: _Context, cols: dict, start: int, stop: int) -> None:
    """Hand one ideal block's read-back columns to the outputs."""
    ctx.out.hit[start:stop] = cols.pop("hit")
    nonfinite = cols.pop("nonfinite")
    if nonfinite.any():
        ctx.out.nonfinite.append(cols["material"][nonfinite])
    if ctx.tables.rgb_only:  # the materials hit matter only to warn of RGB-only ones
        ctx.out.materials_hit.append(_materials_hit(cols["material"]))
    ctx.out.put(0, start, stop, **cols)


#: Offset of the weather draws' PCG32 streams from the beams' own (no beam index reaches it).
_WEATHER_STREAM = 1 << 40


def _weather_draws(inputs, n: int, first_beam, noisy: bool):
    """Functions returning, per call, one uniform and one standard normal (0.0 without receiver
    noise) per beam, from each beam's own weather stream (the clear draws keep theirs)."""
    import mitsuba as mi

    offset = mi.UInt64(first_beam)
    rng = mi.PCG32(
        size=n,
        initstate=inputs.seed_state + offset,
        initseq=inputs.stream + offset + mi.UInt64(_WEATHER_STREAM),
    )

    def normal():
        return box_muller(rng.next_float32(), rng.next_float32()) if noisy else 0.0

    return rng.next_float32, normal


def _materials_hit(material: np.ndarray) -> np.ndarray:
    """The distinct material indices >= 0 among ``material`` (int32)."""
    # np.bincount: several times faster than np.unique on a scan's worth of indices
    return np.flatnonzero(np.bincount(material[material >= 0], minlength=1))


def _echo_block(ctx: _Context, rays, beams, sh: _Shading, draws, start: int, stop: int) -> None:
    """Sub-rays of diverging beams: echoes, return selection, detection and noise (the
    grouping of contributions into echoes runs on the host, :mod:`.echoes`)."""
    cfg = ctx.cfg
    with _timed(ctx.timings, "readback"):
        contrib_range, contrib_energy, attrs, hit = _echo_contributions(ctx, rays, beams, sh)
        if ctx.weather is not None:
            contrib_range, contrib_energy = _with_weather(
                ctx, beams, sh, (contrib_range, contrib_energy, attrs), start
            )
        n = stop - start
        nonfinite = hit & ~np.isfinite(attrs["energy"][:, : cfg.subrays])
        ctx.out.nonfinite.append(attrs["material"][:, : cfg.subrays][nonfinite])
        draws = [tuple(_host(x) for x in d) for d in draws.returns]
    with _timed(ctx.timings, "detect"):
        echoes = group_echoes(contrib_range, contrib_energy, cfg.return_separation)
        normal = (
            _echo_normals(ctx.inputs.seed, start, echoes.energy.shape)
            if cfg.receiver_noise_std > 0
            else 0.0
        )
        candidate = detect(
            echoes.energy,
            echoes.range_m,
            hit=np.isfinite(echoes.range_m),
            threshold=cfg.detection_threshold,
            range_min=cfg.range_min,
            range_max=cfg.range_max,
            noise=cfg.receiver_noise_std,
            normal=normal,
        )
        # the sensor sees (and picks by) each echo's output with its receiver noise
        echoes = echoes._replace(energy=received(echoes.energy, cfg.receiver_noise_std, normal))
        slots = select_returns(echoes, candidate, cfg.return_mode)
        # attributes of beams without a return: their strongest echo, if any
        fallback = np.argmax(np.where(np.isfinite(echoes.range_m), echoes.energy, -1.0), axis=1)
        rows = np.arange(n)
        offset = _offset(cfg, (start + rows) // cfg.horizontal_resolution)
        ctx.out.hit[start:stop] = hit.any(axis=1)
        for m in range(cfg.max_returns):
            slot = slots[:, m]
            u, normal_i, normal_r = draws[m]
            valid = (slot >= 0) & (u >= cfg.dropout)
            pick = np.where(slot >= 0, slot, fallback if m == 0 else 0)
            src = echoes.source[rows, pick]
            has = src >= 0 if m == 0 else valid
            src = np.maximum(src, 0)
            e = echoes.energy[rows, pick]
            r = echoes.range_m[rows, pick]
            material = np.where(has, attrs["material"][rows, src], -1)
            extra = (
                {}
                if ctx.weather is None
                else _echo_weather(ctx, attrs, e, (rows, src, has), (start, m))
            )
            r = r + extra.pop("jitter", 0.0)
            ctx.out.put(
                m,
                start,
                stop,
                valid=valid,
                intensity=np.where(
                    valid,
                    add_noise(e - offset, cfg.noise_intensity_std, normal_i),
                    0.0,
                ),
                range=np.where(valid, add_noise(r, cfg.noise_range_std, normal_r), 0.0),
                reflectance=np.where(has, attrs["reflectance"][rows, src], 0.0),
                cos=np.where(has, attrs["cos"][rows, src], 0.0),
                material=material,
                shape=np.where(has, attrs["shape"][rows, src], -1),
                **extra,
            )
            if m == 0 and ctx.tables.rgb_only:
                ctx.out.materials_hit.append(_materials_hit(material))


def _with_weather(ctx: _Context, beams, sh: _Shading, contributions, start: int):
    """Add each diverging beam's soft return and sampled particles (:mod:`.weather`, on the
    beam's axis) to its (n, K) contributions: the attrs grow in place (``scatterer`` and
    ``clear_ratio``, the clear-air return over the return, join them).

    Returns:
        ``(range_m, energy)`` with the new columns, the surfaces' energies occluded by the
        particles in front of them.
    """
    import drjit as dr
    import mitsuba as mi

    from .weather_returns import candidates

    (model, tables), cfg = ctx.weather, ctx.cfg
    contrib_range, contrib_energy, attrs = contributions
    n = contrib_range.shape[0]
    axis = dr.arange(mi.UInt32, n) * cfg.subrays  # sub-ray 0 of each beam is its axis
    far = cfg.range_max + model.receiver.pulse_length
    limit = dr.select(dr.gather(mi.Bool, beams.hit, axis), dr.gather(mi.Float, sh.d, axis), far)
    uniform, _ = _weather_draws(ctx.inputs, n, dr.opaque(mi.UInt32, start), False)
    c = candidates(model, limit, tables, uniform)
    cols = [c.energy, c.range_m, c.reflectance]
    dr.eval(cols, c.occlusion)
    energy, rng, refl = (
        np.stack([np.broadcast_to(_host(v), n) for v in col], axis=1) for col in cols
    )
    occlusion = np.broadcast_to(_host(c.occlusion), n)[:, None]
    k = energy.shape[1]
    seen = np.where(np.isfinite(contrib_range), contrib_range, 0.0)
    ratio = np.exp(2.0 * model.alpha * seen) / np.maximum(occlusion, 1e-30)
    new = {
        "clear_ratio": (ratio, np.full((n, k), np.inf)),
        "scatterer": (np.zeros(seen.shape, np.uint8), np.tile(np.uint8(c.scatterer), (n, 1))),
        "reflectance": (attrs["reflectance"], refl),
        "cos": (attrs["cos"], np.tile((np.arange(k) > 0).astype(attrs["cos"].dtype), (n, 1))),
        "material": (attrs["material"], np.full((n, k), -1, attrs["material"].dtype)),
        "shape": (attrs["shape"], np.full((n, k), -1, attrs["shape"].dtype)),
    }
    attrs.update({key: np.concatenate(pair, axis=1) for key, pair in new.items()})
    present = energy > 0
    return (
        np.concatenate([contrib_range, np.where(present, rng, np.inf)], axis=1),
        np.concatenate([contrib_energy * occlusion, np.where(present, energy, 0.0)], axis=1),
    )


def _echo_weather(ctx: _Context, attrs: dict, energy, picked, where) -> dict:
    """The weather's columns of one return of a block of diverging beams: what it came from
    (``scatterer``) and its extra range deviation (``jitter``, drawn)."""
    (model, _), cfg = ctx.weather, ctx.cfg
    rows, src, has = picked
    start, m = where
    clear = energy * attrs["clear_ratio"][rows, src]
    normal = _echo_normals(ctx.inputs.seed, start, (rows.size, cfg.max_returns), salt=1)[:, m]
    return {
        "jitter": range_jitter(model, energy, clear) * normal,
        "scatterer": np.where(has, attrs["scatterer"][rows, src], 0),
    }


def _echo_contributions(ctx: _Context, rays, beams, sh: _Shading):
    """The (n, K) contributions of each beam's sub-rays (surface hits, then the specular echoes
    of glass when any beam met glass), read back.

    Returns:
        ``(range_m, energy, attrs, hit)``: (n, K) float ranges (inf: none) and energies (0:
        none); attrs (n, K) ``reflectance``, ``cos``, ``material``, ``shape`` of every
        contribution and ``energy`` of the surface hits before the finiteness test; (n, N)
        bool surface hits.
    """
    import drjit as dr

    inputs, tables, cfg = ctx.inputs, ctx.tables, ctx.cfg
    glass = beams.glass
    cos_a = dr.minimum(dr.abs(dr.dot(glass.normal, rays.axis)), 1.0)
    theta2 = dr.square(inputs.half_angle)
    glass_energy = (
        rays.weight
        * inputs.gain
        * glass.reflectance
        * dr.exp(-8.0 * dr.square(dr.acos(cos_a)) / theta2)
        / (2.0 * theta2)
        * attenuation(
            dr.select(glass.hit, glass.path_m, 1.0), 1.0, inputs.alpha, cfg.intensity_mode
        )
        * sh.laser_gain
        * _range_factor(cfg, dr.select(glass.hit, glass.path_m, 1.0), sh.ring)
    )
    surface = {
        "hit": beams.hit,
        "path": beams.path_m,
        "energy": rays.weight * sh.expected,
        "reflectance": sh.rho,
        "cos": sh.cos_t,
        "material": tables.material_index(sh.bsdf),
        "shape": tables.shape_index(beams.si.shape),
    }
    front = {
        "hit": glass.hit,
        "path": glass.path_m,
        "energy": glass_energy,
        "reflectance": glass.reflectance,
        "cos": cos_a,
        "material": tables.material_index(glass.bsdf),
        "shape": tables.shape_index(glass.shape),
    }
    dr.eval(surface, front)
    count = cfg.subrays

    def grid(x):
        return x.numpy().reshape(-1, count)

    s = {k: grid(v) for k, v in surface.items()}
    hit = s["hit"].astype(bool)
    finite = np.isfinite(s["energy"])
    contrib_range = [np.where(hit, s["path"], np.inf)]
    contrib_energy = [np.where(hit & finite, s["energy"], 0.0)]
    rho = s["reflectance"]
    attrs = {
        "reflectance": [np.where(np.isfinite(rho), rho, 0.0)],
        "cos": [s["cos"]],
        "material": [s["material"]],
        "shape": [s["shape"]],
        "energy": [s["energy"]],
    }
    g_hit = grid(glass.hit).astype(bool)
    if g_hit.any():  # the specular echoes of glass panes
        g = {k: grid(v) for k, v in front.items()}
        contrib_range.append(np.where(g_hit, g["path"], np.inf))
        contrib_energy.append(np.where(g_hit, g["energy"], 0.0))
        for key in ("reflectance", "cos", "material", "shape", "energy"):
            attrs[key].append(g[key])
    attrs = {key: np.concatenate(v, axis=1) for key, v in attrs.items()}
    return (
        np.concatenate(contrib_range, axis=1),
        np.concatenate(contrib_energy, axis=1),
        attrs,
        hit,
    )


def _host(x):
    """A draw as NumPy (a Python float stands for a draw left out: its σ is 0)."""
    return x if isinstance(x, float) else x.numpy()


# ---------------------------------------------------------------- kernel inputs


@contextlib.contextmanager
def _timed(timings: dict[str, float], stage: str):
    t0 = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - t0


_beam_cache: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}
_jit_cache: dict[tuple, tuple[Any, Any]] = {}
_time_cache: dict[Any, np.ndarray] = {}
_pattern_cache: dict[LidarConfig, Any] = {}
_CACHE_SIZE = 16


def _cached(cache: dict, key, make):
    if key not in cache:
        if len(cache) > _CACHE_SIZE:
            cache.clear()
        cache[key] = make()
    return cache[key]


def _pattern_arrays(cfg: LidarConfig, start: int, stop: int):
    """(n, 3) float32 directions and origins (or None) of beams ``start..stop``, read-only and
    cached per sensor configuration and block."""

    def make():
        d, o = _pattern(cfg).beams(start, stop)
        out = tuple(None if a is None else a.astype(np.float32) for a in (d, o))
        for a in out:
            if a is not None:
                a.setflags(write=False)
        return out

    return _cached(_beam_cache, (cfg, start, stop), make)


def _pattern_jit(cfg: LidarConfig, start: int, stop: int):
    """Beams ``start..stop`` as ``mi.Vector3f`` directions and ``mi.Point3f`` origins (or None),
    uploaded once per sensor configuration, block and variant: the pattern stays on the
    device."""
    import mitsuba as mi

    def make():
        d, o = _pattern_arrays(cfg, start, stop)
        directions = mi.Vector3f(*(jit_float(d[:, i]) for i in range(3)))
        origins = None if o is None else mi.Point3f(*(jit_float(o[:, i]) for i in range(3)))
        return directions, origins

    return _cached(_jit_cache, (cfg, start, stop, mi.variant()), make)


def _firing_times(cfg: LidarConfig) -> np.ndarray:
    """(R·C,) float32 firing time of every beam, s; read-only, cached per configuration."""

    def make():
        t = _pattern(cfg).time_s().astype(np.float32)
        t.setflags(write=False)
        return t

    return _cached(_time_cache, cfg, make)


def _pattern(cfg: LidarConfig):
    """``cfg.pattern``, cached (building it, and hashing it, costs ~1 ms each time)."""
    return _cached(_pattern_cache, cfg, lambda: cfg.pattern)


def _pose(sensor, to_world) -> np.ndarray:
    """(4, 4) float64 pose: ``to_world`` when given, else the sensor's own."""
    if to_world is None:
        return transform_matrix(sensor.world_transform())
    return np.asarray(to_world, dtype=np.float64).reshape(4, 4)


class _KernelInputs(NamedTuple):
    """The scalar parameters as Dr.Jit values gathered from one uploaded buffer (data, not
    literals: one compiled kernel for every value). The dropout probability and the noise σ
    are the Python float 0.0 where the sensor's value is 0: that sensor's kernels leave out
    the draws' transforms (the random stream, and every draw that is used, stay the same)."""

    wavelength: Any
    gain: Any
    alpha: Any
    range_min: Any
    range_max: Any
    threshold: Any
    dropout: Any
    noise_intensity: Any
    noise_range: Any
    receiver_noise: Any
    half_angle: Any
    seed_state: Any
    stream: Any
    seed: int


def _kernel_inputs(cfg: LidarConfig, seed: int, pose: np.ndarray | None, weather_alpha: float):
    """The kernels' scalars and the single pose (when given, (4, 4)), in one upload and one
    width-1 kernel (:func:`.rays.jit_scalars`); ``weather_alpha`` (1/m) adds to the clear-air
    extinction (0 in clear weather).

    Returns:
        ``(_KernelInputs, Poses or None)``.
    """
    import drjit as dr
    import mitsuba as mi

    params = [
        cfg.wavelength,
        cfg.gain,
        cfg.atmospheric_extinction + weather_alpha,
        cfg.range_min,
        cfg.range_max,
        cfg.detection_threshold,
        cfg.dropout,
        cfg.noise_intensity_std,
        cfg.noise_range_std,
        cfg.receiver_noise_std,
        cfg.beam_divergence * 5e-4,  # mrad full angle -> rad half angle
    ]
    words = np.array(  # the 64-bit PCG32 seed state and stream, as float32 bit patterns
        [(seed * 0x9E3779B97F4A7C15) % 2**64, _PCG32_DEFAULT_STREAM], dtype="<u8"
    ).view("<u4")
    matrix = np.zeros(0) if pose is None else np.asarray(pose, dtype=np.float64).reshape(16)
    values = np.concatenate(
        [np.asarray(params, dtype=np.float32), matrix.astype(np.float32), words.view(np.float32)]
    )
    jit = jit_scalars(values)
    bits = [mi.UInt64(dr.reinterpret_array(mi.UInt32, x)) for x in jit[-4:]]
    seed_state, stream = bits[0] | (bits[1] << 32), bits[2] | (bits[3] << 32)
    scalars = jit[: len(params)]
    entries = jit[len(params) : len(params) + matrix.size]
    dr.eval(scalars, entries, seed_state, stream)
    for i in range(6, 10):  # dropout and noise σ: a literal 0 where the sensor has none
        if params[i] == 0:
            scalars[i] = 0.0
    inputs = _KernelInputs(*scalars, seed_state, stream, seed)
    return inputs, (static_pose(entries) if pose is not None else None)


_PCG32_DEFAULT_STREAM = 0xDA3E39CB94B95BDB


class _Draws(NamedTuple):
    """Per return ``(u_dropout, normal_intensity, normal_range)``, and the receiver noise's
    standard normal; each a Dr.Jit array of one entry per beam, or the Python float (1.0 for
    the uniform, 0.0 for a normal) where the sensor's probability or σ is 0."""

    returns: list
    receiver: Any


def _draws(cfg: LidarConfig, n: int, inputs, first_beam) -> _Draws:
    """Per beam and return: a uniform dropout draw and standard normals for intensity and range
    noise; then, per beam, a standard normal of the receiver noise (drawn after the others so
    that they keep their values). Beam ``b`` draws from its own stream whatever block it is
    cast in; a draw whose σ (or probability) is 0 still advances the stream."""
    import mitsuba as mi

    offset = mi.UInt64(first_beam)
    rng = mi.PCG32(
        size=n,
        initstate=inputs.seed_state + offset,
        initseq=inputs.stream + offset,
    )

    def uniform(used: bool):
        u = rng.next_float32()
        return u if used else 1.0

    def normal(used: bool):
        u1, u2 = rng.next_float32(), rng.next_float32()
        return box_muller(u1, u2) if used else 0.0

    out = []
    for _ in range(cfg.max_returns):
        out.append(
            (
                uniform(cfg.dropout > 0),
                normal(cfg.noise_intensity_std > 0),
                normal(cfg.noise_range_std > 0),
            )
        )
    return _Draws(out, normal(cfg.receiver_noise_std > 0))


def _mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser (Steele et al., OOPSLA 2014): a bijective uint64 hash."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _echo_normals(seed: int, first_beam: int, shape: tuple[int, int], salt: int = 0) -> np.ndarray:
    """(n, E) standard normals, one per echo slot of beams ``first_beam..first_beam+n``: a
    counter-based draw (hash of seed, beam and slot), the same whatever block a beam is cast in;
    another ``salt`` draws another set.
    """
    n, e = shape
    beam = np.arange(first_beam, first_beam + n, dtype=np.uint64)[:, None]
    slot = np.arange(e, dtype=np.uint64)[None, :]
    with np.errstate(over="ignore"):  # uint64 arithmetic wraps by design
        key = _mix64(
            np.array([seed], dtype=np.uint64) * np.uint64(0x9E3779B97F4A7C15)
            + np.uint64(0x632BE59BD9B4E019)
            + np.uint64(salt) * np.uint64(0xA0761D6478BD642F)
        )
        base = _mix64(key ^ (beam * np.uint64(0xD1B54A32D192ED03) + slot * np.uint64(2)))
        u = [(_mix64(base + np.uint64(i)) >> np.uint64(11)) * 2.0**-53 for i in (1, 2)]
    return box_muller(u[0], u[1])


# ---------------------------------------------------------------- read back


def _drop_materials(layer: ReturnLayer, bad: np.ndarray) -> None:
    """Remove from ``layer`` every return of the materials ``bad`` (indices): a material with no
    data at the laser wavelength gives no trustworthy return anywhere, even where its
    evaluation happens to be finite (Mitsuba's conductor presets read η = k = 0 past their
    table, a perfect mirror at exactly normal incidence and NaN elsewhere)."""
    if len(bad):
        _drop(layer, np.isin(layer.material, bad) & layer.valid)


def _drop(layer: ReturnLayer, drop: np.ndarray) -> None:
    """Report no return at the (R, C) beams ``drop`` (not valid, range and intensity 0)."""
    if drop.any():
        layer.valid = layer.valid & ~drop
        layer.range = np.where(drop, 0.0, layer.range).astype(np.float32)
        layer.intensity = np.where(drop, 0.0, layer.intensity).astype(np.float32)


def _offset_ranges(layer: ReturnLayer, cfg: LidarConfig) -> None:
    """Add each laser's ``laser_range_offsets`` (m) to the range its returns report, no lower
    than 0 (the detection, the intensity and the range gates read the true distance)."""
    if cfg.laser_range_offsets is None:
        return
    off = np.asarray(cfg.laser_range_offsets, dtype=np.float64)[:, None]  # (R, 1)
    moved = np.maximum(layer.range + off, 0.0)
    layer.range = np.where(layer.valid, moved, layer.range).astype(np.float32)


def _warn_nonfinite(cfg: LidarConfig, names: list[str], materials: np.ndarray) -> np.ndarray:
    """One warning per material among ``materials`` (indices) whose returns were not finite;
    returns those materials (the scan drops every return of them)."""
    for idx in np.unique(materials):
        name = names[idx] if idx >= 0 else "?"
        warnings.warn(
            f"lidar '{cfg.name}': material '{name}' has no finite reflectance at "
            f"{cfg.wavelength:g} nm (e.g. a Mitsuba conductor preset past ~886 nm); "
            "its returns are dropped",
            RuntimeWarning,
            stacklevel=3,
        )
    return np.unique(materials)


_warned_rgb: set[tuple[str, str]] = set()


def _warn_rgb_materials(tables: SceneTables, cfg: LidarConfig, materials: np.ndarray) -> None:
    """Warn, once per material and process, when a material hit has RGB-only reflectance.

    ``materials``: indices (>= 0) into the scene's material names of the materials hit.
    """
    for idx in materials:
        name = tables.material_names[idx]
        text = tables.rgb_only.get(name)
        key = (name, text)
        if text is None or key in _warned_rgb:
            continue
        _warned_rgb.add(key)
        warnings.warn(
            f"lidar '{cfg.name}': material '{name}' is RGB-only; its reflectance at "
            f"{cfg.wavelength:g} nm comes from sRGB upsampling and is not physical",
            RuntimeWarning,
            stacklevel=3,
        )
