"""The reconstructed surfaces as a Mitsuba scene in memory: the mesh's PLY (:mod:`.scene_files`)
under the BSDF that ``scene.xml`` declares, a two-sided ``diffuse`` whose reflectance is the
``mesh_attribute`` ``vertex_rho`` (smooth vertex normals, as Mitsuba computes them for a PLY
without normals).

:func:`surface_scene` loads it; :data:`RHO_KEY` is the reflectance's name in
``mi.traverse(scene)``, the parameter the inversion differentiates.
"""

from __future__ import annotations

import os

__all__ = ["surface_scene", "surfaces_dict", "RHO_KEY", "SHAPE_ID"]

#: The mesh's id, and its reflectance's key in ``mi.traverse(scene)``.
SHAPE_ID = "surfaces"
RHO_KEY = f"{SHAPE_ID}.vertex_rho"


def surfaces_dict(ply_path: str | os.PathLike, attribute: str = "vertex_rho") -> dict:
    """The surfaces' shape as a Mitsuba dict (the same as ``scene.xml``'s ``<shape>``)."""
    return {
        "type": "ply",
        "filename": str(ply_path),
        "bsdf": {
            "type": "twosided",
            "material": {
                "type": "diffuse",
                "reflectance": {"type": "mesh_attribute", "name": attribute},
            },
        },
    }


def surface_scene(ply_path: str | os.PathLike):
    """A ``mi.Scene`` holding only the surfaces (active variant)."""
    import mitsuba as mi

    return mi.load_dict({"type": "scene", SHAPE_ID: surfaces_dict(ply_path)})
