"""Mitsuba BSDF dicts (``mi.load_dict`` form) for named materials, spectral or RGB twin.

``bsdf_dict(name)`` is meant for a *spectral* variant: spectra become ``irregular`` spectra on the
360-1700 nm grid, so every material evaluates finite from 360 to 1700 nm (Mitsuba's conductor
presets are NaN past ~886 nm; the metals here carry their own (n, k) tables).

``bsdf_dict(name, rgb_twin=True)`` is the same BSDF with its spectra replaced by the material's
linear sRGB appearance (:func:`nidar_mi.materials.linear_rgb`), which is all a graphics-engine asset
carries; Mitsuba's spectral variants upsample that RGB to a smooth spectrum, whose NIR is the
"what engines do today" baseline. Per kind:

==============  =====================================  ======================================
kind            spectral                               RGB twin
==============  =====================================  ======================================
diffuse         ``diffuse``, ``reflectance``           ``reflectance`` -> rgb
plastic         ``roughplastic``, pigment spectrum     ``diffuse_reflectance`` -> rgb
conductor       ``roughconductor``, ``eta``, ``k``     ``material="none"`` (ideal mirror)
                                                       times rgb of the normal-incidence R
dielectric      ``thindielectric`` pane (or            tint -> rgb (clear glass unchanged)
                ``roughdielectric`` with a roughness
                override), tint spectrum
retroreflector  ``retroreflector``, rho spectrum       ``reflectance`` -> rgb
rough_diffuse   ``roughdiffuse``, facet albedo         ``reflectance`` -> rgb
                spectrum, ``sigma``, opposition surge
==============  =====================================  ======================================

Overrides (``overrides={"roughness": 0.3}``): ``roughness`` (GGX alpha, plastic / conductor /
dielectric), ``int_ior`` (plastic / dielectric), ``lobe_width`` (degrees) and
``diffuse_fraction`` (retroreflector), ``sigma`` (degrees, in [0, 90)),
``opposition_amplitude`` (in [0, 1]) and ``opposition_width`` (degrees, in (0, 90]) (rough_diffuse).

``reflectance=Spectrum(...)`` replaces the material's reflectance spectrum (the pigment layer of a
plastic) while keeping its kind and other parameters: a diffuse, plastic, retroreflector or
rough_diffuse material with another surface's spectrum (values in [0, 1], on 360-1700 nm). Its
RGB twin is the linear sRGB of that spectrum.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from ..errors import NidarError
from .library import get_material, linear_rgb
from .spectra import WL_MAX_NM, WL_MIN_NM, Spectrum
from .srgb import spectrum_to_linear_srgb

__all__ = [
    "OVERRIDES",
    "REFLECTANCE_KINDS",
    "bsdf_dict",
    "check_reflectance",
    "rgb_dict",
    "spectrum_dict",
]

#: Overridable parameters per kind -> (parameter in Material.params, low, high, low included).
#: Intervals are ``(low, high]`` when the low end is excluded, else ``[low, high]``; ``sigma``
#: is ``[0, 90)`` (:data:`_OPEN_HIGH`).
OVERRIDES: dict[str, dict[str, tuple[str, float, float, bool]]] = {
    "diffuse": {},
    "plastic": {"roughness": ("alpha", 0.0, 1.0, False), "int_ior": ("int_ior", 1.0, 3.0, False)},
    "conductor": {"roughness": ("alpha", 0.0, 1.0, False)},
    "dielectric": {
        "roughness": ("alpha", 0.0, 1.0, False),
        "int_ior": ("int_ior", 1.0, 3.0, False),
    },
    "retroreflector": {
        "lobe_width": ("lobe_width", 0.0, 90.0, False),
        "diffuse_fraction": ("diffuse_fraction", 0.0, 1.0, True),
    },
    "rough_diffuse": {
        "sigma": ("sigma", 0.0, 90.0, True),
        "opposition_amplitude": ("opposition_amplitude", 0.0, 1.0, True),
        "opposition_width": ("opposition_width", 0.0, 90.0, False),
    },
}
#: Overrides whose high end is excluded.
_OPEN_HIGH = frozenset({"sigma"})
#: Kinds whose reflectance spectrum ``bsdf_dict(..., reflectance=...)`` replaces.
REFLECTANCE_KINDS = frozenset({"diffuse", "plastic", "retroreflector", "rough_diffuse"})


def spectrum_dict(spectrum: Spectrum) -> dict:
    """Mitsuba ``irregular`` spectrum dict of ``spectrum``."""
    return spectrum.mitsuba_dict()


def rgb_dict(rgb) -> dict:
    """Mitsuba ``rgb`` texture dict of a linear RGB triple."""
    return {"type": "rgb", "value": [float(c) for c in rgb]}


def _resolve(kind: str, params: Mapping, overrides: Mapping[str, float] | None) -> dict:
    out = dict(params)
    allowed = OVERRIDES[kind]
    for key, value in (overrides or {}).items():
        if key not in allowed:
            ok = ", ".join(sorted(allowed)) or "none"
            raise NidarError(
                f"parameter '{key}' cannot be set on a {kind} material (allowed: {ok})"
            )
        target, lo, hi, lo_closed = allowed[key]
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise NidarError(f"parameter '{key}' must be a number, got {value!r}") from None
        hi_closed = key not in _OPEN_HIGH
        if not ((lo <= v) if lo_closed else (lo < v)) or not ((v <= hi) if hi_closed else (v < hi)):
            interval = f"{'[' if lo_closed else '('}{lo:g}, {hi:g}{']' if hi_closed else ')'}"
            raise NidarError(f"parameter '{key}' = {v:g} is outside {interval}")
        out[target] = v
    return out


def check_reflectance(spectrum: Spectrum, what: str = "reflectance") -> Spectrum:
    """``spectrum`` if it is a reflectance the library can render: finite, in [0, 1], spanning
    the library's 360-1700 nm.

    Raises:
        NidarError: it is not.
    """
    wl, v = np.asarray(spectrum.wavelengths_nm), np.asarray(spectrum.values)
    if not np.all(np.isfinite(v)) or v.min() < 0.0 or v.max() > 1.0:
        raise NidarError(f"{what} must be finite and in [0, 1]")
    if wl[0] > WL_MIN_NM or wl[-1] < WL_MAX_NM:
        raise NidarError(
            f"{what} must span {WL_MIN_NM:g}-{WL_MAX_NM:g} nm (got {wl[0]:g}-{wl[-1]:g} nm)"
        )
    return spectrum


def bsdf_dict(
    name: str,
    *,
    rgb_twin: bool = False,
    overrides: Mapping[str, float] | None = None,
    reflectance: Spectrum | None = None,
) -> dict:
    """Mitsuba BSDF dict of a named material for the active spectral variant.

    Args:
        name: material name (see :func:`nidar_mi.materials.list_materials`).
        rgb_twin: replace the material's spectra by its linear sRGB appearance.
        overrides: parameter overrides, see the module docstring.
        reflectance: another reflectance spectrum for the material (a kind of
            :data:`REFLECTANCE_KINDS`; see the module docstring), or None for its own.

    Returns:
        A dict for ``mi.load_dict`` (plain Python values; no Mitsuba import needed).

    Raises:
        NidarError: unknown material, bad override, or a reflectance the material's kind does
            not take or that is not in [0, 1] over 360-1700 nm.
    """
    m = get_material(name)
    p = _resolve(m.kind, m.params, overrides)
    if reflectance is None:
        rgb = rgb_dict(linear_rgb(name)) if rgb_twin else None
    else:
        if m.kind not in REFLECTANCE_KINDS:
            raise NidarError(
                f"material '{name}' ({m.kind}) takes no reflectance spectrum; kinds that do: "
                + ", ".join(sorted(REFLECTANCE_KINDS))
            )
        p["reflectance"] = check_reflectance(reflectance, f"reflectance of '{name}'")
        rgb = rgb_dict(spectrum_to_linear_srgb(reflectance)) if rgb_twin else None

    if m.kind == "diffuse":
        return {"type": "diffuse", "reflectance": rgb or spectrum_dict(p["reflectance"])}
    if m.kind == "plastic":
        return {
            "type": "roughplastic",
            "distribution": "ggx",
            "alpha": float(p["alpha"]),
            "int_ior": float(p["int_ior"]),
            "nonlinear": False,
            "diffuse_reflectance": rgb or spectrum_dict(p["reflectance"]),
        }
    if m.kind == "conductor":
        out = {"type": "roughconductor", "distribution": "ggx", "alpha": float(p["alpha"])}
        if rgb_twin:
            out.update(material="none", specular_reflectance=rgb)
        else:
            out.update(eta=spectrum_dict(p["eta"]), k=spectrum_dict(p["k"]))
        return out
    if m.kind == "dielectric":
        if float(p["alpha"]) > 0.0:
            out = {
                "type": "roughdielectric",
                "distribution": "ggx",
                "alpha": float(p["alpha"]),
                "int_ior": float(p["int_ior"]),
            }
        else:  # a window pane: both interfaces, as the LiDAR passes through it (README)
            out = {"type": "thindielectric", "int_ior": float(p["int_ior"])}
        if p["transmittance"] is not None:
            out["specular_transmittance"] = rgb or spectrum_dict(p["transmittance"])
        return out
    if m.kind == "retroreflector":
        return {
            "type": "retroreflector",
            "reflectance": rgb or spectrum_dict(p["reflectance"]),
            "lobe_width": float(p["lobe_width"]),
            "diffuse_fraction": float(p["diffuse_fraction"]),
        }
    if m.kind == "rough_diffuse":
        return {
            "type": "roughdiffuse",
            "reflectance": rgb or spectrum_dict(p["reflectance"]),
            "sigma": float(p["sigma"]),
            "opposition_amplitude": float(p["opposition_amplitude"]),
            "opposition_width": float(p["opposition_width"]),
        }
    raise AssertionError(f"unhandled kind {m.kind}")  # pragma: no cover
