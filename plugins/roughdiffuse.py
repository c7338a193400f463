"""``roughdiffuse``: a rough diffuse BSDF with backscatter (Oren–Nayar and an opposition surge),
for asphalt, concrete and other rough ground that keeps returning LiDAR light at grazing
incidence.

Executed once per Mitsuba variant by :func:`nidar_mi.plugins.register_all`; see
:class:`RoughDiffuse`. The model and its closed forms are in :mod:`nidar_mi.materials.oren_nayar`.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from nidar_mi.materials.oren_nayar import coefficients, half_width_h

from ._validate import bounded, plugin_name

__all__ = ["VARIANT", "RoughDiffuse"]

#: The Mitsuba variant this module's class belongs to.
VARIANT = mi.variant()


class RoughDiffuse(mi.BSDF):
    """Rough diffuse reflection: Oren–Nayar's qualitative model times a Hapke opposition surge.

    ``f(wi, wo) = rho/pi · [A + B max(0, cos Δφ) sin α tan β] · (1 + B0 / (1 + tan(g/2)/h))``
    (:mod:`nidar_mi.materials.oren_nayar`); ``sigma = 0`` and ``opposition_amplitude = 0`` give
    Lambert's law. A monostatic LiDAR sees ``rho (A + B sin²θ/cosθ)(1 + B0)``.

    .. list-table::
       :header-rows: 1

       * - Parameter
         - Type
         - Meaning
         - Default
       * - ``reflectance``
         - spectrum or texture
         - albedo ``rho`` of the facets, in [0, 1]
         - 0.5
       * - ``sigma``
         - float
         - standard deviation of the facet slope angle, degrees, in [0, 90)
         - 20
       * - ``opposition_amplitude``
         - float
         - ``B0``, amplitude of the shadow-hiding opposition surge at phase angle 0, in [0, 1]
         - 0
       * - ``opposition_width``
         - float
         - half width at half maximum of the surge in phase angle, degrees, in (0, 90]
         - 5

    An invalid value fails the load with :class:`nidar_mi.errors.NidarError`: one
    line naming the BSDF and the parameter. Front-facing only, like ``diffuse``.

    .. code-block:: xml

        <bsdf type="roughdiffuse">
            <spectrum name="reflectance" value="360:0.05, 905:0.13, 1700:0.16"/>
            <float name="sigma" value="40"/>
            <float name="opposition_amplitude" value="0.8"/>
            <float name="opposition_width" value="5"/>
        </bsdf>
    """

    def __init__(self, props: mi.Properties) -> None:
        super().__init__(props)
        self.m_reflectance = props.get_texture("reflectance", 0.5)
        self.sigma, self.amplitude, self.width = _parameters(props)
        a, b = coefficients(self.sigma)
        # Opaque, so that every instance shares one compiled kernel.
        self.m_a = dr.opaque(mi.Float, a)
        self.m_b = dr.opaque(mi.Float, b)
        self.m_amplitude = dr.opaque(mi.Float, self.amplitude)
        self.m_inv_h = dr.opaque(mi.Float, 1.0 / half_width_h(self.width))
        self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide]
        self.m_flags = self.m_components[0]

    def eval(self, ctx, si, wo, active=True):
        return self._eval(ctx, si, wo, active)

    def pdf(self, ctx, si, wo, active=True):
        return self._pdf(ctx, si, wo, active)

    def eval_pdf(self, ctx, si, wo, active=True):
        return self._eval(ctx, si, wo, active), self._pdf(ctx, si, wo, active)

    def sample(self, ctx, si, sample1, sample2, active=True):
        active = active & (mi.Frame3f.cos_theta(si.wi) > 0)
        bs = dr.zeros(mi.BSDFSample3f)
        bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
        bs.eta = 1.0
        bs.sampled_component = mi.UInt32(0)
        bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
        value, pdf = self.eval_pdf(ctx, si, bs.wo, active)
        bs.pdf = pdf
        ok = active & (pdf > 0)
        return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

    def eval_diffuse_reflectance(self, si, active=True):
        """The facets' albedo ``reflectance``: the surface's own reflectance, without the
        viewing-direction effects (Oren-Nayar, opposition surge) of :meth:`eval`."""
        return self.m_reflectance.eval(si, active)

    def traverse(self, callback):
        callback.put("reflectance", self.m_reflectance, mi.ParamFlags.Differentiable)

    def parameters_changed(self, keys):
        pass

    def to_string(self):
        return (
            f"RoughDiffuse[sigma={self.sigma} deg, opposition_amplitude={self.amplitude}, "
            f"opposition_width={self.width} deg, reflectance={self.m_reflectance}]"
        )

    def _eval(self, ctx, si, wo, active):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0)
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0):
            return mi.Spectrum(0.0)
        azimuthal = dr.maximum(si.wi.x * wo.x + si.wi.y * wo.y, 0.0)
        on = self.m_a + self.m_b * azimuthal / dr.maximum(dr.maximum(cos_i, cos_o), 1e-12)
        # tan(g/2) = |wi - wo| / |wi + wo|: exact 0 at wo = wi (1 - cos g would round off)
        tan_half = dr.norm(si.wi - wo) / dr.maximum(dr.norm(si.wi + wo), 1e-12)
        surge = self.m_amplitude / (1.0 + tan_half * self.m_inv_h)
        rho = self.m_reflectance.eval(si, active)
        value = rho * (dr.inv_pi * on * (1.0 + surge) * cos_o)
        return dr.select(active, value, 0.0)

    def _pdf(self, ctx, si, wo, active):
        cos_i = mi.Frame3f.cos_theta(si.wi)
        cos_o = mi.Frame3f.cos_theta(wo)
        active = active & (cos_i > 0) & (cos_o > 0)
        if not ctx.is_enabled(mi.BSDFFlags.DiffuseReflection, 0):
            return mi.Float(0.0)
        return dr.select(active, cos_o * dr.inv_pi, 0.0)


def _parameters(props: mi.Properties) -> tuple[float, float, float]:
    """(``sigma`` deg, ``opposition_amplitude``, ``opposition_width`` deg), validated."""
    where = plugin_name("roughdiffuse", props)
    sigma = bounded(props, where, "sigma", 20.0, ("[", 0.0, 90.0, ")"), " degrees")
    amplitude = bounded(props, where, "opposition_amplitude", 0.0, ("[", 0.0, 1.0, "]"))
    width = bounded(props, where, "opposition_width", 5.0, ("(", 0.0, 90.0, "]"), " degrees")
    return sigma, amplitude, width


mi.register_bsdf("roughdiffuse", lambda props: RoughDiffuse(props))
