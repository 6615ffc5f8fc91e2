"""Kind ``8dna`` evaluated and sampled in Dr.Jit (spec/kinds/8dna.md, spec/kinds/encodings.md).

Encodings: the triplane through ``Texture2f`` (:func:`~.rna.triplane_lookup`), the cube maps as the
SDK's extended tables (``nasset_sdk.portable.cube_extended_table``: every face bordered by the texels
the seam re-projection reads, corners the mean of three) read with one plain bilinear gather, the 1D
grids by linear gathers. Networks: the five ONNX graphs traced by :class:`~.network.DrJitNetwork`.
The rational-quadratic spline and the bounding-box parameterisation follow 8dna.md#spline, #bbox and
#flow in float32, the direct lobe is :class:`~.boundary.GgxJit` (the renderer tier of
spec/conformance.md: images within noise, not bit-exact vectors). Densities are capped at
:data:`PDF_MAX` (float32 cannot hold the spec's 1e300).

:func:`vertex` is the per-hit estimator of spec/renderer.md#8dna for the ``nasset_path`` integrator:
direct lobe at x_o, a flow sample (u_i, w_f), a light sample at u_i, and one continuation (GGX from
x_o or the flow direction from u_i) with the MIS weights of that section.
"""

from __future__ import annotations

import math

import numpy as np

from nasset_sdk.errors import error
from nasset_sdk.kinds.boundary import boundary_params
from nasset_sdk.kinds.eightdna import FLOWS, spline_bins
from nasset_sdk.portable import cube_extended_table

from .boundary import GgxJit
from .network import DrJitNetwork
from .rna import open_asset, plane_textures, safe_normalize, triplane_lookup

#: float32 caps of the flow densities (the spec caps log density at 700 and the pdf at 1e300 in float64)
LOG_PDF_MAX = 80.0
PDF_MAX = 1e30
#: smallest knot difference and derivative (the spec's 1e-300 is below float32's range)
TINY = 1e-30
#: |ds / dt| of t in [0, 1]^4 -> s (8dna.md#bbox)
S_PER_T = 16.0 * math.pi * math.pi
#: (major axis, sign, (axis, sign) of s_c, (axis, sign) of t_c) per face: encodings.md#cubemap
CUBE_FACES = ((0, +1, (2, -1), (1, -1)), (0, -1, (2, +1), (1, -1)), (1, +1, (0, +1), (2, +1)),
              (1, -1, (0, +1), (2, -1)), (2, +1, (0, +1), (1, -1)), (2, -1, (0, -1), (1, -1)))


def _finite(dr, v):
    """NaN -> 0, +-Inf -> +-1e30 (8dna.md#spline)."""
    return dr.clip(dr.select(dr.isnan(v), 0.0, v), -1e30, 1e30)


class JitSpline:
    """One rational-quadratic spline per lane on [0, 1] from raw parameters (3K + 1 Floats:
    [w~ (K), h~ (K), d~ (K+1)]) and the minimums (m_w, m_h, m_d) (8dna.md#spline), in float32."""

    def __init__(self, mi, raw: list, mins) -> None:
        import drjit as dr

        self.mi = mi
        k = (len(raw) - 1) // 3
        raw = [_finite(dr, r) for r in raw]
        mw, mh, md = (float(m) for m in mins)
        self.x = self._knots(dr, raw[:k], mw)
        self.y = self._knots(dr, raw[k:2 * k], mh)
        self.d = [md + dr.maximum(a, 0.0) + dr.log(1.0 + dr.exp(-dr.abs(a))) for a in raw[2 * k:]]
        self.k = k

    @staticmethod
    def _knots(dr, a: list, m: float) -> list:
        top = a[0]
        for v in a[1:]:
            top = dr.maximum(top, v)
        e = [dr.exp(v - top) for v in a]
        total = e[0]
        for v in e[1:]:
            total = total + v
        scale = (1.0 - len(a) * m) / total
        knots, run = [0.0], 0.0
        for v in e[:-1]:
            run = run + (m + scale * v)
            knots.append(run)
        return knots + [1.0]

    def _bin(self, knots: list, v):
        """(x_k, y_k, w_k, h_k, d_k, d_{k+1}) of bin k = #{l in 1..K-1: v >= knots_l} per lane."""
        import drjit as dr

        mi = self.mi
        sel = [mi.Float(self.x[0]), mi.Float(self.y[0]), mi.Float(self.x[1]), mi.Float(self.y[1]), self.d[0], self.d[1]]
        for j in range(1, self.k):
            m = v >= knots[j]
            new = [self.x[j], self.y[j], self.x[j + 1], self.y[j + 1], self.d[j], self.d[j + 1]]
            sel = [dr.select(m, n, o) for n, o in zip(new, sel, strict=True)]
        x0, y0, x1, y1, d0, d1 = sel
        return x0, y0, dr.maximum(x1 - x0, TINY), dr.maximum(y1 - y0, TINY), d0, d1

    @staticmethod
    def _deriv(dr, xi, s, d0, d1, den):
        return s * s * (d1 * xi * xi + 2.0 * s * xi * (1.0 - xi) + d0 * dr.square(1.0 - xi)) / dr.square(den)

    def forward(self, z):
        """z -> (t, log dt/dz) (z clamped to [0, 1], NaN -> 0)."""
        import drjit as dr

        z = dr.clip(dr.select(dr.isnan(z), 0.0, z), 0.0, 1.0)
        x0, y0, w, h, d0, d1 = self._bin(self.x, z)
        s = h / w
        xi = dr.clip((z - x0) / w, 0.0, 1.0)
        om = xi * (1.0 - xi)
        den = dr.maximum(s + (d1 + d0 - 2.0 * s) * om, TINY)
        t = y0 + h * (s * xi * xi + d0 * om) / den
        return dr.clip(t, 0.0, 1.0), dr.log(dr.maximum(self._deriv(dr, xi, s, d0, d1, den), TINY))

    def inverse_log(self, t):
        """log |dz/dt| at t (clamped to [0, 1], NaN -> 0)."""
        import drjit as dr

        t = dr.clip(dr.select(dr.isnan(t), 0.0, t), 0.0, 1.0)
        x0, y0, w, h, d0, d1 = self._bin(self.y, t)
        s = h / w
        dl = t - y0
        delta = d1 + d0 - 2.0 * s
        a = h * (s - d0) + dl * delta
        b = h * d0 - dl * delta
        c = -s * dl
        den = -b - dr.sqrt(dr.maximum(b * b - 4.0 * a * c, 0.0))
        safe = den < 0.0
        xi = dr.clip(dr.select(safe, 2.0 * c / dr.select(safe, den, -1.0), 0.0), 0.0, 1.0)
        dd = dr.maximum(s + delta * xi * (1.0 - xi), TINY)
        return -dr.log(dr.maximum(self._deriv(dr, xi, s, d0, d1, dd), TINY))


def _channel(dr, raw: list, c) -> list:
    """Channel c's 3K + 1 parameters (per-lane c in {0, 1, 2}) of channel-major raw (3 (3K + 1) Floats)."""
    p = len(raw) // 3
    return [dr.select(c == 0, raw[j], dr.select(c == 1, raw[p + j], raw[2 * p + j])) for j in range(p)]


class EightDnaJit:
    """An 8dna asset ready for Dr.Jit, in object space: :meth:`context` (base features and albedo),
    :meth:`sample` / :meth:`pdf_rgb_at` / :meth:`pdf_rgb` of the flow, :meth:`direct_eval` /
    :meth:`direct_pdf` / :meth:`direct_sample` / :meth:`fresnel` of the direct lobe."""

    kind = "8dna"
    fiber = False

    def __init__(self, mi, path: str) -> None:
        self.mi = mi
        self.path = str(path)
        asset = open_asset(path, kinds=("8dna",), variants=("surface",))
        t = {n: np.asarray(asset.tensor("core", n), np.float32) for n in
             ("triplane", "woCube", "s1Grid", "s3Grid", "s12Cube", "splineMinimums", "direct")}
        planes = t["triplane"]
        if planes.ndim != 4 or planes.shape[0] != 3 or planes.shape[1] != planes.shape[2]:
            raise error("TENSOR_CONTRACT", f"triplane shape {planes.shape} is not [3, R, R, C]", file=self.path)
        self.planes = plane_textures(mi, planes)
        self.cubes = {n: self._cube(t[n], n) for n in ("woCube", "s12Cube")}
        self.grids = {n: (mi.Float(np.ascontiguousarray(t[n]).ravel()), t[n].shape[0], t[n].shape[1])
                      for n in ("s1Grid", "s3Grid")}
        self.mins = [float(v) for v in t["splineMinimums"].reshape(-1)]
        self.ggx = GgxJit(mi, *boundary_params(t["direct"]))
        refs = asset.network_refs("core")
        nets = {}
        for name in ("albedo",) + FLOWS:
            nets[name] = DrJitNetwork(mi, asset.evaluable_bytes("core", name), file=self.path, prim=f"/Asset/core/{name}")
        self.albedo_net, self.flows = nets["albedo"], [nets[n] for n in FLOWS]
        for name in FLOWS:
            g = int(refs[name].info.output_widths[0])
            k = spline_bins(g)
            if k is None or not (0 <= self.mins[0] * k < 1 and 0 <= self.mins[1] * k < 1 and self.mins[2] > 0):
                raise error("KIND_CONTRACT", f"flow output width {g} and spline minimums {self.mins} give no valid spline",
                            file=self.path, prim=refs[name].prim_path)
        lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
        self.lo, self.span = lo, np.maximum(hi - lo, 1e-30)
        self.center = 0.5 * (lo + hi)
        self.half = 0.5 * (hi - lo)
        self.geometry = asset.geometry()

    def _cube(self, grid: np.ndarray, name: str):
        if grid.ndim != 4 or grid.shape[0] != 6 or grid.shape[1] != grid.shape[2]:
            raise error("TENSOR_CONTRACT", f"{name} shape {grid.shape} is not [6, Q, Q, C]", file=self.path)
        return self.mi.Float(cube_extended_table(grid).ravel()), grid.shape[1], grid.shape[3]

    # --- encodings ---------------------------------------------------------------------------------

    def cubemap(self, name: str, d) -> list:
        """encodings.md#cubemap of directions d [Vector3f] (any length) in cube ``name``: C Floats."""
        import drjit as dr

        mi = self.mi
        table, q, c = self.cubes[name]
        e = q + 2
        d = safe_normalize(mi, mi.Vector3f(d))
        ax, ay, az = dr.abs(d.x), dr.abs(d.y), dr.abs(d.z)
        is_x = (ax >= ay) & (ax >= az)
        is_y = ~is_x & (ay >= az)
        dk = dr.select(is_x, d.x, dr.select(is_y, d.y, d.z))
        ma = dr.maximum(dr.abs(dk), 1e-30)
        face = dr.select(is_x, 0.0, dr.select(is_y, 2.0, 4.0)) + dr.select(dk < 0, 1.0, 0.0)
        sc, tc = mi.Float(0.0), mi.Float(0.0)
        for f, (_, _, (sa, ss), (ta, ts)) in enumerate(CUBE_FACES):
            on = face == f
            sc = dr.select(on, ss * d[sa], sc)
            tc = dr.select(on, ts * d[ta], tc)

        def coord(v):  # (i0 + 1 on the extended face, fraction)
            f_ = dr.clip((v / ma + 1.0) * 0.5, 0.0, 1.0) * q - 0.5
            i0 = dr.floor(f_)
            return i0 + 1.0, f_ - i0

        i1, a_s = coord(sc)
        j1, a_t = coord(tc)
        row = mi.UInt32(face * float(e * e) + j1 * float(e) + i1)
        out = []
        for ch in range(c):
            tap = [dr.gather(mi.Float, table, (row + off) * c + ch) for off in (0, 1, e, e + 1)]
            top = tap[0] * (1.0 - a_s) + tap[1] * a_s
            bot = tap[2] * (1.0 - a_s) + tap[3] * a_s
            out.append(top * (1.0 - a_t) + bot * a_t)
        return out

    def grid(self, name: str, t) -> list:
        """encodings.md#grid1d of t in [-1, 1] in grid ``name``: C Floats (NaN reads texel 0)."""
        import drjit as dr

        mi = self.mi
        table, k, c = self.grids[name]
        f = dr.clip((t + 1.0) * 0.5 * k - 0.5, 0.0, k - 1.0)
        f = dr.select(dr.isnan(f), 0.0, f)
        i0 = dr.minimum(mi.UInt32(f), k - 1)
        i1 = dr.minimum(i0 + 1, k - 1)
        a = f - mi.Float(i0)
        return [dr.gather(mi.Float, table, i0 * c + ch) * (1.0 - a) + dr.gather(mi.Float, table, i1 * c + ch) * a
                for ch in range(c)]

    def context(self, x, wo) -> dict:
        """Base features [triplane(xn), xn, cube_wo(w_o), w_o] (2C + 6 Floats) and the albedo (Color3f,
        NaN/Inf -> 0, then max(0, .)) of object-space points x and directions wo (any length)."""
        import drjit as dr

        mi = self.mi
        xn = mi.Vector3f(2.0 * (x - mi.ScalarPoint3f(self.lo)) / mi.ScalarVector3f(self.span) - 1.0)
        w = safe_normalize(mi, mi.Vector3f(wo))
        base = triplane_lookup(mi, self.planes, xn) + [xn.x, xn.y, xn.z] + self.cubemap("woCube", w) + [w.x, w.y, w.z]
        y = [dr.select(dr.isfinite(v), dr.maximum(v, 0.0), 0.0) for v in self.albedo_net(base)]
        return {"base": base, "albedo": mi.Color3f(y[0], y[1], y[2]), "n": w}

    # --- bounding-box parameterisation (8dna.md#bbox) ---------------------------------------------

    def _project(self, d):
        """Box point of unit d (object space): (u Point3f, J = e_k* / tau^3, axis k* UInt32)."""
        import drjit as dr

        mi = self.mi
        e = self.half
        r = [dr.select(dr.abs(d[k]) > 0, float(e[k]) / dr.select(dr.abs(d[k]) > 0, dr.abs(d[k]), 1.0), 1e30) for k in range(3)]
        is0 = (r[0] <= r[1]) & (r[0] <= r[2])
        is1 = ~is0 & (r[1] <= r[2])
        tau = dr.select(is0, r[0], dr.select(is1, r[1], r[2]))
        ek = dr.select(is0, float(e[0]), dr.select(is1, float(e[1]), float(e[2])))
        axis = dr.select(is0, mi.UInt32(0), dr.select(is1, mi.UInt32(1), mi.UInt32(2)))
        u = mi.Point3f(mi.ScalarPoint3f(self.center) + d * tau)
        return u, ek / dr.maximum(tau * tau * tau, TINY), axis

    def box_normal(self, u):
        """Outward normal [Vector3f] of the box face holding object-space u."""
        import drjit as dr

        mi = self.mi
        rel = safe_normalize(mi, mi.Vector3f(u - mi.ScalarPoint3f(self.center)))
        _, _, axis = self._project(rel)
        return mi.Vector3f(*[dr.select(axis == k, dr.select(rel[k] < 0, -1.0, 1.0), 0.0) for k in range(3)])

    @staticmethod
    def _dir(mi, z, phi):
        import drjit as dr

        z = dr.clip(z, -1.0, 1.0)
        r = dr.sqrt(dr.maximum(1.0 - z * z, 0.0))
        return mi.Vector3f(r * dr.cos(phi), r * dr.sin(phi), z)

    # --- flow (8dna.md#flow) -----------------------------------------------------------------------

    def _conditioner(self, ctx: dict, j: int, s: list) -> list:
        """Raw spline parameters (3 (3K + 1) Floats) of conditioner j (1..4) given s_1..s_{j-1}."""
        mi = self.mi
        row = list(ctx["base"])
        if j == 2:
            row += self.grid("s1Grid", s[0]) + [s[0]]
        elif j >= 3:
            if "s12" not in ctx:
                d12 = self._dir(mi, s[0], s[1])
                ctx["s12"] = self.cubemap("s12Cube", d12) + [d12.x, d12.y, d12.z]
            row += ctx["s12"]
            if j == 4:
                row += self.grid("s3Grid", s[2]) + [s[2]]
        return self.flows[j - 1](row)

    def _splines(self, raw: list) -> list:
        p = len(raw) // 3
        return [JitSpline(self.mi, raw[c * p:(c + 1) * p], self.mins) for c in range(3)]

    @staticmethod
    def _t_of_s(dr, s, j):
        t = (s + 1.0) * 0.5 if j in (1, 3) else (s + math.pi) / (2.0 * math.pi)
        return dr.clip(t, 0.0, 1.0)

    @staticmethod
    def _s_of_t(t, j):
        return 2.0 * t - 1.0 if j in (1, 3) else 2.0 * math.pi * t - math.pi

    def sample(self, ctx: dict, channel, z: list) -> dict:
        """Flow sample of channel (UInt32 per lane) from latents z (4 Floats in [0, 1)): a state with
        ``u`` (Point3f on the box), ``w`` (unit Vector3f), ``pdf`` (Float, per box area and steradian),
        ``p_u`` (Color3f: p^k(u_i) per box area), ``jac`` and what :meth:`pdf_rgb_at` reuses."""
        import drjit as dr

        mi = self.mi
        ctx = dict(ctx)
        s, t, logp, log_pos = [], [], mi.Float(0.0), [mi.Float(0.0)] * 3
        raw3 = raw4 = None
        for j in (1, 2, 3, 4):
            raw = self._conditioner(ctx, j, s)
            tj, ld = JitSpline(mi, _channel(dr, raw, channel), self.mins).forward(z[j - 1])
            if j <= 2:
                log_pos = [lp + sp.inverse_log(tj) for lp, sp in zip(log_pos, self._splines(raw), strict=True)]
            elif j == 3:
                raw3 = raw
            else:
                raw4 = raw
            logp -= ld
            t.append(tj)
            s.append(self._s_of_t(tj, j))
        u, jac, _ = self._project(self._dir(mi, s[0], s[1]))
        w = self._dir(mi, s[2], s[3])
        cap = lambda v: dr.minimum(dr.exp(dr.minimum(v, LOG_PDF_MAX)), PDF_MAX)  # noqa: E731
        p_u = mi.Color3f(*[dr.minimum(cap(lp) / (4.0 * math.pi) * jac, PDF_MAX) for lp in log_pos])
        return {"u": u, "w": w, "pdf": dr.minimum(cap(logp) / S_PER_T * jac, PDF_MAX), "p_u": p_u, "jac": jac,
                "s": s, "t": t, "log_pos": log_pos, "raw3": raw3, "raw4": raw4, "ctx": ctx}

    def pdf_rgb_at(self, state: dict, w) -> object:
        """p^k(u_i, w | x_o, w_o) [Color3f] at the u_i of a :meth:`sample` state and object-space w (unit):
        conditioners 1-3 reused, conditioner 4 run at w's s3 (8dna.md#evaluation-cost)."""
        import drjit as dr

        mi = self.mi
        w = safe_normalize(mi, mi.Vector3f(w))
        s3, s4 = dr.clip(w.z, -1.0, 1.0), dr.atan2(w.y, w.x)
        s = state["s"][:2] + [s3]
        raw4 = self._conditioner(state["ctx"], 4, s)
        t3, t4 = self._t_of_s(dr, s3, 3), self._t_of_s(dr, s4, 4)
        out = []
        for lp, sp3, sp4 in zip(state["log_pos"], self._splines(state["raw3"]), self._splines(raw4), strict=True):
            lg = lp + sp3.inverse_log(t3) + sp4.inverse_log(t4)
            out.append(dr.minimum(dr.exp(dr.minimum(lg, LOG_PDF_MAX)) / S_PER_T * state["jac"], PDF_MAX))
        return mi.Color3f(*out)

    def pdf_rgb_own(self, state: dict) -> object:
        """p^k(u_i, w_i | x_o, w_o) [Color3f] at a :meth:`sample` state's own (u_i, w_i): all four conditioners
        reused (the sample's s_1..s_3 are the inputs of its conditioner 4), the splines inverted at the
        sample's own t_3, t_4 (8dna.md#evaluation-cost, as the reference renderer's ``pdf_rgb_sampled``).
        Equals ``pdf_rgb_at(state, state["w"])`` up to float32 rounding of
        s_3 = w.z and s_4 = atan2(w.y, w.x) (which that recovers from w; at s_4 = +-pi it may take the other
        end of the phi spline), one conditioner evaluation fewer."""
        import drjit as dr

        out = []
        for lp, sp3, sp4 in zip(state["log_pos"], self._splines(state["raw3"]), self._splines(state["raw4"]), strict=True):
            lg = lp + sp3.inverse_log(state["t"][2]) + sp4.inverse_log(state["t"][3])
            out.append(dr.minimum(dr.exp(dr.minimum(lg, LOG_PDF_MAX)) / S_PER_T * state["jac"], PDF_MAX))
        return self.mi.Color3f(*out)

    def pdf_rgb(self, ctx: dict, u, w):
        """p^k(u_i, w_i | x_o, w_o) [Color3f] per box area and steradian of object-space (u_i, w_i)
        (u_i read as the box point in direction u_i - c)."""
        import drjit as dr

        mi = self.mi
        ctx = dict(ctx)
        d = safe_normalize(mi, mi.Vector3f(u - mi.ScalarPoint3f(self.center)))
        w = safe_normalize(mi, mi.Vector3f(w))
        s = [dr.clip(d.z, -1.0, 1.0), dr.atan2(d.y, d.x), dr.clip(w.z, -1.0, 1.0), dr.atan2(w.y, w.x)]
        _, jac, _ = self._project(d)
        lg = [mi.Float(0.0)] * 3
        for j in (1, 2, 3, 4):
            t = self._t_of_s(dr, s[j - 1], j)
            lg = [a + sp.inverse_log(t) for a, sp in zip(lg, self._splines(self._conditioner(ctx, j, s[:j - 1])), strict=True)]
        return mi.Color3f(*[dr.minimum(dr.exp(dr.minimum(v, LOG_PDF_MAX)) / S_PER_T * jac, PDF_MAX) for v in lg])

    # --- direct lobe (encodings.md#ggx): the shared Dr.Jit GGX boundary -------------------------------

    def fresnel(self, cos_i):
        """Dielectric Fresnel reflectance of ``core/direct`` at |cos_i|."""
        return self.ggx.fresnel(cos_i)

    def direct_eval(self, n, wo, wi):
        """f |n.wi| of the direct lobe [Float, 1/sr, grey] (object space)."""
        return self.ggx.eval(n, wo, wi)

    def direct_pdf(self, n, wo, wi):
        """Density per object steradian of :meth:`direct_sample` at wi."""
        return self.ggx.pdf(n, wo, wi)

    def direct_sample(self, n, wo, u2):
        """(wi, pdf) of the direct lobe's GGX sampler."""
        return self.ggx.sample(n, wo, u2)


# --- the vertex estimator of spec/renderer.md#8dna ----------------------------------------------------

def _matrix(mi, tab, name, k, active) -> list:
    """Rows (3 x 4 Floats) of instance k's affine map ``name`` ('inv': world -> object, 'fwd': object -> world)."""
    import drjit as dr

    return [[dr.gather(mi.Float, tab[name], k * 12 + 4 * r + j, active) for j in range(4)] for r in range(3)]


def _apply(mi, rows, v, point=False):
    return mi.Vector3f(*[r[0] * v.x + r[1] * v.y + r[2] * v.z + (r[3] if point else 0.0) for r in rows])


def draw(sampler) -> tuple:
    """The random numbers of one 8dna vertex, drawn on every lane before the integrator's symbolic ``if``
    (the sampler's sequence does not depend on which lanes hit an 8dna asset): (channel u [Float],
    4 latents z [Float], light sample at x_o [Point2f], light sample at u_i [Point2f], continuation
    pick [Float], GGX sample [Point2f])."""
    u_ch, z = sampler.next_1d(), [sampler.next_1d() for _ in range(4)]
    return u_ch, z, sampler.next_2d(), sampler.next_2d(), sampler.next_1d(), sampler.next_2d()


def vertex(mi, scene, rnd, si, wo_world, sid, assets, tab, k, x, n, wo, on, lights=None, emitters=None) -> dict:
    """The 8dna estimator at asset hits ``on`` (spec/renderer.md#8dna) for the ``nasset_path`` integrator.

    rnd: the vertex's random numbers (:func:`draw`); si: the hit; wo_world: -ray.d; sid: the hit shape's
    registry id (UInt32); assets: (index, EightDnaJit) of the scene's 8dna assets; tab, k: the integrator's
    instance tables and instance index; x, n, wo: the object-space inputs; lights: what shadow rays pass through, light
    surfaces and absent cut-outs (:class:`.plugins.PassThrough`; None: every shape blocks them); emitters: what picks a
    light sample's emitter (a :class:`.light_choice.EmitterChoice`; None: the scene). Returns 'L' (Spectrum: direct lobe
    at x_o plus the light sample at u_i, to be multiplied by the path throughput), the continuation 'd'
    (world, unit), 'from_u' (Bool: it leaves the world point 'origin' = u_i M, else x_o), 'weight' (Spectrum
    throughput factor; 0 where a GGX continuation passes through the asset: 'weight_passed'), 'pdf' (its world
    solid-angle pdf for MIS at a reached light) and 'alive'."""
    import drjit as dr

    from .plugins import _mis, _occluder, _of_asset

    u_ch, z, u_ex, u_eu, u_pick, u_g = rnd
    ch = dr.minimum(mi.UInt32(u_ch * 3.0), 2)
    inv, fwd = _matrix(mi, tab, "inv", k, on), _matrix(mi, tab, "fwd", k, on)
    det = dr.abs(inv[0][0] * (inv[1][1] * inv[2][2] - inv[1][2] * inv[2][1])
                 - inv[0][1] * (inv[1][0] * inv[2][2] - inv[1][2] * inv[2][0])
                 + inv[0][2] * (inv[1][0] * inv[2][1] - inv[1][1] * inv[2][0]))

    def jac(w):  # d omega_object / d omega_world of unit world w
        v = _apply(mi, inv, w)
        return det / dr.maximum(dr.norm(v) ** 3, TINY)

    def obj(w):
        return safe_normalize(mi, _apply(mi, inv, w))

    def world(w):
        return safe_normalize(mi, _apply(mi, fwd, w))

    ng = si.n
    side = dr.select(dr.dot(wo_world, ng) >= 0, 1.0, -1.0)

    def backtrace(p, w, active):  # the ray p - t w first meets this instance
        bt = scene.ray_intersect(mi.Ray3f(p, -w), active)
        return active & bt.is_valid() & (dr.reinterpret_array(mi.UInt32, bt.shape) == sid)

    # direct lobe at x_o: an ordinary light sample (the asset occludes; w_i on the viewer's side)
    emitters = scene if emitters is None else emitters
    ds_x, ew_x = emitters.sample_emitter_direction(si, u_ex, lights is None, on)
    if lights is not None:  # the shadow ray passes through light surfaces (spec/renderer.md#light-surfaces)
        blocked, _ = _occluder(mi, scene, si.spawn_ray_to(ds_x.p), mi.UInt32(0), mi.UInt32(0), mi.UInt32(0),
                               on & (ds_x.pdf != 0), lights)
        ew_x = dr.select(blocked.is_valid(), 0.0, ew_x)
    wl_x = obj(ds_x.d)
    f3 = dict(alpha=mi.Color3f(0), pd=mi.Float(0.5), fd=mi.Float(0), pdl=mi.Float(0), u=mi.Point3f(0), wf=mi.Vector3f(0),
              p_u=mi.Color3f(0), nu=mi.Vector3f(0), wg=mi.Vector3f(0), pdg=mi.Float(0), fg=mi.Float(0))
    states = []
    for a, asset in assets:
        mine = _of_asset(mi, tab, k, a, on)
        ctx = asset.context(x, wo)
        fres = asset.fresnel(dr.dot(n, safe_normalize(mi, wo)))
        am = (ctx["albedo"].x + ctx["albedo"].y + ctx["albedo"].z) / 3.0
        tot = fres + am
        st = asset.sample(ctx, ch, z)
        wg, pdg = asset.direct_sample(n, wo, u_g)
        new = dict(alpha=ctx["albedo"], pd=dr.select(tot > 0, dr.clip(fres / dr.select(tot > 0, tot, 1.0), 0.05, 0.95), 0.5),
                   fd=asset.direct_eval(n, wo, wl_x), pdl=asset.direct_pdf(n, wo, wl_x), u=st["u"], wf=st["w"], p_u=st["p_u"],
                   nu=asset.box_normal(st["u"]), wg=wg, pdg=pdg, fg=asset.direct_eval(n, wo, wg))
        f3 = {key: dr.select(mine, new[key], f3[key]) for key in f3}
        states.append((mine, asset, st))
    pd = f3["pd"]
    ok_x = on & (ds_x.pdf != 0) & (dr.dot(ds_x.d, ng) * side > 0)
    w_x = dr.select(ds_x.delta, 1.0, _mis(ds_x.pdf, pd * f3["pdl"] * jac(ds_x.d)))
    L = dr.select(ok_x, f3["fd"] * jac(ds_x.d) * w_x * ew_x, 0.0)

    # neural part: a light sample at u_i (shadow ray from u_i ignoring the asset; n_u . w > 0; back-trace)
    pbar_u = (f3["p_u"].x + f3["p_u"].y + f3["p_u"].z) / 3.0
    good_u = on & (pbar_u > 0)
    u_w = mi.Point3f(_apply(mi, fwd, f3["u"], point=True))
    it = dr.zeros(mi.Interaction3f)
    it.p, it.time, it.wavelengths = u_w, si.time, si.wavelengths
    ds_u, ew_u = emitters.sample_emitter_direction(it, u_eu, False, good_u)
    wl_u = obj(ds_u.d)
    ok_u = good_u & (ds_u.pdf != 0) & (dr.dot(f3["nu"], wl_u) > 0)
    sh, _ = _occluder(mi, scene, it.spawn_ray_to(ds_u.p), sid, mi.UInt32(0), mi.UInt32(0), ok_u, lights)
    ok_u &= ~sh.is_valid()
    ok_u = backtrace(u_w, ds_u.d, ok_u)
    p_l, p_f = mi.Color3f(0), mi.Color3f(0)
    for mine, asset, st in states:
        p_l = dr.select(mine, asset.pdf_rgb_at(st, wl_u), p_l)
        p_f = dr.select(mine, asset.pdf_rgb_own(st), p_f)  # f3["wf"] is st["w"] on these lanes
    safe_u = dr.select(good_u, pbar_u, 1.0)
    j_u = jac(ds_u.d)
    pbar_wl = (p_l.x + p_l.y + p_l.z) / 3.0 / safe_u
    w_u = dr.select(ds_u.delta, 1.0, _mis(ds_u.pdf, (1.0 - pd) * pbar_wl * j_u))
    L += dr.select(ok_u, f3["alpha"] * p_l * ew_u * (j_u * w_u / safe_u), 0.0)

    # one continuation: GGX from x_o with probability P_d, else the flow direction from u_i
    pick_d = u_pick < pd
    wg = world(f3["wg"])
    ok_g = on & pick_d & (f3["fg"] > 0) & (f3["pdg"] > 0) & (dr.dot(wg, ng) * side > 0)
    wf = world(f3["wf"])
    pbar_wf = (p_f.x + p_f.y + p_f.z) / 3.0 / safe_u
    ok_f = good_u & ~pick_d & (dr.dot(f3["nu"], f3["wf"]) > 0) & (pbar_wf > 0)
    ok_f = backtrace(u_w, wf, ok_f)
    weight_g = mi.Color3f(f3["fg"] / dr.select(ok_g, pd * f3["pdg"], 1.0))
    weight_f = f3["alpha"] * p_f / dr.select(ok_f, pbar_u * pbar_wf * (1.0 - pd), 1.0)
    weight = dr.select(ok_g, weight_g, dr.select(ok_f, weight_f, 0.0))
    return {"L": L, "d": dr.select(pick_d, wg, wf), "from_u": ~pick_d, "origin": u_w, "weight": weight,
            "weight_passed": dr.select(ok_f, weight_f, 0.0),
            "pdf": dr.select(pick_d, pd * f3["pdg"] * jac(wg), (1.0 - pd) * pbar_wf * jac(wf)), "alive": ok_g | ok_f}
