"""The ``8dna`` kind from the spec text alone: asset reading, encodings, spline flow and the shader.

spec/kinds/8dna.md (tensors, networks, bounding-box parameterisation, rational-quadratic spline,
flow sampling and pdf, direct lobe), spec/kinds/encodings.md (cube map with seams, 1D grid, GGX),
spec/renderer.md#8dna (estimator at the first hit). The spline below is written from the
equations of 8dna.md#spline, so it checks that text independently of any other implementation.
"""

from __future__ import annotations

import hashlib

import numpy as np

from nasset_sdk.errors import SceneError

from .integrator import fresnel, ray_eps, register_shader
from .rna import check_network, checked, open_root, read_triangles, safe_normalize, triplane

TWO_PI = 2.0 * np.pi


# --- encodings (spec/kinds/encodings.md) -------------------------------------------------------------

def grid_1d(grid: np.ndarray, t: np.ndarray) -> np.ndarray:
    """encodings.md#grid1d."""
    k = grid.shape[0]
    f = (np.asarray(t, np.float64) + 1.0) * 0.5 * k - 0.5
    f = np.clip(np.where(np.isnan(f), 0.0, f), 0.0, k - 1)
    i0 = np.floor(f).astype(np.int64)
    i1 = np.minimum(i0 + 1, k - 1)
    a = (f - i0)[:, None]
    return (1.0 - a) * grid[i0] + a * grid[i1]


def _face_st(d: np.ndarray):
    """Face index and face coordinates (s_c, t_c) / |d_m| of directions (encodings.md#cubemap)."""
    ad = np.abs(d)
    m = np.argmax(ad, axis=1)  # first maximum: ties -> lower axis
    rows = np.arange(len(d))
    dm = d[rows, m]
    face = 2 * m + (dm < 0)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    sc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4], [-z, z, x, x, x], -x)
    tc = np.select([face == 0, face == 1, face == 2, face == 3, face == 4], [-y, -y, z, -z, -y], -y)
    am = np.maximum(np.abs(dm), 1e-300)
    return face, sc / am, tc / am


def _face_dir(face: np.ndarray, sc: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """Inverse of the face table with |d_m| = 1."""
    one = np.ones_like(sc)
    cands = [
        (one, -tc, -sc),   # +X: s_c = -z, t_c = -y
        (-one, -tc, sc),   # -X: s_c = +z, t_c = -y
        (sc, one, tc),     # +Y: s_c = +x, t_c = +z
        (sc, -one, -tc),   # -Y: s_c = +x, t_c = -z
        (sc, -tc, one),    # +Z: s_c = +x, t_c = -y
        (-sc, -tc, -one),  # -Z: s_c = -x, t_c = -y
    ]
    out = np.zeros((len(sc), 3))
    for f, c in enumerate(cands):
        sel = face == f
        out[sel] = np.stack([c[0][sel], c[1][sel], c[2][sel]], 1)
    return out


def cubemap(grid: np.ndarray, d: np.ndarray) -> np.ndarray:
    """encodings.md#cubemap: bilinear lookup with re-projected taps across face edges, corner taps averaged."""
    r = grid.shape[1]
    d = safe_normalize(d)
    face, sc, tc = _face_st(d)
    s = np.clip((sc + 1.0) * 0.5, 0.0, 1.0)
    t = np.clip((tc + 1.0) * 0.5, 0.0, 1.0)
    fs, ft = s * r - 0.5, t * r - 0.5
    i0, j0 = np.floor(fs).astype(np.int64), np.floor(ft).astype(np.int64)
    a, b = (fs - i0)[:, None], (ft - j0)[:, None]
    taps, outs = [], []
    for dj in (0, 1):
        for di in (0, 1):
            i, j = i0 + di, j0 + dj
            oi, oj = (i < 0) | (i > r - 1), (j < 0) | (j > r - 1)
            val = np.zeros((len(d), grid.shape[3]))
            inside = ~oi & ~oj
            val[inside] = grid[face[inside], j[inside], i[inside]]
            one = oi ^ oj
            if np.any(one):
                scc = 2.0 * (i[one] + 0.5) / r - 1.0
                tcc = 2.0 * (j[one] + 0.5) / r - 1.0
                dd = _face_dir(face[one], scc, tcc)
                f2, s2, t2 = _face_st(dd)
                s2 = np.clip((s2 + 1.0) * 0.5, 0.0, 1.0)
                t2 = np.clip((t2 + 1.0) * 0.5, 0.0, 1.0)
                jj = np.minimum(np.floor(t2 * r).astype(np.int64), r - 1)
                ii = np.minimum(np.floor(s2 * r).astype(np.int64), r - 1)
                val[one] = grid[f2, jj, ii]
            taps.append(val)
            outs.append(oi & oj)
    # a corner tap (both indices outside) is the mean of the other three
    for k in range(4):
        c = outs[k]
        if np.any(c):
            others = [taps[q][c] for q in range(4) if q != k]
            taps[k][c] = (others[0] + others[1] + others[2]) / 3.0
    w = [(1 - a) * (1 - b), a * (1 - b), (1 - a) * b, a * b]
    return w[0] * taps[0] + w[1] * taps[1] + w[2] * taps[2] + w[3] * taps[3]


# --- GGX rough-dielectric direct lobe (encodings.md#ggx) ---------------------------------------------

def _dot(a, b):
    return np.einsum("ij,ij->i", a, b)


def local_frame(n):
    """encodings.md#frames (Duff et al.)."""
    sign = np.copysign(1.0, n[:, 2])
    a = -1.0 / (sign + n[:, 2])
    c = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * c, -sign * n[:, 0]], 1)
    b = np.stack([c, sign + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t, b


class Ggx:
    def __init__(self, params) -> None:
        self.eta = float(np.clip(params[0], 1e-3, 1e3))
        self.alpha = float(np.clip(params[1], 1e-4, 1.0))

    def _d(self, nh):
        a2 = self.alpha ** 2
        den = nh * nh * (a2 - 1.0) + 1.0
        return np.where(nh > 0, a2 / (np.pi * den * den), 0.0)

    def _lam(self, c):
        c = np.clip(np.abs(c), 1e-12, 1.0)
        return (np.sqrt(c * c + self.alpha ** 2 * (1.0 - c * c)) / c - 1.0) * 0.5

    def eval(self, n, wo, wi):
        """f |n.wi| (1/sr, same in R, G, B): returns [N]."""
        s = wo + wi
        ln = np.linalg.norm(s, axis=1, keepdims=True)
        h = np.where(ln > 1e-12, s / np.maximum(ln, 1e-300), n)
        no, ni = _dot(n, wo), _dot(n, wi)
        f = fresnel(_dot(wo, h), self.eta)
        g2 = 1.0 / (1.0 + self._lam(no) + self._lam(ni))
        v = f * self._d(_dot(n, h)) * g2 / (4.0 * np.maximum(no, 1e-12))
        return np.where((no > 0) & (ni > 0), v, 0.0)

    def pdf(self, n, wo, wi):
        h = safe_normalize(wo + wi)
        h = np.where((_dot(n, h) < 0)[:, None], -h, h)
        nh = _dot(n, h)
        p = self._d(nh) * nh / (4.0 * np.maximum(np.abs(_dot(wo, h)), 1e-12))
        return np.where(_dot(n, wo) > 0, p, 0.0)

    def sample(self, n, wo, u):
        tan2 = self.alpha ** 2 * u[:, 0] / np.maximum(1.0 - u[:, 0], 1e-300)
        ct = 1.0 / np.sqrt(1.0 + tan2)
        st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
        ph = TWO_PI * u[:, 1]
        t, b = local_frame(n)
        h = (st * np.cos(ph))[:, None] * t + (st * np.sin(ph))[:, None] * b + ct[:, None] * n
        wi = 2.0 * _dot(wo, h)[:, None] * h - wo
        return wi, self.pdf(n, wo, wi)


# --- rational-quadratic spline (8dna.md#spline) ------------------------------------------------------

def _softmax(a):
    a = a - a.max(axis=-1, keepdims=True)
    e = np.exp(a)
    return e / e.sum(axis=-1, keepdims=True)


def _softplus(a):
    return np.maximum(a, 0.0) + np.log1p(np.exp(-np.abs(a)))


class Spline:
    """K-bin spline on [0, 1] for a batch of parameter rows g [N, 3K+1] = [w~ (K), h~ (K), d~ (K+1)]."""

    def __init__(self, g: np.ndarray, mins) -> None:
        g = np.asarray(g, np.float64)
        g = np.where(np.isnan(g), 0.0, g)
        g = np.clip(g, -1e30, 1e30)  # +-Inf -> +-1e30
        k = (g.shape[1] - 1) // 3
        mw, mh, md = (float(v) for v in mins)
        self.K = k
        self.w = mw + (1.0 - k * mw) * _softmax(g[:, :k])
        self.h = mh + (1.0 - k * mh) * _softmax(g[:, k:2 * k])
        self.d = md + _softplus(g[:, 2 * k:])
        n = len(g)
        self.x = np.concatenate([np.zeros((n, 1)), np.cumsum(self.w, 1)], 1)
        self.y = np.concatenate([np.zeros((n, 1)), np.cumsum(self.h, 1)], 1)
        self.x[:, k] = 1.0
        self.y[:, k] = 1.0

    def _bin(self, knots, v):
        return np.sum(v[:, None] >= knots[:, 1:self.K], axis=1)

    def _parts(self, k):
        r = np.arange(len(k))
        w, h = self.w[r, k], self.h[r, k]
        d0, d1 = self.d[r, k], self.d[r, k + 1]
        s = h / w
        return r, w, h, d0, d1, s, d1 + d0 - 2.0 * s

    @staticmethod
    def _deriv(xi, s, d0, d1, delta):
        om = xi * (1.0 - xi)
        return s * s * (d1 * xi * xi + 2.0 * s * om + d0 * (1.0 - xi) ** 2) / (s + delta * om) ** 2

    def forward(self, z):
        """z -> (t, dt/dz)."""
        z = np.clip(np.asarray(z, np.float64), 0.0, 1.0)
        k = self._bin(self.x, z)
        r, w, h, d0, d1, s, delta = self._parts(k)
        xi = (z - self.x[r, k]) / w
        om = xi * (1.0 - xi)
        t = self.y[r, k] + h * (s * xi * xi + d0 * om) / (s + delta * om)
        return t, self._deriv(xi, s, d0, d1, delta)

    def inverse(self, t):
        """t -> (z, log|dz/dt|)."""
        t = np.clip(np.asarray(t, np.float64), 0.0, 1.0)
        k = self._bin(self.y, t)
        r, w, h, d0, d1, s, delta = self._parts(k)
        dl = t - self.y[r, k]
        a = h * (s - d0) + dl * delta
        b = h * d0 - dl * delta
        c = -s * dl
        den = -b - np.sqrt(np.maximum(b * b - 4.0 * a * c, 0.0))
        xi = np.where(den != 0, 2.0 * c / np.where(den != 0, den, 1.0), 0.0)
        xi = np.clip(xi, 0.0, 1.0)
        z = self.x[r, k] + xi * w
        return z, -np.log(np.maximum(self._deriv(xi, s, d0, d1, delta), 1e-300))


# --- bounding-box parameterisation (8dna.md#bbox) ----------------------------------------------------

def box_point(d, e):
    """u - c = tau d on the box of half extents e; returns (tau, k*)."""
    ad = np.abs(d)
    ratio = np.where(ad > 0, e[None, :] / np.where(ad > 0, ad, 1.0), np.inf)
    ks = np.argmin(ratio, axis=1)  # ties -> lower axis
    return ratio[np.arange(len(d)), ks], ks


def box_jacobian(u_rel, e):
    """J(u) = e_k* / tau^3 with d = normalize(u - c)."""
    d = safe_normalize(u_rel)
    tau, ks = box_point(d, e)
    return e[ks] / tau ** 3


def sphere_dir(s_z, s_phi):
    r = np.sqrt(np.maximum(0.0, 1.0 - s_z * s_z))
    return np.stack([r * np.cos(s_phi), r * np.sin(s_phi), s_z], 1)


def _t_of_s(s, j):
    if j in (0, 2):
        return np.clip((s + 1.0) * 0.5, 0.0, 1.0)
    return np.clip((s + np.pi) / TWO_PI, 0.0, 1.0)


def _s_of_t(t, j):
    return 2.0 * t - 1.0 if j in (0, 2) else TWO_PI * t - np.pi


# --- the asset ----------------------------------------------------------------------------------------

class EightDnaAsset:
    """One 8dna asset file: triangles, encoding box, core tensors and the five networks."""

    kind = "8dna"
    fiber = False
    TENSORS = ("triplane", "woCube", "s1Grid", "s3Grid", "s12Cube", "splineMinimums", "direct")
    NETWORKS = ("albedo", "flow1", "flow2", "flow3", "flow4")

    def __init__(self, path: str, *, threads: int = 0) -> None:
        self.path = str(path)
        self._read(threads)

    def _fail(self, code, msg, prim=None):
        return SceneError(code, msg, file=self.path, prim=prim)

    def _read(self, threads):
        stage, root, attr = open_root(self.path)  # existence, the default prim, the major version, the fetch
        rp = str(root.GetPath())
        if str(attr("nasset:kind")) != "8dna":
            raise self._fail("SCENE_INVALID", "not an 8dna asset", rp)
        if str(attr("nasset:variant")) != "surface":
            raise self._fail("SCENE_UNSUPPORTED", "8dna variant other than surface", rp)
        self.lo = np.asarray(attr("nasset:domainMin"), np.float32).astype(np.float64)
        self.hi = np.asarray(attr("nasset:domainMax"), np.float32).astype(np.float64)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi)) and np.all(self.hi > self.lo)):
            raise self._fail("SCENE_INVALID", "invalid encoding box", rp)
        self.center = 0.5 * (self.lo + self.hi)
        self.half = 0.5 * (self.hi - self.lo)

        self.points, self.faces, self.normals = read_triangles(self.path, root.GetChild("Geometry"), rp)
        p0, p1, p2 = (self.points[self.faces[:, k]] for k in range(3))
        self.face_normals = safe_normalize(np.cross(p1 - p0, p2 - p0))

        core = stage.GetPrimAtPath(rp + "/Components/core")
        if not core:
            raise self._fail("SCENE_INVALID", "required component core is missing", rp + "/Components/core")
        stage.Load(core.GetPath())
        self.t = {}
        for name in self.TENSORS:
            p = core.GetChild(name)
            if not p:
                raise self._fail("SCENE_INVALID", f"component core lacks tensor {name}", str(core.GetPath()))
            shape = [int(s) for s in p.GetAttribute("shape").Get()]
            vals = p.GetAttribute("values").Get()
            if vals is None or len(vals) != int(np.prod(shape)):
                raise self._fail("SCENE_INVALID", f"tensor {name} values do not match its shape", str(p.GetPath()))
            arr = np.asarray(vals, np.float32).reshape(shape).astype(np.float64)
            if not np.all(np.isfinite(arr)):
                raise self._fail("SCENE_INVALID", f"tensor {name} is not finite", str(p.GetPath()))
            self.t[name] = arr
        self.ggx = Ggx(self.t["direct"])
        self.mins = self.t["splineMinimums"]
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = int(threads)
        so.log_severity_level = 3
        self.nets = {}
        for name in self.NETWORKS:
            p = core.GetChild(name)
            model = p.GetAttribute("onnx:model").Get() if p else None
            if model is None or len(model) == 0:
                raise self._fail("SCENE_INVALID", f"network {name} has no onnx:model bytes", str(core.GetPath()))
            data = bytes(np.asarray(model, np.uint8).tobytes())
            digest = p.GetAttribute("onnx:sha256").Get()
            if not digest or hashlib.sha256(data).hexdigest() != str(digest).lower():
                raise self._fail("SCENE_INVALID", f"network {name}: onnx:sha256 does not match the model bytes", str(p.GetPath()))
            check_network(self.path, p, data)
            try:
                sess = ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
            except Exception as exc:
                raise self._fail("SCENE_INVALID", f"network {name} does not load: {str(exc)[:200]}", str(p.GetPath())) from None
            self.nets[name] = (checked(sess, self.path, p), sess.get_inputs()[0].name, sess.get_outputs()[0].name)

    # --- networks -----------------------------------------------------------------------------------

    def _run(self, name, x, chunk=65536):
        sess, i, o = self.nets[name]
        out = [sess.run([o], {i: x[s:s + chunk].astype(np.float32)})[0] for s in range(0, len(x), chunk)]
        return np.concatenate(out).astype(np.float64) if out else np.zeros((0, 1))

    def base(self, x, wo):
        xn = (2.0 * (x - self.lo) / np.maximum(self.hi - self.lo, 1e-30) - 1.0).astype(np.float32).astype(np.float64)
        wo = safe_normalize(wo)
        return np.concatenate([triplane(self.t["triplane"], xn), xn, cubemap(self.t["woCube"], wo), wo], 1)

    def albedo(self, base):
        y = self._run("albedo", base)
        return np.maximum(np.where(np.isfinite(y), y, 0.0), 0.0)

    def _flow_in(self, j, base, s):
        """Input row of flow_{j+1} given s[:, :j]."""
        if j == 0:
            return base
        if j == 1:
            return np.concatenate([base, grid_1d(self.t["s1Grid"], s[:, 0]), s[:, :1]], 1)
        d12 = sphere_dir(s[:, 0], s[:, 1])
        parts = [base, cubemap(self.t["s12Cube"], d12), d12]
        if j == 3:
            parts += [grid_1d(self.t["s3Grid"], s[:, 2]), s[:, 2:3]]
        return np.concatenate(parts, 1)

    def _spline(self, g, c):
        k1 = g.shape[1] // 3
        if np.ndim(c) == 0:
            return Spline(g[:, c * k1:(c + 1) * k1], self.mins)
        rows = np.arange(len(g))[:, None]
        return Spline(g[rows, np.asarray(c)[:, None] * k1 + np.arange(k1)[None, :]], self.mins)

    # --- flow (8dna.md#flow), object space ----------------------------------------------------------

    def params_of(self, u, w):
        """s [N, 4] of (u_i, w_i)."""
        r = safe_normalize(u - self.center)
        w = safe_normalize(w)
        return np.stack([r[:, 2], np.arctan2(r[:, 1], r[:, 0]), w[:, 2], np.arctan2(w[:, 1], w[:, 0])], 1)

    def sample(self, base, channel, z):
        """-> (u_i, w_i, s) in object space from latents z [N, 4]."""
        n = len(base)
        s = np.zeros((n, 4))
        for j in range(4):
            g = self._run(f"flow{j + 1}", self._flow_in(j, base, s))
            t, _ = self._spline(g, channel).forward(z[:, j])
            s[:, j] = _s_of_t(t, j)
        d12 = sphere_dir(s[:, 0], s[:, 1])
        tau, _ = box_point(d12, self.half)
        return self.center + tau[:, None] * d12, sphere_dir(s[:, 2], s[:, 3]), s

    def log_dz(self, base, s, steps):
        """Sum over ``steps`` of log|dz_j/dt_j| for all three channels -> [N, 3]."""
        out = np.zeros((len(base), 3))
        for j in steps:
            g = self._run(f"flow{j + 1}", self._flow_in(j, base, s))
            t = _t_of_s(s[:, j], j)
            for c in range(3):
                out[:, c] += self._spline(g, c).inverse(t)[1]
        return out

    def pdf_position_rgb(self, base, u, s):
        """p^c(u_i) per unit object box area [N, 3]."""
        return np.exp(self.log_dz(base, s, (0, 1))) / (4.0 * np.pi) * box_jacobian(u - self.center, self.half)[:, None]

    def pdf_direction_rgb(self, base, s):
        """p^c(w_i | u_i) per object steradian [N, 3]."""
        return np.exp(self.log_dz(base, s, (2, 3))) / (4.0 * np.pi)

    def box_normal(self, u):
        d = safe_normalize(u - self.center)
        _, ks = box_point(d, self.half)
        n = np.zeros_like(d)
        n[np.arange(len(d)), ks] = np.sign(d[np.arange(len(d)), ks])
        return n

    def shading_normal(self, prim, b1, b2):
        if self.normals is None:
            return self.face_normals[prim]
        f = self.faces[prim]
        n = (1.0 - b1 - b2)[:, None] * self.normals[f[:, 0]] + b1[:, None] * self.normals[f[:, 1]] + b2[:, None] * self.normals[f[:, 2]]
        return safe_normalize(n)


# --- the vertex shader (spec/renderer.md#8dna) --------------------------------------------------------

def _jac(w_world, minv):
    """J = d(omega_obj)/d(omega_world) = |det B| / |w B|^3 for unit world directions w (B = M3^-1)."""
    return abs(np.linalg.det(minv)) / np.maximum(np.linalg.norm(w_world @ minv, axis=1), 1e-300) ** 3


class EightDnaShader:
    """8dna asset vertex: direct lobe at x_o plus the neural estimator at u_i; one continuation."""

    def __init__(self, pt) -> None:
        self.pt = pt

    @staticmethod
    def open(path: str, threads: int = 0):
        return EightDnaAsset(path, threads=threads)

    def vertex(self, L, idx, p, ng, wo, obj, prim, b1, b2, beta, cont, depth, rng):
        """-> (new beta, new direction, its world pdf, alive, new origins (NaN: default offset))."""
        m = len(p)
        out = [np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m), np.zeros(m, bool), np.full((m, 3), np.nan)]
        # the continuation is traced for a lone asset too (spec/renderer.md#8dna)
        cont = np.asarray(depth) < self.pt.max_depth
        u_all = rng.random((m, 8))
        for k in np.unique(obj):
            r = np.nonzero(obj == k)[0]
            res = self._instance(L, idx[r], p[r], ng[r], wo[r], k, prim[r], b1[r], b2[r], beta[r], cont[r], u_all[r], rng)
            for j in range(5):
                out[j][r] = res[j]
        return tuple(out)

    def _backtrace_ok(self, u_w, w_w, k):
        """The ray u_i - t w first meets this instance."""
        tr = self.pt.shadow_tracer.trace(u_w, -w_w, transparent=self.pt.light_shapes)  # light surfaces passed
        return tr["hit"] & (tr["obj"] == k)

    def _instance(self, L, idx, p, ng, wo, k, prim, b1, b2, beta, cont, uu, rng):
        pt = self.pt
        inst = pt.objects[k]
        a: EightDnaAsset = inst["asset"]
        m3, minv, tw = inst["to_world"][:3, :3], inst["m3_inv"], inst["to_world"][3, :3]
        m = len(p)
        x = (p - tw) @ minv
        wo_o = safe_normalize(wo @ minv)
        n = a.shading_normal(prim, b1, b2)
        base = a.base(x, wo_o)
        alpha = a.albedo(base)
        view_side = np.sign(_dot(wo, ng))
        # continuation choice probability
        f = fresnel(_dot(n, wo_o), a.ggx.eta)
        am = alpha.mean(1)
        tot = f + am
        pd_choice = np.where(tot > 0, np.clip(f / np.where(tot > 0, tot, 1.0), 0.05, 0.95), 0.5)
        pf_choice = 1.0 - pd_choice

        # (1) direct lobe: light samples at x_o, ordinary shadow rays (the asset occludes)
        for wi, lw, pl, delta, vis, _ in pt._nee(p, ng, ng, rng, None):
            wi_o = safe_normalize(wi @ minv)
            jac = _jac(wi, minv)
            fd = a.ggx.eval(n, wo_o, wi_o) * jac
            ok = vis & (np.sign(_dot(wi, ng)) == view_side)
            w = np.ones(m) if delta else np.where(cont, _power(pl, pd_choice * a.ggx.pdf(n, wo_o, wi_o) * jac), 1.0)
            np.add.at(L, idx, beta * lw * (fd * w * ok)[:, None])

        # (2) neural part: channel, flow sample (u_i, w_f)
        ch = np.minimum((uu[:, 0] * 3).astype(np.int64), 2)
        u_o, wf_o, s = a.sample(base, ch, uu[:, 1:5])
        p_u = a.pdf_position_rgb(base, u_o, s)  # [m, 3] per unit object area
        pbar_u = p_u.mean(1)
        n_u = a.box_normal(u_o)
        u_w = u_o @ m3 + tw
        good_u = pbar_u > 0
        # light samples at u_i (shadow rays from u_i ignoring the asset)
        for wi, lw, pl, delta, vis, _ in pt._nee(u_w, np.zeros_like(u_w), n_u @ m3, rng, np.full(m, k)):
            wi_o = safe_normalize(wi @ minv)
            ok = vis & good_u & (_dot(n_u, wi_o) > 0)
            if not np.any(ok):
                continue
            r = np.nonzero(ok)[0]
            r = r[self._backtrace_ok(u_w[r], wi[r], k)]
            if len(r) == 0:
                continue
            sl = np.concatenate([s[r, :2], a.params_of(u_o[r], wi_o[r])[:, 2:]], 1)
            p_rgb = p_u[r] * a.pdf_direction_rgb(base[r], sl)
            jac = _jac(wi[r], minv)
            pbar_w = p_rgb.mean(1) / pbar_u[r]
            w = np.ones(len(r)) if delta else np.where(cont[r], _power(pl[r], pf_choice[r] * pbar_w * jac), 1.0)
            c = alpha[r] * p_rgb * lw[r] * (jac * w / pbar_u[r])[:, None]
            np.add.at(L, idx[r], beta[r] * c)

        # (3) one continuation: GGX at x_o with probability P_d, else the flow direction from u_i
        nb, nd, npdf, alive, no = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m), np.zeros(m, bool), np.full((m, 3), np.nan)
        pick_d = uu[:, 5] < pd_choice
        rd = np.nonzero(cont & pick_d)[0]
        if len(rd):
            wg_o, pdg = a.ggx.sample(n[rd], wo_o[rd], uu[rd, 6:8])
            fg = a.ggx.eval(n[rd], wo_o[rd], wg_o)
            wg = safe_normalize(wg_o @ m3)
            ok = (fg > 0) & (pdg > 0) & (np.sign(_dot(wg, ng[rd])) == view_side[rd])
            q = rd[ok]
            if len(q):
                wq = wg[ok]
                origin = p[q] + ng[q] * view_side[q, None] * ray_eps(p[q])[:, None]
                passed = pt.tracer.trace(origin, wq, ignore=np.full(len(q), k))["passed"]
                q, wq, sel = q[~passed], wq[~passed], np.nonzero(ok)[0][~passed]
                nb[q] = beta[q] * (fg[sel] / (pd_choice[q] * pdg[sel]))[:, None]
                nd[q], npdf[q], alive[q] = wq, pd_choice[q] * pdg[sel] * _jac(wq, minv), True
        rf = np.nonzero(cont & ~pick_d & good_u)[0]
        if len(rf):
            wf = safe_normalize(wf_o[rf] @ m3)
            ok = _dot(n_u[rf], wf_o[rf]) > 0
            q, wq = rf[ok], wf[ok]
            if len(q):
                hit = self._backtrace_ok(u_w[q], wq, k)
                q, wq = q[hit], wq[hit]
            if len(q):
                p_rgb = p_u[q] * a.pdf_direction_rgb(base[q], s[q])
                pbar_w = p_rgb.mean(1) / pbar_u[q]
                okp = pbar_w > 0
                q, wq, p_rgb, pbar_w = q[okp], wq[okp], p_rgb[okp], pbar_w[okp]
                nb[q] = beta[q] * alpha[q] * p_rgb / (pbar_u[q] * pbar_w * pf_choice[q])[:, None]
                nd[q], npdf[q], alive[q], no[q] = wq, pf_choice[q] * pbar_w * _jac(wq, minv), True, u_w[q]
        return nb, nd, npdf, alive, no


def _power(a, b):
    a2, b2 = a * a, b * b
    return np.where(a2 + b2 > 0, a2 / np.maximum(a2 + b2, 1e-300), 0.0)


register_shader("8dna", EightDnaShader)
