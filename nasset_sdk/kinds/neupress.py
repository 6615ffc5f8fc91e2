"""Kind ``neupress``: Neural Precomputed Subsurface Scattering
(papers/neupress-precomputed-subsurface-scattering.txt, spec/kinds/neupress.md).

The appearance MLP represents S^(w_i; x_o, w_o), outgoing radiance per unit radiance of a distant
light from w_i (full sphere, units 1/sr when integrated over solid angle), subsurface transport only.
Surface reflection at x_o is the analytic GGX rough dielectric of :mod:`.boundary`. Network input is
the Fourier feature map gamma(v) = [cos(2 pi G v), sin(2 pi G v)] of

    appearance: v = [xn (3), theta_o/pi, phi_o/(2 pi), theta_i/pi, phi_i/(2 pi)]   (7, object space)
    sampling:   v = [xn (3), theta_o/pi, phi_o/(2 pi)]                              (5)

with xn = to_unit_box(x) and spherical angles of object-space directions (encodings.spherical_coords).
The sampling network predicts log sigma of a zero-mean 2D Gaussian in the azimuthal-equidistant
projection around the normal n; sigma = exp(clamp(y, log SIGMA_MIN, log SIGMA_MAX)).
"""

from __future__ import annotations

import numpy as np

from ..errors import UsageError
from . import ComponentSpec, Finding, KindContract, NetworkSpec, TensorSpec, new_evaluator, register_kind, rows3
from .boundary import boundary_params, ggx_reflection
from .encodings import atan2_columns, fourier_features, from_local, sh9, spherical_coords, to_local, to_unit_box, unit64
from .query import Evaluator, Query

#: preset -> (M appearance frequencies, hidden layers, hidden width, Ms sampling frequencies,
#:            sampling hidden widths, PRT theta bins, PRT phi bins)
SIZES = {
    "tiny": (16, 3, 16, 8, (16, 8), 2, 4),
    "small": (64, 5, 64, 32, (128, 32), 8, 16),
    "hq": (256, 7, 128, 256, (512, 128, 32), 16, 64),
}
SIGMA_MIN = 1e-3
SIGMA_MAX = 1e3
#: paper section 4.1: G ~ N(18, 1) elementwise
FOURIER_MEAN = 18.0
FOURIER_STD = 1.0


# ----------------------------------------------------------------------------------------
# Gaussian lobe in the azimuthal equidistant projection (spec/kinds/neupress.md#lobe)


def _sigma(sigma, n: int) -> np.ndarray:
    s = np.nan_to_num(np.asarray(sigma, np.float64), nan=1.0, posinf=SIGMA_MAX, neginf=SIGMA_MIN)
    s = np.broadcast_to(s, (n,)) if s.ndim == 0 else s.reshape(-1)
    return np.clip(s, SIGMA_MIN, SIGMA_MAX)


def _disk_mass(sigma: np.ndarray) -> np.ndarray:
    """2 pi sigma^2 Z with Z = 1 - exp(-pi^2 / (2 sigma^2)) (the truncated Gaussian's mass times its peak)."""
    return 2.0 * np.pi * sigma * sigma * -np.expm1(-np.pi ** 2 / (2.0 * sigma * sigma))


def gaussian_lobe_pdf(n, sigma, wi) -> np.ndarray:
    """Density per steradian [N] of :func:`gaussian_lobe_sample` at wi.

    r = acos(n . wi), pdf = exp(-r^2 / (2 sigma^2)) / (2 pi sigma^2 Z) * r / sin r,
    with r / sin r = 1 + r^2 / 6 for r < 1e-4 and r / max(sin r, 1e-7) otherwise (finite at wi = -n).
    """
    n = unit64(n)
    wi = unit64(wi)
    s = _sigma(sigma, len(n))
    c = np.clip((n * wi).sum(1), -1.0, 1.0)
    r = np.arccos(c)
    jac = np.where(r < 1e-4, 1.0 + r * r / 6.0, r / np.maximum(np.sin(r), 1e-7))
    return np.exp(-r * r / (2.0 * s * s)) / _disk_mass(s) * jac


def gaussian_lobe_sample(n, sigma, u2) -> tuple[np.ndarray, np.ndarray]:
    """Box-Muller draw restricted to the projection disk |p| <= pi: (wi [N,3], pdf [N]).

    r = sigma sqrt(-2 log1p(u1 expm1(-pi^2 / (2 sigma^2)))) (clamped to pi), phi = 2 pi u2,
    wi = cos r n + sin r (cos phi t + sin phi b) with (t, b, n) = encodings.local_frame(n).
    """
    n = unit64(n)
    u2 = np.clip(np.nan_to_num(np.asarray(u2, np.float64)), 0.0, 1.0 - 1e-16)
    if u2.shape != (len(n), 2):
        raise UsageError(f"u2 must be [N, 2], got {u2.shape}")
    s = _sigma(sigma, len(n))
    a = np.pi ** 2 / (2.0 * s * s)
    r = s * np.sqrt(np.maximum(-2.0 * np.log1p(u2[:, 0] * np.expm1(-a)), 0.0))
    r = np.minimum(r, np.pi)
    phi = 2.0 * np.pi * u2[:, 1]
    sr = np.sin(r)
    wi = from_local(np.stack([sr * np.cos(phi), sr * np.sin(phi), np.cos(r)], axis=1), n)
    wi = unit64(wi)
    return wi, gaussian_lobe_pdf(n, s, wi)


# ----------------------------------------------------------------------------------------


def skip_mlp(rng, in_width: int, hidden: int, layers: int, out: int) -> bytes:
    """Random MLP with ``layers`` hidden ReLU layers and skip connections (i, i+2), i = 0, 2, ...,
    i + 2 < layers: the input of layer i (before its own skip concat) is appended to the input of layer i + 2."""
    from ..networks import mlp_onnx

    skips = [(i, i + 2) for i in range(0, layers, 2) if i + 2 < layers]
    skip_src = {d: s for s, d in skips}
    in_w: list[int] = []
    ws, bs = [], []
    width = in_width
    for i in range(layers + 1):
        w_in = width + (in_w[skip_src[i]] if i in skip_src else 0)
        in_w.append(width)  # mlp_onnx concatenates the input of layer src before its own skip
        w_out = out if i == layers else hidden
        ws.append(rng.normal(0.0, np.sqrt(2.0 / w_in), (w_in, w_out)).astype(np.float32))
        bs.append(rng.normal(0.0, 0.05, w_out).astype(np.float32))
        width = w_out
    return mlp_onnx(ws, bs, skips=skips, name="neupress_appearance")


class NeupressKind(KindContract):
    id = "neupress"
    variants = ("surface",)
    paper = "neupress-precomputed-subsurface-scattering.txt"

    def components(self, variant: str) -> dict[str, ComponentSpec]:
        return {
            "core": ComponentSpec(
                required=True,
                purpose="evaluation",
                tensors={
                    "fourier": TensorSpec(("M", "7"), "frequency,input", "Fourier matrix G of the appearance input v (7)"),
                    "boundary": TensorSpec(("2",), "parameter", "rough dielectric boundary: eta (n_in/n_out), GGX alpha"),
                },
                networks={"appearance": NetworkSpec((("x", "2*M"),), (("y", "3"),),
                                                    "subsurface transport RGB from [cos(2 pi G v), sin(2 pi G v)]")},
            ),
            "sampling": ComponentSpec(
                required=False,
                purpose="importance-sampling",
                tensors={"fourier": TensorSpec(("S", "5"), "frequency,input", "Fourier matrix of the sampling input v (5)")},
                networks={"sigma": NetworkSpec((("x", "2*S"),), (("y", "1"),), "log sigma of the Gaussian lobe around n")},
            ),
            "prt": ComponentSpec(
                required=False,
                purpose="prt",
                tensors={"sh": TensorSpec(("V", "T", "P", "9", "3"), "vertex,theta_o,phi_o,sh,rgb",
                                          "degree-2 SH transport coefficients per vertex and local w_o bin")},
            ),
            "portable": ComponentSpec(
                required=False,
                purpose="portable-evaluation",
                networks={"appearance": NetworkSpec((("x", "3"), ("wo", "3"), ("wi", "3")), (("transport", "3"),),
                                                    "the appearance MLP with its encodings: raw queries to clamped transport")},
            ),
        }

    def value_findings(self, variant, present, get_tensor, prim_of) -> list[Finding]:
        out: list[Finding] = []
        for comp, names in (("core", ("fourier", "boundary")), ("sampling", ("fourier",)), ("prt", ("sh",))):
            tensors = present.get(comp, ({}, {}))[0]
            for name in names:
                if name not in tensors:
                    continue
                arr = np.asarray(get_tensor(comp, name), np.float64)
                if not np.isfinite(arr).all():
                    out.append(Finding("KIND_CONTRACT", f"{name} holds NaN/Inf", prim_of(comp, name), "values"))
                elif comp == "core" and name == "boundary" and not (arr[0] > 0 and arr[1] > 0):
                    out.append(Finding("KIND_CONTRACT", f"boundary (eta, alpha) = {tuple(arr)} must both be > 0",
                                       prim_of(comp, name), "values"))
        return out

    def build_random(self, rng, *, variant="surface", size="small", geometry=None):
        from ..asset import AssetBuilder
        from ..geometry import MeshGeometry
        from ..networks import random_mlp
        from .rna import example_mesh

        if variant not in self.variants:
            raise UsageError(f"neupress has no variant {variant!r}")
        if size not in SIZES:
            raise UsageError(f"size must be one of {sorted(SIZES)}")
        m, layers, hidden, ms, s_hidden, nt, nphi = SIZES[size]
        b = AssetBuilder("neupress", variant=variant)
        if geometry is None:
            geometry = example_mesh()
        if not isinstance(geometry, MeshGeometry):
            geometry = MeshGeometry.from_trimesh(geometry)
        b.set_geometry(geometry)
        core = b.component("core", required=True, purpose="evaluation", quality=None)
        core.add_tensor("fourier", rng.normal(FOURIER_MEAN, FOURIER_STD, (m, 7)), dtype="float32", layout="frequency,input")
        core.add_tensor("boundary", np.array([1.5, 0.2]), dtype="float32", layout="parameter")
        core.add_network("appearance", skip_mlp(rng, 2 * m, hidden, layers, 3))
        samp = b.component("sampling", required=False, purpose="importance-sampling", quality=None)
        samp.add_tensor("fourier", rng.normal(FOURIER_MEAN, FOURIER_STD, (ms, 5)), dtype="float32", layout="frequency,input")
        samp.add_network("sigma", random_mlp(rng, [2 * ms, *s_hidden, 1]))
        prt = b.component("prt", required=False, purpose="prt", quality=None)
        v = len(geometry.points)
        prt.add_tensor("sh", rng.normal(0, 0.1, (v, nt, nphi, 9, 3)), dtype="float16", layout="vertex,theta_o,phi_o,sh,rgb")
        b.provenance = {"generator": "random", "size": size}
        return b

    def evaluator(self, asset, **options):
        return new_evaluator(NeupressEvaluator, asset, options)


class NeupressEvaluator(Evaluator):
    """numpy + onnxruntime evaluation of a neupress asset; all vectors in object space.

    :meth:`radiance` (the interface every kind shares) is S + f_r |n.w_i| (the reflection zeroed where
    ``Query.shadowed``); :meth:`evaluate` is the subsurface term S alone."""

    def __init__(self, asset, *, intra_threads: int = 0, batch: int = 65536) -> None:
        self.asset = asset
        self.lo, self.hi = asset.domain
        self.G = np.asarray(asset.tensor("core", "fourier"), np.float32)
        self.eta, self.alpha = boundary_params(asset.tensor("core", "boundary"))
        self.session = asset.session("core", "appearance", intra_threads=intra_threads)
        comps = asset.components()
        self.has_sampling = "sampling" in comps and comps["sampling"].loaded
        self.has_prt = "prt" in comps and comps["prt"].loaded
        if self.has_sampling:
            self.Gs = np.asarray(asset.tensor("sampling", "fourier"), np.float32)
            self.sigma_session = asset.session("sampling", "sigma", intra_threads=intra_threads)
        self.batch = int(batch)

    def _run(self, session, feats: np.ndarray, width: int) -> np.ndarray:
        out = np.empty((len(feats), width), np.float32)
        for s in range(0, len(feats), self.batch):
            out[s:s + self.batch] = session.run(None, {"x": feats[s:s + self.batch]})[0]
        return out

    def appearance_input(self, x, wo, wi) -> np.ndarray:
        """v [N, 7] = [xn, theta_o/pi, phi_o/2pi, theta_i/pi, phi_i/2pi] (float32)."""
        return np.concatenate([to_unit_box(x, self.lo, self.hi), spherical_coords(wo), spherical_coords(wi)], axis=1)

    def evaluate(self, x, n, wo, wi) -> np.ndarray:
        """Subsurface transport S^(wi; x, wo) RGB [N,3] per unit incident radiance (>= 0, finite).

        ``n`` is not a network input (the paper's network sees x, wo, wi only); it is checked for shape
        so all neupress calls share arguments."""
        x, n, wo, wi = rows3(x, n, wo, wi)
        y = self._run(self.session, fourier_features(self.G, self.appearance_input(x, wo, wi)), 3)
        y = np.nan_to_num(y, nan=0.0, posinf=0.0, neginf=0.0)
        return np.maximum(y, 0.0)

    def _radiance(self, q: Query) -> np.ndarray:
        self._no_h(q)
        return self.evaluate(q.x, q.n, q.wo, q.wi) + self.surface_reflection(q.n, q.wo, q.wi) * ~q.shadowed[:, None]

    def surface_reflection(self, n, wo, wi) -> np.ndarray:
        """Analytic GGX rough-dielectric reflection f |n.wi| as RGB [N,3] (grey)."""
        n, wo, wi = rows3(n, wo, wi)
        f = ggx_reflection(n, wo, wi, self.eta, self.alpha).astype(np.float32)
        return np.repeat(f[:, None], 3, axis=1)

    def sigma(self, x, wo) -> np.ndarray:
        """Lobe standard deviation [N] (radians in the projection plane), in [SIGMA_MIN, SIGMA_MAX]."""
        if not self.has_sampling:
            raise UsageError("component 'sampling' is not loaded; open with load=['core', 'sampling'] or 'all'")
        x, wo = rows3(x, wo)
        v = np.concatenate([to_unit_box(x, self.lo, self.hi), spherical_coords(wo)], axis=1)
        y = self._run(self.sigma_session, fourier_features(self.Gs, v), 1)[:, 0].astype(np.float64)
        y = np.nan_to_num(y, nan=0.0, posinf=np.log(SIGMA_MAX), neginf=np.log(SIGMA_MIN))
        return np.exp(np.clip(y, np.log(SIGMA_MIN), np.log(SIGMA_MAX)))

    def sample_lobe(self, x, n, wo, u2) -> tuple[np.ndarray, np.ndarray]:
        """wi [N,3] ~ Gaussian lobe around n with the network's sigma, and its pdf per steradian [N]."""
        x, n, wo = rows3(x, n, wo)
        return gaussian_lobe_sample(n, self.sigma(x, wo), u2)

    def lobe_pdf(self, x, n, wo, wi) -> np.ndarray:
        x, n, wo, wi = rows3(x, n, wo, wi)
        return gaussian_lobe_pdf(n, self.sigma(x, wo), wi)

    def prt_coefficients(self) -> np.ndarray:
        """SH transport coefficients [V, T, P, 9, 3] float32 (component 'prt')."""
        if not self.has_prt:
            raise UsageError("component 'prt' is not loaded; open with load='all'")
        return np.asarray(self.asset.tensor("prt", "sh"), np.float32)

    def prt_radiance(self, light_sh, vertex, n, wo) -> np.ndarray:
        """Outgoing subsurface radiance [N,3] = sum_k a_k b_k at a vertex, from lighting SH b [9, 3].

        The w_o bin is the one containing wo in the local frame of n (nearest bin, no interpolation):
        theta bin = min(floor((1 - cos theta_o) T), T - 1) (equal solid angle), phi bin =
        min(floor((phi_o + pi) / (2 pi) P), P - 1); wo below the surface uses theta bin T - 1.
        """
        a = self.prt_coefficients()
        b = np.asarray(light_sh, np.float64)
        if b.shape != (9, 3):
            raise UsageError(f"light_sh must be [9, 3], got {b.shape}")
        vertex = np.asarray(vertex, np.int64).reshape(-1)
        if (vertex < 0).any() or (vertex >= a.shape[0]).any():
            raise UsageError("vertex index out of range")
        n, wo = rows3(n, wo)
        loc = to_local(unit64(wo), n)
        t_bins, p_bins = a.shape[1], a.shape[2]
        ti = np.clip(np.floor((1.0 - np.clip(loc[:, 2], 0.0, 1.0)) * t_bins), 0, t_bins - 1).astype(np.int64)
        pi_ = np.clip(np.floor((atan2_columns(loc, 1, 0) + np.pi) / (2 * np.pi) * p_bins), 0, p_bins - 1).astype(np.int64)
        coeff = a[vertex, ti, pi_].astype(np.float64)  # [N, 9, 3]
        return (coeff * b[None]).sum(1).astype(np.float32)


def sh_project_light(directions, radiance, weights) -> np.ndarray:
    """Lighting coefficients b [9, 3] = sum_j L(w_j) Y(w_j) weight_j (a quadrature of Eq. 9)."""
    y = sh9(directions)
    return (y[:, :, None] * np.asarray(radiance, np.float64)[:, None, :] * np.asarray(weights, np.float64)[:, None, None]).sum(0)


register_kind(NeupressKind())
