"""One LiDAR scan: beam pattern → cast through glass → monostatic ρ at λ → return model →
detection and noise → read back.

:func:`scan` casts every beam at once in Dr.Jit (in blocks of bounded memory for very large
scans, :mod:`.memory`); the physics is :mod:`.return_model`'s, the ray casting :mod:`.raycast`'s,
the rays (pose per column, beam origins, sub-rays) :mod:`.rays`'s. The pose and every scalar
parameter enter the kernels as opaque values, so scanning again with another pose, other
per-column poses or another seed reuses the compiled kernels.

Two paths, one per beam model:

* **ideal beam** (``beam_divergence`` 0): one ray per beam, detection and noise in Dr.Jit.
* **diverging beam**: ``N`` sub-rays per beam (:mod:`.footprint`), each carrying its footprint
  weight ``w`` of the pulse: a surface hit contributes ``w · g·ρ·T²·a(d, θ)``, and the first glass
  pane a beam meets contributes its specular echo ``w · g · R_F · exp(-8 α² / θ_w²) / (2 θ_w²) ·
  a'(d)`` (a mirror of Fresnel reflectance ``R_F`` tilted by ``α`` from the beam axis returns a
  Gaussian beam of divergence ``θ_w`` centred ``2α`` off the receiver, over twice the range;
  ``a'`` is ``a`` without the cosine). The contributions are grouped into echoes and the returns
  selected per ``return_mode`` (:mod:`.echoes`); detection and noise per return.

Reading back names the materials (:func:`material_table`) and the shapes (``scene.shapes()``
order), and warns once per material whose reflectance is not finite (Mitsuba's conductor presets
past ~886 nm: its returns are dropped) or comes from RGB upsampling (not physical past 830 nm).
"""

from __future__ import annotations

import contextlib
import time
import warnings
from typing import Any, NamedTuple

import numpy as np

from ..labels import SceneLabels, shape_labels
from .config import LidarConfig
from .echoes import group_echoes, select_returns
from .footprint import subray_offsets
from .memory import check_scan_memory, chunk_beams
from .raycast import cast, monostatic_reflectance
from .rays import block_rays, column_poses, jit_float, static_pose
from .result import ReturnLayer, ScanResult
from .return_model import add_noise, attenuation, box_muller, detect, expected_intensity

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

    Returns:
        The scan on the (ring, column) grid.

    Raises:
        NidarError: the scan would need more memory than ``max_memory``, or the per-column
            poses do not match the columns.
    """
    from ..errors import NidarError

    cfg: LidarConfig = sensor.config
    check_scan_memory(cfg, max_memory)
    timings: dict[str, float] = {}
    pattern = cfg.pattern
    pose = _pose(sensor, to_world)
    if poses_per_column is not None:
        poses_per_column = np.asarray(poses_per_column, dtype=np.float64)
        if poses_per_column.shape != (cfg.horizontal_resolution, 4, 4) or not np.all(
            np.isfinite(poses_per_column)
        ):
            raise NidarError(
                f"lidar '{cfg.name}': poses per column must be a finite "
                f"({cfg.horizontal_resolution}, 4, 4) array (got {poses_per_column.shape})"
            )
    with _timed(timings, "pattern"):
        inputs = _kernel_inputs(cfg, cfg.seed if seed is None else int(seed))
        poses = static_pose(pose) if poses_per_column is None else column_poses(poses_per_column)
        directions = np.empty((pattern.size, 3), dtype=np.float32)
        origins = (
            np.zeros((pattern.size, 3), dtype=np.float32) if cfg.laser_table.has_origins else None
        )
    out = _Outputs(pattern.size, cfg.max_returns)
    for start, stop in chunk_beams(cfg):
        _scan_block(scene, cfg, inputs, poses, start, stop, directions, origins, out, timings)

    with _timed(timings, "readback"):
        shape = (cfg.rings, cfg.horizontal_resolution)
        names, lut = material_table(scene)
        bad = _warn_nonfinite(cfg, names, _lookup(lut, np.concatenate(out.nonfinite_ids)))
        shape_names, shape_lut = shape_table(scene)
        layers = []
        for m in range(cfg.max_returns):
            material = np.where(out.has_attr[m], _lookup(lut, out.bsdf_id[m]), -1)
            layers.append(
                ReturnLayer(
                    valid=out.valid[m].reshape(shape),
                    range=out.range[m].reshape(shape),
                    intensity=out.intensity[m].reshape(shape),
                    reflectance=out.reflectance[m].reshape(shape),
                    cos_incidence=out.cos[m].reshape(shape),
                    material=material.astype(np.int32).reshape(shape),
                    shape_index=np.where(out.has_attr[m], _lookup(shape_lut, out.shape_id[m]), -1)
                    .astype(np.int32)
                    .reshape(shape),
                )
            )
        for layer in layers:
            _drop_materials(layer, bad)
        first = layers[0]
        _warn_rgb_materials(scene, cfg, names, first.material[first.material >= 0])
        result = ScanResult(
            config=cfg,
            valid=first.valid,
            range=first.range,
            intensity=first.intensity,
            reflectance=first.reflectance,
            cos_incidence=first.cos_incidence,
            material=first.material,
            directions=directions.reshape(*shape, 3),
            to_world=pose,
            material_names=names,
            hit=out.hit.reshape(shape),
            timings=timings,
            shape_index=first.shape_index,
            shape_labels=shape_labels(scene, labels),
            shape_names=shape_names,
            time=pattern.time_s().astype(np.float32).reshape(shape),
            origins=None if origins is None else origins.reshape(*shape, 3),
            column_poses=poses_per_column,
            further=layers[1:],
        )
    return result


# ---------------------------------------------------------------- one block of beams


class _Outputs:
    """Flat (R·C,) per-beam outputs, one list entry per return, filled block by block."""

    def __init__(self, beams: int, returns: int) -> None:
        def arr(dtype):
            return [np.zeros(beams, dtype=dtype) for _ in range(returns)]

        self.valid = arr(bool)
        self.range = arr(np.float32)
        self.intensity = arr(np.float32)
        self.reflectance = arr(np.float32)
        self.cos = arr(np.float32)
        self.bsdf_id = arr(np.uint32)
        self.shape_id = arr(np.uint32)
        self.has_attr = arr(bool)
        self.hit = np.zeros(beams, dtype=bool)
        self.nonfinite_ids: list[np.ndarray] = [np.zeros(0, dtype=np.uint32)]


def _scan_block(scene, cfg, inputs, poses, start, stop, directions, origins, out, timings):
    """Scan beams ``start..stop`` and write their outputs into ``out``."""
    import drjit as dr
    import mitsuba as mi

    with _timed(timings, "pattern"):
        d_np, o_np = _beams(cfg, start, stop)
        directions[start:stop] = d_np
        if origins is not None:
            origins[start:stop] = o_np
        first = dr.opaque(mi.UInt32, start)
        subrays = subray_offsets(cfg.beam_sample_quality) if cfg.beam_divergence > 0 else None
        rays = block_rays(
            poses,
            mi.Vector3f(*(jit_float(d_np[:, i]) for i in range(3))),
            None if o_np is None else mi.Point3f(*(jit_float(o_np[:, i]) for i in range(3))),
            first_beam=first,
            cols=cfg.horizontal_resolution,
            subrays=subrays,
            half_angle=inputs.half_angle,
        )
    with _timed(timings, "raycast"):
        beams = cast(scene, rays.ray, inputs.wavelength, glass_front=subrays is not None)
    with _timed(timings, "bsdf"):
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
    n = stop - start
    draws = _draws(n, cfg.max_returns, inputs.seed_state, first)
    if subrays is None:
        _ideal_block(
            cfg, inputs, beams, rho, cos_t, bsdf, d, expected, draws, start, stop, out, timings
        )
    else:
        _echo_block(
            cfg, inputs, rays, beams, rho, cos_t, bsdf, expected, draws, start, stop, out, timings
        )


def _ideal_block(
    cfg, inputs, beams, rho, cos_t, bsdf, d, expected, draws, start, stop, out, timings
):
    """One ray per beam: detection and noise in Dr.Jit."""
    import drjit as dr
    import mitsuba as mi

    s = slice(start, stop)
    with _timed(timings, "detect"):
        u_dropout, normal_intensity, normal_range = draws[0]
        valid = detect(
            expected,
            d,
            hit=beams.hit,
            threshold=inputs.threshold,
            range_min=inputs.range_min,
            range_max=inputs.range_max,
            dropout=inputs.dropout,
            u=u_dropout,
        )
        intensity = dr.select(
            valid, add_noise(expected, inputs.noise_intensity, normal_intensity), 0.0
        )
        range_m = dr.select(valid, add_noise(d, inputs.noise_range, normal_range), 0.0)
        finite = dr.isfinite(expected)
        bsdf_id = dr.reinterpret_array(mi.UInt32, bsdf)
        shape_id = dr.reinterpret_array(mi.UInt32, beams.si.shape)
        dr.eval(intensity, range_m, rho, cos_t, bsdf_id, shape_id, valid, beams.hit, finite)
    with _timed(timings, "readback"):
        hit = beams.hit.numpy().astype(bool)
        ids = bsdf_id.numpy()
        rho_np = rho.numpy()
        out.valid[0][s] = valid.numpy().astype(bool)
        out.range[0][s] = range_m.numpy()
        out.intensity[0][s] = intensity.numpy()
        out.reflectance[0][s] = np.where(np.isfinite(rho_np), rho_np, 0.0)
        out.cos[0][s] = np.where(hit, cos_t.numpy(), 0.0)
        out.bsdf_id[0][s] = ids
        out.shape_id[0][s] = shape_id.numpy()
        out.has_attr[0][s] = hit
        out.hit[s] = hit
        out.nonfinite_ids.append(ids[hit & ~finite.numpy().astype(bool)])


def _echo_block(
    cfg, inputs, rays, beams, rho, cos_t, bsdf, expected, draws, start, stop, out, timings
):
    """Sub-rays of diverging beams: echoes, return selection, detection and noise."""
    import drjit as dr
    import mitsuba as mi

    n, count = stop - start, cfg.subrays
    with _timed(timings, "detect"):
        glass = beams.glass
        cos_a = dr.minimum(dr.abs(dr.dot(glass.normal, rays.axis)), 1.0)
        alpha2 = dr.square(dr.acos(cos_a))
        theta2 = dr.square(inputs.half_angle)
        d_glass = dr.select(glass.hit, glass.path_m, 1.0)
        glass_energy = (
            rays.weight
            * inputs.gain
            * glass.reflectance
            * dr.exp(-8.0 * alpha2 / theta2)
            / (2.0 * theta2)
            * attenuation(d_glass, 1.0, inputs.alpha, cfg.intensity_mode)
        )
        energy = rays.weight * expected
        ids = dr.reinterpret_array(mi.UInt32, bsdf)
        shape_ids = dr.reinterpret_array(mi.UInt32, beams.si.shape)
        glass_ids = dr.reinterpret_array(mi.UInt32, glass.bsdf)
        glass_shape_ids = dr.reinterpret_array(mi.UInt32, glass.shape)
        dr.eval(
            beams.hit,
            beams.path_m,
            energy,
            rho,
            cos_t,
            ids,
            shape_ids,
            glass.hit,
            glass.path_m,
            glass.reflectance,
            glass_energy,
            cos_a,
            glass_ids,
            glass_shape_ids,
        )
    with _timed(timings, "readback"):

        def grid(x, dtype=None):
            a = x.numpy()
            return (a if dtype is None else a.astype(dtype)).reshape(n, count)

        hit = grid(beams.hit, bool)
        e_surf = grid(energy)
        finite = np.isfinite(e_surf)
        surf_ids = grid(ids)
        out.nonfinite_ids.append(surf_ids[hit & ~finite])
        rho_np = grid(rho)
        contrib_range = [np.where(hit, grid(beams.path_m), np.inf)]
        contrib_energy = [np.where(hit & finite, e_surf, 0.0)]
        attrs = {
            "reflectance": [np.where(np.isfinite(rho_np), rho_np, 0.0)],
            "cos": [grid(cos_t)],
            "bsdf_id": [surf_ids],
            "shape_id": [grid(shape_ids)],
        }
        g_hit = grid(glass.hit, bool)
        if g_hit.any():  # the specular echoes of glass panes
            contrib_range.append(np.where(g_hit, grid(glass.path_m), np.inf))
            contrib_energy.append(np.where(g_hit, grid(glass_energy), 0.0))
            attrs["reflectance"].append(grid(glass.reflectance))
            attrs["cos"].append(grid(cos_a))
            attrs["bsdf_id"].append(grid(glass_ids))
            attrs["shape_id"].append(grid(glass_shape_ids))
        contrib_range = np.concatenate(contrib_range, axis=1)
        contrib_energy = np.concatenate(contrib_energy, axis=1)
        attrs = {key: np.concatenate(v, axis=1) for key, v in attrs.items()}
    with _timed(timings, "detect"):
        echoes = group_echoes(contrib_range, contrib_energy, cfg.return_separation)
        candidate = detect(
            echoes.energy,
            echoes.range_m,
            hit=np.isfinite(echoes.range_m),
            threshold=cfg.detection_threshold,
            range_min=cfg.range_min,
            range_max=cfg.range_max,
        )
        slots = select_returns(echoes, candidate, cfg.return_mode)
        # attributes of beams without a return: their strongest echo, if any
        fallback = np.argmax(np.where(np.isfinite(echoes.range_m), echoes.energy, -1.0), axis=1)
        rows = np.arange(n)
        s = slice(start, stop)
        out.hit[s] = hit.any(axis=1)
        for m in range(cfg.max_returns):
            slot = slots[:, m]
            u, normal_i, normal_r = (x.numpy() for x in draws[m])
            valid = (slot >= 0) & (u >= cfg.dropout)
            pick = np.where(slot >= 0, slot, fallback if m == 0 else 0)
            src = echoes.source[rows, pick]
            has = src >= 0 if m == 0 else valid
            src = np.maximum(src, 0)
            e = echoes.energy[rows, pick]
            r = echoes.range_m[rows, pick]
            out.valid[m][s] = valid
            out.intensity[m][s] = np.where(
                valid, add_noise(e, cfg.noise_intensity_std, normal_i), 0.0
            )
            out.range[m][s] = np.where(valid, add_noise(r, cfg.noise_range_std, normal_r), 0.0)
            for key, target in (("reflectance", out.reflectance), ("cos", out.cos)):
                target[m][s] = np.where(has, attrs[key][rows, src], 0.0)
            out.bsdf_id[m][s] = attrs["bsdf_id"][rows, src]
            out.shape_id[m][s] = attrs["shape_id"][rows, src]
            out.has_attr[m][s] = has


# ---------------------------------------------------------------- kernel inputs


@contextlib.contextmanager
def _timed(timings: dict[str, float], stage: str):
    t0 = time.perf_counter()
    yield
    timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - t0


_beam_cache: dict[tuple, tuple[np.ndarray, np.ndarray | None]] = {}


def _beams(cfg: LidarConfig, start: int, stop: int):
    """(n, 3) float32 directions and origins (or None) of beams ``start..stop``; whole sweeps
    are cached per pattern."""
    pattern = cfg.pattern
    key = (pattern, start, stop)
    if key in _beam_cache:
        return _beam_cache[key]
    d, o = pattern.beams(start, stop)
    d = d.astype(np.float32)
    o = None if o is None else o.astype(np.float32)
    if stop - start == pattern.size:
        if len(_beam_cache) > 16:
            _beam_cache.clear()
        for a in (d, o):
            if a is not None:
                a.setflags(write=False)
        _beam_cache[key] = (d, o)
    return d, o


def _pose(sensor, to_world) -> np.ndarray:
    """(4, 4) float64 pose: ``to_world`` when given, else the sensor's own."""
    if to_world is None:
        return np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
    return np.asarray(to_world, dtype=np.float64).reshape(4, 4)


class _KernelInputs(NamedTuple):
    """The scalar parameters as opaque Dr.Jit values (one compiled kernel for all)."""

    wavelength: Any
    gain: Any
    alpha: Any
    range_min: Any
    range_max: Any
    threshold: Any
    dropout: Any
    noise_intensity: Any
    noise_range: Any
    half_angle: Any
    seed_state: Any


def _kernel_inputs(cfg: LidarConfig, seed: int) -> _KernelInputs:
    import drjit as dr
    import mitsuba as mi

    def opaque(value: float):
        return dr.opaque(mi.Float, value)

    return _KernelInputs(
        wavelength=opaque(cfg.wavelength),
        gain=opaque(cfg.gain),
        alpha=opaque(cfg.atmospheric_extinction),
        range_min=opaque(cfg.range_min),
        range_max=opaque(cfg.range_max),
        threshold=opaque(cfg.detection_threshold),
        dropout=opaque(cfg.dropout),
        noise_intensity=opaque(cfg.noise_intensity_std),
        noise_range=opaque(cfg.noise_range_std),
        half_angle=opaque(cfg.beam_divergence * 5e-4),  # mrad full angle -> rad half angle
        seed_state=dr.opaque(mi.UInt64, (seed * 0x9E3779B97F4A7C15) % 2**64),
    )


_PCG32_DEFAULT_STREAM = 0xDA3E39CB94B95BDB


def _draws(n: int, returns: int, seed_state, first_beam):
    """Per beam and return: a uniform dropout draw and standard normals for intensity and range
    noise. Beam ``b`` draws from its own stream whatever block it is cast in."""
    import drjit as dr
    import mitsuba as mi

    offset = mi.UInt64(first_beam)
    rng = mi.PCG32(
        size=n,
        initstate=seed_state + offset,
        initseq=dr.opaque(mi.UInt64, _PCG32_DEFAULT_STREAM) + offset,
    )
    out = []
    for _ in range(returns):
        u_dropout = rng.next_float32()
        normal_intensity = box_muller(rng.next_float32(), rng.next_float32())
        normal_range = box_muller(rng.next_float32(), rng.next_float32())
        out.append((u_dropout, normal_intensity, normal_range))
    return out


# ---------------------------------------------------------------- read back


def _lookup(lut: dict[int, int], ids: np.ndarray) -> np.ndarray:
    """int32 index per registry id (-1 for ids not in ``lut``)."""
    table = np.full(max(lut, default=0) + 2, -1, dtype=np.int32)
    for reg, idx in lut.items():
        table[reg] = idx
    return table[np.minimum(np.asarray(ids, dtype=np.int64), table.size - 1)]


def shape_table(scene) -> tuple[list[str], dict[int, int]]:
    """Shapes of a scene in ``scene.shapes()`` order.

    Returns:
        (their ids, map from the shape's Dr.Jit registry id to its index).
    """
    import drjit as dr
    import mitsuba as mi

    shapes = list(scene.shapes())
    regs = {
        int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]): i for i, s in enumerate(shapes)
    }
    return [s.id() for s in shapes], regs


def material_table(scene) -> tuple[list[str], dict[int, int]]:
    """Materials (BSDFs) of a scene in a stable order.

    Returns:
        (names sorted alphabetically, map from the BSDF's Dr.Jit registry id to index in names).
    """
    import drjit as dr
    import mitsuba as mi

    by_name: dict[str, int] = {}
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if bsdf is None:
            continue
        reg = int(dr.reinterpret_array(mi.UInt32, mi.BSDFPtr(bsdf))[0])
        by_name.setdefault(_bsdf_name(shape), reg)
    names = sorted(by_name)
    regs = {}
    for shape in scene.shapes():
        bsdf = shape.bsdf()
        if bsdf is not None:
            reg = int(dr.reinterpret_array(mi.UInt32, mi.BSDFPtr(bsdf))[0])
            regs[reg] = names.index(_bsdf_name(shape))
    return names, regs


def _bsdf_name(shape) -> str:
    """The BSDF's id, or ``<shape id>.bsdf`` for an anonymous BSDF."""
    return shape.bsdf().id() or f"{shape.id()}.bsdf"


def _drop_materials(layer: ReturnLayer, bad: np.ndarray) -> None:
    """Remove from ``layer`` every return of the materials ``bad`` (indices): a material with no
    data at the laser wavelength gives no trustworthy return anywhere, even where its
    evaluation happens to be finite (Mitsuba's conductor presets read η = k = 0 past their
    table, a perfect mirror at exactly normal incidence and NaN elsewhere)."""
    drop = np.isin(layer.material, bad) & layer.valid
    if drop.any():
        layer.valid = layer.valid & ~drop
        layer.range = np.where(drop, 0.0, layer.range).astype(np.float32)
        layer.intensity = np.where(drop, 0.0, layer.intensity).astype(np.float32)


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


def _warn_rgb_materials(scene, cfg: LidarConfig, names: list[str], materials: np.ndarray) -> None:
    """Warn, once per material and process, when a material hit has RGB-only reflectance.

    ``materials``: indices (>= 0) into ``names`` of the materials hit, one per return.
    """
    by_name = {}
    for shape in scene.shapes():
        if shape.bsdf() is not None:
            by_name[_bsdf_name(shape)] = shape.bsdf()
    # np.bincount: several times faster than np.unique on a scan's worth of indices
    for idx in np.flatnonzero(np.bincount(materials, minlength=len(names))):
        name = names[idx]
        key = (name, str(by_name.get(name)))
        if key in _warned_rgb or "SRGBReflectanceSpectrum" not in key[1]:
            continue
        _warned_rgb.add(key)
        warnings.warn(
            f"lidar '{cfg.name}': material '{name}' is RGB-only; its reflectance at "
            f"{cfg.wavelength:g} nm comes from sRGB upsampling and is not physical",
            RuntimeWarning,
            stacklevel=3,
        )
