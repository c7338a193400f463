"""One LiDAR scan: beam pattern → cast through glass → monostatic ρ at λ → return model →
detection and noise → read back.

:func:`scan` runs every beam at once in Dr.Jit; the physics is :mod:`.return_model`'s, the ray
casting :mod:`.raycast`'s. The pose and every scalar parameter enter the kernels as opaque
values, so scanning again with another pose or seed reuses the compiled kernels.

Reading back names the materials (:func:`material_table`) and warns once per material whose
reflectance is not finite (Mitsuba's conductor presets past ~886 nm: its returns are dropped)
or comes from RGB upsampling (not physical past 830 nm).
"""

from __future__ import annotations

import contextlib
import time
import warnings
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

from ..labels import SceneLabels, ShapeLabels, shape_labels
from .config import LidarConfig
from .pattern import beam_directions
from .raycast import cast, monostatic_reflectance
from .return_model import add_noise, box_muller, detect, expected_intensity

__all__ = ["ScanResult", "scan", "material_table"]


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
        shape_index: int32 index into ``scene.shapes()`` of the surface hit; -1 where no hit.
        shape_labels: per-shape class and instance tables
            (:class:`nidar_mi.labels.ShapeLabels`) that :meth:`points` turns into ``label``
            and ``instance``.
        timings: seconds per stage (``pattern``, ``raycast``, ``bsdf``, ``detect``, ``readback``).
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
    shape_index: np.ndarray
    shape_labels: ShapeLabels
    timings: dict[str, float] = field(default_factory=dict)

    def points(self) -> dict[str, np.ndarray]:
        """The valid returns as a points dict (schema in :mod:`nidar_mi.io.points`)."""
        m = self.valid
        rings, cols = np.nonzero(m)
        rng = self.range[m].astype(np.float32)
        xyz = (self.directions[m] * rng[:, None]).astype(np.float32)
        R, t = self.to_world[:3, :3], self.to_world[:3, 3]
        xyz_world = (xyz.astype(np.float64) @ R.T + t).astype(np.float32)
        label, instance = self.shape_labels.lookup(self.shape_index[m])
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
            "label": label,
            "instance": instance,
            "instance_names": self.shape_labels.instance_names,
        }


def scan(
    scene, sensor, *, seed: int | None = None, to_world=None, labels: SceneLabels | None = None
) -> ScanResult:
    """Cast every beam of ``sensor`` and compute its return.

    Args:
        scene: a loaded ``mi.Scene`` (spectral variant).
        sensor: a ``lidar`` sensor of that scene.
        seed: overrides the sensor's ``seed`` for the noise and dropout draws.
        to_world: optional (4,4) pose overriding the sensor's ``to_world`` (frame animation).
        labels: the scene's label declaration (:attr:`nidar_mi.scene.LoadedScene.labels`);
            None: every point ``unlabeled``, every shape its own instance.

    Returns:
        The scan on the (ring, column) grid.
    """
    import drjit as dr
    import mitsuba as mi

    cfg: LidarConfig = sensor.config
    timings: dict[str, float] = {}
    with _timed(timings, "pattern"):
        directions, directions_dr = _directions(cfg)
        pose = _pose(sensor, to_world)
        inputs = _kernel_inputs(cfg, pose, cfg.seed if seed is None else int(seed))

    with _timed(timings, "raycast"):
        beams = cast(scene, inputs.to_world, directions_dr, inputs.wavelength)

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

    with _timed(timings, "detect"):
        u_dropout, normal_intensity, normal_range = _draws(dr.width(d), inputs.seed_state)
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
        shape = (cfg.rings, cfg.horizontal_resolution)
        hit = beams.hit.numpy().astype(bool)
        names, material = _materials(scene, bsdf_id.numpy(), hit)
        _warn_nonfinite(cfg, names, material[hit & ~finite.numpy().astype(bool)])
        _warn_rgb_materials(scene, cfg, names, material[hit & (material >= 0)])
        rho_np = rho.numpy()
        rho_np = np.where(np.isfinite(rho_np), rho_np, 0.0)
        result = ScanResult(
            config=cfg,
            valid=valid.numpy().astype(bool).reshape(shape),
            range=range_m.numpy().astype(np.float32).reshape(shape),
            intensity=intensity.numpy().astype(np.float32).reshape(shape),
            reflectance=rho_np.astype(np.float32).reshape(shape),
            cos_incidence=np.where(hit, cos_t.numpy(), 0.0).astype(np.float32).reshape(shape),
            material=material.reshape(shape),
            directions=directions,
            to_world=pose,
            material_names=names,
            hit=hit.reshape(shape),
            shape_index=_shape_index(scene, shape_id.numpy(), hit).reshape(shape),
            shape_labels=shape_labels(scene, labels),
            timings=timings,
        )
    return result


# ---------------------------------------------------------------- kernel inputs


@contextlib.contextmanager
def _timed(timings: dict[str, float], stage: str):
    t0 = time.perf_counter()
    yield
    timings[stage] = time.perf_counter() - t0


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


def _pose(sensor, to_world) -> np.ndarray:
    """(4, 4) float64 pose: ``to_world`` when given, else the sensor's own."""
    if to_world is None:
        return np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
    return np.asarray(to_world, dtype=np.float64).reshape(4, 4)


class _KernelInputs(NamedTuple):
    """The pose and scalar parameters as opaque Dr.Jit values (one compiled kernel for all)."""

    to_world: Any
    wavelength: Any
    gain: Any
    alpha: Any
    range_min: Any
    range_max: Any
    threshold: Any
    dropout: Any
    noise_intensity: Any
    noise_range: Any
    seed_state: Any


def _kernel_inputs(cfg: LidarConfig, pose: np.ndarray, seed: int) -> _KernelInputs:
    import drjit as dr
    import mitsuba as mi

    T = mi.Transform4f(pose.astype(np.float32))
    dr.make_opaque(T)

    def opaque(value: float):
        return dr.opaque(mi.Float, value)

    return _KernelInputs(
        to_world=T,
        wavelength=opaque(cfg.wavelength),
        gain=opaque(cfg.gain),
        alpha=opaque(cfg.atmospheric_extinction),
        range_min=opaque(cfg.range_min),
        range_max=opaque(cfg.range_max),
        threshold=opaque(cfg.detection_threshold),
        dropout=opaque(cfg.dropout),
        noise_intensity=opaque(cfg.noise_intensity_std),
        noise_range=opaque(cfg.noise_range_std),
        seed_state=dr.opaque(mi.UInt64, (seed * 0x9E3779B97F4A7C15) % 2**64),
    )


def _draws(n: int, seed_state):
    """Per beam: a uniform dropout draw and standard normals for intensity and range noise."""
    import mitsuba as mi

    rng = mi.PCG32(size=n, initstate=seed_state)
    u_dropout = rng.next_float32()
    normal_intensity = box_muller(rng.next_float32(), rng.next_float32())
    normal_range = box_muller(rng.next_float32(), rng.next_float32())
    return u_dropout, normal_intensity, normal_range


# ---------------------------------------------------------------- read back


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


def _materials(scene, bsdf_ids: np.ndarray, hit: np.ndarray) -> tuple[list[str], np.ndarray]:
    """Material names and, per beam, the int32 index of the material hit (-1: no hit)."""
    names, regs = material_table(scene)
    lut = np.full(max(regs, default=0) + 2, -1, dtype=np.int32)
    for reg, idx in regs.items():
        lut[reg] = idx
    material = np.where(hit, lut[np.minimum(bsdf_ids, lut.size - 1)], -1).astype(np.int32)
    return names, material


def _shape_index(scene, shape_ids: np.ndarray, hit: np.ndarray) -> np.ndarray:
    """Per beam, the int32 index into ``scene.shapes()`` of the shape hit (-1: no hit)."""
    import drjit as dr
    import mitsuba as mi

    regs = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in scene.shapes()]
    lut = np.full(max(regs, default=0) + 2, -1, dtype=np.int32)
    lut[regs] = np.arange(len(regs), dtype=np.int32)
    return np.where(hit, lut[np.minimum(shape_ids, lut.size - 1)], -1).astype(np.int32)


def _warn_nonfinite(cfg: LidarConfig, names: list[str], materials: np.ndarray) -> None:
    """One warning per material among ``materials`` (indices) whose returns were not finite."""
    for idx in np.unique(materials):
        name = names[idx] if idx >= 0 else "?"
        warnings.warn(
            f"lidar '{cfg.name}': material '{name}' has no finite reflectance at "
            f"{cfg.wavelength:g} nm (e.g. a Mitsuba conductor preset past ~886 nm); "
            "its returns are dropped",
            RuntimeWarning,
            stacklevel=3,
        )


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
