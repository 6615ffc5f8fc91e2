"""The continuation mixture of rna assets in Dr.Jit (spec/renderer.md#neural-assets item 4, #fibers).

The reference renderer draws rna continuations from a defensive mixture of the uniform sphere and lobes
where a trained transport is large (surfaces: a cosine lobe on wo's side and a von Mises-Fisher lobe about
the mirror direction; fibers: a lobe about the forward direction -wo and the band of the specular cone
about the tangent). This is the same mixture, with the same weights and widths, built in the asset's object
space: the integrator maps it to world directions with their Jacobian (p_c = p_obj J), as it does the
neupress lobe. Any density that is positive everywhere gives the same expected image.
"""

from __future__ import annotations

import math

from nasset_reference_renderer.shaders.rna_fiber import CONE_HALF_WIDTH, CONT_MIX, FORWARD_KAPPA
from nasset_reference_renderer.shaders.rna_surface import MIRROR_KAPPA, SURFACE_CONT_MIX

INV_4PI = 0.25 / math.pi


class RnaLobes:
    """The mixture at rna hits, object space: ``frame`` the normal (surface) or tangent (fiber) [Vector3f,
    unit], ``wo`` [Vector3f, unit] toward the viewer. ``sample(u) -> (w, pdf)`` from u [Point2f]: u.x picks
    the component and is stretched back onto [0, 1); ``pdf(w)`` per object-space steradian."""

    def __init__(self, mi, fiber: bool, frame, wo) -> None:
        import drjit as dr

        self.mi, self.dr, self.fiber = mi, dr, fiber
        frame = dr.select(dr.squared_norm(frame) > 0.5, frame, wo)  # a degenerate frame: lobes about wo
        self.weights = CONT_MIX if fiber else SURFACE_CONT_MIX
        if fiber:
            self.axis = mi.Vector3f(frame)
            self.lobe = -wo  # forward
            s_o = dr.clip(dr.dot(wo, self.axis), -1.0, 1.0)
            self.lo = dr.maximum(-1.0, -s_o - CONE_HALF_WIDTH)
            self.hi = dr.minimum(1.0, -s_o + CONE_HALF_WIDTH)
            self.kappa = FORWARD_KAPPA
        else:
            self.axis = dr.select(dr.dot(frame, wo) < 0.0, -frame, frame)  # the normal on wo's side
            self.lobe = dr.normalize(2.0 * dr.dot(wo, self.axis) * self.axis - wo)  # mirror direction
            self.kappa = MIRROR_KAPPA

    def sample(self, u):
        mi, dr = self.mi, self.dr
        w0, w1, _ = self.weights
        pick1 = u.x >= w0
        pick2 = u.x >= w0 + w1
        ux = dr.select(pick2, (u.x - w0 - w1) / (1.0 - w0 - w1), dr.select(pick1, (u.x - w0) / w1, u.x / w0))
        v = mi.Point2f(dr.clip(ux, 0.0, 1.0 - 1e-7), u.y)
        uniform = mi.warp.square_to_uniform_sphere(v)
        toward_lobe = mi.Frame3f(self.lobe).to_world(mi.warp.square_to_von_mises_fisher(v, self.kappa))
        if self.fiber:  # the band: uniform in z = sin(theta) about the tangent over [lo, hi], and in azimuth
            z = self.lo + v.x * (self.hi - self.lo)
            r = dr.safe_sqrt(1.0 - z * z)
            s, c = dr.sincos(2.0 * math.pi * v.y)
            second, third = toward_lobe, mi.Frame3f(self.axis).to_world(mi.Vector3f(r * c, r * s, z))
        else:
            second = mi.Frame3f(self.axis).to_world(mi.warp.square_to_cosine_hemisphere(v))
            third = toward_lobe
        w = dr.normalize(dr.select(pick2, third, dr.select(pick1, second, uniform)))
        return w, self.pdf(w)

    def pdf(self, w):
        mi, dr = self.mi, self.dr
        w = dr.normalize(w)
        w0, w1, w2 = self.weights
        lobe = mi.warp.square_to_von_mises_fisher_pdf(mi.Frame3f(self.lobe).to_local(w), self.kappa)
        if self.fiber:
            z = dr.dot(w, self.axis)
            band = dr.select((z >= self.lo) & (z <= self.hi), 1.0 / (2.0 * math.pi * (self.hi - self.lo)), 0.0)
            return w0 * INV_4PI + w1 * lobe + w2 * band
        return w0 * INV_4PI + w1 * dr.maximum(dr.dot(w, self.axis), 0.0) * (1.0 / math.pi) + w2 * lobe
