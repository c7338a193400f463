"""The materials and shapes of a scene as a scan names them, and their look-up on the device.

A scan reports a material index into :func:`material_table`'s names (sorted BSDF ids) and a
shape index into ``scene.shapes()``. The kernels hold the hit's ``mi.BSDFPtr`` and
``mi.ShapePtr``, whose Dr.Jit registry ids :class:`SceneTables` turns into those indices by a
gather from a small look-up table on the device (-1 for a null pointer or an unknown id), so the
scan reads back indices, never pointers.

The tables of a scene are built once and cached (the last few scenes, recognised by their shape
objects): reading a registry id is a device round trip per shape, and the description of a BSDF
(which material is RGB-only) is long to print.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["SceneTables", "material_table", "shape_table", "scene_tables"]

#: Scenes whose tables are kept.
_CACHE_SIZE = 4


def _registry_id(ptr) -> int:
    import drjit as dr
    import mitsuba as mi

    return int(dr.reinterpret_array(mi.UInt32, ptr)[0])


def shape_table(scene) -> tuple[list[str], dict[int, int]]:
    """Shapes of a scene in ``scene.shapes()`` order.

    Returns:
        (their ids, map from the shape's Dr.Jit registry id to its index).
    """
    import mitsuba as mi

    shapes = list(scene.shapes())
    regs = {_registry_id(mi.ShapePtr(s)): i for i, s in enumerate(shapes)}
    return [s.id() for s in shapes], regs


def material_table(scene) -> tuple[list[str], dict[int, int]]:
    """Materials (BSDFs) of a scene in a stable order.

    Returns:
        (names sorted alphabetically, map from the BSDF's Dr.Jit registry id to index in names).
    """
    import mitsuba as mi

    by_name: dict[str, int] = {}
    for shape in scene.shapes():
        if shape.bsdf() is not None:
            by_name.setdefault(_bsdf_name(shape), _registry_id(mi.BSDFPtr(shape.bsdf())))
    names = sorted(by_name)
    regs = {}
    for shape in scene.shapes():
        if shape.bsdf() is not None:
            regs[_registry_id(mi.BSDFPtr(shape.bsdf()))] = names.index(_bsdf_name(shape))
    return names, regs


def _bsdf_name(shape) -> str:
    """The BSDF's id, or ``<shape id>.bsdf`` for an anonymous BSDF."""
    return shape.bsdf().id() or f"{shape.id()}.bsdf"


class SceneTables(NamedTuple):
    """A scene's names and look-up tables (built by :func:`scene_tables`).

    Attributes:
        material_names: (M,) material (BSDF) ids, sorted.
        shape_names: ids of ``scene.shapes()`` in that order.
        material_lut: ``mi.Int32`` material index per BSDF registry id (-1: none).
        shape_lut: ``mi.Int32`` shape index per shape registry id (-1: none).
        rgb_only: the description of each material whose reflectance comes from RGB
            upsampling (by name), for the scan's warning.
    """

    material_names: list[str]
    shape_names: list[str]
    material_lut: Any
    shape_lut: Any
    rgb_only: dict[str, str]

    def material_index(self, bsdf):
        """``mi.Int32`` material index of each ``mi.BSDFPtr`` (-1 for none)."""
        return _gather_index(self.material_lut, bsdf)

    def shape_index(self, shape):
        """``mi.Int32`` shape index of each ``mi.ShapePtr`` (-1 for none)."""
        return _gather_index(self.shape_lut, shape)


def _lut(table: dict[int, int]):
    """``mi.Int32`` array mapping registry ids to indices, -1 elsewhere (its last entry too)."""
    import mitsuba as mi

    lut = np.full(max(table, default=0) + 2, -1, dtype=np.int32)
    for reg, idx in table.items():
        lut[reg] = idx
    return mi.Int32(lut)


def _gather_index(lut, ptr):
    import drjit as dr
    import mitsuba as mi

    reg = dr.reinterpret_array(mi.UInt32, ptr)
    return dr.gather(mi.Int32, lut, dr.minimum(reg, dr.width(lut) - 1))


_cache: list[tuple[list, SceneTables]] = []


def scene_tables(scene) -> SceneTables:
    """The tables of ``scene``, built on first use and cached."""
    shapes = list(scene.shapes())
    for known, tables in _cache:
        if len(known) == len(shapes) and all(a is b for a, b in zip(known, shapes)):
            return tables
    names, materials = material_table(scene)
    shape_names, shape_regs = shape_table(scene)
    by_name = {_bsdf_name(s): s.bsdf() for s in shapes if s.bsdf() is not None}
    described = {name: str(bsdf) for name, bsdf in by_name.items()}
    rgb_only = {n: text for n, text in described.items() if "SRGBReflectanceSpectrum" in text}
    tables = SceneTables(names, shape_names, _lut(materials), _lut(shape_regs), rgb_only)
    _cache.insert(0, (shapes, tables))
    del _cache[_CACHE_SIZE:]
    return tables
