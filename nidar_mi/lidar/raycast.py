"""Cast a LiDAR's whole beam pattern through a Mitsuba scene and apply the return model.

Everything per ray runs vectorised in Dr.Jit (no Python loop over rays); the pose and every scalar
parameter enter the kernels as opaque values, so scanning again with another pose or seed reuses
the compiled kernels.

Glass: a hit on a BSDF whose only components are delta or null transmission and delta reflection
(Mitsuba's ``dielectric``, ``thindielectric``) returns nothing itself: the beam passes through,
up to :data:`MAX_PASSES` interfaces, and the return from the surface behind it is scaled by the
two-way Fresnel transmittance ``T²`` (``T`` from the BSDF's own delta-transmission weight at the
laser wavelength). The reported range is the path length and the point lies on the original beam.
Smooth conductors and other purely specular surfaces return nothing (no monostatic lobe), and
a return carrying no energy (``g·ρ·a = 0``) is never reported, whatever the threshold.

NaN reflectances (Mitsuba's conductor presets past ~886 nm) are dropped with one warning per
material.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from .config import LidarConfig
from .pattern import beam_directions

__all__ = ["ScanResult", "scan", "MAX_PASSES", "material_table"]

#: Number of glass interfaces a beam may pass through.
MAX_PASSES = 4
_EPS_COS = 1e-6


@dataclass
class ScanResult:
    """One scan on the (ring, column) grid. All arrays are (R, C) unless noted.

    Attributes:
        config: the sensor's resolved parameters.
        valid: bool, a return was reported.
        range: float32 m (after range noise); 0 where not valid.
        intensity: float32 (after intensity noise, clipped at 0); 0 where not valid.
        reflectance: float32 ρ at the laser wavelength (monostatic BSDF × π); 0 where no hit.
        cos_incidence: float32 cosine of the incidence angle; 0 where no hit.
        material: int32 index into ``material_names``; -1 where no hit.
        directions: (R, C, 3) float32 unit beam directions in the LiDAR frame.
        to_world: (4, 4) float64 LiDAR pose.
        material_names: list of material (BSDF) ids.
        hit: bool, the beam hit a surface (before range, threshold and dropout tests).
        timings: seconds per stage.
    """

    config: LidarConfig
    valid: np.ndarray
    range: np.ndarray
    intensity: np.ndarray
    reflectance: np.ndarray
    cos_incidence: np.ndarray
    material: np.ndarray
    directions: np.ndarray
    to_world: np.ndarray
    material_names: list[str]
    hit: np.ndarray
    timings: dict[str, float] = field(default_factory=dict)

    def points(self) -> dict[str, np.ndarray]:
        """The valid returns as a points dict (schema in :mod:`nidar_mi.io.points`)."""
        m = self.valid
        rings, cols = np.nonzero(m)
        rng = self.range[m].astype(np.float32)
        xyz = (self.directions[m] * rng[:, None]).astype(np.float32)
        R, t = self.to_world[:3, :3], self.to_world[:3, 3]
        xyz_world = (xyz.astype(np.float64) @ R.T + t).astype(np.float32)
        return {
            "xyz": xyz,
            "xyz_world": xyz_world,
            "range": rng,
            "intensity": self.intensity[m].astype(np.float32),
            "reflectance": self.reflectance[m].astype(np.float32),
            "cos_incidence": self.cos_incidence[m].astype(np.float32),
            "ring": rings.astype(np.uint16),
            "column": cols.astype(np.uint32),
            "material": self.material[m].astype(np.int32),
            "material_names": np.asarray(self.material_names, dtype=np.str_),
        }


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


_dir_cache: dict[tuple, tuple[np.ndarray, object]] = {}


def _directions(cfg: LidarConfig):
    """(R, C, 3) float32 beam directions and their Dr.Jit copy, cached per pattern and variant."""
    import mitsuba as mi

    key = (cfg.elevations_deg, cfg.horizontal_resolution, cfg.fov_h, mi.variant())
    if key not in _dir_cache:
        if len(_dir_cache) > 16:
            _dir_cache.clear()
        d = beam_directions(cfg.elevations, cfg.horizontal_resolution, cfg.fov_h).astype(np.float32)
        flat = d.reshape(-1, 3)
        d.setflags(write=False)
        _dir_cache[key] = (d, mi.Vector3f(flat[:, 0], flat[:, 1], flat[:, 2]))
    return _dir_cache[key]


def _has_glass(scene) -> bool:
    """Whether any BSDF of the scene lets a beam through (delta or null transmission)."""
    import mitsuba as mi

    through = int(mi.BSDFFlags.DeltaTransmission) | int(mi.BSDFFlags.Null)
    return any(
        shape.bsdf() is not None and int(shape.bsdf().flags()) & through for shape in scene.shapes()
    )


def _rgb_only(bsdf) -> bool:
    return "SRGBReflectanceSpectrum" in str(bsdf)


def scan(scene, sensor, *, seed: int | None = None, to_world=None) -> ScanResult:
    """Cast every beam of ``sensor`` and compute its return.

    Args:
        scene: a loaded ``mi.Scene`` (spectral variant).
        sensor: a ``lidar`` sensor of that scene.
        seed: overrides the sensor's ``seed`` for the noise and dropout draws.
        to_world: optional (4,4) pose overriding the sensor's ``to_world`` (frame animation).

    Returns:
        The scan on the (ring, column) grid.
    """
    import drjit as dr
    import mitsuba as mi

    cfg: LidarConfig = sensor.config
    timings: dict[str, float] = {}
    t0 = time.perf_counter()

    R, C = cfg.rings, cfg.horizontal_resolution
    n = R * C
    dirs_np, d_local = _directions(cfg)
    if to_world is None:
        T_np = np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
    else:
        T_np = np.asarray(to_world, dtype=np.float64).reshape(4, 4)
    T = mi.Transform4f(T_np.astype(np.float32))
    dr.make_opaque(T)
    seed = cfg.seed if seed is None else int(seed)
    wl = dr.opaque(mi.Float, cfg.wavelength)
    gain = dr.opaque(mi.Float, cfg.gain)
    alpha = dr.opaque(mi.Float, cfg.atmospheric_extinction)
    r_min = dr.opaque(mi.Float, cfg.range_min)
    r_max = dr.opaque(mi.Float, cfg.range_max)
    thresh = dr.opaque(mi.Float, cfg.detection_threshold)
    p_drop = dr.opaque(mi.Float, cfg.dropout)
    s_int = dr.opaque(mi.Float, cfg.noise_intensity_std)
    s_rng = dr.opaque(mi.Float, cfg.noise_range_std)
    timings["pattern"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- ray cast (+ glass)
    t0 = time.perf_counter()
    d_world = dr.normalize(T @ d_local)
    ray = mi.Ray3f(T @ mi.Point3f(0.0), d_world)
    si = scene.ray_intersect(ray)
    path = dr.select(si.is_valid(), si.t, 0.0)  # accumulated path length
    trans = mi.Float(1.0)  # one-way transmittance through glass
    ctx_t = mi.BSDFContext(
        mi.TransportMode.Importance, mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.Null
    )
    spec_wl = mi.UnpolarizedSpectrum(wl)
    for _ in range(MAX_PASSES if _has_glass(scene) else 0):
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        passes = mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission) | mi.has_flag(
            flags, mi.BSDFFlags.Null
        )
        glass = si.is_valid() & passes & ~mi.has_flag(flags, mi.BSDFFlags.Smooth)
        si.wavelengths = spec_wl
        bs, w = bsdf.sample(ctx_t, si, 0.5, mi.Point2f(0.5, 0.5), glass)
        trans = dr.select(glass, trans * w[0], trans)
        nray = si.spawn_ray(ray.d)
        si2 = scene.ray_intersect(nray, glass)
        path = dr.select(glass, dr.select(si2.is_valid(), path + si2.t, path), path)
        si = dr.select(glass, si2, si)
    hit = si.is_valid()
    timings["raycast"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- monostatic BSDF at λ
    t0 = time.perf_counter()
    si.wavelengths = spec_wl
    si.wi = si.to_local(-ray.d)
    bsdf = si.bsdf(ray)
    f_cos = bsdf.eval(mi.BSDFContext(), si, si.wi, hit)[0]  # f_r · cos θ
    cos_t = dr.minimum(dr.abs(mi.Frame3f.cos_theta(si.wi)), 1.0)  # two-sided BSDFs: either face
    rho = dr.select(hit & (cos_t > _EPS_COS), dr.pi * f_cos / dr.maximum(cos_t, _EPS_COS), 0.0)
    d = dr.select(hit, path, 1.0)
    ideal = gain * rho * trans * trans * cos_t * dr.exp(-2.0 * alpha * d)
    if cfg.intensity_mode == "raw":
        ideal = ideal / (d * d)
    timings["bsdf"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- detection and noise
    t0 = time.perf_counter()
    from .return_model import box_muller

    rng = mi.PCG32(size=n, initstate=dr.opaque(mi.UInt64, (seed * 0x9E3779B97F4A7C15) % 2**64))
    u_drop = rng.next_float32()
    g_int = box_muller(rng.next_float32(), rng.next_float32())
    g_rng = box_muller(rng.next_float32(), rng.next_float32())
    ok = dr.isfinite(ideal)
    detected = (
        hit
        & ok
        & (ideal > 0.0)
        & (ideal >= thresh)
        & (d >= r_min)
        & (d <= r_max)
        & (u_drop >= p_drop)
    )
    intensity = dr.select(detected, dr.maximum(ideal + s_int * g_int, 0.0), 0.0)
    rng_out = dr.select(detected, dr.maximum(d + s_rng * g_rng, 0.0), 0.0)
    mat_id = dr.reinterpret_array(mi.UInt32, bsdf)
    dr.eval(intensity, rng_out, rho, cos_t, mat_id, detected, hit, ok)
    timings["detect"] = time.perf_counter() - t0

    # ---------------------------------------------------------------- read back
    t0 = time.perf_counter()
    names, regs = material_table(scene)
    lut = np.full(max(regs, default=0) + 2, -1, dtype=np.int32)
    for reg, idx in regs.items():
        lut[reg] = idx
    hit_np = hit.numpy().astype(bool)
    mat = np.where(hit_np, lut[np.minimum(mat_id.numpy(), lut.size - 1)], -1).astype(np.int32)
    rho_np = rho.numpy()
    bad = hit_np & ~ok.numpy().astype(bool)
    if bad.any():
        for idx in np.unique(mat[bad]):
            name = names[idx] if idx >= 0 else "?"
            warnings.warn(
                f"lidar '{cfg.name}': material '{name}' has no finite reflectance at "
                f"{cfg.wavelength:g} nm (e.g. a Mitsuba conductor preset past ~886 nm); "
                "its returns are dropped",
                RuntimeWarning,
                stacklevel=2,
            )
    rho_np = np.where(np.isfinite(rho_np), rho_np, 0.0)
    used = np.flatnonzero(np.bincount(mat[hit_np & (mat >= 0)], minlength=len(names)))
    _warn_rgb_materials(scene, names, used, cfg)

    shape = (R, C)
    result = ScanResult(
        config=cfg,
        valid=detected.numpy().astype(bool).reshape(shape),
        range=rng_out.numpy().astype(np.float32).reshape(shape),
        intensity=intensity.numpy().astype(np.float32).reshape(shape),
        reflectance=rho_np.astype(np.float32).reshape(shape),
        cos_incidence=np.where(hit_np, cos_t.numpy(), 0.0).astype(np.float32).reshape(shape),
        material=mat.reshape(shape),
        directions=dirs_np,
        to_world=T_np,
        material_names=names,
        hit=hit_np.reshape(shape),
        timings=timings,
    )
    timings["readback"] = time.perf_counter() - t0
    return result


_warned_rgb: set[tuple[str, str]] = set()


def _warn_rgb_materials(scene, names, used, cfg) -> None:
    by_name = {}
    for shape in scene.shapes():
        if shape.bsdf() is not None:
            by_name[_bsdf_name(shape)] = shape.bsdf()
    for idx in used:
        name = names[idx]
        key = (name, str(by_name.get(name)))
        if key in _warned_rgb or not _rgb_only(by_name.get(name)):
            continue
        _warned_rgb.add(key)
        warnings.warn(
            f"lidar '{cfg.name}': material '{name}' is RGB-only; its reflectance at "
            f"{cfg.wavelength:g} nm comes from sRGB upsampling and is not physical",
            RuntimeWarning,
            stacklevel=3,
        )
