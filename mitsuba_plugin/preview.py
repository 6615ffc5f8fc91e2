"""BSDF ``nasset_preview``: UsdPreviewSurface as spec/renderer.md#materials defines it, in Dr.Jit.

``f = kd / pi + D G2 F / (4 cos_o cos_i)``: GGX D with ``alpha``, height-correlated Smith G2, Schlick
F with ``f0`` (taken literally: F0 = 0 still reflects at grazing angles). Sampling: the diffuse lobe (cosine) or
the GGX normal distribution with probability 1/2 each; the pdf is the mixture's. Properties: ``kd``, ``f0`` (rgb),
``alpha`` (float, clamped to >= 1e-3), ``beckmann`` (bool: a Beckmann D and Smith G2 in the lobe, its half vectors
drawn with density D(h) cos_h; the glass lobe stays GGX).

Shading normals (spec/renderer.md#shading-normals): with ``normals`` (the name of a 3-wide mesh attribute of world
corner normals, :func:`nasset_mitsuba_plugin.scene.usd_scene` writes it) a hit is shaded in the frame of ``ns``, the
normalised barycentric sum of its corners' normals, flipped with the front side's geometric normal ``ng`` toward the
viewer; where ``ns . wo <= 1e-6`` (or ``ns`` is undefined) the frame is ``ng``'s. A direction counts only above both
``ns`` and ``ng``, so no light leaks through a surface. Without ``normals``, ``ns = ng``.

Per-hit inputs (spec/renderer.md#textures, #primvar-colors): with ``per_hit`` (a
:class:`~nasset_mitsuba_plugin.textures.PerHitInputs`, attached after loading) the front's kd, f0 and alpha come from
textures and primvar colours at each hit. With ``normal_map`` (a :class:`~nasset_mitsuba_plugin.textures.ImageLookup`)
the shading normal is the map's (spec/renderer.md#normal-maps) and the value carries the bump-terminator term.

Sides (spec/renderer.md#sidedness): both sides are front-facing, shaded alike, unless ``one_sided`` (a hit on the
back reflects nothing: the path ends) or a back material is given (``back_kd``, ``back_f0``, ``back_alpha``: the
back is shaded with it). The back is where the geometric normal, times ``front_sign`` (-1 for a prim whose front
is against its world triangles' winding: mirrored or leftHanded), faces away from the viewer.
"""

from __future__ import annotations

import math

import drjit as dr

from .boundary import fresnel

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
            self.beckmann = bool(props.get("beckmann", False))  # Beckmann microfacets (nasset:microfacet)
            self.one_sided = bool(props.get("one_sided", False))
            self.front_sign = float(props.get("front_sign", 1.0))
            self.normals = str(props.get("normals", ""))
            self.per_hit = None  # a textures.PerHitInputs, set after loading (usd_scene): kd, f0, alpha per hit
            self.normal_map = None  # a textures.ImageLookup of a tangent-space normal map, set after loading
            self.presence = None  # a textures.Presence of a cut-out, set after loading (the integrator reads it)
            self.has_back = "back_kd" in props
            if self.has_back:
                self.back_kd = mi.Color3f(props.get("back_kd"))
                self.back_f0 = mi.Color3f(props.get("back_f0", mi.ScalarColor3f(0.04)))
                self.back_alpha = max(float(props.get("back_alpha", 0.25)), 1e-3)
                self.back_beckmann = bool(props.get("back_beckmann", False))
            self.has_beckmann = self.beckmann or (self.has_back and self.back_beckmann)  # else GGX only is traced
            # the glass lobe of a transmitting material (spec/renderer.md#transmission): weight, colours, IOR, thin wall
            self.glass = float(props.get("glass", 0.0))
            self.glass_tint = mi.Color3f(props.get("glass_tint", mi.ScalarColor3f(1.0)))
            self.glass_reflect = mi.Color3f(props.get("glass_reflect", mi.ScalarColor3f(1.0)))
            self.glass_ior = float(props.get("glass_ior", 1.5))
            self.glass_thin = bool(props.get("glass_thin", False))
            flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide,
                                 mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide]
            if self.glass > 0:
                flags = flags | mi.BSDFFlags.GlossyTransmission
                self.m_components.append(mi.BSDFFlags.GlossyTransmission | mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide)
            self.m_flags = flags

        @staticmethod
        def _lambda(w, alpha):
            """Smith Lambda of GGX for a local direction w (cos > 0)."""
            c2 = dr.square(w.z)
            t2 = dr.maximum(1.0 - c2, 0.0) / dr.maximum(c2, 1e-12)
            return 0.5 * (dr.sqrt(1.0 + alpha * alpha * t2) - 1.0)

        @staticmethod
        def _beckmann_d(h, alpha):
            """exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4) of a local half vector h (0 below the surface)."""
            c2 = dr.maximum(dr.square(h.z), 1e-18)  # c2^2 stays a normal float32
            a2 = alpha * alpha
            d = dr.exp(-dr.maximum(1.0 - c2, 0.0) / (c2 * a2)) / (math.pi * a2 * c2 * c2)
            return dr.select(h.z > 0, d, 0.0)

        @staticmethod
        def _beckmann_lambda(w, alpha):
            """Smith Lambda of Beckmann in Walter et al.'s rational form (spec/renderer.md#materials)."""
            c = dr.clip(dr.abs(w.z), 1e-6, 1.0)
            a = c / (alpha * dr.sqrt(dr.maximum(1.0 - c * c, 1e-12)))
            return dr.select(a < 1.6, (1.0 - 1.259 * a + 0.396 * a * a) / (3.535 * a + 2.181 * a * a), 0.0)

        @staticmethod
        def _beckmann_sample(alpha, u):
            """A local half vector of density D(h) cos_h."""
            t2 = -alpha * alpha * dr.log(dr.maximum(1.0 - u.x, 1e-7))
            c = dr.rsqrt(1.0 + t2)
            s = dr.sqrt(dr.maximum(1.0 - c * c, 0.0))
            sp, cp = dr.sincos(2.0 * math.pi * u.y)
            return mi.Vector3f(s * cp, s * sp, c)

        def _side(self, si, active):
            """(kd, f0, alpha, GGX distribution, active, Beckmann mask) of the side of hit si the viewer is on: a
            one-sided back leaves no lane active, a back material's parameters on the back (spec/renderer.md#sidedness)."""
            kd, f0, alpha = self.kd, self.f0, mi.Float(self.alpha)
            beckmann = mi.Bool(self.beckmann)
            if self.per_hit is not None:  # textures, primvar colours (nasset_mitsuba_plugin.textures)
                kd, f0, alpha = self.per_hit.material(si, active)
            if self.one_sided or self.has_back:
                back = dr.dot(si.n, si.to_world(si.wi)) * self.front_sign < 0
                if self.one_sided:
                    active = active & ~back
                else:
                    kd, f0 = dr.select(back, self.back_kd, kd), dr.select(back, self.back_f0, f0)
                    alpha = dr.select(back, self.back_alpha, alpha)
                    beckmann = dr.select(back, self.back_beckmann, beckmann)
            return kd, f0, alpha, mi.MicrofacetDistribution(mi.MicrofacetType.GGX, alpha, True), active, beckmann

        def _eval_pdf(self, wi, wo, active, side):
            """(f cos_o [Color3f], pdf) with wi (camera side) and wo (light side) in the shading frame (:meth:`_frame`),
            with the parameters ``side`` of :meth:`_side`."""
            kd, f0, alpha, ggx, side_active, beckmann = side
            ok = active & side_active & (wi.z > 0) & (wo.z > 0)
            h = dr.normalize(wi + wo)
            d = ggx.eval(h)
            l_i, l_o = self._lambda(wi, alpha), self._lambda(wo, alpha)
            if self.has_beckmann:
                d = dr.select(beckmann, self._beckmann_d(h, alpha), d)
                l_i = dr.select(beckmann, self._beckmann_lambda(wi, alpha), l_i)
                l_o = dr.select(beckmann, self._beckmann_lambda(wo, alpha), l_o)
            g2 = dr.rcp(1.0 + l_i + l_o)
            f = f0 + (1.0 - f0) * dr.power(dr.maximum(1.0 - dr.dot(wi, h), 0.0), 5.0)
            spec = d * g2 * f / dr.maximum(4.0 * wi.z * wo.z, 1e-12)
            value = (kd * (1.0 / math.pi) + spec) * wo.z
            # visible-normal density D_wi(h) = G1(wi) max(0, wi.h) D(h) / cos_i, times the reflection Jacobian 1 / (4 wo.h)
            g1 = dr.rcp(1.0 + self._lambda(wi, alpha))
            pdf_spec = g1 * dr.maximum(dr.dot(wi, h), 0.0) * d / dr.maximum(wi.z, 1e-12) / dr.maximum(4.0 * dr.abs(dr.dot(wo, h)), 1e-12)
            if self.has_beckmann:  # Beckmann's half vectors have density D(h) cos_h
                pdf_spec = dr.select(beckmann, d * dr.maximum(h.z, 0.0) / dr.maximum(4.0 * dr.abs(dr.dot(wi, h)), 1e-12),
                                     pdf_spec)
            pdf = P_SPECULAR * pdf_spec + (1.0 - P_SPECULAR) * wo.z * (1.0 / math.pi)
            return dr.select(ok, value, 0.0), dr.select(ok, pdf, 0.0)

        def _reflectance(self, c, eta):
            """The glass lobe's reflectance at wi.h: F, or a thin wall's 2 F / (1 + F)."""
            f = fresnel(c, eta)
            return 2.0 * f / (1.0 + f) if self.glass_thin else f

        def _eta(self, si):
            """IOR across the surface from the viewer's side: the material's from its front, else the inverse."""
            outside = dr.dot(si.n, si.to_world(si.wi)) * self.front_sign > 0
            return dr.select(outside | self.glass_thin, self.glass_ior, 1.0 / self.glass_ior)

        def _glass_eval_pdf(self, wi, wo, eta, alpha, ggx, active):
            """(f |cos_o| [Color3f], pdf) of the glass lobe, wi the viewer's direction (wi.z > 0) and wo the light's
            in the shading frame (as reference_renderer.bsdf.glass_eval)."""
            up = wo.z > 0
            g2 = dr.rcp(1.0 + self._lambda(wi, alpha) + self._lambda(wo, alpha))
            g1 = dr.rcp(1.0 + self._lambda(wi, alpha))
            cos_i = dr.maximum(wi.z, 1e-12)
            wr = dr.select(up, wo, mi.Vector3f(wo.x, wo.y, -wo.z))  # the thin wall's transmission: mirrored
            hr = dr.normalize(wi + wr)
            c_r = dr.dot(wi, hr)
            fr = self._reflectance(c_r, eta)
            w_r = dr.select(up, fr, 1.0 - fr)
            d_r = ggx.eval(hr)
            f_r = w_r * d_r * g2 / (4.0 * cos_i)  # times |cos_o| / cos_o
            p_r = w_r * g1 * d_r / (4.0 * cos_i)
            ok_r = (up | self.glass_thin) & (c_r > 0)
            ht = wi + eta * wo
            ht = dr.normalize(dr.select(ht.z < 0, -ht, ht))
            c_i, c_o = dr.dot(wi, ht), dr.dot(wo, ht)
            den = dr.maximum(dr.square(c_i + eta * c_o), 1e-12)
            ft = 1.0 - fresnel(dr.maximum(c_i, 0.0), eta)
            d_t = ggx.eval(ht)
            f_t = ft * d_t * g2 * dr.abs(c_o) * dr.abs(c_i) / (cos_i * den)
            p_t = ft * g1 * d_t * dr.maximum(c_i, 0.0) / cos_i * eta * eta * dr.abs(c_o) / den
            ok_t = ~up & (not self.glass_thin) & (c_i > 0) & (c_o < 0)
            value = dr.select(ok_r, f_r, dr.select(ok_t, f_t, 0.0)) * dr.select(up, self.glass_reflect, self.glass_tint)
            pdf = dr.select(ok_r, p_r, dr.select(ok_t, p_t, 0.0))
            return dr.select(active, value, 0.0), dr.select(active, pdf, 0.0)

        def _mixed_eval_pdf(self, si, frame, ng, wi, w, active, side):
            """(value, pdf) at world direction w: the opaque lobes, and with a glass weight t ``(1 - t)`` of them plus
            ``t`` glass (transmission below the surface, where both normals agree)."""
            wl = frame.to_local(w)
            above = dr.dot(w, ng) > 0
            value, pdf = self._eval_pdf(wi, wl, active & above, side)
            if self.glass <= 0:
                return value, pdf
            consistent = dr.select(above, wl.z > 0, wl.z < 0) & side[4]
            gv, gp = self._glass_eval_pdf(wi, wl, self._eta(si), side[2], side[3], active & consistent)
            t = self.glass
            return (1.0 - t) * value + t * gv, (1.0 - t) * pdf + t * gp

        def _frame(self, si, active):
            """(shading frame, geometric normal flipped toward the viewer [world], the viewer's direction in the frame,
            the interpolated normal flipped alike under a normal map, else None: the terminator term's reference)."""
            wo_w = si.to_world(si.wi)
            ng = dr.select(dr.dot(si.n, wo_w) < 0, -si.n, si.n)
            if not self.normals and self.normal_map is None:
                return mi.Frame3f(ng), ng, mi.Frame3f(ng).to_local(wo_w), None
            # the interpolated normal on the front side (the triangle's own without normals), not yet flipped
            n = dr.normalize(si.shape.eval_attribute_3(self.normals, si, active)) if self.normals else si.n * self.front_sign
            smooth = None
            if self.normal_map is not None:
                smooth, n = n, self._mapped(si, n, active)
            sign = dr.dot(si.n, wo_w) * self.front_sign  # flipped with ng (of the front side)
            ns = dr.mulsign(n, sign)
            frame = mi.Frame3f(dr.select(dr.dot(ns, wo_w) > 1e-6, ns, ng))  # also ng where ns is NaN (a zero sum)
            if smooth is not None:
                smooth = dr.mulsign(smooth, sign)
                smooth = dr.select(dr.all(dr.isfinite(smooth)), smooth, frame.n)
            return frame, ng, frame.to_local(wo_w), smooth

        def _mapped(self, si, n, active):
            """The normal map's normal (spec/renderer.md#normal-maps): its texel (x, y, z) in the frame T = dP/ds made
            orthogonal to ``n``, B = n x T, n; T any tangent where the triangle's st are degenerate; ``n`` where the
            result is zero or not finite."""
            v = self.normal_map.eval(si.uv.x, si.uv.y, active)
            dpds = si.dp_du
            tan = dpds - n * dr.dot(n, dpds)
            length = dr.norm(tan)
            ok = dr.isfinite(length) & (length > 1e-12 * dr.norm(dpds))
            tan = dr.select(ok, tan / dr.select(ok, length, 1.0), mi.Frame3f(n).s)
            turned = tan * v.x + dr.cross(n, tan) * v.y + n * v.z
            size = dr.norm(turned)
            good = dr.isfinite(size) & (size > 1e-12)
            return dr.select(good, turned / dr.select(good, size, 1.0), n)

        @staticmethod
        def _terminator(smooth, mapped, w):
            """Estevez et al.'s bump-terminator shadowing (Mitsuba's normalmap, spec/renderer.md#normal-maps) at world
            direction ``w``: a GGX masking term with alpha^2 = min(tan^2(theta_d) / 8, 1), theta_d the angle between the
            interpolated normal ``smooth`` and ``mapped``; 0 at or below ``smooth``'s horizon; 1 without a map."""
            if smooth is None:
                return 1.0
            cos_d = dr.minimum(dr.abs(dr.dot(smooth, mapped)), 1.0)
            alpha2 = dr.minimum(0.125 * (1.0 - cos_d * cos_d) / dr.maximum(cos_d * cos_d, 1e-30), 1.0)
            cos_i = dr.dot(smooth, w)
            c2 = dr.maximum(cos_i * cos_i, 1e-30)
            return dr.select(cos_i > 1e-6, 2.0 / (1.0 + dr.sqrt(1.0 + alpha2 * (1.0 - c2) / c2)), 0.0)

        def eval(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self.eval_pdf(ctx, si, wo, active)[1]

        def _terminator_above(self, smooth, n, w, ng):
            """:meth:`_terminator` for directions above the surface; 1 for transmitted ones."""
            if smooth is None:
                return 1.0
            return dr.select(dr.dot(w, ng) > 0, self._terminator(smooth, n, w), 1.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            frame, ng, wi, smooth = self._frame(si, active)
            w = si.to_world(wo)
            value, pdf = self._mixed_eval_pdf(si, frame, ng, wi, w, active, self._side(si, active))
            return value * self._terminator_above(smooth, frame.n, w, ng), pdf

        def sample(self, ctx, si, sample1, sample2, active=True):
            frame, ng, wi, smooth = self._frame(si, active)
            side = self._side(si, active)
            t = self.glass
            through = mi.Bool(False)
            valid = mi.Bool(True)
            u = sample1
            if t > 0:  # sample1 < t: the glass lobe (sample1 / t picks reflection or transmission), else the rest
                through = sample1 < t
                u = dr.select(through, sample1 / t, (sample1 - t) / max(1.0 - t, 1e-12))
            spec = (u < P_SPECULAR) & ~through
            m, _ = side[3].sample(wi, sample2)  # GGX's visible normals: the glass lobe's always
            m_spec = dr.select(side[5], self._beckmann_sample(side[2], sample2), m) if self.has_beckmann else m
            w_spec = mi.reflect(wi, m_spec)
            w_glass = mi.reflect(wi, m)
            w_diff = mi.warp.square_to_cosine_hemisphere(sample2)
            wl = dr.select(through, w_glass, dr.select(spec, w_spec, w_diff))
            if t > 0:
                eta = self._eta(si)
                keep = u < self._reflectance(dr.dot(wi, m), eta)
                if self.glass_thin:
                    passed = mi.Vector3f(w_glass.x, w_glass.y, -w_glass.z)
                else:
                    passed = _refract(wi, m, eta)
                wl = dr.select(through & ~keep, passed, wl)
                # an opaque sample below the surface (whose glass lobe has a density there) is no sample either
                valid = dr.select(through, dr.select(keep | self.glass_thin, w_glass.z > 0, wl.z < 0), wl.z > 0)
            w_world = frame.to_world(wl)
            value, pdf = self._mixed_eval_pdf(si, frame, ng, wi, w_world, active, side)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = si.to_local(w_world)
            bs.pdf = pdf
            bs.eta = 1.0
            kind = dr.select(wl.z < 0, mi.UInt32(+mi.BSDFFlags.GlossyTransmission), mi.UInt32(+mi.BSDFFlags.GlossyReflection))
            bs.sampled_type = mi.UInt32(dr.select(spec | through, kind, mi.UInt32(+mi.BSDFFlags.DiffuseReflection)))
            bs.sampled_component = dr.select(through & (wl.z < 0), mi.UInt32(2), dr.select(spec | through, mi.UInt32(1), mi.UInt32(0)))
            ok = active & valid & (pdf > 0)
            bs.pdf = dr.select(ok, pdf, 0.0)
            return bs, dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0) * self._terminator_above(smooth, frame.n, w_world, ng)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"NassetPreviewBSDF[alpha={self.alpha}]"

    def _refract(wi, m, eta):
        """wi refracted about microfacet normal m into a medium of relative IOR eta (wi outside; undefined under
        total internal reflection, whose reflectance is 1), as reference_renderer.bsdf.refract."""
        c = dr.dot(wi, m)
        cos_t = dr.sqrt(dr.maximum(1.0 - (1.0 - c * c) / (eta * eta), 0.0))
        return dr.normalize(-wi / eta + (c / eta - cos_t) * m)

    mi.register_bsdf(NAME, lambda props: PreviewBSDF(props))
    _REGISTERED.add(mi.variant())
