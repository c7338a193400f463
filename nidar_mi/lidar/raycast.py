"""Cast LiDAR beams through a Mitsuba scene: glass passes, and what the surface hit reflects back.

Both functions run vectorised in Dr.Jit over every beam of a scan (no Python loop over rays) and
take their scalars as Dr.Jit values, so the caller can make them opaque and reuse the compiled
kernels from one scan to the next.

Glass: a hit on a BSDF whose only components are delta or null transmission and delta reflection
(Mitsuba's ``dielectric``, ``thindielectric``) returns nothing itself: the beam passes through,
up to :data:`MAX_PASSES` interfaces, and the return comes from the surface behind it, scaled by
the two-way Fresnel transmittance ``T²`` (``T`` from the BSDF's own delta-transmission weight at
the laser wavelength). The range is the path length; the point lies on the original beam.
Smooth conductors and other purely specular surfaces have no monostatic lobe: their
reflectance is 0.

With ``glass_front=True`` the first glass interface of each beam is kept as well (:class:`GlassFront`:
its path length, normal, Fresnel reflectance at λ, BSDF and shape): a diverging beam sees the
specular reflection of a pane within its divergence cone as an echo of its own
(:mod:`nidar_mi.lidar.scan`).
"""

from __future__ import annotations

from typing import Any, NamedTuple

__all__ = ["MAX_PASSES", "Cast", "GlassFront", "cast", "monostatic_reflectance"]

#: Number of glass interfaces a beam may pass through.
MAX_PASSES = 4
_EPS_COS = 1e-6


class Cast(NamedTuple):
    """The beams of one scan after the glass passes; Dr.Jit arrays of one entry per beam.

    Attributes:
        ray: ``mi.Ray3f``, the beams in world space (unit directions).
        si: ``mi.SurfaceInteraction3f`` of the surface each beam returns from.
        hit: ``mi.Bool``, the beam hit a surface that is not glass.
        path_m: ``mi.Float`` path length to that surface in m (0 where nothing was hit).
        two_way_transmittance: ``mi.Float`` ``T²`` of the glass on the way (1 without glass).
        glass: the first glass interface (:class:`GlassFront`), or None when not asked for.
    """

    ray: Any
    si: Any
    hit: Any
    path_m: Any
    two_way_transmittance: Any
    glass: Any = None


class GlassFront(NamedTuple):
    """The first glass interface of each beam (Dr.Jit arrays, one entry per beam).

    Attributes:
        hit: ``mi.Bool``, the beam met glass before the surface it returns from.
        path_m: ``mi.Float`` path length to the glass, m.
        normal: ``mi.Vector3f`` world-space shading normal of the glass.
        reflectance: ``mi.Float`` Fresnel reflectance of the interface at λ (its delta
            reflection weight).
        bsdf: ``mi.BSDFPtr`` of the glass.
        shape: ``mi.ShapePtr`` of the glass.
    """

    hit: Any
    path_m: Any
    normal: Any
    reflectance: Any
    bsdf: Any
    shape: Any


def _has_glass(scene) -> bool:
    """Whether any BSDF of the scene lets a beam through (delta or null transmission)."""
    import mitsuba as mi

    through = int(mi.BSDFFlags.DeltaTransmission) | int(mi.BSDFFlags.Null)
    return any(
        shape.bsdf() is not None and int(shape.bsdf().flags()) & through for shape in scene.shapes()
    )


def cast(scene, ray, wavelength, *, glass_front: bool = False) -> Cast:
    """Intersect the beams with the scene, passing through glass.

    Args:
        scene: a loaded ``mi.Scene`` (spectral variant).
        ray: ``mi.Ray3f`` the beams in world space (unit directions).
        wavelength: ``mi.Float`` laser wavelength in nm (for the Fresnel transmittance).
        glass_front: also keep each beam's first glass interface (:class:`GlassFront`).

    Returns:
        The beams, the surface each returns from, and the path to it.
    """
    import drjit as dr
    import mitsuba as mi

    si = scene.ray_intersect(ray)
    path = dr.select(si.is_valid(), si.t, 0.0)  # accumulated path length
    trans = mi.Float(1.0)  # one-way transmittance through glass
    ctx = mi.BSDFContext(
        mi.TransportMode.Importance, mi.BSDFFlags.DeltaTransmission | mi.BSDFFlags.Null
    )
    spectrum = mi.UnpolarizedSpectrum(wavelength)
    front = None
    for i in range(MAX_PASSES if _has_glass(scene) else 0):
        bsdf = si.bsdf(ray)
        flags = bsdf.flags()
        passes = mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission) | mi.has_flag(
            flags, mi.BSDFFlags.Null
        )
        glass = si.is_valid() & passes & ~mi.has_flag(flags, mi.BSDFFlags.Smooth)
        si.wavelengths = spectrum
        if glass_front and i == 0:
            front = _glass_front(si, bsdf, glass, path)
        _, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5), glass)
        trans = dr.select(glass, trans * weight[0], trans)
        behind = scene.ray_intersect(si.spawn_ray(ray.d), glass)
        path = dr.select(glass & behind.is_valid(), path + behind.t, path)
        si = dr.select(glass, behind, si)
    if glass_front and front is None:
        zero = dr.zeros(mi.Float, dr.width(path))
        front = GlassFront(
            dr.zeros(mi.Bool, dr.width(path)),
            zero,
            mi.Vector3f(0.0, 0.0, 1.0),
            zero,
            dr.zeros(mi.BSDFPtr, dr.width(path)),
            dr.zeros(mi.ShapePtr, dr.width(path)),
        )
    return Cast(ray, si, si.is_valid(), path, trans * trans, front)


def _glass_front(si, bsdf, glass, path) -> GlassFront:
    """The Fresnel reflectance (delta reflection weight at λ) of the glass hit ``si``."""
    import drjit as dr
    import mitsuba as mi

    ctx = mi.BSDFContext(mi.TransportMode.Importance, mi.BSDFFlags.DeltaReflection)
    _, weight = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5), glass)
    return GlassFront(
        hit=glass,
        path_m=dr.select(glass, path, 0.0),
        normal=mi.Vector3f(si.n),
        reflectance=dr.select(glass, weight[0], 0.0),
        bsdf=dr.select(glass, bsdf, dr.zeros(mi.BSDFPtr)),
        shape=dr.select(glass, si.shape, dr.zeros(mi.ShapePtr)),
    )


def monostatic_reflectance(beams: Cast, wavelength) -> tuple[Any, Any, Any]:
    """ρ = π · f_r(ω, ω; λ) of the surface each beam hit, seen from the beam's own direction.

    Args:
        beams: the result of :func:`cast`.
        wavelength: ``mi.Float`` laser wavelength in nm.

    Returns:
        (ρ ``mi.Float`` unitless, 0 where nothing was hit or at grazing incidence;
        cos θ ``mi.Float`` in [0, 1], of either face for two-sided BSDFs;
        the hit ``mi.BSDFPtr``).
    """
    import drjit as dr
    import mitsuba as mi

    si, hit = beams.si, beams.hit
    si.wavelengths = mi.UnpolarizedSpectrum(wavelength)
    si.wi = si.to_local(-beams.ray.d)
    bsdf = si.bsdf(beams.ray)
    f_cos = bsdf.eval(mi.BSDFContext(), si, si.wi, hit)[0]  # f_r · cos θ
    cos_t = dr.minimum(dr.abs(mi.Frame3f.cos_theta(si.wi)), 1.0)
    rho = dr.select(hit & (cos_t > _EPS_COS), dr.pi * f_cos / dr.maximum(cos_t, _EPS_COS), 0.0)
    return rho, cos_t, bsdf
