"""Procedural scene generator: ``python -m nidar_mi.scenegen --count N --seed S -o DIR``.

* :mod:`.primitives`: the plain records of a scene (shapes, sun, sky, rig).
* :mod:`.objects`: seeded builders of vehicles, buildings, trees, poles, signs and clutter.
* :mod:`.layout`: :func:`sample_layout`, urban and vegetated layouts from one generator.
* :mod:`.streets`, :mod:`.city`: city and suburb grids of blocks (:func:`.city.sample_city`);
  :mod:`.trajectory`, :mod:`.drives`: the drives through them and their pose files.
* :mod:`.xml`: :func:`scene_xml`, the Mitsuba XML of a layout.
* :mod:`.generate`: per-scene seeds, resumable writing and ``index.json``.
"""

from .generate import KINDS, generate, generate_scene, scene_id, scene_rng
from .layout import sample_layout
from .primitives import Block, Cylinder, Layout, Panel, Patch, Rig, Sky, Sphere, Sun
from .xml import scene_xml

__all__ = [
    "KINDS",
    "Block",
    "Cylinder",
    "Layout",
    "Panel",
    "Patch",
    "Rig",
    "Sky",
    "Sphere",
    "Sun",
    "generate",
    "generate_scene",
    "sample_layout",
    "scene_id",
    "scene_rng",
    "scene_xml",
]
