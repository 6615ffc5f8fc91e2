"""Kind ``neupress`` evaluated in Dr.Jit (spec/kinds/neupress.md, spec/kinds/encodings.md, spec/renderer.md#neupress).

Per sample, all in Dr.Jit arrays of the active Mitsuba variant, object space:

- the subsurface term S (1/sr, RGB): Fourier features of v = [xn, theta_o, phi_o, theta_i, phi_i]
  (encodings.md#fourier, #spherical) fed to the ``appearance`` network traced by :class:`~.network.DrJitNetwork`;
- the boundary reflection f_r |n.w_i| (1/sr, grey): GGX rough dielectric of ``core/boundary`` (encodings.md#ggx);
- the asset technique: the Gaussian lobe of neupress.md#lobe around n with sigma from the ``sampling``
  network (:class:`GaussianLobe`), or none (the integrator's uniform world sphere) when the asset has no
  ``sampling`` component. The render reads sigma from a table of that network (:class:`SigmaTable`, built once
  per asset, on first use): only the variance depends on sigma (spec/renderer.md#neupress), and evaluating the network at every
  vertex cost 0.34-0.36 of a path-traced sample, a sixth of the asset's render (docs/bench-mitsuba-jit.md#sigma-table).

Precision: float32 throughout (the SDK computes phases, angles, GGX and the lobe in float64). The Fourier
phase is reduced to its fractional cycle before the sine and cosine (|G v| reaches ~100 cycles); theta is
``atan2(sqrt(x^2 + y^2), z)`` and the lobe radius ``atan2(|n x w|, n.w)``, accurate near the poles where acos
is not; expm1 and log1p use Kahan's compensated forms (the lobe's normaliser at sigma ~ 1e3).
"""

from __future__ import annotations

import math

import numpy as np

from nasset_sdk.asset import COMPONENTS
from nasset_sdk.errors import error
from nasset_sdk.kinds.boundary import boundary_params
from nasset_sdk.kinds.neupress import SIGMA_MAX, SIGMA_MIN

from .boundary import GgxJit
from .network import DrJitNetwork
from .rna import RnaJit, open_asset, safe_normalize

TWO_PI = 2.0 * math.pi
LOG_SIGMA = (math.log(SIGMA_MIN), math.log(SIGMA_MAX))
#: :class:`SigmaTable`'s resolution: nodes per axis of the encoding box, theta_o and phi_o bins
SIGMA_TABLE = (16, 8, 16)


def _dr():
    import drjit as dr

    return dr


def expm1(x):
    """exp(x) - 1 [Float], accurate for small |x| (Kahan: (e^x - 1) x / log(e^x))."""
    dr = _dr()
    u = dr.exp(x)
    return dr.select(u == 1.0, x, dr.select(u - 1.0 == -1.0, -1.0, (u - 1.0) * x / dr.log(u)))


def log1p(x):
    """log(1 + x) [Float], accurate for small |x| (Kahan: log(1 + x) x / ((1 + x) - 1))."""
    dr = _dr()
    u = 1.0 + x
    return dr.select(u == 1.0, x, dr.log(u) * x / (u - 1.0))


def spherical(mi, w) -> list:
    """[theta / pi, phi / (2 pi)] (2 Floats) of object-space directions w [Vector3f] (encodings.md#spherical)."""
    dr = _dr()
    w = safe_normalize(mi, mi.Vector3f(w))
    theta = dr.atan2(dr.sqrt(dr.square(w.x) + dr.square(w.y)), w.z)
    return [theta * (1.0 / math.pi), dr.atan2(w.y, w.x) * (1.0 / TWO_PI)]


def fourier_features(g: np.ndarray, v: list) -> list:
    """[cos(2 pi G v) (M), sin(2 pi G v) (M)]: G [M, n] numpy, v n Floats -> 2M Floats (encodings.md#fourier).

    NaN in v -> 0; a non-finite phase -> 0. The phase 2 pi G v is taken modulo one cycle in float32."""
    dr = _dr()
    v = [dr.select(dr.isnan(c), 0.0, c) for c in v]
    cos, sin = [], []
    for row in np.asarray(g, np.float64):
        c = None
        for gk, vk in zip(row, v, strict=True):
            c = vk * float(gk) if c is None else dr.fma(vk, float(gk), c)
        c = dr.select(dr.isfinite(c), c, 0.0)
        s, co = dr.sincos((c - dr.round(c)) * TWO_PI)
        cos.append(co)
        sin.append(s)
    return cos + sin


def local_frame(mi, n):
    """(t, b) of encodings.md#frames (Duff et al. 2017) for unit normals n [Vector3f]."""
    dr = _dr()
    sign = dr.copysign(1.0, n.z)
    a = -dr.rcp(sign + n.z)
    c = n.x * n.y * a
    t = mi.Vector3f(1.0 + sign * dr.square(n.x) * a, sign * c, -sign * n.x)
    b = mi.Vector3f(c, sign + dr.square(n.y) * a, -n.y)
    return t, b


class GaussianLobe:
    """The truncated planar Gaussian of neupress.md#lobe around unit normals n [Vector3f], sigma [Float] (radians)."""

    def __init__(self, mi, n, sigma) -> None:
        self.mi, self.n, self.sigma = mi, n, sigma
        a = math.pi ** 2 / (2.0 * sigma * sigma)
        self.em1 = expm1(-a)  # exp(-pi^2 / (2 sigma^2)) - 1 = -Z
        self.norm = _dr().rcp(2.0 * math.pi * sigma * sigma * -self.em1)

    def pdf(self, w):
        """Density per object-space steradian [Float] at directions w [Vector3f] (normalised here)."""
        dr = _dr()
        w = safe_normalize(self.mi, w)
        r = dr.atan2(dr.norm(dr.cross(self.n, w)), dr.dot(self.n, w))
        jac = dr.select(r < 1e-4, 1.0 + dr.square(r) / 6.0, r / dr.maximum(dr.sin(r), 1e-7))
        return dr.exp(-dr.square(r) / (2.0 * dr.square(self.sigma))) * self.norm * jac

    def sample(self, u):
        """(w [Vector3f] unit object-space direction, pdf [Float]) from u [Point2f] in [0, 1)^2 (Box-Muller, truncated)."""
        dr = _dr()
        r = self.sigma * dr.sqrt(dr.maximum(-2.0 * log1p(dr.clip(u.x, 0.0, 1.0) * self.em1), 0.0))
        r = dr.select(dr.isnan(r), math.pi, dr.minimum(r, math.pi))
        sr, cr = dr.sincos(r)
        sp, cp = dr.sincos(TWO_PI * u.y)
        t, b = local_frame(self.mi, self.n)
        w = dr.normalize((t * (sr * cp) + b * (sr * sp)) + self.n * cr)
        return w, self.pdf(w)


class SigmaTable:
    """The lobe width sigma(x, w_o) of a ``sigma(xn, theta / pi, phi / 2 pi) -> log sigma`` function, tabulated once:
    log sigma at R^3 nodes spanning the encoding box (xn in [-1, 1]^3, trilinear between them) times the centres of
    N_theta x N_phi equal-angle w_o bins (nearest bin). Lookups are 8 gathers instead of the network; the lobe
    sampled and the pdf used are those of the table's sigma, so the estimate is unbiased whatever the table's
    error (spec/renderer.md#neupress)."""

    def __init__(self, mi, log_sigma, res=SIGMA_TABLE) -> None:
        dr = _dr()
        self.mi, (self.r, self.nt, self.np) = mi, (int(v) for v in res)
        r, nt, npb = self.r, self.nt, self.np
        if r < 2 or nt < 1 or npb < 1:
            raise error("USAGE", f"sigma table resolution {res} needs >= 2 nodes per axis and >= 1 bin")
        i = np.arange(r, dtype=np.float64) * (2.0 / (r - 1)) - 1.0
        th = (np.arange(nt) + 0.5) / nt  # theta / pi at the bin centres
        ph = (np.arange(npb) + 0.5) / npb - 0.5  # phi / (2 pi)
        # row ((d * r + iz) * r + iy) * r + ix, d = theta bin * N_phi + phi bin
        t, p, z, y, x = np.meshgrid(th, ph, i, i, i, indexing="ij")
        cols = [mi.Float(np.ascontiguousarray(a).ravel().astype(np.float32)) for a in (x, y, z, t, p)]
        self.table = mi.Float(log_sigma(cols))
        dr.eval(self.table)

    def __call__(self, xn, wo):
        """sigma [Float, radians] at unit-box points xn [Vector3f] and object-space directions wo [Vector3f]."""
        dr, mi = _dr(), self.mi
        r = self.r
        f = [(dr.clip(dr.select(dr.isfinite(c), c, 0.0), -1.0, 1.0) + 1.0) * (0.5 * (r - 1)) for c in (xn.x, xn.y, xn.z)]
        i0 = [dr.minimum(mi.UInt32(c), r - 2) for c in f]
        fr = [c - mi.Float(i) for c, i in zip(f, i0, strict=True)]
        w = safe_normalize(mi, mi.Vector3f(wo))
        theta = dr.atan2(dr.sqrt(dr.square(w.x) + dr.square(w.y)), w.z)
        phi = dr.atan2(w.y, w.x)
        it = mi.UInt32(dr.clip(dr.select(dr.isfinite(theta), theta, 0.0) * (self.nt / math.pi), 0.0, self.nt - 1))
        ip = mi.UInt32(dr.clip((dr.select(dr.isfinite(phi), phi, 0.0) + math.pi) * (self.np / TWO_PI), 0.0, self.np - 1))
        base = (it * self.np + ip) * (r * r * r)
        out = None
        for dz in (0, 1):
            for dy in (0, 1):
                for dx in (0, 1):
                    idx = base + ((i0[2] + dz) * r + (i0[1] + dy)) * r + (i0[0] + dx)
                    wgt = (fr[0] if dx else 1.0 - fr[0]) * (fr[1] if dy else 1.0 - fr[1]) * (fr[2] if dz else 1.0 - fr[2])
                    term = dr.gather(mi.Float, self.table, idx) * wgt
                    out = term if out is None else out + term
        return dr.exp(out)


class NeupressJit:
    """A neupress surface asset ready for Dr.Jit.

    ``transport(x, n, wo, wi) -> (S + f_r |n.wi|, S)`` Color3f (1/sr): the first for light the asset does not
    block (V_self = 1), the second for light behind the asset itself (V_self = 0; S already holds the
    self-shadowing). ``technique(x, n, wo)`` is the Gaussian lobe when the asset has ``sampling``, else None
    (the integrator samples the uniform world sphere; so does ``nasset_path`` with ``lobe`` false)."""

    to_unit_box = RnaJit.to_unit_box  # the encoding box of encodings.md#unit-box, as for rna
    kind = "neupress"
    fiber = False  # neupress assets are surfaces: the frame is the normal, no h

    def __init__(self, mi, path: str) -> None:
        self.mi = mi
        self.path = str(path)
        asset = open_asset(path, kinds=("neupress",))
        self.g = self._fourier(asset, "core", 7)
        self.ggx = GgxJit(mi, *boundary_params(asset.tensor("core", "boundary")))
        self.appearance = DrJitNetwork(mi, asset.evaluable_bytes("core", "appearance"), file=self.path,
                                       prim=f"{COMPONENTS}/core/appearance")
        self.sigma_net = None
        if "sampling" in asset.components():
            asset.load(["sampling"])
            self.gs = self._fourier(asset, "sampling", 5)
            self.sigma_net = DrJitNetwork(mi, asset.evaluable_bytes("sampling", "sigma"), file=self.path,
                                          prim=f"{COMPONENTS}/sampling/sigma")
        self._sigma_table = None  # SigmaTable, built on first use (a render that samples the lobe)
        self.asset = asset
        self.prt = None  # (coefficients Float [V*T*P*27], T, P, V), read on first use (PRT mode only)
        lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
        self.lo = lo
        # spec/kinds/neupress.md#near-field-fetch: f (0 when not authored) and the encoding box's centre (object
        # space); the integrator fetches the light of rna and neupress hits alike (plugins.py)
        self.fetch = asset.near_field_fetch
        self.centre = 0.5 * (lo + hi)
        self.span = np.maximum(hi - lo, 1e-30)
        self.geometry = asset.geometry()

    def _fourier(self, asset, component: str, width: int) -> np.ndarray:
        g = np.asarray(asset.tensor(component, "fourier"), np.float32)
        if g.ndim != 2 or g.shape[1] != width or not np.isfinite(g).all():
            raise error("TENSOR_CONTRACT", f"fourier matrix of shape {g.shape} is not a finite [M, {width}]", file=self.path,
                        prim=f"{COMPONENTS}/{component}/fourier")
        return g

    def subsurface(self, x, wo, wi) -> list:
        """S^(wi; x, wo) as 3 Floats (1/sr): NaN/Inf -> 0, then max(0, y)."""
        dr = _dr()
        xn = self.to_unit_box(x)
        v = [xn.x, xn.y, xn.z] + spherical(self.mi, wo) + spherical(self.mi, wi)
        y = self.appearance(fourier_features(self.g, v))
        return [dr.select(dr.isfinite(c), dr.maximum(c, 0.0), 0.0) for c in y]

    def reflection(self, n, wo, wi):
        """f_r |n.wi| [Float, 1/sr] of the boundary (the same in R, G, B)."""
        return self.ggx.eval(n, wo, wi)

    def transport(self, x, n, wo, wi, h=None):
        """(unshadowed S + f_r |n.wi|, shadowed S) [Color3f, 1/sr]; h (fibers only) is ignored."""
        s = self.mi.Color3f(*self.subsurface(x, wo, wi))
        return s + self.reflection(n, wo, wi), s

    def _log_sigma(self, v: list):
        """clamp(y, ln 1e-3, ln 1e3) [Float] of the ``sampling`` network at v = [xn (3), theta_o / pi, phi_o / 2 pi],
        NaN y -> 0."""
        dr = _dr()
        (y,) = self.sigma_net(fourier_features(self.gs, v))
        return dr.clip(dr.select(dr.isnan(y), 0.0, y), *LOG_SIGMA)

    def sigma(self, x, wo):
        """Lobe width [Float, radians] from the ``sampling`` network: exp(clamp(y, ln 1e-3, ln 1e3)), NaN y -> 1."""
        xn = self.to_unit_box(x)
        return _dr().exp(self._log_sigma([xn.x, xn.y, xn.z] + spherical(self.mi, wo)))

    #: False: the technique evaluates the ``sampling`` network at every vertex instead of :class:`SigmaTable`
    tabulate_sigma = True

    @property
    def sigma_table(self) -> SigmaTable:
        """The :class:`SigmaTable` of the ``sampling`` network, built on first use: renders that never sample the
        lobe (``lobe`` false, PRT) do not pay for it (0.2 s at ``small``, 2.6 s at ``hq``)."""
        if self.sigma_net is None:
            raise error("COMPONENT_MISSING", "the asset has no sampling component to tabulate", file=self.path,
                        prim=f"{COMPONENTS}/sampling")
        if self._sigma_table is None:
            self._sigma_table = SigmaTable(self.mi, self._log_sigma)
        return self._sigma_table

    def technique(self, x, n, wo):
        """The asset's direction sampler at a vertex: :class:`GaussianLobe` around n with sigma from the table (or
        the network, :attr:`tabulate_sigma`), or None (uniform world sphere)."""
        if self.sigma_net is None:
            return None
        sigma = self.sigma_table(self.to_unit_box(x), wo) if self.tabulate_sigma else self.sigma(x, wo)
        return GaussianLobe(self.mi, safe_normalize(self.mi, n), sigma)

    def _prt_table(self):
        if self.prt is None:
            if "prt" not in self.asset.components():
                raise error("COMPONENT_MISSING", "PRT shading needs the asset's 'prt' component", file=self.path,
                            prim=f"{COMPONENTS}/prt")
            self.asset.load(["prt"])
            sh = np.asarray(self.asset.tensor("prt", "sh"), np.float32)
            if sh.ndim != 5 or sh.shape[3:] != (9, 3) or min(sh.shape[:3]) < 1:
                raise error("TENSOR_CONTRACT", f"prt sh of shape {sh.shape} is not [V, T, P, 9, 3]", file=self.path,
                            prim=f"{COMPONENTS}/prt/sh")
            self.prt = (self.mi.Float(np.ascontiguousarray(sh).ravel()), sh.shape[1], sh.shape[2], sh.shape[0])
        return self.prt

    def prt_radiance(self, light_sh, vertex, n, wo):
        """sum_k a_k(vertex, bin(wo)) b_k [Color3f] of neupress.md#component-prt: ``light_sh`` b [9, 3] (numpy,
        the same for every lane) or a list of 27 Floats (per lane, b[k, c] at 3 k + c), ``vertex`` UInt32
        indices (past V - 1 read V - 1), ``n`` the vertex normals n_v and ``wo`` object-space directions [Vector3f].
        The w_o bin in the local frame of n_v, equal solid angle in theta, below the surface theta bin T - 1."""
        dr, mi = _dr(), self.mi
        coeff, nt, nphi, nv = self._prt_table()
        if isinstance(light_sh, list):
            if len(light_sh) != 27:
                raise error("USAGE", f"light_sh as a list needs 27 Floats, got {len(light_sh)}")
            b = [light_sh[3 * k:3 * k + 3] for k in range(9)]
        else:
            b = np.asarray(light_sh, np.float64)
            if b.shape != (9, 3) or not np.isfinite(b).all():
                raise error("USAGE", f"light_sh must be a finite [9, 3], got {b.shape}")
            b = b.tolist()
        n = safe_normalize(mi, mi.Vector3f(n))
        w = safe_normalize(mi, mi.Vector3f(wo))
        t, bt = local_frame(mi, n)
        ti = mi.UInt32(dr.clip(dr.floor((1.0 - dr.clip(dr.dot(w, n), 0.0, 1.0)) * nt), 0, nt - 1))
        pi = mi.UInt32(dr.clip(dr.floor((dr.atan2(dr.dot(w, bt), dr.dot(w, t)) + math.pi) * (nphi / TWO_PI)), 0, nphi - 1))
        v = dr.minimum(mi.UInt32(vertex), nv - 1)
        base = ((v * nt + ti) * nphi + pi) * 27
        out = [None, None, None]
        for k in range(9):
            for c in range(3):
                term = dr.gather(mi.Float, coeff, base + (3 * k + c)) * b[k][c]
                out[c] = term if out[c] is None else out[c] + term
        return mi.Color3f(*out)
