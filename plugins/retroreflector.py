"""``retroreflector``: a BSDF for retroreflective sheeting (road signs, licence plates, vests).

Executed once per Mitsuba variant by :func:`nidar_mi.plugins.register_all`; see
:class:`Retroreflector`.

Model
-----
The BRDF is a von Mises-Fisher (vMF) lobe centred on the *incident* direction ``wi`` plus an
optional Lambertian base::

    f(wi, wo) = rho * [ (1 - d) * V_kappa(wi . wo)  +  d / pi ]
    V_kappa(c) = kappa / (2 pi (1 - exp(-2 kappa))) * exp(kappa (c - 1))    # vMF density, 1/sr

with ``rho`` the spectral reflectance, ``d`` the diffuse fraction and ``kappa`` the lobe
concentration. ``V_kappa`` integrates to one over the sphere, so the directional albedo
``a(wi) = rho [(1-d) \\int_H V cos(theta_o) dw + d]`` never exceeds ``rho`` (energy
conserving); at normal incidence with a narrow lobe it is ``rho [(1-d)(coth k - 1/k) + d]``.
The lobe loses energy at grazing entrance (the ``cos(theta_o)`` of the return path and the
horizon cut), as real sheeting does. The BRDF is symmetric in ``wi`` and ``wo`` (reciprocal).

``lobe_width`` (degrees) sets ``kappa = ln 2 / (1 - cos(lobe_width))``: it is the half width at
half maximum of the lobe, and the cone around ``wi`` that holds half of the lobe's energy.

For a monostatic LiDAR (``wo = wi``) the effective reflectance ``pi f`` is angle independent::

    rho_eff = rho * [ (1 - d) * kappa / (2 (1 - exp(-2 kappa))) + d ]

i.e. about ``570 * rho`` for the default 2 degree lobe and ``d = 0``, against ``rho`` for a
Lambertian panel (engineering-grade sheeting measures 100-300 cd/lx/m^2 at small observation
angles, a white Lambertian panel about 0.3). The closed forms are in :mod:`nidar_mi.materials.vmf`.

The BSDF is front-facing only (zero below the surface), like Mitsuba's ``diffuse``; wrap it in a
``twosided`` BSDF for sheets seen from both sides.
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi

from nidar_mi.materials.vmf import lobe_concentration, normalisation

from ._validate import bounded, plugin_name

__all__ = ["VARIANT", "Retroreflector"]

#: The Mitsuba variant this module's class belongs to.
VARIANT = mi.variant()


class Retroreflector(mi.BSDF):
    """Retroreflective sheeting: a vMF lobe back towards the incident direction.

    .. list-table::
       :header-rows: 1

       * - Parameter
         - Type
         - Meaning
         - Default
       * - ``reflectance``
         - spectrum or texture
         - spectral reflectance ``rho`` in [0, 1]: the albedo scale of both terms
         - 0.8
       * - ``lobe_width``
         - float
         - half width at half maximum of the retro lobe, degrees, in (0, 90]
         - 2.0
       * - ``diffuse_fraction``
         - float
         - share ``d`` of ``rho`` sent into a Lambertian base, in [0, 1]
         - 0.0

    An invalid value fails the load with :class:`nidar_mi.errors.NidarError`: one
    line naming the BSDF and the parameter.

    .. code-block:: xml

        <bsdf type="retroreflector">
            <spectrum name="reflectance" value="360:0.78, 1700:0.80"/>
            <float name="lobe_width" value="2.0"/>
            <float name="diffuse_fraction" value="0.05"/>
        </bsdf>
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.m_reflectance = props.get_texture("reflectance", 0.8)
        self.lobe_width, self.diffuse_fraction = _parameters(props)
        self.kappa = kappa = lobe_concentration(self.lobe_width)
        # Opaque, so that every lobe shares one compiled kernel.
        self.m_kappa = dr.opaque(mi.Float, kappa)
        self.m_norm = dr.opaque(mi.Float, normalisation(kappa))
        self.m_exp2k = dr.opaque(mi.Float, math.exp(-2.0 * kappa))  # for sampling
        self.m_diffuse = dr.opaque(mi.Float, self.diffuse_fraction)
        glossy = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
        diffuse = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
        self.m_components = [glossy, diffuse]
        self.m_flags = glossy | diffuse

    # ---------------------------------------------------------------- Mitsuba's BSDF interface
    def eval(self, ctx, si, wo, active=True):
        return self._eval(ctx, si, wo, active)

    def pdf(self, ctx, si, wo, active=True):
        return self._pdf(ctx, si, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self._eval(ctx, si, wo, active), self._pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0)
        p_lobe, _, _, _ = self._weights(ctx)
        pick_lobe = sample1 < p_lobe
        wo_diffuse = mi.warp.square_to_cosine_hemisphere(sample2)

        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = dr.select(pick_lobe, self._sample_lobe(si.wi, sample2), wo_diffuse)
        bs.eta = 1.0
        bs.sampled_component = dr.select(pick_lobe, mi.UInt32(0), mi.UInt32(1))
        bs.sampled_type = dr.select(
            pick_lobe,
            mi.UInt32(+mi.BSDFFlags.GlossyReflection),
            mi.UInt32(+mi.BSDFFlags.DiffuseReflection),
        )
        value, pdf = self.eval_pdf(ctx, si, bs.wo, active)
        bs.pdf = pdf
        ok = active & (pdf > 0) & (mi.Frame3f.cos_theta(bs.wo) > 0)
        weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)
        return bs, weight

    def traverse(self, callback):
        callback.put("reflectance", self.m_reflectance, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return (
            f"Retroreflector[lobe_width={self.lobe_width} deg, kappa={self.kappa:.6g}, "
            f"diffuse_fraction={self.diffuse_fraction}, reflectance={self.m_reflectance}]"
        )

    # ---------------------------------------------------------------- the model
    def _weights(self, ctx):
        """Probabilities (lobe, diffuse) of sampling each enabled component."""
        has_lobe = ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
        has_diffuse = ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 1)
        p_lobe = mi.Float(1.0 - self.diffuse_fraction) if has_lobe else mi.Float(0.0)
        p_diff = self.m_diffuse if has_diffuse else mi.Float(0.0)
        total = p_lobe + p_diff
        # Both weights zero only when d is 0 and the lobe is disabled, or d is 1 and the
        # diffuse part is disabled: fall back to the enabled one.
        p_lobe = dr.select(total > 0, p_lobe / total, mi.Float(1.0 if has_lobe else 0.0))
        p_diff = dr.select(total > 0, p_diff / total, mi.Float(1.0 if has_diffuse else 0.0))
        return p_lobe, p_diff, has_lobe, has_diffuse

    def _vmf(self, cos_angle):
        """``V_kappa(cos_angle)``, 1/sr."""
        return self.m_norm * dr.exp(self.m_kappa * (dr.minimum(cos_angle, 1.0) - 1.0))

    def _eval(self, ctx, si, wo, active):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0)
        _, _, has_lobe, has_diffuse = self._weights(ctx)
        lobe = (1.0 - self.m_diffuse) * self._vmf(dr.dot(si.wi, wo)) if has_lobe else 0.0
        diff = self.m_diffuse * dr.inv_pi if has_diffuse else 0.0
        rho = self.m_reflectance.eval(si, active)
        value = rho * ((lobe + diff) * cos_o)
        return dr.select(active, value, 0.0)

    def _pdf(self, ctx, si, wo, active):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0)
        p_lobe, p_diff, _, _ = self._weights(ctx)
        pdf = p_lobe * self._vmf(dr.dot(si.wi, wo)) + p_diff * cos_o * dr.inv_pi
        return dr.select(active, pdf, 0.0)

    def _sample_lobe(self, wi, sample2):
        """A direction drawn from the vMF lobe around ``wi`` (Wenzel Jakob, "Numerically stable
        sampling of the von Mises Fisher distribution on S2", 2012):
        ``1 - cos = -log(u + (1 - u) e^{-2 kappa}) / kappa``."""
        u = sample2.x
        one_minus_w = -dr.log(u + (1.0 - u) * self.m_exp2k) / self.m_kappa
        one_minus_w = dr.clip(one_minus_w, 0.0, 2.0)
        sin_t = dr.safe_sqrt(one_minus_w * (2.0 - one_minus_w))
        s, c = dr.sincos(dr.two_pi * sample2.y)
        return mi.Frame3f(wi).to_world(mi.Vector3f(c * sin_t, s * sin_t, 1.0 - one_minus_w))


def _parameters(props: mi.Properties) -> tuple[float, float]:
    """(``lobe_width`` in degrees, ``diffuse_fraction``), validated."""
    where = plugin_name("retroreflector", props)
    lobe_width = bounded(props, where, "lobe_width", 2.0, ("(", 0.0, 90.0, "]"), " degrees")
    diffuse_fraction = bounded(props, where, "diffuse_fraction", 0.0, ("[", 0.0, 1.0, "]"))
    return lobe_width, diffuse_fraction


mi.register_bsdf("retroreflector", lambda props: Retroreflector(props))
