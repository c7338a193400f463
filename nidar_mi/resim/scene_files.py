"""The reconstructed drive as a Mitsuba scene: the surfaces (PLY with per-vertex reflectance),
the recovered sensor, and another sensor to put in its place.

Files (all in one folder, referenced relative to ``scene.xml``)::

    scene.xml              the surfaces and ``<include filename="sensor_$sensor.xml"/>``
    surfaces.ply           the mesh and the splats (:mod:`.splats`, their vertices last); vertex
                           properties ``rho_0`` (the recovered reflectance at
                           the sensor's wavelength, the fitted ρ over the albedo scale of
                           :func:`.write.albedo_scale`: Mitsuba's attribute ``vertex_rho``)
                           and ``rho1550_0`` (the same surface at 1550 nm: ``vertex_rho1550``)
    sensor_recovered.xml   the recovered sensor (``lidar``: its per-laser layout in
                           ``layout.yaml``, ``laser_gains`` (times the albedo scale),
                           ``range_response``,
                           ``laser_range_response``, offset, threshold, receiver noise,
                           dropout and the mounting's ``laser_shadow``: :mod:`.shadow`) at
                           frame 0's pose, the world origin
    sensor_preset.xml      a preset sensor at the same pose: ``preset`` and ``wavelength`` from
                           the defaults ``$preset`` (``hdl64e``) and ``$wavelength`` (905)
    layout.yaml            the per-laser layout (ROS velodyne calibration YAML)

The surfaces are ``diffuse`` (two-sided) with a ``mesh_attribute`` reflectance named by the
default ``$rho`` (``vertex_rho``), so::

    python -m nidar_mi.render OUT/scene.xml                       # the recovered sensor
    python -m nidar_mi.render OUT/scene.xml -D sensor=preset -D preset=vlp16
    python -m nidar_mi.render OUT/scene.xml -D sensor=preset -D preset=os1_128 \\
        -D wavelength=1550 -D rho=vertex_rho1550
    python -m nidar_mi.render OUT/scene.xml --trajectory OUT/poses.txt   # every frame's pose

(the world frame is frame 0's LiDAR frame, so ``poses.txt`` moves the sensor to each frame).
"""

from __future__ import annotations

import os
from xml.sax.saxutils import quoteattr

import numpy as np

from .mesh import Mesh

__all__ = ["write_surfaces_ply", "write_scene", "SensorXml"]

#: File names inside the scene folder.
SCENE, SURFACES, LAYOUT = "scene.xml", "surfaces.ply", "layout.yaml"


def write_surfaces_ply(path: str | os.PathLike, mesh: Mesh, attributes: dict[str, np.ndarray]):
    """Write the mesh as binary PLY with per-vertex float attributes (each written as the
    property ``<name>_0``, which Mitsuba loads as the mesh attribute ``vertex_<name>``).

    Args:
        path: the ``.ply`` file.
        mesh: vertices (V, 3), faces (T, 3).
        attributes: name -> (V,) values.
    """
    from plyfile import PlyData, PlyElement

    from ..io.atomic import atomic_path

    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [(f"{name}_0", "<f4") for name in attributes]
    vertex = np.empty(len(mesh.vertices), dtype=fields)
    for i, axis in enumerate("xyz"):
        vertex[axis] = mesh.vertices[:, i]
    for name, values in attributes.items():
        vertex[f"{name}_0"] = np.asarray(values, dtype=np.float32)
    face = np.empty(len(mesh.faces), dtype=[("vertex_indices", "<i4", (3,))])
    face["vertex_indices"] = mesh.faces
    with atomic_path(path) as tmp:
        PlyData(
            [PlyElement.describe(vertex, "vertex"), PlyElement.describe(face, "face")], text=False
        ).write(tmp)


class SensorXml:
    """The ``<sensor>`` element of a ``lidar`` with the given parameters (name -> value; str,
    float, int or bool; ``to_world`` a (4, 4) matrix)."""

    def __init__(self, sensor_id: str, params: dict, to_world: np.ndarray) -> None:
        self.sensor_id, self.params, self.to_world = sensor_id, dict(params), to_world

    def xml(self) -> str:
        lines = [f'<sensor type="lidar" id={quoteattr(self.sensor_id)}>']
        for name, value in self.params.items():
            if isinstance(value, bool):
                kind, text = "boolean", "true" if value else "false"
            elif isinstance(value, int):
                kind, text = "integer", str(value)
            elif isinstance(value, float):
                kind, text = "float", repr(float(value))
            else:
                kind, text = "string", str(value)
            lines.append(f"    <{kind} name={quoteattr(name)} value={quoteattr(text)}/>")
        m = " ".join(f"{v:.9g}" for v in np.asarray(self.to_world, dtype=np.float64).ravel())
        lines.append(f'    <transform name="to_world"><matrix value="{m}"/></transform>')
        lines.append("</sensor>")
        return "\n".join(lines)


def _wrap(body: str) -> str:
    return f'<scene version="3.0.0">\n{body}\n</scene>\n'


def write_scene(folder: str, recovered: SensorXml, preset: SensorXml) -> list[str]:
    """Write ``scene.xml`` and the two sensor files into ``folder`` (``surfaces.ply`` and
    ``layout.yaml`` are written by the caller). Returns the paths written."""
    from ..io.atomic import atomic_write_text

    scene = "\n".join(
        [
            '<default name="sensor" value="recovered"/>',
            '<default name="rho" value="vertex_rho"/>',
            '<shape type="ply" id="surfaces">',
            f'    <string name="filename" value="{SURFACES}"/>',
            '    <bsdf type="twosided">',
            '        <bsdf type="diffuse">',
            '            <texture type="mesh_attribute" name="reflectance">',
            '                <string name="name" value="$rho"/>',
            "            </texture>",
            "        </bsdf>",
            "    </bsdf>",
            "</shape>",
            '<include filename="sensor_$sensor.xml"/>',
        ]
    )
    files = {
        SCENE: _wrap(scene),
        "sensor_recovered.xml": _wrap(recovered.xml()),
        "sensor_preset.xml": _wrap(
            '<default name="preset" value="hdl64e"/>\n'
            '<default name="wavelength" value="905"/>\n' + preset.xml()
        ),
    }
    out = []
    for name, text in files.items():
        path = os.path.join(folder, name)
        atomic_write_text(path, text)
        out.append(path)
    return out
