"""Shading vertex of kind ``neupress`` (spec/renderer.md#neupress; papers/neupress-precomputed-subsurface-scattering.txt).

Far-field 6D transport at the first hit x_o (object-space inputs, world-space rays):

    L_o(x_o, w_o) = integral over the sphere of L_i(w_i) [S(x_o, w_o, w_i) + f_r(w_o, w_i) |n.w_i| V_self(w_i)] dw_i

estimated with two techniques combined by the power heuristic: light sampling (every light, one
sample each, or the draws of light_selection; dome lights importance-sampled) and the asset technique p_a (the Gaussian lobe of the
``sampling`` network, or the uniform sphere when the asset has none or the plan leaves it
unloaded). Shadow rays ignore the asset (S contains the self-shadowing); the same ray records
whether the asset itself lies on it, which zeroes the surface-reflection term (V_self). The asset
technique's sample continues the path (as the rna continuation), with weight (S + f_r V_self) / p_a.

An asset with a near-field fetch f > 0 takes the light of the whole integrand at p = x + f (c_w - x)
(spec/kinds/neupress.md#near-field-fetch), with rna's machinery: light samples drawn at p and tested
against other objects from p, the A sample's ray leaving p; S, f_r, the lobe and V_self (rays from x,
only the asset's own triangles counting) evaluated at x as with f = 0.

PRT mode replaces all of it by the dot product of the ``prt`` SH coefficients (barycentric blend of
the three vertices of the hit triangle) with the SH projection of the dome lights (object space).
"""

from __future__ import annotations

import time

import numpy as np

from nasset_sdk.kinds.encodings import sh9
from nasset_sdk.kinds.neupress import gaussian_lobe_pdf, gaussian_lobe_sample

from ..lights import DomeLight
from ..sampling import INV_4PI, dot, normalize, power_heuristic, square_to_uniform_sphere
from .common import Frames, gather_hit, max3
from .registry import register_shader
from .rna_surface import fetch_continuations, light_shadows


def dome_sh_world(lights, min_rows: int = 128):
    """(directions [K,3] world, radiance [K,3], solid angle [K]): a quadrature of every DomeLight.

    Cells are the dome's lat-long texels subdivided so that there are >= ``min_rows`` rows, with
    exact solid angles (2 pi / W)(cos theta_0 - cos theta_1); nearest-texel radiance is constant
    per cell, so the quadrature only approximates the SH basis inside a cell."""
    dirs, rad, wts = [], [], []
    for light in lights:
        if not isinstance(light, DomeLight):
            continue
        h, w = (1, 1) if light.image is None else light.image.shape[:2]
        sub_r = max(1, -(-min_rows // h))
        sub_c = max(1, -(-2 * min_rows // w))
        nh, nw = h * sub_r, w * sub_c
        v0 = np.arange(nh) / nh
        v1 = (np.arange(nh) + 1) / nh
        vc = (v0 + v1) / 2
        uc = (np.arange(nw) + 0.5) / nw
        uu, vv = np.meshgrid(uc, vc)
        uv = np.stack([uu.ravel(), vv.ravel()], 1)
        dl, _ = DomeLight.uv_to_dir(uv)
        omega = (2 * np.pi / nw) * (np.cos(v0 * np.pi) - np.cos(v1 * np.pi))
        wts.append(np.repeat(omega, nw))
        dirs.append(dl @ light.R)
        rad.append(light._lookup(uv) if light.image is not None else np.broadcast_to(light.scale, (len(uv), 3)))
    if not dirs:
        return np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0)
    return np.concatenate(dirs), np.concatenate(rad), np.concatenate(wts)


def dome_sh(quadrature, to_obj3) -> np.ndarray:
    """b_k = sum over the cells of ``quadrature`` (:func:`dome_sh_world` of the lights) of L w Y_k(d_obj) [9, 3]:
    the SH projection of the domes in an object space, d_obj = normalize(d @ to_obj3) (to_obj3 [3, 3] the
    world-to-object linear map, row vectors)."""
    d, rad, w = quadrature
    d_obj = normalize(d @ np.asarray(to_obj3, np.float64))
    return (sh9(d_obj)[:, :, None] * (rad * w[:, None])[:, None, :]).sum(0)


class NeupressShader:
    def __init__(self, integ) -> None:
        self.integ = integ
        self.frames = Frames(integ.scene)
        self._sh_cache: dict = {}
        self._vnormals: dict = {}

    # -- PRT -------------------------------------------------------------------------------
    def _light_sh(self, inst: int) -> np.ndarray:
        """b_k = integral L_i(w) Y_k(w_obj) dw for instance ``inst`` (object-space SH of the domes) [9,3]."""
        if inst not in self._sh_cache:
            self._sh_cache[inst] = dome_sh(dome_sh_world(self.integ.scene.lights), self.frames.to_obj[inst, :3, :3])
        return self._sh_cache[inst]

    def _vertex_normals(self, a: int) -> np.ndarray:
        if a not in self._vnormals:
            data = self.integ.scene.assets[a]
            if data.normals is not None:
                vn = data.normals
            else:
                p = data.points[data.faces]
                fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])  # area-weighted
                vn = np.zeros_like(data.points)
                for j in range(3):
                    np.add.at(vn, data.faces[:, j], fn)
            self._vnormals[a] = normalize(np.asarray(vn, np.float64))
        return self._vnormals[a]

    def _prt(self, h, ev, L) -> None:
        integ = self.integ
        faces = integ.scene.assets[h.asset].faces[integ.scene.tri_local[h.prim]]  # [n,3] vertex ids
        vn = self._vertex_normals(h.asset)
        bary = np.stack([1 - h.bu - h.bv, h.bu, h.bv], 1)
        out = np.zeros((len(h), 3))
        for i in np.unique(h.inst):
            m = h.inst == i
            b = self._light_sh(int(i))
            for j in range(3):
                v = faces[m, j]
                out[m] += bary[m, j:j + 1] * ev.prt_radiance(b, v, vn[v], h.wo_obj[m])
        L[h.ridx] += h.beta * out  # one row per path

    # -- path mode -------------------------------------------------------------------------
    def vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset: int, mode: dict):
        integ = self.integ
        h = gather_hit(integ, r, idx, x, d, beta, prim, bu, bv, inst, asset)
        ev = integ.scene.assets[asset].evaluator
        if mode.get("prt"):
            self._prt(h, ev, L)
            return None
        smode, lobe = mode["sampling"], mode["lobe"]
        cont_on = integ.indirect[h.inst] | (smode != "dome")
        sigma = None
        if lobe:
            t0 = time.perf_counter()
            sigma = ev.sigma(h.x_obj, h.wo_obj)
            integ.stats.time["network"] += time.perf_counter() - t0
        def shadow_origin(s, wi_s, at):  # offset along the geometric normal, to the side wi leaves
            return at + h.ng[s] * np.sign(dot(h.ng[s], wi_s))[:, None] * h.scale[s], None

        fetch = integ.fetch_points(h.x, h.inst)  # None: every hit fetches its light at x (f = 0)
        at = h.x if fetch is None else fetch[0]
        rows, wis, wgt, selfh = [], [], [], []
        # with the lobe, lights with a surface or solid angle are reached by the lobe samples instead
        for delta, wi, dist, li, pdf in integ.light_choice.samples(at, rng, delta_only=smode == "lobe"):
            s = np.nonzero((pdf > 0) & (max3(li) > 0))[0]
            if not len(s):
                continue
            hh, self_hit = light_shadows(integ, s, h.x[s], wi[s], dist[s], h.inst[s], shadow_origin, fetch)
            free = hh.prim < 0
            s = s[free]
            wi_obj, jac = self.frames.dir_to_object(wi[s], h.inst[s])
            if delta or smode == "dome":
                w = np.ones(len(s))
            else:
                p_a = gaussian_lobe_pdf(h.n_obj[s], sigma[s], wi_obj) * jac if lobe else np.full(len(s), INV_4PI)
                w = np.where(cont_on[s], power_heuristic(pdf[s], p_a), 1.0)
            rows.append(s)
            wis.append(wi_obj)
            wgt.append(li[s] * (w / pdf[s])[:, None])
            selfh.append(self_hit[free])
        n_nee = sum(len(s) for s in rows)
        c = np.nonzero(cont_on)[0]
        u2 = rng.random((len(c), 2))
        if lobe:
            wc_obj, p_obj = gaussian_lobe_sample(h.n_obj[c], sigma[c], u2)
            wc = self.frames.dir_to_world(wc_obj, h.inst[c])
            wc_obj, jac = self.frames.dir_to_object(wc, h.inst[c])
            p_c = p_obj * jac
        else:
            wc = square_to_uniform_sphere(u2)
            wc_obj, _ = self.frames.dir_to_object(wc, h.inst[c])
            p_c = np.full(len(c), INV_4PI)
        rows.append(c)
        wis.append(wc_obj)
        ray = np.concatenate(rows)
        if not len(ray):
            return None
        wi_all = np.concatenate(wis)
        t0 = time.perf_counter()
        S = ev.evaluate(h.x_obj[ray].astype(np.float32), h.n_obj[ray].astype(np.float32), h.wo_obj[ray].astype(np.float32),
                        wi_all.astype(np.float32)).astype(np.float64)
        integ.stats.time["network"] += time.perf_counter() - t0
        integ.stats.network_evals += len(ray)
        fr = ev.surface_reflection(h.n_obj[ray], h.wo_obj[ray], wi_all).astype(np.float64)
        if n_nee:
            lr = ray[:n_nee]
            self_hit = np.concatenate(selfh)
            t = S[:n_nee] + np.where(self_hit[:, None], 0.0, fr[:n_nee])
            np.add.at(L, h.ridx[lr], h.beta[lr] * t * np.concatenate(wgt))
        if not len(c):
            return None
        inv_p = (1.0 / p_c)[:, None]
        ts = S[n_nee:] * inv_p
        tu = (S[n_nee:] + fr[n_nee:]) * inv_p
        offset = h.ng[c] * np.sign(dot(h.ng[c], wc))[:, None] * h.scale[c]
        # f > 0: the branch (V_self) chosen now by the ray from x, the ray itself leaving p
        origin, beta_c, pend = fetch_continuations(integ, fetch, c, h.x[c] + offset, offset, wc, h.inst[c], h.beta[c],
                                                   tu, ts)
        prev = p_c if smode == "mis" else np.zeros(len(c))  # dome: lights reached get weight 0 (light-sampled)
        specular = np.full(len(c), smode == "lobe")  # lobe only: lights reached get weight 1
        return (h.ridx[c], origin, wc, beta_c, prev, h.inst[c].astype(np.int64), pend, specular)


register_shader("neupress")(NeupressShader)
