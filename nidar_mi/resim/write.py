"""The reconstruction's files: the scene (:mod:`.scene_files`) with the recovered sensor, the
surfaces with their reflectance at 905 and 1550 nm, the layout and every frame's pose."""

from __future__ import annotations

import os

import numpy as np

from .drive_folder import Drive
from .frames import MIN_RANGE_M, Frames
from .inversion import SensorFit
from .mesh import Mesh

__all__ = ["sensor_params", "write_outputs", "albedo_scale", "LASER_PRESET", "DEFAULT_ALBEDO_SCALE"]

#: The preset whose firing timing the recovered layout keeps (a 64-laser drive).
LASER_PRESET = "hdl64e"
#: The fitted ρ over the surfaces' reflectance (the written per-laser gains' geometric mean)
#: where no camera gives it:
#: the median over the five KITTI drives of docs/RESIMULATION.md of NIDAR's scale (each drive's
#: median ratio of the fitted ρ to NIDAR's R; 1.8 to 3.4, the drive's two runs averaged).
DEFAULT_ALBEDO_SCALE = 2.4


def albedo_scale(inv, given: float | None = None) -> tuple[float, str]:
    """``(k, source)``: the scale ``k`` of the fitted ρ over the surfaces' reflectance (ρ at
    normal incidence, 0 to 1 for a diffuse surface), from ``given`` (``"given"``), else NIDAR's
    prior (``"nidar"``: the median ratio of the fitted ρ to R where the camera sees the
    vertices), else :data:`DEFAULT_ALBEDO_SCALE` (``"default"``)."""
    if given is not None:
        return float(given), "given"
    if inv.prior is not None and np.isfinite(inv.prior_scale) and inv.prior_scale > 0:
        return float(inv.prior_scale), "nidar"
    return DEFAULT_ALBEDO_SCALE, "default"


def sensor_params(
    frames: Frames,
    s: SensorFit,
    *,
    laser_gains: bool = True,
    shadow=(),
    range_offsets=None,
    scale: float = 1.0,
) -> dict:
    """The ``lidar`` plugin's parameters of the recovered sensor (``shadow``: its
    ``laser_shadow`` intervals, :mod:`.shadow`; ``range_offsets``: (R,) its
    ``laser_range_offsets``, m, :mod:`.range_offsets`; ``scale``: the fitted ρ over the
    surfaces' ρ as written, :func:`albedo_scale`, carried by the per-laser gains: their
    geometric mean is ``scale``, and ``gain`` stays 1, the full scale of the KITTI and LAS
    encodings)."""
    from .scene_files import LAYOUT
    from .shadow import shadow_value

    params = {
        "preset": LASER_PRESET,
        "calibration_file": LAYOUT,
        "horizontal_resolution": int(frames.columns),
        "intensity_mode": "compensated",
        "gain": 1.0,
        "range_min": MIN_RANGE_M,
        "range_response": ", ".join(f"{d:g}:{f:.6g}" for d, f in zip(s.knots_m, s.response)),
        "intensity_offset": float(round(s.offset, 6)),
        "detection_threshold": float(round(s.threshold, 6)),
        "receiver_noise_std": float(round(s.noise, 6)),
        "dropout": float(round(s.dropout, 6)),
    }
    if not laser_gains and scale != 1.0:
        raise ValueError("sensor_params: a scale needs the per-laser gains that carry it")
    if laser_gains:
        params["laser_gains"] = ", ".join(f"{g * scale:.6g}" for g in s.gains)
        if s.laser_response is not None:
            params["laser_range_response"] = "; ".join(
                ", ".join(f"{f:.6g}" for f in row) for row in s.laser_response
            )
    if shadow:
        params["laser_shadow"] = shadow_value(shadow)
    if range_offsets is not None:
        params["laser_range_offsets"] = ", ".join(f"{o:.5f}" for o in range_offsets)
    return params


def write_outputs(
    stage: str,
    drive: Drive,
    frames: Frames,
    poses,
    mesh: Mesh,
    inv,
    range_offsets=None,
    albedo: tuple[float, str] = (1.0, "given"),
) -> str:
    """Write the scene and ``poses.txt`` into ``stage``; returns the scene file's path
    (``range_offsets``: the recovered :class:`.range_offsets.RangeOffsets` or None;
    ``albedo``: :func:`albedo_scale`'s ``(k, source)``: the surfaces are written with the
    fitted ρ over ``k`` and the recovered sensor's per-laser gains times ``k``, the same
    product, so that the 905 → 1550 nm map and the presets read reflectance)."""
    from ..io.kitti import write_kitti_poses
    from ..lidar.layouts import preset_table
    from .laser_layout import write_velodyne_yaml
    from .scene_files import LAYOUT, SCENE, SURFACES, SensorXml, write_scene, write_surfaces_ply
    from .spectral import band_map

    k = float(albedo[0])
    rho = np.asarray(inv.rho, dtype=np.float64) / k
    rho1550 = band_map(905.0, 1550.0)(rho)
    write_surfaces_ply(os.path.join(stage, SURFACES), mesh, {"rho": rho, "rho1550": rho1550})
    table = preset_table(LASER_PRESET)
    ids = table.laser_id if frames.layout.rings == table.rings else range(frames.layout.rings)
    write_velodyne_yaml(os.path.join(stage, LAYOUT), frames.layout, list(ids))
    shadow = inv.shadow.intervals
    offsets = None if range_offsets is None else range_offsets.offsets_m
    params = sensor_params(frames, inv.sensor, shadow=shadow, range_offsets=offsets, scale=k)
    recovered = SensorXml("lidar", params, np.eye(4))
    preset = SensorXml(
        "lidar",
        {"preset": "$preset", "wavelength": "$wavelength", "intensity_mode": "compensated"},
        np.eye(4),
    )
    write_scene(stage, recovered, preset)
    write_kitti_poses(os.path.join(stage, "poses.txt"), poses)
    return os.path.join(stage, SCENE)
