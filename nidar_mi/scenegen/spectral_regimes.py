"""Spectral regimes of generated scenes: the library's spectra, or measured spectra drawn anew.

``library`` keeps each material's own spectrum (:mod:`nidar_mi.materials.catalog`). ``earthlib``
gives each material of a scene whose kind takes a reflectance spectrum (diffuse, rough diffuse,
paint; not metals, glass or retroreflective sheeting), with probability
:data:`REPLACED_FRACTION`, a spectrum drawn from earthlib's 7261 measured spectra: first a class
(earthlib's ``LEVEL_2/LEVEL_3``, e.g. ``bare/soil``, ``built/comp_shingle``) uniformly among
:func:`pool_classes`, then a spectrum uniformly within it, so that the 4185 soils and 2000
canopies do not crowd out the small classes. The material keeps its kind and other parameters
(a road stays a rough diffuse surface with its opposition surge), so only the spectrum changes:
the camera colour, the NIR image and the surfaces' reflectance maps of a frame follow it.

``earthlib-family`` keeps what a surface is: a material takes a spectrum of its own family
(:data:`FAMILIES`: a grass or a tree crown another vegetation canopy, a soil or gravel another
soil or gravel, wood or bark another wood, bark or dead vegetation, a shingle another roofing, a
road or concrete another pavement), with the same probability and the class drawn uniformly within
the family; materials of no family (paints, metals, glass, sheeting, the modelled plastics and
fabric) keep their own.

The pool leaves out every class that holds the spectrum of a held-out material
(:data:`nidar_mi.scenegen.objects.HELDOUT_MATERIALS`: road, sidewalk, tile, paint, litter,
dirt, sand) and earthlib's two glass spectra, so a network trained on these scenes has seen no
spectrum of the families it is tested on. The draw is deterministic per seed and scene, from a
stream of its own, ``SeedSequence(seed, spawn_key=(k, 2))`` (``(k, 3)`` for
``earthlib-family``): the shapes, the light and the materials' kinds stay those of the
``library`` regime.

Training scenes with many measured spectra teach a network the relation between the visible
colour and the reflectance at the LiDAR wavelength, where the library's two dozen spectra only
let it learn those two dozen.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from ..errors import NidarError
from ..materials.earthlib_data import earthlib_row_spectrum, load_earthlib
from ..materials.library import get_material
from ..materials.mitsuba_dict import REFLECTANCE_KINDS
from ..materials.spectra import Spectrum
from .objects import HELDOUT_MATERIALS

__all__ = [
    "FAMILIES",
    "REPLACED_FRACTION",
    "SPECTRA_REGIMES",
    "draw_spectra",
    "pool_classes",
    "SurfaceSpectrum",
]

#: The spectral regimes of :func:`draw_spectra`.
SPECTRA_REGIMES = ("library", "earthlib", "earthlib-family")
_VEGETATION = (("vegetation", "canopy"),)
_GROUND = (("bare", "soil"), ("bare", "gravel"), ("built", "gravel"))
_WOOD = (("npv", "wood"), ("npv", "bark"), ("npv", "npv"))
_ROOFING = (("built", "comp_shingle"), ("built", "wood_shingle"), ("built", "concrete_tile"))
_PAVEMENT = (
    ("built", "asphalt"),
    ("built", "parking_lot"),
    ("built", "driveway"),
    ("built", "bridge"),
)
#: ``earthlib-family``: the earthlib classes each training material draws from (all in
#: :func:`pool_classes`; a road and concrete, whose own classes hold held-out spectra, draw from
#: the other pavements).
FAMILIES: dict[str, tuple[tuple[str, str], ...]] = {
    "grass": _VEGETATION,
    "tree_canopy": _VEGETATION,
    "soil_dry": _GROUND,
    "gravel": _GROUND,
    "wood_pallet": _WOOD,
    "bark": _WOOD,
    "shingle": _ROOFING,
    "asphalt_new": _PAVEMENT,
    "concrete": _PAVEMENT,
}
#: Share of a scene's replaceable materials that take an earthlib spectrum.
REPLACED_FRACTION = 0.75
#: Kinds whose spectrum is replaced (retroreflective sheeting keeps its own).
_REPLACED_KINDS = REFLECTANCE_KINDS - {"retroreflector"}
#: earthlib classes left out besides those of the held-out materials.
_EXCLUDED_CLASSES = frozenset({("built", "glass")})


class SurfaceSpectrum(NamedTuple):
    """A drawn spectrum: its provenance (``earthlib:LEVEL_2/LEVEL_3/NAME``) and its values on the
    library grid (360-1700 nm, in [0, 1])."""

    source: str
    spectrum: Spectrum


def _class_of(source: str) -> tuple[str, str] | None:
    if not source.startswith("earthlib:"):
        return None
    level_2, level_3, _ = source[len("earthlib:") :].split("/", 2)
    return level_2, level_3


@functools.cache
def pool_classes() -> tuple[tuple[tuple[str, str], tuple[int, ...]], ...]:
    """The earthlib classes the ``earthlib`` regime draws from, each with its library rows:
    ``((level_2, level_3), rows)``, sorted by class.

    Raises:
        NidarError: earthlib is not installed.
    """
    held = {_class_of(get_material(m).source) for m in HELDOUT_MATERIALS} - {None}
    lib = load_earthlib()
    rows: dict[tuple[str, str], list[int]] = {}
    for i, key in enumerate(zip(lib.level_2, lib.level_3)):
        if key not in held and key not in _EXCLUDED_CLASSES:
            rows.setdefault(key, []).append(i)
    return tuple((key, tuple(rows[key])) for key in sorted(rows))


def draw_spectra(
    materials: list[str] | tuple[str, ...], seed: int, k: int, regime: str = "library"
) -> dict[str, SurfaceSpectrum]:
    """The materials of scene ``k`` of run ``seed`` that take another spectrum, and theirs.

    Args:
        materials: the scene's material names, in a fixed order (``Layout.materials()``).
        seed: run seed.
        k: scene index.
        regime: one of :data:`SPECTRA_REGIMES`.

    Returns:
        material name -> its :class:`SurfaceSpectrum` (empty for ``library``).

    Raises:
        NidarError: an unknown regime, or earthlib is not installed.
    """
    if regime not in SPECTRA_REGIMES:
        raise NidarError(f"spectra must be one of {', '.join(SPECTRA_REGIMES)} (got {regime!r})")
    if regime == "library":
        return {}
    lib = load_earthlib()
    pool = dict(pool_classes())
    family = regime == "earthlib-family"
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(k, 3 if family else 2)))
    out = {}
    for name in materials:
        # three draws per material whatever it is, so one material's kind never shifts the others'
        if family:
            classes = FAMILIES.get(name, ())
            replace, c, j = rng.uniform(), rng.uniform(), rng.uniform()
            c = int(c * len(classes))
        else:
            classes = tuple(pool) if get_material(name).kind in _REPLACED_KINDS else ()
            replace, c, j = rng.uniform(), rng.integers(len(pool)), rng.uniform()
        if not classes or replace >= REPLACED_FRACTION:
            continue
        rows = pool[classes[min(int(c), len(classes) - 1)]]
        row = rows[min(int(j * len(rows)), len(rows) - 1)]
        source = f"earthlib:{lib.level_2[row]}/{lib.level_3[row]}/{lib.names[row]}"
        out[name] = SurfaceSpectrum(source, earthlib_row_spectrum(row))
    return out
