"""The ``neupress`` kind from the spec text alone (spec/kinds/neupress.md, spec/renderer.md#neupress).

:class:`NeupressAsset` reads the asset (triangle mesh, ``core``: Fourier matrix, boundary
parameters, appearance network; ``sampling`` when the lobe technique uses it) and evaluates the
subsurface transport S (Fourier features of encodings.md#fourier + onnxruntime), the analytic GGX
rough-dielectric reflection of encodings.md#ggx and the Gaussian lobe of neupress.md#lobe.
:class:`NeupressShader` is the far-field vertex: one light sample per light and one technique-A
sample (lobe or uniform sphere) that continues the path, combined per ``--neupress-sampling``
(``auto`` | ``dome`` | ``lobe`` | ``mis``). With a near-field fetch f > 0 (neupress.md#near-field-fetch)
the light samples and the A sample's radiance ray use the fetch point (:meth:`.PathTracer.fetch_points`), the branch
rays from x count only the asset's own triangles (:meth:`.PathTracer.own_branch`), as for rna. PRT mode is not
implemented.
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.errors import SceneError

from .integrator import INV_FOUR_PI, dot, normalized, power, ray_eps, register_shader
from .rna import near_field_fetch, open_root, read_network, read_tensor, read_triangles, safe_normalize

#: sampling mode of every neupress vertex (set by the CLI's --neupress-sampling)
SAMPLING = ["auto"]
MODES = ("auto", "dome", "lobe", "mis")


def fourier_features(g: np.ndarray, v: np.ndarray) -> np.ndarray:
    """encodings.md#fourier: [cos(2π v Gᵀ), sin(2π v Gᵀ)] in float64, NaN in v -> 0, non-finite phase -> 0."""
    v = np.where(np.isnan(v), 0.0, v).astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        ph = 2.0 * np.pi * (v @ g.T)
    ph = np.where(np.isfinite(ph), ph, 0.0)
    return np.concatenate([np.cos(ph), np.sin(ph)], 1).astype(np.float32)


def spherical_coords(w: np.ndarray) -> np.ndarray:
    """encodings.md#spherical: (acos(z)/π, atan2(y, x)/2π) of safe-normalised w."""
    w = safe_normalize(w)
    return np.stack([np.arccos(np.clip(w[:, 2], -1.0, 1.0)) / np.pi, np.arctan2(w[:, 1], w[:, 0]) / (2.0 * np.pi)], 1).astype(np.float32)


def local_frame(n: np.ndarray):
    """encodings.md#frames (Duff et al. 2017)."""
    sign = np.copysign(1.0, n[:, 2])
    a = -1.0 / (sign + n[:, 2])
    c = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * c, -sign * n[:, 0]], 1)
    b = np.stack([c, sign + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t, b


def lobe_pdf(n: np.ndarray, sigma: np.ndarray, wi: np.ndarray) -> np.ndarray:
    """neupress.md#lobe: truncated planar Gaussian in the azimuthal-equidistant plane, per steradian."""
    n, wi = safe_normalize(n), safe_normalize(wi)
    z = -np.expm1(-np.pi ** 2 / (2.0 * sigma ** 2))
    r = np.arccos(np.clip(dot(n, wi), -1.0, 1.0))
    jac = np.where(r < 1e-4, 1.0 + r * r / 6.0, r / np.maximum(np.sin(r), 1e-7))
    return np.exp(-r * r / (2.0 * sigma ** 2)) / (2.0 * np.pi * sigma ** 2 * z) * jac


def lobe_sample(n: np.ndarray, sigma: np.ndarray, u: np.ndarray) -> np.ndarray:
    n = safe_normalize(n)
    r = np.minimum(np.pi, sigma * np.sqrt(np.maximum(0.0, -2.0 * np.log1p(u[:, 0] * np.expm1(-np.pi ** 2 / (2.0 * sigma ** 2))))))
    ph = 2.0 * np.pi * u[:, 1]
    t, b = local_frame(n)
    return np.cos(r)[:, None] * n + np.sin(r)[:, None] * (np.cos(ph)[:, None] * t + np.sin(ph)[:, None] * b)


def ggx_reflection(n, wo, wi, eta: float, alpha: float) -> np.ndarray:
    """encodings.md#ggx value f|n·wi| (grey) for unit object-space directions."""
    n, wo, wi = safe_normalize(n), safe_normalize(wo), safe_normalize(wi)
    s = wo + wi
    ln = np.linalg.norm(s, axis=1, keepdims=True)
    h = np.where(ln > 1e-12, s / np.maximum(ln, 1e-300), n)
    c = np.abs(dot(wo, h))
    st2 = (1.0 - c * c) / eta ** 2
    ct = np.sqrt(np.maximum(0.0, 1.0 - st2))
    rs = (c - eta * ct) / np.maximum(c + eta * ct, 1e-12)
    rp = (eta * c - ct) / np.maximum(eta * c + ct, 1e-12)
    f = np.where(st2 >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))
    nh = dot(n, h)
    a2 = alpha * alpha
    d = np.where(nh > 0, a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2), 0.0)

    def lam(cc):
        cc = np.clip(np.abs(cc), 1e-12, 1.0)
        return (np.sqrt(cc * cc + a2 * (1.0 - cc * cc)) / cc - 1.0) * 0.5

    no, ni = dot(n, wo), dot(n, wi)
    g2 = 1.0 / (1.0 + lam(no) + lam(ni))
    val = np.where((no > 0) & (ni > 0), f * d * g2 / (4.0 * np.maximum(no, 1e-12)), 0.0)
    return np.repeat(val[:, None], 3, 1)


class NeupressAsset:
    kind = "neupress"
    fiber = False

    def __init__(self, path: str, *, threads: int = 0) -> None:
        self.path = str(path)
        stage, root, attr = open_root(self.path)
        rp = str(root.GetPath())
        variant = str(attr("nasset:variant"))
        if variant != "surface":
            raise SceneError("SCENE_UNSUPPORTED", f"neupress variant {variant!r} is not supported (surface only)", file=self.path, prim=rp)
        self.lo = np.asarray(attr("nasset:domainMin"), np.float32).astype(np.float64)
        self.hi = np.asarray(attr("nasset:domainMax"), np.float32).astype(np.float64)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi)) and np.all(self.hi > self.lo)):
            raise SceneError("SCENE_INVALID", "invalid encoding box", file=self.path, prim=rp)
        # spec/kinds/neupress.md#near-field-fetch: f (0 when not authored) and the encoding box's centre c
        self.fetch = near_field_fetch(self.path, root)
        self.centre = 0.5 * (self.lo + self.hi)
        self.points, self.faces, self.normals = read_triangles(self.path, root.GetChild("Geometry"), rp)
        p0, p1, p2 = (self.points[self.faces[:, k]] for k in range(3))
        self.face_normals = safe_normalize(np.cross(p1 - p0, p2 - p0))
        core = stage.GetPrimAtPath(rp + "/Components/core")
        if not core:
            raise SceneError("SCENE_INVALID", "required component core is missing", file=self.path, prim=rp + "/Components/core")
        stage.Load(core.GetPath())
        self.G = read_tensor(self.path, core, "fourier", lambda sh: len(sh) == 2 and sh[1] == 7)
        bnd = read_tensor(self.path, core, "boundary", lambda sh: sh == [2])
        if not np.all(np.isfinite(bnd)) or np.any(bnd <= 0):
            raise SceneError("SCENE_INVALID", "boundary parameters must be finite and > 0", file=self.path, prim=str(core.GetPath()))
        self.eta, self.alpha = float(np.clip(bnd[0], 1e-3, 1e3)), float(np.clip(bnd[1], 1e-4, 1.0))
        self.app = read_network(self.path, core, "appearance", threads, 2 * self.G.shape[0], 3)
        self._stage, self._rp, self._threads = stage, rp, threads
        self.has_sampling = bool(stage.GetPrimAtPath(rp + "/Components/sampling"))
        self.sig = None

    def load_sampling(self) -> None:
        """Load the optional ``sampling`` component (only when the lobe technique uses it)."""
        if self.sig is not None:
            return
        comp = self._stage.GetPrimAtPath(self._rp + "/Components/sampling")
        self._stage.Load(comp.GetPath())
        self.Gs = read_tensor(self.path, comp, "fourier", lambda sh: len(sh) == 2 and sh[1] == 5)
        self.sig = read_network(self.path, comp, "sigma", self._threads, 2 * self.Gs.shape[0], 1)

    def to_unit_box(self, x):
        return (2.0 * (x - self.lo) / np.maximum(self.hi - self.lo, 1e-30) - 1.0).astype(np.float32).astype(np.float64)

    @staticmethod
    def _run(net, x, chunk=65536):
        sess, i, o = net
        out = [sess.run([o], {i: x[s:s + chunk]})[0] for s in range(0, len(x), chunk)]
        return np.concatenate(out).astype(np.float64) if out else np.zeros((0, 1))

    def subsurface(self, x, wo, wi) -> np.ndarray:
        """S (RGB, 1/sr) of object-space inputs, clamped (NaN/Inf -> 0, >= 0)."""
        v = np.concatenate([self.to_unit_box(x), spherical_coords(wo), spherical_coords(wi)], 1)
        y = self._run(self.app, fourier_features(self.G, v))
        return np.maximum(np.where(np.isfinite(y), y, 0.0), 0.0)

    def sigma(self, x, wo) -> np.ndarray:
        v = np.concatenate([self.to_unit_box(x), spherical_coords(wo)], 1)
        y = self._run(self.sig, fourier_features(self.Gs, v))[:, 0]
        lo, hi = np.log(1e-3), np.log(1e3)
        return np.where(np.isnan(y), 1.0, np.exp(np.clip(np.nan_to_num(y, nan=0.0, posinf=hi, neginf=lo), lo, hi)))

    def shading_normal(self, prim, b1, b2) -> np.ndarray:
        """Object-space normal (renderer.md#neural-assets item 1): vertex normals interpolated, else the face normal."""
        if self.normals is None:
            return self.face_normals[prim]
        f = self.faces[prim]
        b0 = 1.0 - b1 - b2
        return safe_normalize(b0[:, None] * self.normals[f[:, 0]] + b1[:, None] * self.normals[f[:, 1]] + b2[:, None] * self.normals[f[:, 2]])


class NeupressShader:
    """The neupress far-field vertex (spec/renderer.md#neupress)."""

    def __init__(self, pt) -> None:
        self.pt = pt
        self.mode = SAMPLING[0]
        if self.mode not in MODES:
            raise SceneError("SCENE_INVALID", f"neupress sampling must be one of {MODES}, got {self.mode!r}")

    @staticmethod
    def open(path: str, threads: int = 0) -> NeupressAsset:
        return NeupressAsset(path, threads=threads)

    def _mode(self, asset):
        mode = self.mode
        if mode == "auto":
            mode = "mis" if asset.has_sampling else "dome"
        lobe = mode in ("lobe", "mis") and asset.has_sampling
        if lobe:
            asset.load_sampling()
        return mode, lobe

    def vertex(self, L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, depth, rng):
        m = len(p)
        out = [np.zeros_like(beta), np.zeros_like(p), np.zeros(m), np.zeros(m, bool), np.full_like(p, np.nan)]
        moved = False
        for k in np.unique(obj):
            r = np.nonzero(obj == k)[0]
            res = self._instance(k, L, idx[r], p[r], ng[r], wo[r], prim[r], b1[r], b2[r], beta[r], depth[r], rng)
            for j in range(5):
                out[j][r] = res[j]
            moved |= bool(np.any(~np.isnan(res[4])))
        return tuple(out[:4]) + (out[4] if moved else None,)

    def _instance(self, k, L, idx, p, ng, wo, prim, b1, b2, beta, depth, rng):
        pt = self.pt
        inst = pt.objects[k]
        asset, B = inst["asset"], inst["m3_inv"]
        det_b = abs(float(np.linalg.det(B)))
        mode, lobe = self._mode(asset)
        m = len(p)
        # spec/kinds/neupress.md#near-field-fetch: the light is taken at the fetch point `at` (p itself for f = 0);
        # S^, f_r, the lobe and the branch stay at the hit p
        at, moved = pt.fetch_points(p, np.full(m, k))
        x = (p - inst["to_world"][3, :3]) @ B
        wo_o = normalized(wo @ B)
        n_o = asset.shading_normal(prim, b1, b2)
        indirect = pt.n_reflective > 1
        cont = (depth < pt.max_depth) & (indirect or mode != "dome")
        sigma = asset.sigma(x, wo_o) if lobe else None

        def to_obj(w):
            v = w @ B
            ln = np.maximum(np.linalg.norm(v, axis=1), 1e-300)
            return v / ln[:, None], det_b / ln ** 3

        def p_a(sel, wi_o, jac):
            return lobe_pdf(n_o[sel], sigma[sel], wi_o) * jac if lobe else np.full(len(sel), INV_FOUR_PI)

        rows, wis, wgt, selfh = [], [], [], []
        for lt in pt.lights:
            if mode == "lobe" and not lt.delta:
                continue
            wi, dist, le, pdf = lt.sample(pt.mi, at, ng, rng.random((m, 2)))
            wi = normalized(wi)
            s = np.nonzero((pdf > 0) & np.any(le > 0, axis=1))[0]
            if not len(s):
                continue
            side = np.sign(dot(wi[s], ng[s]))[:, None]
            side[side == 0] = 1.0
            offset = ng[s] * side * ray_eps(p[s])[:, None]
            maxt = np.where(np.isfinite(dist[s]), dist[s] * (1.0 - 1e-3), np.inf)
            free, passed = pt.light_rays(p[s] + offset, at[s] + offset, moved[s], wi[s], maxt, np.full(len(s), k))
            s, passed = s[free], passed[free]
            wi_o, jac = to_obj(wi[s])
            if lt.delta or mode == "dome":
                w = np.ones(len(s))
            else:
                w = np.where(cont[s], power(pdf[s], p_a(s, wi_o, jac)), 1.0)
            rows.append(s)
            wis.append(wi_o)
            wgt.append(le[s] * (w / pdf[s])[:, None])
            selfh.append(passed)
        c = np.nonzero(cont)[0]
        u = rng.random((len(c), 2))
        if lobe:
            wc = normalized(lobe_sample(n_o[c], sigma[c], u) @ np.linalg.inv(B))
        else:
            z = 1.0 - 2.0 * u[:, 0]
            sz = np.sqrt(np.maximum(0.0, 1.0 - z * z))
            wc = np.stack([sz * np.cos(2.0 * np.pi * u[:, 1]), sz * np.sin(2.0 * np.pi * u[:, 1]), z], 1)
        wc_o, jac_c = to_obj(wc)
        pc = p_a(c, wc_o, jac_c)
        n_nee = sum(len(s) for s in rows)
        ray = np.concatenate([*rows, c]).astype(np.int64)
        nb = np.zeros_like(beta)
        nd = np.zeros_like(p)
        npdf = np.zeros(m)
        alive = np.zeros(m, bool)
        new_o = np.full_like(p, np.nan)  # NaN: the integrator's origin, x offset to the direction's side
        if not len(ray):
            return nb, nd, npdf, alive, new_o
        wi_all = np.concatenate([*wis, wc_o])
        S = asset.subsurface(x[ray], wo_o[ray], wi_all)
        fr = ggx_reflection(n_o[ray], wo_o[ray], wi_all, asset.eta, asset.alpha)
        if n_nee:
            lr = ray[:n_nee]
            t = S[:n_nee] + np.where(np.concatenate(selfh)[:, None], 0.0, fr[:n_nee])
            np.add.at(L, idx[lr], beta[lr] * t * np.concatenate(wgt))
        if len(c):
            side = np.sign(dot(wc, ng[c]))[:, None]
            side[side == 0] = 1.0
            offset = ng[c] * side * ray_eps(p[c])[:, None]
            mc = moved[c]
            passed = pt.continuation_rays(p[c] + offset, mc, wc, np.full(len(c), k))
            new_o[c[mc]] = at[c[mc]] + offset[mc]  # the radiance: a ray from the fetch point
            t = S[n_nee:] + np.where(passed[:, None], 0.0, fr[n_nee:])
            nb[c] = beta[c] * t / np.maximum(pc, 1e-300)[:, None]
            nd[c] = wc
            # mis: power heuristic at lights reached; dome: lights are light-sampled (weight 0); lobe: weight 1
            npdf[c] = pc if mode == "mis" else (-1.0 if mode == "dome" else 0.0)
            alive[c] = pc > 0
        return nb, nd, npdf, alive, new_o


register_shader("neupress", NeupressShader)
