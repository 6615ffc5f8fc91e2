"""Shading vertex of kind ``8dna`` (spec/renderer.md#8dna; papers/8dna-8d-neural-asset-light-transport.txt §3.3).

Near-field 8D transport at the first hit x_o, per colour channel k:

    L_o = integral f_d(w_o, w_i) L_i(x_o, w_i) V(x_o, w_i) dw_i                       (direct lobe, analytic)
        + integral integral alpha^k(x_o, w_o) p^k(u_i, w_i) L_i^k(u_i, w_i) dA(u_i) dw_i   (indirect, neural)

Direct lobe: one light sample per light (or draw: light_selection) at x_o (ordinary shadow ray, the asset occludes) and the
GGX-sampled continuation, power heuristic. Neural part: one channel c uniform in {0,1,2}, one
(u_i, w_i) ~ p^c from the flow; at u_i one light sample per light or draw (shadow ray from u_i ignoring the
asset) and the flow's direction w_i as the continuation, power heuristic between the light pdf and
the channel-averaged conditional p(w_i | u_i) = mean_k p^k(u_i, w_i) / mean_k p^k(u_i). Samples
with n_u . w_i <= 0 or whose back-traced ray u_i - t w_i misses the asset contribute nothing.
The continuation is the direct-lobe sample with probability P_d, else the flow direction from u_i.

Object-space densities (box area, object solid angle) are converted to world solid angle with
J = d omega_obj / d omega_world of the instance's linear map (1 for rigid motions).
"""

from __future__ import annotations

import time

import numpy as np

from nasset_sdk.kinds.boundary import fresnel_dielectric

from ..sampling import dot, power_heuristic
from ..shadow import aim_shadow
from .common import Frames, gather_hit, max3
from .registry import register_shader

P_DIRECT_MIN, P_DIRECT_MAX = 0.05, 0.95


def direct_probability(fresnel: np.ndarray, albedo: np.ndarray) -> np.ndarray:
    """P_d = clamp(F / (F + mean_k alpha^k), 0.05, 0.95); 0.5 where both are 0."""
    a = albedo.mean(1)
    den = fresnel + a
    return np.where(den > 0, np.clip(fresnel / np.where(den > 0, den, 1.0), P_DIRECT_MIN, P_DIRECT_MAX), 0.5)


class EightdnaShader:
    #: the evaluator's spline knots in float32: ~2x faster flow sampling and densities, which differ from the
    #: spec's float64 by < 1e-3 relative and stay consistent between sampling and evaluation (images within noise)
    evaluator_options = {"spline_dtype": "float32"}

    def __init__(self, integ) -> None:
        self.integ = integ
        self.frames = Frames(integ.scene)

    def _backtrace_ok(self, u_w, w_w, inst) -> np.ndarray:
        """The ray from u_i along -w_i reaches this instance first (the configuration receives light)."""
        hh = self.integ.trace(u_w, -w_w, None, None)
        ok = hh.prim >= 0
        ok[ok] = self.integ.scene.tri_inst[hh.prim[ok]] == inst[ok]
        return ok

    def vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset: int, mode: dict):
        integ = self.integ
        h = gather_hit(integ, r, idx, x, d, beta, prim, bu, bv, inst, asset)
        ev = integ.scene.assets[asset].evaluator
        fr = self.frames
        n = len(h)
        smode = mode["sampling"]
        cont_on = integ.indirect[h.inst] | (smode != "light")
        t0 = time.perf_counter()
        ctx = ev.context(h.x_obj, h.wo_obj)  # shared by the albedo and all flow evaluations of these hits
        alpha = ev.albedo(h.x_obj, h.wo_obj, context=ctx).astype(np.float64)
        integ.stats.time["network"] += time.perf_counter() - t0
        cos_o = dot(h.n_obj, h.wo_obj)
        p_d = direct_probability(np.where(cos_o > 0, fresnel_dielectric(cos_o, ev.eta), 0.0), alpha)
        ngf = np.where((dot(h.ng, -h.d) < 0)[:, None], -h.ng, h.ng)  # geometric normal on the viewer's side
        x_off = h.x + ngf * h.scale
        delta_only = smode == "flow"  # then lights with a surface or solid angle are reached by the flow's samples

        # 1. direct lobe: light samples at x_o (the asset itself occludes)
        for delta, wi, dist, li, pdf in integ.light_choice.samples(h.x, rng, delta_only=delta_only):
            s = np.nonzero((pdf > 0) & (max3(li) > 0) & (dot(wi, ngf) > 0))[0]  # the lobe only where it can count
            wi_obj, jac = fr.dir_to_object(wi[s], h.inst[s])
            f, pb = ev.direct_eval_pdf(h.n_obj[s], h.wo_obj[s], wi_obj)
            f = f[:, 0].astype(np.float64) * jac
            keep = f > 0
            s, wi_obj, jac, f, pb = s[keep], wi_obj[keep], jac[keep], f[keep], pb[keep]
            if not len(s):
                continue
            if delta or smode == "light":
                w = np.ones(len(s))
            else:
                pb = p_d[s] * pb * jac
                w = np.where(cont_on[s], power_heuristic(pdf[s], pb), 1.0)
            d_s, tmax = aim_shadow(h.x[s], x_off[s], wi[s], dist[s], integ.eps)
            vis = ~integ.occluded(x_off[s], d_s, tmax)
            s, w = s[vis], w[vis]
            np.add.at(L, h.ridx[s], h.beta[s] * li[s] * (f[vis] * w / pdf[s])[:, None])

        # 2. neural: (u_i, w_i) ~ p^c, c uniform
        ch = rng.integers(0, 3, n)
        choose_d = rng.random(n) < p_d  # the continuation: direct lobe, else the flow's w_i (drawn only there)
        t0 = time.perf_counter()
        fs = ev.sample_state(h.x_obj, h.wo_obj, ch, u=rng.random((n, 4)), context=ctx, directions=cont_on & ~choose_d)
        u_obj, wf_obj = fs.ui, fs.wi
        integ.stats.time["network"] += time.perf_counter() - t0
        n_u = ev.box.face_normal(u_obj)  # outward normal of u_i's face
        u_w = fr.point_to_world(u_obj, h.inst)

        # rows needing p^k(u_i, w_i): light samples at u_i, then the flow continuation
        q_rows, q_w, nee_info = [], [], []
        for delta, wl, dist, li, pl in integ.light_choice.samples(u_w, rng, delta_only=delta_only):
            wl_obj, jac = fr.dir_to_object(wl, h.inst)
            s = np.nonzero((pl > 0) & (max3(li) > 0) & (dot(n_u, wl_obj) > 0))[0]
            if not len(s):
                continue
            d_s, tmax = aim_shadow(u_w[s], u_w[s], wl[s], dist[s], integ.eps)  # from u_i itself: d_s = wl
            free = integ.trace(u_w[s], d_s, tmax, h.inst[s]).prim < 0
            s = s[free]
            s = s[self._backtrace_ok(u_w[s], wl[s], h.inst[s])]
            q_rows.append(s)
            q_w.append(wl_obj[s])
            nee_info.append((delta, li[s], pl[s], jac[s]))
        n_nee = sum(len(s) for s in q_rows)
        dn = np.nonzero(cont_on & choose_d)[0]
        fn = np.nonzero(cont_on & ~choose_d)[0]
        fn = fn[dot(n_u[fn], wf_obj[fn]) > 0]
        wf_w = fr.dir_to_world(wf_obj[fn], h.inst[fn])
        keep = self._backtrace_ok(u_w[fn], wf_w, h.inst[fn])
        fn, wf_w = fn[keep], wf_w[keep]
        _, jac_f = fr.dir_to_object(wf_w, h.inst[fn])
        q_rows.append(fn)
        rows = np.concatenate(q_rows)
        t0 = time.perf_counter()
        p_u = np.zeros(n)  # the channel-averaged density of u_i: only for the rows that use it
        p_u[rows] = fs.pdf_position_rgb(rows).mean(1)
        # conditioners 1-3 of the sample serve the light rows; the flow continuations reuse conditioner 4 too
        P = np.concatenate([ev.pdf_rgb_at(fs, rows[:n_nee], np.concatenate(q_w) if q_w else np.zeros((0, 3))),
                            ev.pdf_rgb_sampled(fs, fn)])
        integ.stats.time["network"] += time.perf_counter() - t0
        P[p_u[rows] <= 0] = 0.0  # an underflowed p(u_i): no contribution, and p_u only divides
        p_u = np.where(p_u > 0, p_u, 1.0)
        # albedo + conditioners 1-3 per hit, conditioner 4 per drawn w_i and per light row
        integ.stats.network_evals += n * 4 + len(fs.raw4) + n_nee
        q = P.mean(1)
        o = 0
        for s, (delta, li, pl, jac) in zip(q_rows[:-1], nee_info, strict=True):
            Ps, qs = P[o:o + len(s)], q[o:o + len(s)]
            o += len(s)
            if delta or smode == "light":
                w = np.ones(len(s))
            else:
                p_cond = (1 - p_d[s]) * qs / p_u[s] * jac
                w = np.where(cont_on[s], power_heuristic(pl, p_cond), 1.0)
            c = h.beta[s] * alpha[s] * Ps * li * (jac * w / (p_u[s] * pl))[:, None]
            np.add.at(L, h.ridx[s], c)
        assert o == n_nee

        # 3. continuation rays
        Pf, qf = P[n_nee:], q[n_nee:]
        okf = qf > 0
        fn, wf_w, Pf, qf, jac_f = fn[okf], wf_w[okf], Pf[okf], qf[okf], jac_f[okf]
        tf = alpha[fn] * Pf / (qf * (1 - p_d[fn]))[:, None]
        prev_f = (1 - p_d[fn]) * qf / p_u[fn] * jac_f
        wd_obj, pd_obj, fd = ev.direct_sample_eval(h.n_obj[dn], h.wo_obj[dn], rng.random((len(dn), 2)))
        fd = fd[:, 0].astype(np.float64)
        wd_w = fr.dir_to_world(wd_obj, h.inst[dn])
        _, jac_d = fr.dir_to_object(wd_w, h.inst[dn])
        okd = (pd_obj > 0) & (fd > 0) & (dot(wd_w, ngf[dn]) > 0)
        dn, wd_w, fd, pd_obj, jac_d = dn[okd], wd_w[okd], fd[okd], pd_obj[okd], jac_d[okd]
        td = np.repeat((fd / (p_d[dn] * pd_obj))[:, None], 3, 1)
        prev_d = p_d[dn] * pd_obj * jac_d
        m = len(fn) + len(dn)
        if not m:
            return None
        ridx = np.concatenate([h.ridx[fn], h.ridx[dn]])
        origin = np.concatenate([u_w[fn], x_off[dn]])
        dirs = np.concatenate([wf_w, wd_w])
        tu = np.concatenate([tf, td])
        # the direct-lobe continuation must leave the asset without passing through it (else 0)
        ts = np.concatenate([tf, np.zeros_like(td)])
        if smode == "mis":
            prev = np.concatenate([prev_f, prev_d])
        else:  # light: lights reached get weight 0; flow: weight 1 (specular flag)
            prev = np.zeros(m)
        specular = np.full(m, smode == "flow")
        inst_all = np.concatenate([h.inst[fn], h.inst[dn]]).astype(np.int64)
        beta_all = np.concatenate([h.beta[fn], h.beta[dn]])
        return ridx, origin, dirs, beta_all, prev, inst_all, (np.ones(m, bool), tu, ts), specular


register_shader("8dna")(EightdnaShader)
