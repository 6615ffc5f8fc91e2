"""BSDF ``nasset_preview``: UsdPreviewSurface as spec/renderer.md#materials defines it, in Dr.Jit.

``f = kd / pi + D G2 F / (4 cos_o cos_i)``: GGX D with ``alpha``, height-correlated Smith G2, Schlick
F with ``f0`` (taken literally: F0 = 0 still reflects at grazing angles). Sampling: the diffuse lobe (cosine) or
the GGX normal distribution with probability 1/2 each; the pdf is the mixture's. Properties: ``kd``, ``f0`` (rgb),
``alpha`` (float, clamped to >= 1e-3).

Sides (spec/renderer.md#sidedness): both sides are front-facing, shaded alike, unless ``one_sided`` (a hit on the
back reflects nothing: the path ends) or a back material is given (``back_kd``, ``back_f0``, ``back_alpha``: the
back is shaded with it). The back is where the geometric normal, times ``front_sign`` (-1 for a prim whose front
is against its world triangles' winding: mirrored or leftHanded), faces away from the viewer.
"""

from __future__ import annotations

import math

import drjit as dr

NAME = "nasset_preview"
_REGISTERED: set[str] = set()
#: probability of sampling the GGX lobe
P_SPECULAR = 0.5


def register(mi) -> None:
    """Register ``nasset_preview`` for the active variant (idempotent)."""
    if mi.variant() in _REGISTERED:
        return

    class PreviewBSDF(mi.BSDF):
        def __init__(self, props):
            super().__init__(props)
            self.kd = mi.Color3f(props.get("kd", mi.ScalarColor3f(0.18)))
            self.f0 = mi.Color3f(props.get("f0", mi.ScalarColor3f(0.04)))
            self.alpha = max(float(props.get("alpha", 0.25)), 1e-3)
            self.one_sided = bool(props.get("one_sided", False))
            self.front_sign = float(props.get("front_sign", 1.0))
            self.has_back = "back_kd" in props
            if self.has_back:
                self.back_kd = mi.Color3f(props.get("back_kd"))
                self.back_f0 = mi.Color3f(props.get("back_f0", mi.ScalarColor3f(0.04)))
                self.back_alpha = max(float(props.get("back_alpha", 0.25)), 1e-3)
            flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_flags = flags
            self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide,
                                 mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide]

        @staticmethod
        def _lambda(w, alpha):
            """Smith Lambda of GGX for a local direction w (cos > 0)."""
            c2 = dr.square(w.z)
            t2 = dr.maximum(1.0 - c2, 0.0) / dr.maximum(c2, 1e-12)
            return 0.5 * (dr.sqrt(1.0 + alpha * alpha * t2) - 1.0)

        def _side(self, si, active):
            """(kd, f0, alpha, GGX distribution, active) of the side of hit si the viewer is on: a one-sided back leaves
            no lane active, a back material's parameters on the back (spec/renderer.md#sidedness)."""
            kd, f0, alpha = self.kd, self.f0, mi.Float(self.alpha)
            if self.one_sided or self.has_back:
                back = dr.dot(si.n, si.to_world(si.wi)) * self.front_sign < 0
                if self.one_sided:
                    active = active & ~back
                else:
                    kd, f0 = dr.select(back, self.back_kd, kd), dr.select(back, self.back_f0, f0)
                    alpha = dr.select(back, self.back_alpha, alpha)
            return kd, f0, alpha, mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True), active

        def _eval_pdf(self, wi, wo, active, side):
            """(f cos_o [Color3f], pdf) with wi (camera side) and wo (light side) local, already flipped to wi.z >= 0,
            with the parameters ``side`` of :meth:`_side`."""
            kd, f0, alpha, ggx, active = side
            ok = active & (wi.z > 0) & (wo.z > 0)
            h = dr.normalize(wi + wo)
            d = ggx.eval(h)
            g2 = dr.rcp(1.0 + self._lambda(wi, alpha) + self._lambda(wo, alpha))
            f = f0 + (1.0 - f0) * dr.power(dr.maximum(1.0 - dr.dot(wi, h), 0.0), 5.0)
            spec = d * g2 * f / dr.maximum(4.0 * wi.z * wo.z, 1e-12)
            value = (kd * (1.0 / math.pi) + spec) * wo.z
            # visible-normal density D_wi(h) = G1(wi) max(0, wi.h) D(h) / cos_i, times the reflection Jacobian 1 / (4 wo.h)
            g1 = dr.rcp(1.0 + self._lambda(wi, alpha))
            pdf_spec = g1 * dr.maximum(dr.dot(wi, h), 0.0) * d / dr.maximum(wi.z, 1e-12) / dr.maximum(4.0 * dr.abs(dr.dot(wo, h)), 1e-12)
            pdf = P_SPECULAR * pdf_spec + (1.0 - P_SPECULAR) * wo.z * (1.0 / math.pi)
            return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

        @staticmethod
        def _flip(si, wo):
            s = dr.select(si.wi.z < 0, -1.0, 1.0)
            return mi.Vector3f(si.wi.x, si.wi.y, si.wi.z * s), mi.Vector3f(wo.x, wo.y, wo.z * s), s

        def eval(self, ctx, si, wo, active=True):
            wi, wl, _ = self._flip(si, wo)
            return self._eval_pdf(wi, wl, active, self._side(si, active))[0]

        def pdf(self, ctx, si, wo, active=True):
            wi, wl, _ = self._flip(si, wo)
            return self._eval_pdf(wi, wl, active, self._side(si, active))[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            wi, wl, _ = self._flip(si, wo)
            return self._eval_pdf(wi, wl, active, self._side(si, active))

        def sample(self, ctx, si, sample1, sample2, active=True):
            wi, _, s = self._flip(si, si.wi)
            side = self._side(si, active)
            spec = sample1 < P_SPECULAR
            m, _ = side[3].sample(wi, sample2)
            w_spec = mi.reflect(wi, m)
            w_diff = mi.warp.square_to_cosine_hemisphere(sample2)
            wl = dr.select(spec, w_spec, w_diff)
            value, pdf = self._eval_pdf(wi, wl, active, side)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = mi.Vector3f(wl.x, wl.y, wl.z * s)
            bs.pdf = pdf
            bs.eta = 1.0
            bs.sampled_type = mi.UInt32(dr.select(spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)))
            bs.sampled_component = dr.select(spec, mi.UInt32(1), mi.UInt32(0))
            ok = active & (pdf > 0)
            return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"NassetPreviewBSDF[alpha={self.alpha}]"

    mi.register_bsdf(NAME, lambda props: PreviewBSDF(props))
    _REGISTERED.add(mi.variant())
