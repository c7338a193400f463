"""The record of one named material: its kind, physical parameters and provenance.

The registry that looks materials up is :mod:`nidar_mi.materials.library`; the materials
themselves are defined in :mod:`nidar_mi.materials.catalog`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["KINDS", "Material"]

KINDS = ("diffuse", "plastic", "conductor", "dielectric", "retroreflector", "rough_diffuse")


@dataclass(frozen=True)
class Material:
    """A named material.

    Attributes:
        name: lowercase snake_case identifier.
        kind: one of :data:`KINDS`.
        description: one line for people.
        source: provenance: ``earthlib:<LEVEL_2>/<LEVEL_3>/<NAME>`` for a measured spectrum, or
            ``model:<citation>`` for a modelled one.
        license: licence of the data the material is built from.
        params: physical parameters, by kind: ``reflectance`` (Spectrum) for diffuse, plastic and
            retroreflector; ``alpha`` (roughness), ``int_ior`` for plastic and dielectric;
            ``metal``, ``eta``, ``k`` (Spectrum) and ``alpha`` for conductor; ``transmittance``
            (Spectrum or None) for dielectric; ``lobe_width`` (deg) and ``diffuse_fraction``
            for retroreflector.
        notes: how the data were chosen or processed.
    """

    name: str
    kind: str
    description: str
    source: str
    license: str
    params: Mapping[str, Any]
    notes: str = ""

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"material '{self.name}': unknown kind '{self.kind}'")
        if not self.source.startswith(("earthlib:", "model:")):
            raise ValueError(f"material '{self.name}': source must start with earthlib: or model:")
