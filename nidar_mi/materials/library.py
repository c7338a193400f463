"""The named material registry: lookup, spectral reflectance and sRGB appearance.

A :class:`~nidar_mi.materials.material.Material` is a frozen record: its kind (which Mitsuba BSDF
renders it), its physical parameters (spectra on the 360-1700 nm grid, roughness, ...) and its
provenance (``source``, ``license``, ``notes``). The materials themselves are defined in
:mod:`.catalog`.

Kinds and what :func:`reflectance` returns for them:

==============  =========================  ==============================================
kind            Mitsuba BSDF               ``reflectance(name, wl)``
==============  =========================  ==============================================
diffuse         ``diffuse``                the Lambertian albedo
plastic         ``roughplastic``           the albedo of the diffuse (pigment) layer
conductor       ``roughconductor``         normal-incidence Fresnel R from (n, k)
dielectric      ``roughdielectric``        normal-incidence Fresnel R of one surface
retroreflector  ``retroreflector``         the sheeting reflectance rho
rough_diffuse   ``roughdiffuse``           the facet albedo rho (Oren–Nayar + opposition)
==============  =========================  ==============================================
"""

from __future__ import annotations

import difflib
import functools

import numpy as np

from ..errors import NidarError
from ..io.images import linear_to_srgb
from .catalog import build_catalog
from .material import KINDS, Material
from .optics import fresnel_conductor_normal, fresnel_dielectric_normal, soda_lime_ior
from .spectra import GRID_NM, Spectrum, check_wavelengths, flat
from .srgb import spectrum_to_linear_srgb

__all__ = [
    "KINDS",
    "Material",
    "list_materials",
    "get_material",
    "reflectance",
    "appearance_spectrum",
    "linear_rgb",
    "srgb",
]


@functools.lru_cache(maxsize=1)
def _catalog() -> dict[str, Material]:
    return build_catalog()


def list_materials() -> list[str]:
    """Names of all materials, sorted."""
    return sorted(_catalog())


def get_material(name: str) -> Material:
    """The material called ``name``.

    Raises:
        NidarError: unknown name (the message suggests close names).
    """
    cat = _catalog()
    if name not in cat:
        close = difflib.get_close_matches(str(name), list(cat), n=3)
        hint = (
            f"; did you mean {', '.join(close)}?"
            if close
            else "; see python -m nidar_mi.materials --list"
        )
        raise NidarError(f"unknown material '{name}'{hint}")
    return cat[name]


def reflectance(name: str, wavelengths_nm: np.ndarray | float) -> np.ndarray:
    """Spectral reflectance of a material (meaning per kind: see the module docstring).

    Args:
        name: material name.
        wavelengths_nm: any shape, nm, within 360-1700.

    Returns:
        Reflectance in [0, 1], shape of ``wavelengths_nm``.

    Raises:
        NidarError: unknown material or wavelength out of range.
    """
    m = get_material(name)
    p = m.params
    if m.kind == "conductor":
        return fresnel_conductor_normal(p["eta"](wavelengths_nm), p["k"](wavelengths_nm))
    if m.kind == "dielectric":
        return fresnel_dielectric_normal(soda_lime_ior(check_wavelengths(wavelengths_nm)))
    return p["reflectance"](wavelengths_nm)


def appearance_spectrum(name: str) -> Spectrum:
    """The spectrum whose sRGB colour stands for the material in an RGB-only engine.

    The reflectance for diffuse, plastic (pigment) and retroreflector kinds; the
    normal-incidence reflectance (the metallic "base colour") for conductors; the
    transmittance tint for dielectrics (white for clear glass).
    """
    m = get_material(name)
    if m.kind == "conductor":
        return Spectrum(GRID_NM, reflectance(name, GRID_NM))
    if m.kind == "dielectric":
        return m.params["transmittance"] or flat(1.0)
    return m.params["reflectance"]


@functools.cache
def _linear_rgb(name: str) -> tuple[float, float, float]:
    return tuple(float(c) for c in spectrum_to_linear_srgb(appearance_spectrum(name)))


def linear_rgb(name: str) -> np.ndarray:
    """Linear sRGB (D65) of the material's :func:`appearance_spectrum`, in [0, 1]. Shape (3,)."""
    return np.array(_linear_rgb(get_material(name).name))


def srgb(name: str) -> np.ndarray:
    """Encoded sRGB (D65) of the material's :func:`appearance_spectrum`, in [0, 1]. Shape (3,)."""
    return linear_to_srgb(linear_rgb(name))
