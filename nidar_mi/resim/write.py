"""The reconstruction's files: the scene (:mod:`.scene_files`) with the recovered sensor, the
surfaces with their reflectance at 905 and 1550 nm, the layout and every frame's pose."""

from __future__ import annotations

import os

import numpy as np

from .drive_folder import Drive
from .frames import MIN_RANGE_M, Frames
from .inversion import SensorFit
from .mesh import Mesh

__all__ = ["sensor_params", "write_outputs", "LASER_PRESET"]

#: The preset whose firing timing the recovered layout keeps (a 64-laser drive).
LASER_PRESET = "hdl64e"


def sensor_params(
    frames: Frames, s: SensorFit, *, laser_gains: bool = True, shadow=(), range_offsets=None
) -> dict:
    """The ``lidar`` plugin's parameters of the recovered sensor (``shadow``: its
    ``laser_shadow`` intervals, :mod:`.shadow`; ``range_offsets``: (R,) its
    ``laser_range_offsets``, m, :mod:`.range_offsets`)."""
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
    if laser_gains:
        params["laser_gains"] = ", ".join(f"{g:.6g}" for g in s.gains)
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
    stage: str, drive: Drive, frames: Frames, poses, mesh: Mesh, inv, range_offsets=None
) -> str:
    """Write the scene and ``poses.txt`` into ``stage``; returns the scene file's path
    (``range_offsets``: the recovered :class:`.range_offsets.RangeOffsets` or None)."""
    from ..io.kitti import write_kitti_poses
    from ..lidar.layouts import preset_table
    from .laser_layout import write_velodyne_yaml
    from .scene_files import LAYOUT, SCENE, SURFACES, SensorXml, write_scene, write_surfaces_ply
    from .spectral import band_map

    rho1550 = band_map(905.0, 1550.0)(inv.rho)
    write_surfaces_ply(os.path.join(stage, SURFACES), mesh, {"rho": inv.rho, "rho1550": rho1550})
    table = preset_table(LASER_PRESET)
    ids = table.laser_id if frames.layout.rings == table.rings else range(frames.layout.rings)
    write_velodyne_yaml(os.path.join(stage, LAYOUT), frames.layout, list(ids))
    shadow = inv.shadow.intervals
    offsets = None if range_offsets is None else range_offsets.offsets_m
    params = sensor_params(frames, inv.sensor, shadow=shadow, range_offsets=offsets)
    recovered = SensorXml("lidar", params, np.eye(4))
    preset = SensorXml(
        "lidar",
        {"preset": "$preset", "wavelength": "$wavelength", "intensity_mode": "compensated"},
        np.eye(4),
    )
    write_scene(stage, recovered, preset)
    write_kitti_poses(os.path.join(stage, "poses.txt"), poses)
    return os.path.join(stage, SCENE)
