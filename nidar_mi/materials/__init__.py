"""Spectral material library: named materials with reflectance from 360 to 1700 nm.

Measured spectra come from the installed ``earthlib`` package (read at run time), metals from
published (n, k) tables, and the rest from documented models; every :class:`Material` records its
``source`` and ``license``. Materials render in Mitsuba through :func:`bsdf_dict` (Python) or
``<bsdf type="nidar_material">`` in scene XML expanded by :func:`expand_scene_xml`, either
spectrally or as their RGB-only twin (what a graphics-engine asset carries).

The plugin BSDFs' closed forms (NumPy, no Mitsuba) are here too: :mod:`.oren_nayar` for
``roughdiffuse``, :mod:`.vmf` for ``retroreflector``.

``python -m nidar_mi.materials --list`` prints the library; ``--plot NAME ...`` plots spectra.
"""

from .library import (
    KINDS,
    Material,
    appearance_spectrum,
    get_material,
    linear_rgb,
    list_materials,
    reflectance,
    srgb,
)
from .mitsuba_dict import bsdf_dict
from .scene_xml import expand_scene_xml
from .spectra import GRID_NM, Spectrum

__all__ = [
    "GRID_NM",
    "KINDS",
    "Material",
    "Spectrum",
    "appearance_spectrum",
    "bsdf_dict",
    "expand_scene_xml",
    "get_material",
    "linear_rgb",
    "list_materials",
    "reflectance",
    "srgb",
]
