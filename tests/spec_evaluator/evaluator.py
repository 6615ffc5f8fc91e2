"""An evaluator written from spec/ alone (spec/kinds/*.md, spec/format.md, spec/evaluator-vectors.md).

It reads the asset with pxr and runs networks with onnxruntime; it does not import the SDK. Used as
the ``--evaluator`` of ``nasset conformance`` (tests/spec_evaluator/test_spec_evaluator.py) to show
that the spec text, as written, determines the SDK's answers.

    python -m tests.spec_evaluator.evaluator ASSET INPUT.npz OUTPUT.npz
"""

from __future__ import annotations

import math
import sys

import numpy as np

F32 = np.float32


# -- reading (format.md#tensors, #networks) -----------------------------------------------------------
class AssetFile:
    def __init__(self, path: str) -> None:
        from pxr import Sdf

        self.layer = Sdf.Layer.FindOrOpen(str(path))
        root = self.layer.GetPrimAtPath("/Asset")
        self.kind = root.attributes["nasset:kind"].default
        self.variant = root.attributes["nasset:variant"].default
        self.lo = np.array(root.attributes["nasset:domainMin"].default, np.float64)
        self.hi = np.array(root.attributes["nasset:domainMax"].default, np.float64)
        self._sessions = {}

    def _prim(self, comp: str, name: str):
        return self.layer.GetPrimAtPath(f"/_NassetPayloads/{comp}/{name}")

    def has(self, comp: str, name: str) -> bool:
        return self._prim(comp, name) is not None

    def tensor(self, comp: str, name: str) -> np.ndarray:
        a = self._prim(comp, name).attributes
        dtype = {"float16": np.float16, "float32": np.float32}[a["dtype"].default]
        return np.array(a["values"].default, dtype).reshape(tuple(a["shape"].default)).astype(np.float32)

    def run(self, comp: str, name: str, x: np.ndarray) -> np.ndarray:
        import onnxruntime as ort

        key = (comp, name)
        if key not in self._sessions:
            model = bytes(np.array(self._prim(comp, name).attributes["onnx:model"].default, np.uint8))
            self._sessions[key] = ort.InferenceSession(model, providers=["CPUExecutionProvider"])
        s = self._sessions[key]
        return s.run(None, {s.get_inputs()[0].name: np.ascontiguousarray(x, F32)})[0]


# -- shared functions (kinds/encodings.md) ----------------------------------------------------------------
def to_unit_box(x, lo, hi) -> np.ndarray:
    """#unit-box: float64, rounded to float32."""
    x = np.asarray(x, np.float64)
    return (2.0 * (x - lo) / np.maximum(hi - lo, 1e-30) - 1.0).astype(F32)


def safe_normalize(v) -> np.ndarray:
    """#normalize, in float64: non-finite -> 0, overflow-safe length, |v| <= 1e-20 -> +Z."""
    v = np.array(v, np.float64).reshape(-1, 3)
    v[~np.isfinite(v)] = 0.0
    n = np.sqrt(v[:, 0] * v[:, 0] + v[:, 1] * v[:, 1] + v[:, 2] * v[:, 2])
    big = np.isinf(n)
    if big.any():
        v[big] /= np.abs(v[big]).max(1, keepdims=True)
        n[big] = np.sqrt(v[big, 0] ** 2 + v[big, 1] ** 2 + v[big, 2] ** 2)
    out = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    ok = n > 1e-20
    out[ok] = v[ok] / n[ok, None]
    return out


def _texel(t, size: int):
    f = np.asarray(t, F32) + F32(1.0)
    f = f * F32(0.5) * F32(size) - F32(0.5)
    f = np.where(np.isnan(f), F32(0.0), np.minimum(np.maximum(f, F32(0.0)), F32(size - 1)))
    i0 = np.floor(f).astype(np.int64)
    return i0, np.minimum(i0 + 1, size - 1), (f - i0).astype(F32)


def grid_sample_2d(plane, u, v) -> np.ndarray:
    """#grid2d in float32: top = P00 (1-a) + P01 a, bottom likewise, result = top (1-b) + bottom b."""
    h, w, _ = plane.shape
    i0, i1, a = _texel(u, w)
    j0, j1, b = _texel(v, h)
    a, b = a[:, None], b[:, None]
    top = plane[j0, i0] * (F32(1) - a) + plane[j0, i1] * a
    bot = plane[j1, i0] * (F32(1) - a) + plane[j1, i1] * a
    return top * (F32(1) - b) + bot * b


def triplane(planes, xn) -> np.ndarray:
    """#triplane: (plane0(x, y) + plane1(y, z)) + plane2(z, x), float32."""
    return (grid_sample_2d(planes[0], xn[:, 0], xn[:, 1]) + grid_sample_2d(planes[1], xn[:, 1], xn[:, 2])
            + grid_sample_2d(planes[2], xn[:, 2], xn[:, 0]))


def grid_1d(g, t) -> np.ndarray:
    """#grid1d in float64, rounded to float32."""
    k = len(g)
    f = (np.asarray(t, np.float64) + 1.0) / 2.0 * k - 0.5
    f = np.where(np.isnan(f), 0.0, np.clip(f, 0.0, k - 1))
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, k - 1)
    a = (f - i0)[:, None]
    return ((1 - a) * g[i0] + a * g[i1]).astype(F32)


#: face -> (major axis, sign, (axis, sign) of s_c, (axis, sign) of t_c), the table of #cubemap
FACES = ((0, 1, (2, -1), (1, -1)), (0, -1, (2, 1), (1, -1)), (1, 1, (0, 1), (2, 1)),
         (1, -1, (0, 1), (2, -1)), (2, 1, (0, 1), (1, -1)), (2, -1, (0, -1), (1, -1)))


def _face_st(d):
    d = safe_normalize(d)
    ad = np.abs(d)
    m = np.argmax(ad, 1)  # first maximum: ties go to the lower axis
    dm = d[np.arange(len(d)), m]
    face = 2 * m + (dm < 0)
    s = np.empty(len(d))
    t = np.empty(len(d))
    for f, (_, _, (sa, ss), (ta, ts)) in enumerate(FACES):
        k = face == f
        s[k] = np.clip((ss * d[k, sa] / ad[k, m[k]] + 1) / 2, 0, 1)
        t[k] = np.clip((ts * d[k, ta] / ad[k, m[k]] + 1) / 2, 0, 1)
    return face, s, t


def cubemap(grid, d) -> np.ndarray:
    """#cubemap with re-projected taps across edges and the three-tap mean beyond corners."""
    r = grid.shape[1]
    face, s, t = _face_st(d)
    fs, ft = s * r - 0.5, t * r - 0.5
    i0, j0 = np.floor(fs).astype(np.int64), np.floor(ft).astype(np.int64)
    a, b = (fs - i0)[:, None], (ft - j0)[:, None]
    taps, corner = [], []
    for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1)):
        i, j = i0 + di, j0 + dj
        oi, oj = (i < 0) | (i >= r), (j < 0) | (j >= r)
        val = np.zeros((len(face), grid.shape[-1]))
        inside = ~oi & ~oj
        val[inside] = grid[face[inside], j[inside], i[inside]]
        one = oi ^ oj
        if one.any():
            sc, tc = 2 * (i[one] + 0.5) / r - 1, 2 * (j[one] + 0.5) / r - 1
            dirs = np.zeros((one.sum(), 3))
            for f, (ax, sg, (sa, ss), (ta, ts)) in enumerate(FACES):
                k = face[one] == f
                dirs[k, ax] = sg
                dirs[k, sa] = ss * sc[k]
                dirs[k, ta] = ts * tc[k]
            f2, s2, t2 = _face_st(dirs)
            val[one] = grid[f2, np.minimum(np.floor(t2 * r), r - 1).astype(int), np.minimum(np.floor(s2 * r), r - 1).astype(int)]
        taps.append(val)
        corner.append(oi & oj)
    for k in range(4):
        if corner[k].any():
            taps[k][corner[k]] = sum(taps[m][corner[k]] for m in range(4) if m != k) / 3.0
    return (taps[0] * (1 - a) * (1 - b) + taps[1] * a * (1 - b) + taps[2] * (1 - a) * b + taps[3] * a * b).astype(F32)


def fourier(G, v) -> np.ndarray:
    """#fourier: v rounded to float32 (by the caller), phase in float64, NaN/Inf phase -> 0."""
    v = np.nan_to_num(np.asarray(v, F32).astype(np.float64), nan=0.0, posinf=np.inf, neginf=-np.inf)
    with np.errstate(invalid="ignore", over="ignore"):
        phase = 2.0 * math.pi * (v @ np.asarray(G, np.float64).T)
    phase[~np.isfinite(phase)] = 0.0
    return np.concatenate([np.cos(phase), np.sin(phase)], 1).astype(F32)


def local_frame(n):
    """#frames (Duff et al.), float64: returns t, b, n."""
    n = safe_normalize(n)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    c = x * y * a
    return (np.stack([1 + sign * x * x * a, sign * c, -sign * x], 1), np.stack([c, sign + y * y * a, -y], 1), n)


def dot(a, b) -> np.ndarray:
    """Dot products, float64, summed left to right (encodings.md#precision)."""
    return a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1] + a[:, 2] * b[:, 2]


def spherical(w) -> np.ndarray:
    """#spherical: IEEE atan2 (signed zeros), float64, rounded to float32."""
    w = safe_normalize(w)
    return np.stack([np.arccos(np.clip(w[:, 2], -1, 1)) / math.pi, np.arctan2(w[:, 1], w[:, 0]) / (2 * math.pi)], 1).astype(F32)


# -- GGX (#ggx) ----------------------------------------------------------------------------------------------
def _ggx_d(c, alpha):
    den = c * c * (alpha * alpha - 1) + 1
    return np.where(c > 0, alpha * alpha / (math.pi * np.maximum(den * den, 1e-12)), 0.0)


def _ggx_lambda(c, alpha):
    c = np.minimum(np.maximum(np.abs(c), 1e-12), 1.0)
    return (np.sqrt(c * c + alpha * alpha * (1 - c * c)) / c - 1) / 2


def _fresnel(c, eta):
    c = np.clip(np.abs(c), 0, 1)
    st2 = (1 - c * c) / (eta * eta)
    ct = np.sqrt(np.maximum(1 - st2, 0))
    rs = (c - eta * ct) / np.maximum(c + eta * ct, 1e-12)
    rp = (eta * c - ct) / np.maximum(eta * c + ct, 1e-12)
    return np.where(st2 >= 1, 1.0, np.clip((rs * rs + rp * rp) / 2, 0, 1))


def _half(n, wo, wi):
    n, wo, wi = safe_normalize(n), safe_normalize(wo), safe_normalize(wi)
    h = wo + wi
    hl = np.sqrt(dot(h, h))
    h = np.where(hl[:, None] > 1e-12, h / np.maximum(hl, 1e-12)[:, None], n)
    return n, wo, wi, h


def ggx_value(n, wo, wi, eta, alpha):
    n, wo, wi, h = _half(n, wo, wi)
    co, ci = dot(n, wo), dot(n, wi)
    g2 = 1 / (1 + _ggx_lambda(co, alpha) + _ggx_lambda(ci, alpha))
    v = _fresnel(dot(wo, h), eta) * _ggx_d(dot(n, h), alpha) * g2 / (4 * np.maximum(co, 1e-12))
    return np.where((co > 0) & (ci > 0), v, 0.0)


def ggx_pdf(n, wo, wi, alpha):
    n, wo, wi, h = _half(n, wo, wi)
    ch, coh = dot(n, h), dot(wo, h)
    flip = np.where(ch < 0, -1.0, 1.0)
    ch, coh = ch * flip, coh * flip
    p = _ggx_d(ch, alpha) * ch / (4 * np.maximum(np.abs(coh), 1e-12))
    return np.where((dot(n, wo) > 0) & (ch > 0), p, 0.0)


def ggx_sample(n, wo, u, alpha):
    u = np.clip(u, 0, np.nextafter(1.0, 0.0))
    tan2 = alpha * alpha * u[:, 0] / (1 - u[:, 0])
    ct = 1 / np.sqrt(1 + tan2)
    st = np.sqrt(np.maximum(1 - ct * ct, 0))
    phi = 2 * math.pi * u[:, 1]
    t, b, nn = local_frame(n)
    h = (st * np.cos(phi))[:, None] * t + (st * np.sin(phi))[:, None] * b + ct[:, None] * nn
    wo = safe_normalize(wo)
    wi = safe_normalize(2 * dot(wo, h)[:, None] * h - wo)
    return wi, ggx_pdf(n, wo, wi, alpha)


def boundary(p):
    return float(np.clip(p[0], 1e-3, 1e3)), float(np.clip(p[1], 1e-4, 1.0))


def clamp_out(y):
    y = np.where(np.isfinite(y), y, 0.0)
    return np.maximum(y, 0.0).astype(F32)


# -- kinds ----------------------------------------------------------------------------------------------------------
def rna(a: AssetFile, q: str, args: dict) -> dict:
    planes = a.tensor("core", "triplane")
    xn = to_unit_box(args["x"], a.lo, a.hi)
    cols = [triplane(planes, xn), xn]
    if a.variant == "fiber":
        h = np.nan_to_num(np.asarray(args["h"], np.float64), nan=0.0)
        cols += [safe_normalize(args["t"]).astype(F32), np.clip(h, -1, 1).astype(F32)[:, None]]
    else:
        cols += [safe_normalize(args["n"]).astype(F32)]
    cols += [safe_normalize(args["wo"]).astype(F32), safe_normalize(args["wi"]).astype(F32)]
    x = np.concatenate(cols, 1).astype(F32)
    y = clamp_out(a.run("core", "decoder", x))
    return {"unshadowed": y[:, :3], "shadowed": y[:, 3:], "input": x}


def _sigma(a, x, wo):
    v = np.concatenate([to_unit_box(x, a.lo, a.hi), spherical(wo)], 1)
    feats = fourier(a.tensor("sampling", "fourier"), v)
    y = a.run("sampling", "sigma", feats)[:, 0].astype(np.float64)
    y = np.where(np.isnan(y), 0.0, y)
    return np.exp(np.clip(y, math.log(1e-3), math.log(1e3))), feats


def _lobe_pdf(n, sigma, wi):
    r = np.arccos(np.clip(dot(safe_normalize(n), safe_normalize(wi)), -1, 1))
    z = -np.expm1(-math.pi ** 2 / (2 * sigma * sigma))
    with np.errstate(divide="ignore", invalid="ignore"):
        j = np.where(r < 1e-4, 1 + r * r / 6, r / np.maximum(np.sin(r), 1e-7))
    return np.exp(-r * r / (2 * sigma * sigma)) / (2 * math.pi * sigma * sigma * z) * j


def neupress(a: AssetFile, q: str, args: dict) -> dict:
    if q == "subsurface":
        v = np.concatenate([to_unit_box(args["x"], a.lo, a.hi), spherical(args["wo"]), spherical(args["wi"])], 1)
        feats = fourier(a.tensor("core", "fourier"), v)
        return {"y": clamp_out(a.run("core", "appearance", feats)), "input": feats}
    eta, alpha = boundary(a.tensor("core", "boundary").astype(np.float64))
    if q == "reflection":
        return {"y": np.repeat(ggx_value(args["n"], args["wo"], args["wi"], eta, alpha)[:, None], 3, 1)}
    if q == "sigma":
        s, feats = _sigma(a, args["x"], args["wo"])
        return {"sigma": s, "input": feats}
    if q == "lobe_pdf":
        return {"pdf": _lobe_pdf(args["n"], _sigma(a, args["x"], args["wo"])[0], args["wi"])}
    if q == "lobe_sample":
        s = _sigma(a, args["x"], args["wo"])[0]
        u = np.clip(args["u"], 0, np.nextafter(1.0, 0.0))
        r = np.minimum(math.pi, s * np.sqrt(np.maximum(-2 * np.log1p(u[:, 0] * np.expm1(-math.pi ** 2 / (2 * s * s))), 0)))
        phi = 2 * math.pi * u[:, 1]
        t, b, n = local_frame(args["n"])
        wi = safe_normalize(np.cos(r)[:, None] * n + np.sin(r)[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b))
        return {"wi": wi, "pdf": _lobe_pdf(n, s, wi)}
    if q == "prt":
        sh = a.tensor("prt", "sh").astype(np.float64)
        _, nt, npb = sh.shape[:3]
        t, b, n = local_frame(args["n"])
        wo = safe_normalize(args["wo"])
        cos_o = dot(wo, n)
        ti = np.minimum(np.floor((1 - np.clip(cos_o, 0, 1)) * nt), nt - 1).astype(int)
        phi = np.arctan2(dot(wo, b), dot(wo, t))
        pi_ = np.minimum(np.floor((phi + math.pi) / (2 * math.pi) * npb), npb - 1).astype(int)
        coeff = sh[np.asarray(args["vertex"], int), ti, pi_]
        return {"y": (coeff * np.asarray(args["light_sh"], np.float64)[None]).sum(1)}
    raise KeyError(q)


def eightdna(a: AssetFile, q: str, args: dict) -> dict:
    eta, alpha = boundary(a.tensor("core", "direct").astype(np.float64))
    if q == "albedo":
        wo = safe_normalize(args["wo"]).astype(F32)  # the cube map is read at the float32 w_o the network sees
        xn = to_unit_box(args["x"], a.lo, a.hi)
        base = np.concatenate([triplane(a.tensor("core", "triplane"), xn), xn, cubemap(a.tensor("core", "woCube"), wo), wo], 1)
        return {"y": clamp_out(a.run("core", "albedo", base)), "input": base}
    if q == "direct":
        return {"y": np.repeat(ggx_value(args["n"], args["wo"], args["wi"], eta, alpha)[:, None], 3, 1)}
    if q == "direct_pdf":
        return {"pdf": ggx_pdf(args["n"], args["wo"], args["wi"], alpha)}
    if q == "direct_sample":
        wi, pdf = ggx_sample(args["n"], args["wo"], args["u"], alpha)
        return {"wi": wi, "pdf": pdf}
    return _flow(a, q, args)


# -- 8dna flow (8dna.md#bbox, #spline, #flow) ------------------------------------------------------------------
TINY = 1e-300


def _softmax(v):
    e = np.exp(v - v.max(1, keepdims=True))
    return e / e.sum(1, keepdims=True)


class Spline:
    """8dna.md#spline for one row per query; widths and heights are the knot differences."""

    def __init__(self, g, mins) -> None:
        g = np.nan_to_num(g.astype(np.float64), nan=0.0, posinf=1e30, neginf=-1e30)
        k = (g.shape[1] - 1) // 3
        mw, mh, md = mins
        self.x = self._knots(mw + (1 - k * mw) * _softmax(g[:, :k]))
        self.y = self._knots(mh + (1 - k * mh) * _softmax(g[:, k:2 * k]))
        self.d = md + np.maximum(g[:, 2 * k:], 0) + np.log1p(np.exp(-np.abs(g[:, 2 * k:])))

    @staticmethod
    def _knots(sizes):
        kn = np.concatenate([np.zeros((len(sizes), 1)), np.cumsum(sizes, 1)], 1)
        kn[:, -1] = 1.0
        return kn

    def _bin(self, knots, v):
        k = (v[:, None] >= knots[:, 1:-1]).sum(1)
        r = np.arange(len(v))
        w = np.maximum(self.x[r, k + 1] - self.x[r, k], TINY)
        h = np.maximum(self.y[r, k + 1] - self.y[r, k], TINY)
        return self.x[r, k], self.y[r, k], w, h, self.d[r, k], self.d[r, k + 1]

    @staticmethod
    def _dtdz(xi, s, d0, d1):
        t = xi * (1 - xi)
        den = np.maximum(s + (d1 + d0 - 2 * s) * t, TINY)
        return s * s * (d1 * xi * xi + 2 * s * t + d0 * (1 - xi) ** 2) / (den * den), den

    def forward(self, z):
        """(t, log dt/dz)"""
        z = np.clip(np.nan_to_num(z), 0, 1)
        x0, y0, w, h, d0, d1 = self._bin(self.x, z)
        s = h / w
        xi = np.clip((z - x0) / w, 0, 1)
        dtdz, den = self._dtdz(xi, s, d0, d1)
        t = y0 + h * (s * xi * xi + d0 * xi * (1 - xi)) / den
        return np.clip(t, 0, 1), np.log(np.maximum(dtdz, TINY))

    def inverse_log_dz(self, t):
        """log |dz/dt|"""
        t = np.clip(np.nan_to_num(t), 0, 1)
        x0, y0, w, h, d0, d1 = self._bin(self.y, t)
        s = h / w
        dy = t - y0
        delta = d1 + d0 - 2 * s
        a = h * (s - d0) + dy * delta
        b = h * d0 - dy * delta
        c = -s * dy
        den = -b - np.sqrt(np.maximum(b * b - 4 * a * c, 0))
        xi = np.clip(np.where(den < -TINY, 2 * c / np.where(den < -TINY, den, -1.0), 0.0), 0, 1)
        return -np.log(np.maximum(self._dtdz(xi, s, d0, d1)[0], TINY))


def _cyl(z, phi):
    z = np.clip(z, -1, 1)
    r = np.sqrt(np.maximum(1 - z * z, 0))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


def _box_point(a: AssetFile, d):
    """u = c + tau d and J = e_k* / tau^3 for unit d (8dna.md#bbox)."""
    c, e = (a.lo + a.hi) / 2, (a.hi - a.lo) / 2
    ad = np.abs(d)
    ratio = np.where(ad > TINY, e / np.maximum(ad, TINY), np.inf)
    k = np.argmin(ratio, 1)
    tau = ratio[np.arange(len(d)), k]
    return c + d * tau[:, None], e[k] / np.maximum(tau, TINY) ** 3


def _flow_input(a: AssetFile, j, base, s):
    parts = [base]
    if j == 2:
        parts += [grid_1d(a.tensor("core", "s1Grid"), s[:, 0]), s[:, :1]]
    elif j >= 3:
        d12 = _cyl(s[:, 0], s[:, 1])
        parts += [cubemap(a.tensor("core", "s12Cube"), d12), d12]
        if j == 4:
            parts += [grid_1d(a.tensor("core", "s3Grid"), s[:, 2]), s[:, 2:3]]
    return np.concatenate([np.asarray(p, F32) for p in parts], 1)


def _spline(a: AssetFile, j, base, s, ch):
    g = a.run("core", f"flow{j}", _flow_input(a, j, base, s)).astype(np.float64)
    p = g.shape[1] // 3
    rows = np.take_along_axis(g, ch[:, None] * p + np.arange(p)[None], 1)
    return Spline(rows, a.tensor("core", "splineMinimums").astype(np.float64))


def _s_of_t(t, j):
    return 2 * t - 1 if j in (1, 3) else 2 * math.pi * t - math.pi


def _flow(a: AssetFile, q: str, args: dict) -> dict:
    base = eightdna(a, "albedo", {"x": args["x"], "wo": args["wo"]})["input"]
    ch = np.asarray(args["channel"], np.int64)
    n = len(ch)
    s = np.zeros((n, 4))
    logp = np.zeros(n)
    if q == "sample":
        z = np.clip(np.asarray(args["u"], np.float64), 0, 1)
        for j in range(1, 5):
            t, ld = _spline(a, j, base, s, ch).forward(z[:, j - 1])
            s[:, j - 1] = _s_of_t(t, j)
            logp -= ld
        ui, jac = _box_point(a, _cyl(s[:, 0], s[:, 1]))
        wi = _cyl(s[:, 2], s[:, 3])
    else:
        d = safe_normalize(np.asarray(args["ui"], np.float64) - (a.lo + a.hi) / 2)
        w = safe_normalize(args["wi"])
        given = np.stack([np.clip(d[:, 2], -1, 1), np.arctan2(d[:, 1], d[:, 0]), np.clip(w[:, 2], -1, 1), np.arctan2(w[:, 1], w[:, 0])], 1)
        t = np.clip(np.stack([(given[:, 0] + 1) / 2, (given[:, 1] + math.pi) / (2 * math.pi),
                              (given[:, 2] + 1) / 2, (given[:, 3] + math.pi) / (2 * math.pi)], 1), 0, 1)
        for j in range(1, 5):
            logp += _spline(a, j, base, s, ch).inverse_log_dz(t[:, j - 1])
            s[:, j - 1] = given[:, j - 1]
        _, jac = _box_point(a, d)
    pdf = np.minimum(np.exp(np.minimum(logp, 700.0)) / (16 * math.pi ** 2) * jac, 1e300)
    return {"pdf": pdf} if q == "pdf" else {"ui": ui, "wi": wi, "pdf": pdf}


KINDS = {"rna": rna, "neupress": neupress, "8dna": eightdna}


def main(argv=None) -> int:
    asset, inp, out = argv if argv is not None else sys.argv[1:]
    a = AssetFile(asset)
    queries: dict[str, dict] = {}
    with np.load(inp, allow_pickle=False) as z:
        for k in z.files:
            q, _, arg = k.partition(".")
            queries.setdefault(q, {})[arg] = z[k]
    result = {}
    for q, args in queries.items():
        for name, arr in KINDS[a.kind](a, q, args).items():
            result[f"{q}.{name}"] = np.asarray(arr, F32)
    np.savez(out, **result)
    return 0


if __name__ == "__main__":
    sys.exit(main())
