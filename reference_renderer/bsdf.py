"""UsdPreviewSurface as a BSDF: Lambert diffuse + GGX (Trowbridge-Reitz) microfacet specular.

Model (spec/renderer.md#materials), in a local frame where the shading normal is +Z:

    f(wo, wi) = kd / pi + D(h) G2(wo, wi) F(wo.h) / (4 cos_o cos_i)

kd = diffuseColor * (1 - metallic); F is Schlick with F0 = specularColor (specular workflow)
or lerp(((1-ior)/(1+ior))^2, diffuseColor, metallic); alpha = max(roughness^2, 1e-3);
G2 is the height-correlated Smith term. Both sides of a surface are front faces unless the prim is
one-sided (spec/renderer.md#sidedness, handled by the integrator).
Specular directions are drawn from the distribution of visible normals (Heitz 2018). A material whose shader
says ``nasset:microfacet = beckmann`` has a Beckmann D and Smith G2 in the lobe instead (its glass lobe stays
GGX), its half vectors drawn with density D(h) cos_h.

A material with a transmission weight t (MaterialX ``transmission``, spec/renderer.md#transmission) is
``(1 - t) f + t f_glass``: a dielectric of relative IOR eta with the same GGX alpha and the exact Fresnel
reflectance F, reflecting F times the specular colour and transmitting (1 - F) times the transmission colour. A solid one refracts
(Walter et al. 2007, radiance form: no eta^2 factor); a thin-walled one lets the light through unbent, its
transmitted lobe the reflected one mirrored through the surface, with the reflectance of a slab
R = 2 F / (1 + F) (every internal bounce summed, Mitsuba's thindielectric).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nasset_sdk.kinds.boundary import fresnel_dielectric

from .sampling import (
    INV_PI,
    cosine_hemisphere_pdf,
    dot,
    luminance,
    normalize,
    square_to_cosine_hemisphere,
)

MIN_ALPHA = 1e-3


# -- GGX ------------------------------------------------------------------------------------
def ggx_d(h, alpha):
    a2 = alpha * alpha
    c2 = h[:, 2] ** 2
    den = np.pi * (c2 * (a2 - 1.0) + 1.0) ** 2
    return np.where(h[:, 2] > 0, a2 / np.maximum(den, 1e-300), 0.0)


def ggx_lambda(w, alpha):
    c2 = np.maximum(w[:, 2] ** 2, 1e-300)
    t2 = np.maximum(1.0 - c2, 0.0) / c2
    return 0.5 * (-1.0 + np.sqrt(1.0 + alpha * alpha * t2))


def ggx_g1(w, alpha):
    return 1.0 / (1.0 + ggx_lambda(w, alpha))


def ggx_sample_vndf(wo, alpha, u):
    """Half vectors distributed as D_wo(h) = G1(wo) max(0, wo.h) D(h) / cos_o (Heitz 2018)."""
    vh = normalize(np.stack([alpha * wo[:, 0], alpha * wo[:, 1], wo[:, 2]], 1))
    lensq = vh[:, 0] ** 2 + vh[:, 1] ** 2
    inv = np.where(lensq > 0, 1.0 / np.sqrt(np.maximum(lensq, 1e-300)), 0.0)
    t1 = np.where((lensq > 0)[:, None], np.stack([-vh[:, 1] * inv, vh[:, 0] * inv, np.zeros_like(inv)], 1),
                  np.array([1.0, 0.0, 0.0]))
    t2 = np.cross(vh, t1)
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    p1 = r * np.cos(phi)
    p2 = r * np.sin(phi)
    s = 0.5 * (1.0 + vh[:, 2])
    p2 = (1.0 - s) * np.sqrt(np.maximum(0.0, 1.0 - p1 * p1)) + s * p2
    nh = p1[:, None] * t1 + p2[:, None] * t2 + np.sqrt(np.maximum(0.0, 1.0 - p1 * p1 - p2 * p2))[:, None] * vh
    return normalize(np.stack([alpha * nh[:, 0], alpha * nh[:, 1], np.maximum(1e-9, nh[:, 2])], 1))


def ggx_reflect_pdf(wo, wi, alpha):
    """Solid-angle pdf of wi = reflect(wo, h) with h ~ VNDF(wo)."""
    h = normalize(wo + wi)
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    pdf = ggx_g1(wo, alpha) * ggx_d(h, alpha) / (4.0 * np.maximum(wo[:, 2], 1e-300))
    return np.where(ok, pdf, 0.0)


# -- Beckmann (a material's nasset:microfacet = beckmann; spec/renderer.md#materials) ----------------------------


def beckmann_d(h, alpha):
    """exp(-tan^2 / alpha^2) / (pi alpha^2 cos^4) of half vectors h [N,3] (0 below the surface)."""
    c2 = np.maximum(h[:, 2] ** 2, 1e-150)  # c2^2 stays a normal number
    t2 = np.maximum(1.0 - c2, 0.0) / c2
    a2 = alpha * alpha
    return np.where(h[:, 2] > 0, np.exp(-t2 / a2) / (np.pi * a2 * c2 * c2), 0.0)


def beckmann_lambda(w, alpha):
    """Smith's Lambda of the Beckmann distribution in Walter et al.'s (2007) rational form (as Cycles and Mitsuba
    evaluate it): a = cos / (alpha sin); (1 - 1.259 a + 0.396 a^2) / (3.535 a + 2.181 a^2) for a < 1.6, else 0."""
    c = np.abs(w[:, 2])
    s = np.sqrt(np.maximum(1.0 - c * c, 0.0))
    a = c / np.maximum(alpha * s, 1e-300)
    rational = (1.0 - 1.259 * a + 0.396 * a * a) / np.maximum(3.535 * a + 2.181 * a * a, 1e-300)
    return np.where(a < 1.6, rational, 0.0)


def beckmann_sample(alpha, u):
    """Half vectors [N,3] with density D(h) cos_h (tan^2 = -alpha^2 log(1 - u0), phi = 2 pi u1)."""
    t2 = -(alpha * alpha) * np.log1p(-np.minimum(u[:, 0], 1.0 - 1e-16))
    c = 1.0 / np.sqrt(1.0 + t2)
    s = np.sqrt(np.maximum(1.0 - c * c, 0.0))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([s * np.cos(phi), s * np.sin(phi), c], 1)


def beckmann_reflect_pdf(wo, wi, alpha):
    """Solid-angle pdf of wi = reflect(wo, h) with h of density D(h) cos_h: D cos_h / (4 wo.h)."""
    h = normalize(wo + wi)
    ok = (wi[:, 2] > 0) & (wo[:, 2] > 0)
    pdf = beckmann_d(h, alpha) * h[:, 2] / (4.0 * np.maximum(dot(wo, h), 1e-300))
    return np.where(ok, pdf, 0.0)


def microfacet_terms(wo, wi, h, alpha, beckmann):
    """(D(h) [N], height-correlated G2 [N], reflection pdf of wi [N]) of the GGX lobe, or of Beckmann's on rows
    where ``beckmann`` [N] bool (None: none)."""
    d = ggx_d(h, alpha)
    g2 = 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))
    pdf = ggx_reflect_pdf(wo, wi, alpha)
    if beckmann is not None and beckmann.any():
        b = beckmann
        alpha = np.broadcast_to(alpha, b.shape)
        d[b] = beckmann_d(h[b], alpha[b])
        g2[b] = 1.0 / (1.0 + beckmann_lambda(wo[b], alpha[b]) + beckmann_lambda(wi[b], alpha[b]))
        pdf[b] = beckmann_reflect_pdf(wo[b], wi[b], alpha[b])
    return d, g2, pdf


def reflect(w, h):
    return 2.0 * dot(w, h)[:, None] * h - w


def mirror_z(w):
    """w [N,3] mirrored through the local tangent plane (z negated)."""
    return w * np.array([1.0, 1.0, -1.0])


def refract(wo, h, eta):
    """Direction [N,3] refracted from wo about microfacet normal h [N,3] into a medium of relative IOR eta [N]
    (n_inside / n_outside, wo outside); rows under total internal reflection are undefined (their F is 1)."""
    c = dot(wo, h)
    cos_t = np.sqrt(np.maximum(1.0 - (1.0 - c * c) / (eta * eta), 0.0))
    return normalize(-wo / eta[:, None] + (c / eta - cos_t)[:, None] * h)


def glass_reflectance(cos_oh, eta, thin):
    """Reflectance [N] of the glass lobe at wo.h: exact dielectric Fresnel F (1 under total internal reflection),
    or for a thin wall the slab's 2 F / (1 + F)."""
    f = fresnel_dielectric(cos_oh, eta)
    return np.where(thin, 2.0 * f / (1.0 + f), f)


def glass_eval(wo, wi, alpha, eta, thin, tint, reflect_tint=None):
    """f(wo, wi) [N,3] (cosine not included) and pdf [N] of the glass lobe in the local frame (wo.z > 0).

    ``eta`` [N]: IOR of the side wo is not on over the side it is on; ``thin`` [N] bool; ``tint`` [N,3] the
    transmission colour, ``reflect_tint`` [N,3] the reflection's (None: white). Reflection for wi.z > 0; below,
    refraction (solid) or the mirrored reflection lobe (thin). The tints do not change the pdf."""
    up = wi[:, 2] > 0
    cos_o = np.maximum(wo[:, 2], 1e-300)
    cos_i = np.maximum(np.abs(wi[:, 2]), 1e-300)
    g2 = 1.0 / (1.0 + ggx_lambda(wo, alpha) + ggx_lambda(wi, alpha))
    g1 = ggx_g1(wo, alpha)
    # reflection, and the thin wall's transmission (its mirrored twin): h = normalize(wo + wi') with wi' above
    wr = np.where(up[:, None], wi, mirror_z(wi))
    hr = normalize(wo + wr)
    cos_ohr = dot(wo, hr)
    fr = glass_reflectance(np.clip(cos_ohr, 0.0, 1.0), eta, thin)
    w_r = np.where(up, fr, 1.0 - fr)
    dr = ggx_d(hr, alpha)
    f_r = w_r * dr * g2 / (4.0 * cos_o * cos_i)
    p_r = w_r * g1 * dr / (4.0 * cos_o)
    ok_r = (up | thin) & (cos_ohr > 0)
    # solid refraction: h = -normalize(wo + eta wi) turned up; wo.h > 0 > wi.h
    ht = wo + eta[:, None] * wi
    ht = normalize(np.where((ht[:, 2] < 0)[:, None], -ht, ht))
    c_o, c_i = dot(wo, ht), dot(wi, ht)
    den = (c_o + eta * c_i) ** 2
    ft = 1.0 - fresnel_dielectric(np.clip(c_o, 0.0, 1.0), eta)
    dt = ggx_d(ht, alpha)
    f_t = ft * dt * g2 * np.abs(c_i) * np.abs(c_o) / (cos_o * cos_i * np.maximum(den, 1e-300))
    p_t = ft * g1 * dt * np.maximum(c_o, 0.0) / cos_o * eta * eta * np.abs(c_i) / np.maximum(den, 1e-300)
    ok_t = ~up & ~thin & (c_o > 0) & (c_i < 0) & (den > 0)
    f = np.where(ok_r, f_r, np.where(ok_t, f_t, 0.0))
    pdf = np.where(ok_r, p_r, np.where(ok_t, p_t, 0.0))
    f = f[:, None] * np.where(up[:, None], 1.0 if reflect_tint is None else reflect_tint, tint)
    return f, pdf


def glass_sample(wo, alpha, eta, thin, u_lobe, u):
    """(wi [N,3], valid [N]) of the glass lobe: h ~ VNDF(wo), reflected with probability R(wo.h), else refracted
    (solid) or reflected and mirrored through the surface (thin). A reflection below the surface, or a transmission
    above it, is not valid (its density is not the lobe's pdf there)."""
    h = ggx_sample_vndf(wo, alpha, u)
    r = reflect(wo, h)
    keep = u_lobe < glass_reflectance(np.clip(dot(wo, h), 0.0, 1.0), eta, thin)
    through = np.where(thin[:, None], mirror_z(r), refract(wo, h, eta))
    wi = np.where(keep[:, None], r, through)
    return wi, np.where(keep | thin, r[:, 2] > 0, wi[:, 2] < 0)


# -- material table -------------------------------------------------------------------------
def spec_probability(kd: np.ndarray, f0: np.ndarray) -> np.ndarray:
    """Probability [N] of sampling the specular lobe for diffuse colours kd [N,3] and F0 [N,3]."""
    sd = luminance(kd)
    ss = luminance(f0 + (1.0 - f0) * 0.1)
    ss = np.where(f0.max(-1) > 0, ss, 0.0)
    tot = sd + ss
    p = np.where(tot > 0, ss / np.where(tot > 0, tot, 1.0), 0.0)
    both = (sd > 0) & (ss > 0)
    return np.where(both, np.clip(p, 0.1, 0.9), p)


@dataclass
class MaterialTable:
    """Per-material constants, indexed by material id; ``textures[m]`` (a
    :class:`~nasset_reference_renderer.textures.TexturedMaterial` or None) replaces kd, F0 and alpha per hit."""

    kd: np.ndarray  # [M,3]
    f0: np.ndarray  # [M,3]
    alpha: np.ndarray  # [M]
    emission: np.ndarray  # [M,3]
    names: list
    textures: list = field(default_factory=list)  # [M] TexturedMaterial | None (empty: none textured)
    opacities: list = field(default_factory=list)  # [M] textures.Opacity | None (empty: every material opaque)
    emission_textures: list = field(default_factory=list)  # [M] textures.ImageTexture | None: emission per hit
    transmission: np.ndarray | None = None  # [M] glass weight t in [0, 1] (None: no material transmits)
    transmission_color: np.ndarray | None = None  # [M,3] tint of the transmitted light
    eta: np.ndarray | None = None  # [M] IOR of the glass lobe (inside over outside)
    thin: np.ndarray | None = None  # [M] bool: thin-walled (unbent transmission)
    reflection_color: np.ndarray | None = None  # [M,3] tint of the glass lobe's reflection (MaterialX specular_color)
    beckmann: np.ndarray | None = None  # [M] bool: the specular lobe's distribution is Beckmann's (None: all GGX)

    @property
    def transmits(self) -> bool:
        return self.transmission is not None and bool((self.transmission > 0).any())

    def glass(self, m: np.ndarray, outside: np.ndarray):
        """(t [N], tint [N,3], eta [N], thin [N], reflection tint [N,3]) of materials m [N] seen from ``outside``
        [N] bool (the front of the surface: eta is the material's, else its inverse; a thin wall's is the
        material's), None where no material transmits."""
        if not self.transmits:
            return None
        eta = self.eta[m]
        thin = self.thin[m]
        return (self.transmission[m], self.transmission_color[m], np.where(outside | thin, eta, 1.0 / eta), thin,
                self.reflection_color[m])

    def emission_at(self, m: np.ndarray, st: np.ndarray | None) -> np.ndarray:
        """Emitted radiance [N,3] of materials m [N] at texture coordinates st [N,2] (their constant where untextured;
        a texture's value clamped to >= 0)."""
        out = self.emission[m].copy()
        if st is None:
            return out
        for k, tex in enumerate(self.emission_textures):
            if tex is not None and (sel := m == k).any():
                out[sel] = np.maximum(tex.sample(st[sel]), 0.0)
        return out

    @property
    def p_spec(self) -> np.ndarray:
        """Probability of sampling the specular lobe."""
        return spec_probability(self.kd, self.f0)

    def has_specular(self, m):
        return self.f0[m].max(-1) > 0

    def opacity_of(self, m: int):
        """The presence (textures.Opacity) of material ``m``, None where it is opaque."""
        return self.opacities[m] if m < len(self.opacities) else None

    @property
    def textured(self) -> bool:
        return any(t is not None for t in self.textures)

    def lookup(self, m: np.ndarray, st: np.ndarray, colors: np.ndarray | None = None):
        """(kd [N,3], F0 [N,3], alpha [N]) of materials m [N] at texture coordinates st [N,2] and primvar colours
        ``colors`` [N,3] (for materials whose diffuse colour is a primvar; constants where untextured)."""
        kd, f0, alpha = self.kd[m].copy(), self.f0[m].copy(), self.alpha[m].copy()
        for k, tex in enumerate(self.textures):
            if tex is None:
                continue
            sel = m == k
            if sel.any():
                kd[sel], f0[sel], alpha[sel] = tex.lookup(st[sel], None if colors is None else colors[sel])
        return kd, f0, alpha


def bsdf_eval(mt: MaterialTable, m, wo, wi, kd=None, f0=None, alpha=None, glass=None):
    """f(wo, wi) [N,3] and pdf(wi) [N] for local-frame directions (normal = +Z, wo.z > 0; wi below the surface
    counts only through ``glass``).

    ``kd``, ``f0`` [N,3] and ``alpha`` [N] override the materials' constants (textured materials,
    :meth:`MaterialTable.lookup`); ``glass``: :meth:`MaterialTable.glass` of the rows, None where no material
    transmits.
    """
    kd = mt.kd[m] if kd is None else kd
    f0 = mt.f0[m] if f0 is None else f0
    alpha = mt.alpha[m] if alpha is None else alpha
    ps = spec_probability(kd, f0)
    ok = (wo[:, 2] > 0) & (wi[:, 2] > 0)
    h = normalize(wo + wi)
    d, g2, spec_pdf = microfacet_terms(wo, wi, h, alpha, None if mt.beckmann is None else mt.beckmann[m])
    cos_oh = np.clip(dot(wo, h), 0.0, 1.0)
    fres = f0 + (1.0 - f0) * ((1.0 - cos_oh) ** 5)[:, None]
    den = 4.0 * np.maximum(wo[:, 2] * wi[:, 2], 1e-300)
    f = kd * INV_PI + fres * (d * g2 / den)[:, None]
    f = np.where(ok[:, None], f, 0.0)
    pdf = np.where(ok, (1.0 - ps) * cosine_hemisphere_pdf(wi) + ps * spec_pdf, 0.0)
    if glass is None:
        return f, pdf
    t, tint, eta, thin, reflect_tint = glass
    fg, pg = glass_eval(wo, wi, alpha, eta, thin, tint, reflect_tint)
    return (1.0 - t)[:, None] * f + t[:, None] * fg, (1.0 - t) * pdf + t * pg


def bsdf_sample(mt: MaterialTable, m, wo, u_lobe, u, kd=None, f0=None, alpha=None, glass=None):
    """Sample wi: returns (wi [N,3], f [N,3], pdf [N]); pdf 0 marks a failed sample (``kd``, ``f0``, ``alpha``,
    ``glass`` as in bsdf_eval). The glass lobe is drawn with probability t."""
    kd = mt.kd[m] if kd is None else kd
    f0 = mt.f0[m] if f0 is None else f0
    alpha = mt.alpha[m] if alpha is None else alpha
    u_lobe = np.asarray(u_lobe, np.float64)
    through = np.zeros(len(u_lobe), bool)
    if glass is not None:  # u_lobe < t: the glass lobe (u_lobe / t chooses within it), else the rest, rescaled
        t = glass[0]
        through = u_lobe < t
        u_lobe = np.where(through, u_lobe / np.maximum(t, 1e-300), (u_lobe - t) / np.maximum(1.0 - t, 1e-300))
    ps = spec_probability(kd, f0)
    spec = (u_lobe < ps) & ~through
    wi = square_to_cosine_hemisphere(u)
    if spec.any():
        h = ggx_sample_vndf(wo[spec], alpha[spec], u[spec])
        if mt.beckmann is not None and (b := mt.beckmann[m][spec]).any():
            h[b] = beckmann_sample(alpha[spec][b], u[spec][b])
        wi[spec] = reflect(wo[spec], h)
    # an opaque sample below the surface is no sample (the glass lobe has a density there that did not draw it)
    valid = wi[:, 2] > 0 if glass is not None else np.ones(len(u_lobe), bool)
    if through.any():
        _, _, eta, thin, _ = glass
        wi[through], valid[through] = glass_sample(wo[through], alpha[through], eta[through], thin[through],
                                                   u_lobe[through], u[through])
    f, pdf = bsdf_eval(mt, m, wo, wi, kd, f0, alpha, glass)
    return wi, np.where(valid[:, None], f, 0.0), np.where(valid, pdf, 0.0)
