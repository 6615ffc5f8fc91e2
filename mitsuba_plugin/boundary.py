"""The analytic rough-dielectric boundary reflection (GGX, Walter et al. 2007) in Dr.Jit, float32: the
formulas of spec/kinds/encodings.md#ggx as ``nasset_sdk.kinds.boundary`` writes them in numpy (eta and
alpha already clamped by ``boundary_params``). Directions are object-space, pointing away from the surface.
"""

from __future__ import annotations

import math

from .rna import safe_normalize


def fresnel(cos_i, eta):
    """Unpolarised dielectric Fresnel reflectance at |cos_i| (NaN read as 0) for relative IOR ``eta`` (a float or a
    per-lane Float), 1 under total internal reflection: ``nasset_sdk.kinds.boundary.fresnel_dielectric`` in Dr.Jit."""
    import drjit as dr

    c = dr.clip(dr.abs(dr.select(dr.isnan(cos_i), 0.0, cos_i)), 0.0, 1.0)
    st2 = (1.0 - c * c) / (eta * eta)
    ct = dr.sqrt(dr.maximum(1.0 - st2, 0.0))
    rs = (c - eta * ct) / dr.maximum(c + eta * ct, 1e-12)
    rp = (eta * c - ct) / dr.maximum(eta * c + ct, 1e-12)
    return dr.select(st2 >= 1.0, 1.0, dr.clip(0.5 * (rs * rs + rp * rp), 0.0, 1.0))


class GgxJit:
    """GGX rough-dielectric reflection of relative IOR ``eta`` and roughness ``alpha``: :meth:`eval`
    (f |n.wi|, 1/sr), :meth:`pdf` (per steradian), :meth:`sample`, :meth:`fresnel`."""

    def __init__(self, mi, eta: float, alpha: float) -> None:
        self.mi, self.eta, self.alpha = mi, float(eta), float(alpha)


    def fresnel(self, cos_i):
        """Unpolarised dielectric Fresnel reflectance at |cos_i| (1 under total internal reflection)."""
        return fresnel(cos_i, self.eta)

    def _d(self, cos_h):
        import drjit as dr

        a2 = self.alpha * self.alpha
        den = cos_h * cos_h * (a2 - 1.0) + 1.0
        return dr.select(cos_h > 0, a2 / (math.pi * dr.maximum(den * den, 1e-12)), 0.0)

    def _lambda(self, c):
        import drjit as dr

        c = dr.minimum(dr.maximum(dr.abs(c), 1e-12), 1.0)
        return 0.5 * (dr.sqrt(c * c + self.alpha * self.alpha * (1.0 - c * c)) / c - 1.0)

    def _dots(self, n, wo, wi):
        import drjit as dr

        mi = self.mi
        n, wo, wi = (safe_normalize(mi, mi.Vector3f(v)) for v in (n, wo, wi))
        h = wo + wi
        hl = dr.norm(h)
        h = dr.select(hl > 1e-12, h / dr.maximum(hl, 1e-12), n)
        return dr.dot(n, wo), dr.dot(n, wi), dr.dot(n, h), dr.dot(wo, h)

    def eval(self, n, wo, wi):
        """f |n.wi| of the GGX rough-dielectric reflection [Float, 1/sr, grey] (object space)."""
        import drjit as dr

        co, ci, ch, coh = self._dots(n, wo, wi)
        g2 = 1.0 / (1.0 + self._lambda(co) + self._lambda(ci))
        val = self.fresnel(coh) * self._d(ch) * g2 / (4.0 * dr.maximum(co, 1e-12))
        return dr.select((co > 0) & (ci > 0), val, 0.0)

    def pdf(self, n, wo, wi):
        """Density per object steradian of :meth:`sample` at wi."""
        import drjit as dr

        co, _, ch, coh = self._dots(n, wo, wi)
        flip = dr.select(ch < 0, -1.0, 1.0)
        ch, coh = ch * flip, coh * flip
        pdf = self._d(ch) * ch / (4.0 * dr.maximum(dr.abs(coh), 1e-12))
        return dr.select((co > 0) & (ch > 0), pdf, 0.0)

    def sample(self, n, wo, u2):
        """wo reflected about h ~ D(h) (n.h) (encodings.md#frames for the frame of n): (wi, pdf)."""
        import drjit as dr

        mi = self.mi
        n = safe_normalize(mi, mi.Vector3f(n))
        wo = safe_normalize(mi, mi.Vector3f(wo))
        u0 = dr.clip(u2.x, 0.0, 1.0 - 1e-7)
        tan2 = self.alpha * self.alpha * u0 / dr.maximum(1.0 - u0, 1e-7)
        ct = dr.rsqrt(1.0 + tan2)
        st = dr.sqrt(dr.maximum(1.0 - ct * ct, 0.0))
        phi = 2.0 * math.pi * u2.y
        sign = dr.select(n.z >= 0, 1.0, -1.0)
        a = -1.0 / (sign + n.z)
        c = n.x * n.y * a
        t = mi.Vector3f(1.0 + sign * n.x * n.x * a, sign * c, -sign * n.x)
        b = mi.Vector3f(c, sign + n.y * n.y * a, -n.y)
        h = st * dr.cos(phi) * t + st * dr.sin(phi) * b + ct * n
        wi = safe_normalize(mi, 2.0 * dr.dot(wo, h) * h - wo)
        return wi, self.pdf(n, wo, wi)
