"""A rendered drive with known surfaces and a known sensor: what the inversion must recover.

:func:`street_scene` writes a street (road, two facades, three boxes for parked cars) as one
PLY mesh whose per-vertex reflectance is a known function of position, seen by an HDL-64E
(``hdl64e`` preset, its published per-laser layout) with known per-laser gains and a known
shadow of its mounting (:data:`TRUE_SHADOW`);
:func:`render_drive` renders it along a straight trajectory with the project's own sequence
renderer (:func:`nidar_mi.sequence.render_sequence`) and returns the KITTI-layout drive it wrote
(``kitti/velodyne/*.bin``, ``kitti/poses.txt``). The scans are the renderer's: motion
distortion along the sweep included, no noise.

True reflectance (world coordinates, m): the road ``0.12 + 0.08·cos(2πx/9)`` with 0.6 lane
marks (``|y| ∈ [1.6, 1.9]``); the side facades ``0.45 + 0.3·sin(2πx/7)·cos(2πz/5)``, the
facade closing the street (x = 50) ``0.3 + 0.25·cos(2πy/6)``; the boxes 0.25, 0.55 and 0.8.
"""

from __future__ import annotations

import os

import numpy as np

from .mesh import Mesh

__all__ = ["true_rho", "street_mesh", "street_scene", "true_gains", "render_drive", "TRUE_SHADOW"]

#: The rendered sensor's ``laser_shadow`` (laser, from, to degrees): its eight lowest lasers
#: blocked behind it (a roof's rear edge) and its four lowest to its right (a mirror).
TRUE_SHADOW = tuple((r, a, b) for r in range(56, 64) for a, b in ((150.0, 180.0), (-180.0, -150.0)))
TRUE_SHADOW += tuple((r, -100.0, -80.0) for r in range(60, 64))

_BOXES = (((14.0, -4.0), 0.25), ((22.0, 3.5), 0.55), ((31.0, -4.5), 0.8))


def true_rho(xyz: np.ndarray) -> np.ndarray:
    """(N,) the scene's reflectance at (N, 3) points on its surfaces."""
    x, y, z = (np.asarray(xyz, dtype=np.float64)[:, k] for k in range(3))
    road = 0.12 + 0.08 * np.cos(2 * np.pi * x / 9.0)
    road = np.where((np.abs(y) >= 1.6) & (np.abs(y) <= 1.9), 0.6, road)
    facade = 0.45 + 0.3 * np.sin(2 * np.pi * x / 7.0) * np.cos(2 * np.pi * z / 5.0)
    out = np.where((np.abs(y) > 7.9) & (z > 0.01), facade, road)
    end = 0.3 + 0.25 * np.cos(2 * np.pi * y / 6.0)
    out = np.where((x > 49.9) & (z > 0.01), end, out)
    for (cx, cy), rho in _BOXES:
        inside = (np.abs(x - cx) <= 2.01) & (np.abs(y - cy) <= 0.91) & (z > 0.01)
        out = np.where(inside, rho, out)
    return out


def _grid(origin, u, v, nu: int, nv: int) -> Mesh:
    """A (nu x nv) quad grid from ``origin`` along vectors ``u`` and ``v`` (each cell 1/n)."""
    a, b = np.meshgrid(np.linspace(0, 1, nu + 1), np.linspace(0, 1, nv + 1), indexing="ij")
    pts = np.asarray(origin) + a.reshape(-1, 1) * np.asarray(u) + b.reshape(-1, 1) * np.asarray(v)
    idx = np.arange((nu + 1) * (nv + 1)).reshape(nu + 1, nv + 1)
    q0, q1, q2, q3 = (
        idx[:-1, :-1].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
        idx[:-1, 1:].ravel(),
    )
    faces = np.concatenate([np.column_stack([q0, q1, q2]), np.column_stack([q0, q2, q3])])
    return Mesh(pts, faces)


def street_mesh(step: float = 0.25) -> Mesh:
    """The street's surfaces (road x in [-10, 50], y in [-8, 8]; facades 6 m high)."""
    parts = [
        _grid((-10, -8, 0), (60, 0, 0), (0, 16, 0), int(60 / step), int(16 / step)),
        _grid((-10, -8, 0), (60, 0, 0), (0, 0, 6), int(60 / step), int(6 / step)),
        _grid((-10, 8, 0), (60, 0, 0), (0, 0, 6), int(60 / step), int(6 / step)),
        _grid((50, -8, 0), (0, 16, 0), (0, 0, 6), int(16 / step), int(6 / step)),
    ]
    for (cx, cy), _ in _BOXES:
        x0, x1, y0, y1, h = cx - 2, cx + 2, cy - 0.9, cy + 0.9, 1.5
        n = int(4 / step)
        m = int(1.8 / step)
        k = int(h / step)
        parts += [
            _grid((x0, y0, 0), (4, 0, 0), (0, 0, h), n, k),
            _grid((x0, y1, 0), (4, 0, 0), (0, 0, h), n, k),
            _grid((x0, y0, 0), (0, 1.8, 0), (0, 0, h), m, k),
            _grid((x1, y0, 0), (0, 1.8, 0), (0, 0, h), m, k),
            _grid((x0, y0, h), (4, 0, 0), (0, 1.8, 0), n, m),
        ]
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts[:-1]])
    return Mesh(
        np.concatenate([p.vertices for p in parts]),
        np.concatenate([p.faces + o for p, o in zip(parts, offsets)]),
    )


def true_gains(rings: int = 64, seed: int = 0) -> np.ndarray:
    """(rings,) the rendered sensor's per-laser gains, uniform in [0.7, 1.3] (seeded)."""
    return np.random.default_rng(seed).uniform(0.7, 1.3, rings)


def street_scene(folder: str, *, columns: int = 1024, seed: int = 0) -> str:
    """Write the scene (``street.xml``, ``street.ply``) into ``folder``; returns the XML path."""
    from .scene_files import SensorXml, write_surfaces_ply

    os.makedirs(folder, exist_ok=True)
    mesh = street_mesh()
    write_surfaces_ply(os.path.join(folder, "street.ply"), mesh, {"rho": true_rho(mesh.vertices)})
    sensor = SensorXml(
        "lidar",
        {
            "preset": "hdl64e",
            "horizontal_resolution": int(columns),
            "intensity_mode": "compensated",
            "range_max": 60.0,
            # a sweep in 10 ms: the frames (10 Hz) are 1/10 of a metre-per-frame drive apart
            # in time, each sweep all but free of motion distortion
            "rotation_rate": 100.0,
            "laser_gains": ", ".join(f"{g:.6f}" for g in true_gains(seed=seed)),
            "laser_shadow": ", ".join(f"{r}:{a:g}:{b:g}" for r, a, b in TRUE_SHADOW),
        },
        np.eye(4),
    )
    xml = "\n".join(
        [
            '<scene version="3.0.0">',
            '<shape type="ply" id="street">',
            '    <string name="filename" value="street.ply"/>',
            '    <bsdf type="twosided"><bsdf type="diffuse">',
            '        <texture type="mesh_attribute" name="reflectance">',
            '            <string name="name" value="vertex_rho"/>',
            "        </texture>",
            "    </bsdf></bsdf>",
            "</shape>",
            sensor.xml(),
            "</scene>",
        ]
    )
    path = os.path.join(folder, "street.xml")
    with open(path, "w", encoding="utf-8") as f:
        f.write(xml + "\n")
    return path


def render_drive(folder: str, *, frames: int = 10, step_m: float = 1.0, columns: int = 1024) -> str:
    """Render the street along x (``step_m`` per frame at 10 Hz, sensor 1.73 m up) into
    ``folder/render``; returns the KITTI drive folder (``folder/render/kitti``, ``frames``
    scans)."""
    from ..io.kitti import write_kitti_poses
    from ..render_session import RenderOptions
    from ..sequence import SequenceOptions, render_sequence

    scene = street_scene(folder, columns=columns)
    poses = np.tile(np.eye(4), (frames + 1, 1, 1))  # the last sweep needs the pose after it
    poses[:, 0, 3] = np.arange(frames + 1) * step_m
    poses[:, 2, 3] = 1.73
    traj = os.path.join(folder, "trajectory.txt")
    write_kitti_poses(traj, poses)
    options = SequenceOptions(
        RenderOptions(scene, formats=("npz",), cameras=False, progress=False),
        traj,
        rate=10.0,
        frames=frames,
        sequence_formats=("kitti",),
        previews="none",
    )
    out = os.path.join(folder, "render")
    render_sequence(options, out, overwrite=True)
    return os.path.join(out, "kitti")
