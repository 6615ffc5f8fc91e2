"""Shading vertex of rna surface assets (spec/renderer.md#neural-assets).

Transport T is evaluated at the hit; the light-sample rows pick T_shadowed or T_unshadowed by whether
the asset itself blocks the direction, and the continuation carries both until its ray is traced. Assets with a
near-field fetch f > 0 take their incident light at the fetch point p = x + f (c_w - x) instead
(spec/kinds/rna.md#near-field-fetch): light samples drawn at p, other objects looked for by rays from p, the
branch chosen by rays from x along the same directions (one more query per light sample and continuation).
Scenes holding only rna assets shade every rna surface instance in one call
(:class:`nasset_reference_renderer.shaders.NeuralShading`).
"""

from __future__ import annotations

import time

import numpy as np

from ..sampling import (
    INV_4PI,
    INV_PI,
    Z_AXIS,
    around,
    dot,
    normalize,
    power_heuristic,
    sample_mixture,
    square_to_cosine_hemisphere,
    square_to_uniform_sphere,
    square_to_vmf,
    unit_or,
    vmf_pdf,
)
from ..shadow import aim_shadow
from .common import Frames, max3, unique
from .registry import register_shader

#: the surface continuation's mixture weights: uniform sphere, cosine lobe about the normal on wo's side, mirror
#: lobe (:class:`SurfaceContinuation`). Chosen on the built-in rna example and the high-albedo pebble (300 camera
#: hits each, T on 4096 directions): the variance of T / pdf is 4.7x and 3.2x lower than the uniform sphere's
#: (second moments 0.32 against 0.89 and 0.94 against 1.52; sampling proportional to T: 0.17 and 0.70)
SURFACE_CONT_MIX = (0.4, 0.2, 0.4)
#: the mirror lobe's von Mises-Fisher concentration
MIRROR_KAPPA = 6.0


class SurfaceContinuation:
    """Continuation directions of rna surface hits (spec/renderer.md#neural-assets): a defensive mixture, per
    world steradian, of the uniform sphere, a cosine lobe about the shading normal on wo's side and a von
    Mises-Fisher lobe about the mirror direction of wo (most assets reflect most of their light near it: a
    glossy boundary, a rough surface). Density >= SURFACE_CONT_MIX[0] / 4pi everywhere.

    ``wo``, ``n`` [n,3]: unit world directions toward the viewer and shading normals, one row per hit."""

    def __init__(self, wo: np.ndarray, n: np.ndarray) -> None:
        n = unit_or(unit_or(n, wo), Z_AXIS)  # no normal (a degenerate one): lobes about wo, or +z without either
        self.n = np.where((dot(n, wo) < 0)[:, None], -n, n)
        self.mirror = unit_or(normalize(2.0 * dot(wo, self.n)[:, None] * self.n - wo), self.n)  # n for a zero wo

    def sample(self, rows: np.ndarray, u: np.ndarray) -> np.ndarray:
        n, mirror = self.n[rows], self.mirror[rows]
        return sample_mixture(SURFACE_CONT_MIX, u, (
            lambda m, u2: square_to_uniform_sphere(u2),
            lambda m, u2: around(n[m], square_to_cosine_hemisphere(u2)),
            lambda m, u2: around(mirror[m], square_to_vmf(u2, MIRROR_KAPPA))))

    def pdf(self, rows: np.ndarray, wi: np.ndarray) -> np.ndarray:
        return (SURFACE_CONT_MIX[0] * INV_4PI + SURFACE_CONT_MIX[1] * np.maximum(dot(wi, self.n[rows]), 0.0) * INV_PI
                + SURFACE_CONT_MIX[2] * vmf_pdf(dot(wi, self.mirror[rows]), MIRROR_KAPPA))


def light_shadows(integ, s, x_s, wi_s, dist_s, inst_s, shadow_origin, fetch):
    """Shadow rays of the light samples ``s`` (rows of the hits, wi_s, dist_s from the point the light was sampled
    at) of neural hits x_s [m,3] on instances inst_s, ignoring the asset. ``shadow_origin(s, wi_s, at) ->
    (origins, exempt or None)`` offsets rays leaving the points ``at``. ``fetch``: None, or (p [n,3], far [n] bool)
    from ``integ.fetch_points`` (n hits, s indexing them): where ``far`` other objects are looked for by rays from
    p, and whether the asset itself lies on the way by the ray from x toward x + wi dist, only its own triangles
    counting (spec/kinds/rna.md#near-field-fetch). Returns (hits of the other objects, self_hit [m] bool)."""
    origin, exempt = shadow_origin(s, wi_s, x_s)
    d_s, tmax = aim_shadow(x_s, origin, wi_s, dist_s, integ.eps)
    if fetch is None:
        h = integ.trace(origin, d_s, tmax, inst_s, exempt)
        return h, h.self_hit
    # other objects from p (its rows: the same offset as from x); the branch from x where f > 0
    p_s, far_s = (fetch[0], fetch[1]) if len(s) == len(fetch[0]) else (fetch[0][s], fetch[1][s])
    o_p, _ = shadow_origin(s, wi_s, p_s)
    d_p, tmax_p = aim_shadow(p_s, o_p, wi_s, dist_s, integ.eps)
    h = integ.trace(o_p, d_p, tmax_p, inst_s, exempt, ~far_s)
    self_hit = h.self_hit
    b = np.nonzero(far_s & (h.prim < 0))[0]  # a blocked sample contributes 0 whatever its branch
    self_hit[b] = integ.passes_own(origin[b], d_s[b], tmax[b], inst_s[b], None if exempt is None else exempt[b])
    return h, self_hit


def rna_sample_rows(integ, x, inst, indirect, rng, shadow_origin, continuation=None, fetch=None):
    """Rows to evaluate at rna hit points x [n,3]: one light sample per NEE light or draw (light_selection; kept when no other object
    blocks it; ``self_hit`` says whether the asset itself does) and one continuation where ``indirect``.
    ``shadow_origin(s, wi_s, at) -> (origins, exempt or None)`` places the shadow rays of rows s leaving the points
    ``at`` [len(s),3] (the hits x[s] or their fetch points); they are aimed at the light sample point
    (:func:`nasset_reference_renderer.shadow.aim_shadow`). ``continuation``: the
    continuation's direction sampler, an object with ``sample(rows, u [m,3]) -> wi [m,3]`` and ``pdf(rows, wi)
    -> [m]`` (world solid angle, > 0 everywhere; spec/renderer.md#neural-assets); None: the uniform sphere.
    ``fetch``: None, or (p [n,3], far [n] bool) from ``integ.fetch_points``: the lights are sampled at p; where
    ``far`` other objects are looked for from p and the branch by the ray from x toward x + wi dist
    (spec/kinds/rna.md#near-field-fetch). The continuation directions are sampled at x either way.

    Returns (ray index, wi world [m,3], weight [m,3], self_hit [m], is_continuation [m], continuation rows, their
    wi, their pdf).
    """
    n = len(x)
    rows_ray, rows_wi, rows_w, rows_self, rows_kind = [], [], [], [], []
    at = x if fetch is None else fetch[0]
    for delta, wi, dist, li, pdf in integ.light_choice.samples(at, rng):
        ok = (pdf > 0) & (max3(li) > 0)
        s = np.nonzero(ok)[0]
        if not len(s):
            continue
        full = len(s) == n
        x_s, wi_s, dist_s, inst_s = (x, wi, dist, inst) if full else (x[s], wi[s], dist[s], inst[s])
        h, self_hit = light_shadows(integ, s, x_s, wi_s, dist_s, inst_s, shadow_origin, fetch)
        free = h.prim < 0  # no other object in the way
        s = s[free]
        if delta:
            w = np.ones(len(s))
        else:
            p_cont = INV_4PI if continuation is None else continuation.pdf(s, wi[s])
            w = np.where(indirect[s], power_heuristic(pdf[s], p_cont), 1.0)
        rows_ray.append(s)
        rows_wi.append(wi[s])
        rows_w.append(li[s] * (w / pdf[s])[:, None])
        rows_self.append(self_hit[free])
        rows_kind.append(np.zeros(len(s), bool))
    cont = np.nonzero(indirect)[0]
    if continuation is None:
        wi_c = square_to_uniform_sphere(rng.random((len(cont), 2)))
        pdf_c = np.full(len(cont), INV_4PI)
    else:
        wi_c = continuation.sample(cont, rng.random((len(cont), 3)))
        pdf_c = continuation.pdf(cont, wi_c)
    if len(cont) or not rows_ray:
        rows_ray.append(cont)
        rows_wi.append(wi_c)
        rows_w.append(np.repeat((1.0 / pdf_c)[:, None], 3, 1))
        rows_self.append(np.zeros(len(cont), bool))
        rows_kind.append(np.ones(len(cont), bool))
    cat = (lambda parts: parts[0]) if len(rows_ray) == 1 else np.concatenate  # one part: no copies
    return cat(rows_ray), cat(rows_wi), cat(rows_w), cat(rows_self), cat(rows_kind), cont, wi_c, pdf_c


def fetch_continuations(integ, fetch, cont, origin, offset, wi_c, inst_c, beta_c, cu, cs, exempt_c=None):
    """Continuation rays of rna hits ``cont`` under a near-field fetch (spec/kinds/rna.md#near-field-fetch):
    where f > 0 the branch is chosen now, by the ray from the offset hit ``origin`` [m,3] along wi_c, its
    transport folded into beta, and the ray moved to start at the fetch point plus ``offset`` ([m,3], None: no
    offset, fiber hits). Returns (origin, beta, pend): pend = (mask, cu, cs) for the integrator, mask the rows whose
    branch is still chosen by the traced ray and cu, cs [mask.sum(), 3] their weights of either branch."""
    mask = np.ones(len(cont), bool)
    if fetch is None:
        return origin, beta_c, (mask, cu, cs)
    p, far = fetch
    fr = np.nonzero(far[cont])[0]
    if not len(fr):
        return origin, beta_c, (mask, cu, cs)
    own = integ.passes_own(origin[fr], wi_c[fr], np.full(len(fr), np.inf), inst_c[fr],
                           None if exempt_c is None else exempt_c[fr])
    beta_c, origin = beta_c.copy(), origin.copy()
    beta_c[fr] *= np.where(own[:, None], cs[fr], cu[fr])
    origin[fr] = p[cont[fr]] if offset is None else p[cont[fr]] + offset[fr]
    mask[fr] = False
    return origin, beta_c, (mask, cu[mask], cs[mask])


@register_shader("rna", "surface")
class RnaSurfaceShader:
    def __init__(self, integ) -> None:
        self.integ = integ
        self.frames = Frames(integ.scene)
        self.lobes = integ.s.rna_continuation == "lobes"  # else the uniform sphere (RenderSettings)

    def vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset: int | None = None, mode: dict | None = None):
        integ = self.integ
        if len(r) != len(x):  # (all rows in a scene of neural assets only: no gathers)
            x, d, beta, prim, bu, bv, inst, ridx = x[r], d[r], beta[r], prim[r], bu[r], bv[r], inst[r], idx[r]
        else:
            ridx = idx
        n = len(x)
        ng = integ.tri_ng[prim]
        scale = (integ.eps * (1.0 + max3(np.abs(x)) / integ.accel.scale))[:, None]
        x_obj = integ.to_object(x, inst, point=True)
        wo_obj = normalize(integ.to_object(-d, inst))
        asset_id = integ.inst_asset[inst]
        local = integ.scene.tri_local[prim]
        assets = unique(asset_id)
        w0 = 1 - bu - bv
        if len(assets) == 1:
            cn = integ.asset_corner_n[assets[0]][local]
            n_obj = normalize(cn[:, 0] * w0[:, None] + cn[:, 1] * bu[:, None] + cn[:, 2] * bv[:, None])
        else:
            n_obj = np.zeros((n, 3))
            for a in assets:
                m = asset_id == a
                cn = integ.asset_corner_n[a][local[m]]
                n_obj[m] = normalize(cn[:, 0] * w0[m][:, None] + cn[:, 1] * bu[m][:, None] + cn[:, 2] * bv[m][:, None])
        indirect = integ.indirect[inst]
        def shadow_origin(s, wi_s, at):  # offset along the geometric normal, to the side wi leaves
            ng_s, scale_s = (ng, scale) if len(s) == n else (ng[s], scale[s])
            return at + ng_s * np.sign(dot(ng_s, wi_s))[:, None] * scale_s, None

        continuation = None  # the uniform sphere
        if self.lobes and indirect.any():
            continuation = SurfaceContinuation(-d, self.frames.normal_to_world(n_obj, inst))
        fetch = integ.fetch_points(x, inst)  # None: every hit fetches its light at x (f = 0)
        ray, wi_all, w_all, self_all, is_cont, cont, wi_c, pdf_c = rna_sample_rows(integ, x, inst, indirect, rng,
                                                                                   shadow_origin, continuation, fetch)
        # one light sample per hit that nothing else blocks, no continuation: rows are the hits in order
        every = len(ray) == n and not len(cont) and len(integ.nee) == 1
        tu = ts = np.zeros((len(ray), 3), np.float32)
        if len(ray):
            wi_obj = normalize(integ.to_object(wi_all, inst if every else inst[ray]))
            ray_asset = asset_id if every else asset_id[ray]
            # float32 once per hit point, then gathered per row (a point has a light and a continuation row)
            x32, n32, wo32 = x_obj.astype(np.float32), n_obj.astype(np.float32), wo_obj.astype(np.float32)
            if len(assets) > 1:
                tu, ts = np.zeros((len(ray), 3), np.float32), np.zeros((len(ray), 3), np.float32)
            for a in (assets if len(assets) == 1 else unique(ray_asset)):
                ev = integ.scene.assets[a].evaluator
                if len(assets) == 1:
                    m, rr, wi_m = slice(None), (slice(None) if every else ray), wi_obj
                else:
                    m = ray_asset == a
                    rr, wi_m = ray[m], wi_obj[m]
                t0 = time.perf_counter()
                u_, s_ = ev.evaluate(x32[rr], n32[rr], wo32[rr], wi_m.astype(np.float32))
                integ.stats.time["network"] += time.perf_counter() - t0
                integ.stats.network_evals += len(u_)
                if len(assets) == 1:
                    tu, ts = u_, s_
                else:
                    tu[m], ts[m] = u_, s_
        if every:  # every row a light row, in hit order
            L[ridx] += beta * np.where(self_all[:, None], ts, tu) * w_all
            return None
        light_rows = ~is_cont
        if light_rows.any():
            lr = ray[light_rows]
            tsel = np.where(self_all[light_rows][:, None], ts[light_rows], tu[light_rows])
            c = beta[lr] * tsel * w_all[light_rows]
            if len(integ.nee) == 1:  # one row per ray: plain indexed add (np.add.at only for repeats)
                L[ridx[lr]] += c
            else:
                np.add.at(L, ridx[lr], c)
        if not len(cont):
            return None
        cu, cs = tu[is_cont] * w_all[is_cont], ts[is_cont] * w_all[is_cont]
        offset = ng[cont] * np.sign(dot(ng[cont], wi_c))[:, None] * scale[cont]
        origin, beta_c, pend = fetch_continuations(integ, fetch, cont, x[cont] + offset, offset, wi_c, inst[cont],
                                                   beta[cont], cu, cs)
        return ridx[cont], origin, wi_c, beta_c, pdf_c, inst[cont], pend
