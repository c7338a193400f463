"""The benchmark scene: a procedural city around a LiDAR, as PLY meshes and a scene XML.

A height-field terrain of ``2·(grid-1)²`` triangles (115 200 by default) rolling by < 0.4 m, and
100 box buildings on 20 m blocks with 6 m streets along x and y through the origin. The LiDAR
stands :data:`SENSOR_HEIGHT_M` above the terrain at the central crossing, turned by
:data:`SENSOR_YAW_DEG`. Most beams hit (97.7 % for ``os1_128`` at 2048 columns).
"""

from __future__ import annotations

import os
import tempfile

import numpy as np

__all__ = [
    "SENSOR_HEIGHT_M",
    "SENSOR_YAW_DEG",
    "terrain_height",
    "city_mesh",
    "write_ply",
    "scene_xml",
    "load_city",
    "world_rays",
]

#: LiDAR height above the terrain at the origin, m.
SENSOR_HEIGHT_M = 1.8
#: LiDAR yaw about +z, degrees.
SENSOR_YAW_DEG = 10.0


def terrain_height(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Ground height in m at (x, y) in m: gentle rolling, |h| < 0.4 m, |h''| <= 0.015 /m."""
    return 0.25 * np.sin(0.05 * x) * np.cos(0.07 * y) + 0.1 * np.sin(0.31 * x + 0.17 * y)


def city_mesh(
    grid: int = 241, half_size_m: float = 100.0, seed: int = 0
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """A terrain height field and a grid of box buildings.

    Buildings stand on 20 m blocks (14 m footprints, 6 m streets; streets run along x and y through
    the origin), heights uniform in [8, 40] m, bases sunk 1 m under the terrain. Box faces do not
    share vertices (flat shading); the bottom face is left out.

    Args:
        grid: terrain vertices per side; the terrain has ``2·(grid-1)²`` triangles.
        half_size_m: the terrain covers ``[-half_size_m, half_size_m]²``.
        seed: seed of the building heights.

    Returns:
        ``{"terrain": (V, F), "buildings": (V, F)}``: (n, 3) float32 vertices in m and
        (m, 3) int32 triangle indices, counter-clockwise seen from outside / above.
    """
    # ------------------------------------------------------------------ terrain
    s = np.linspace(-half_size_m, half_size_m, grid)
    x, y = np.meshgrid(s, s, indexing="xy")
    tv = np.stack([x, y, terrain_height(x, y)], axis=-1).reshape(-1, 3)
    i = np.arange(grid - 1)
    a = (i[:, None] * grid + i[None, :]).reshape(-1)  # lower-left corner of each cell
    b, c, d = a + 1, a + grid + 1, a + grid
    tf = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])

    # ------------------------------------------------------------------ buildings
    rng = np.random.default_rng(seed)
    pitch, half_fp = 20.0, 7.0
    centres = np.arange(-half_size_m + pitch / 2, half_size_m, pitch)
    corners = np.array(
        [
            [-1, -1, 0],
            [1, -1, 0],
            [1, 1, 0],
            [-1, 1, 0],
            [-1, -1, 1],
            [1, -1, 1],
            [1, 1, 1],
            [-1, 1, 1],
        ],
        dtype=np.float64,
    )
    quads = [(4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]  # top, sides
    bv, bf = [], []
    for cx in centres:
        for cy in centres:
            h = rng.uniform(8.0, 40.0)
            z0 = float(terrain_height(np.array(cx), np.array(cy))) - 1.0
            box = np.column_stack(
                [cx + half_fp * corners[:, 0], cy + half_fp * corners[:, 1], z0 + h * corners[:, 2]]
            )
            for q in quads:
                base = sum(len(v) for v in bv)
                bv.append(box[list(q)])
                bf.append([[base, base + 1, base + 2], [base, base + 2, base + 3]])
    return {
        "terrain": (tv.astype(np.float32), tf.astype(np.int32)),
        "buildings": (np.concatenate(bv).astype(np.float32), np.concatenate(bf).astype(np.int32)),
    }


def write_ply(path: str, vertices: np.ndarray, faces: np.ndarray) -> None:
    """Write (n, 3) float32 vertices and (m, 3) int32 triangles as a binary PLY."""
    from plyfile import PlyData, PlyElement

    v = np.empty(len(vertices), dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])
    v["x"], v["y"], v["z"] = vertices.T
    f = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,))])
    f["vertex_indices"] = faces
    PlyData([PlyElement.describe(v, "vertex"), PlyElement.describe(f, "face")]).write(path)


def scene_xml(plys: dict[str, str], rings: int, cols: int) -> str:
    """Scene XML: the meshes with diffuse spectral materials and the LiDAR.

    Args:
        plys: mesh name -> PLY path (``terrain``, ``buildings``).
        rings: LiDAR channels (128 uses the ``os1_128`` preset's uniform table, else uniform
            over ±22.5°).
        cols: columns per scan.
    """
    if rings == 128:
        # its uniform table: the rays below are the uniform grid
        pattern = '<string name="preset" value="os1_128"/><string name="layout" value="uniform"/>'
    else:
        angles = ", ".join(f"{a:.6f}" for a in np.linspace(22.5, -22.5, rings))
        pattern = f'<string name="elevation_angles" value="{angles}"/>'
    z = SENSOR_HEIGHT_M + float(terrain_height(np.array(0.0), np.array(0.0)))
    spectra = {  # flat-ish NIR reflectances (asphalt-like, concrete-like)
        "terrain": "400:0.06, 600:0.08, 800:0.10, 1000:0.12",
        "buildings": "400:0.25, 600:0.30, 800:0.34, 1000:0.36",
    }
    shapes = "\n".join(
        f"""    <shape type="ply" id="{name}">
        <string name="filename" value="{path}"/>
        <boolean name="face_normals" value="true"/>
        <bsdf type="diffuse" id="{name}_bsdf">
            <spectrum name="reflectance" value="{spectra[name]}"/>
        </bsdf>
    </shape>"""
        for name, path in plys.items()
    )
    return f"""<scene version="3.0.0">
    <sensor type="lidar" id="lidar">
        {pattern}
        <integer name="horizontal_resolution" value="{cols}"/>
        <float name="wavelength" value="905"/>
        <float name="range_max" value="400"/>
        <float name="noise_intensity_std" value="0.0002"/>
        <float name="noise_range_std" value="0"/>
        <transform name="to_world">
            <rotate z="1" angle="{SENSOR_YAW_DEG}"/><translate z="{z}"/>
        </transform>
    </sensor>
{shapes}
</scene>
"""


def world_rays(sensor) -> np.ndarray:
    """(R·C, 6) float32 rays ``[origin, unit direction]`` of every beam, in the world frame.

    Same ray order as the scan (ring-major); directions as :func:`nidar_mi.lidar.scan.scan`
    computes them (float32 beam directions, rotated by the pose, normalised).
    """
    from nidar_mi.lidar.pattern import beam_directions

    cfg = sensor.config
    T = np.array(sensor.world_transform().matrix.numpy(), dtype=np.float64).reshape(4, 4)
    d = beam_directions(cfg.elevations, cfg.horizontal_resolution, cfg.fov_h)
    d = d.astype(np.float32).reshape(-1, 3).astype(np.float64) @ T[:3, :3].T
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(T[:3, 3], d.shape)
    return np.concatenate([o, d], axis=1).astype(np.float32)


def load_city(*, rings: int = 128, cols: int = 2048, grid: int = 241, variant: str):
    """Build the city, write it to a temporary directory and load it with the LiDAR.

    Args:
        rings, cols: the LiDAR's beam grid.
        grid: terrain vertices per side (see :func:`city_mesh`).
        variant: Mitsuba variant.

    Returns:
        ``(loaded, meshes)``: the :class:`~nidar_mi.scene.LoadedScene` (its only LiDAR is
        ``loaded.lidars[0]``) and the :func:`city_mesh` arrays it was built from.
    """
    from nidar_mi.scene import load_scene

    meshes = city_mesh(grid=grid)
    with tempfile.TemporaryDirectory(prefix="nidar_bench_") as tmp:
        plys = {}
        for name, (v, f) in meshes.items():
            plys[name] = os.path.join(tmp, f"{name}.ply")
            write_ply(plys[name], v, f)
        xml_path = os.path.join(tmp, "city.xml")
        with open(xml_path, "w", encoding="utf-8") as fh:
            fh.write(scene_xml(plys, rings, cols))
        return load_scene(xml_path, variant=variant), meshes
