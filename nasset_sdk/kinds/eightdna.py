"""Kind ``8dna``: 8D neural asset light transport (papers/8dna-8d-neural-asset-light-transport.txt,
spec/kinds/8dna.md).

Indirect transport F(x_o, w_o, x_i, w_i) = alpha(x_o, w_o) p(x_i, w_i | x_o, w_o) per colour channel.
alpha comes from the albedo MLP; p is an autoregressive rational-quadratic spline flow over the
bounding-box cylindrical parameters s = (u^z/|u|, atan2(u^y, u^x), w^z, atan2(w^y, w^x)) of the
incident ray (u_i on the asset box, w_i pointing away from the asset towards the light). The direct
lobe (one boundary reflection at x_o) is the analytic GGX rough dielectric of :mod:`.boundary`.

Network inputs (object space, unit directions; xn = to_unit_box(x_o); base = [tri(xn) (C), xn (3), cube_wo(w_o) (C), w_o (3)]):

    albedo: base                                                        2C + 6  -> 3
    flow1:  base                                                        2C + 6  -> G
    flow2:  base, grid_s1(s1) (C), s1                                   3C + 7  -> G
    flow3:  base, cube_s12(d12) (C), d12 (3)                            3C + 9  -> G
    flow4:  base, cube_s12(d12) (C), d12 (3), grid_s3(s3) (C), s3       4C + 10 -> G

with d12 = (sqrt(1 - s1^2) cos s2, sqrt(1 - s1^2) sin s2, s1) and G = 3 (3K + 1) spline parameters.
"""

from __future__ import annotations

import numpy as np

from ..errors import UsageError, error
from ..networks import CheckedSession, make_session, mlp_onnx, split_first_layer
from . import ComponentSpec, Finding, KindContract, NetworkSpec, TensorSpec, new_evaluator, register_kind, rows3
from .boundary import boundary_params, ggx_pdf, ggx_reflection, ggx_reflection_pdf, ggx_sample
from .encodings import cube_table, cubemap, grid_1d, to_unit_box, triplane, unit64
from .query import Evaluator, Query
from .spline import MIN_BIN_HEIGHT, MIN_BIN_WIDTH, MIN_DERIVATIVE, BoxFlow, BoxParam, FlowSample, cylindrical_to_direction, finite64

#: ``spline_dtype`` option of the evaluator -> float type of the spline knots (float64: the spec)
SPLINE_DTYPE_NAMES = {"float64": np.float64, "float32": np.float32}

#: preset -> (triplane R, channels C, cube Q (w_o and s12), 1D grid L, spline bins K,
#:            flow hidden layers, flow width, albedo hidden layers, albedo width)
SIZES = {
    "tiny": (8, 4, 4, 8, 4, 2, 16, 1, 16),
    "small": (32, 8, 16, 32, 16, 4, 128, 2, 64),
    "hq": (64, 8, 32, 32, 32, 4, 128, 2, 128),
}
FLOWS = ("flow1", "flow2", "flow3", "flow4")


def spline_bins(g_width: int) -> int | None:
    """K from the flow output width G = 3 (3K + 1); None if G has no such form."""
    if g_width <= 0 or g_width % 3:
        return None
    p = g_width // 3
    if (p - 1) % 3 or p < 4:
        return None
    return (p - 1) // 3


class EightDnaKind(KindContract):
    id = "8dna"
    variants = ("surface",)
    paper = "8dna-8d-neural-asset-light-transport.txt"

    def components(self, variant: str) -> dict[str, ComponentSpec]:
        base = "2*C+6"
        return {
            "core": ComponentSpec(
                required=True,
                purpose="evaluation",
                tensors={
                    "triplane": TensorSpec(("3", "R", "R", "C"), "plane,v,u,channel", "x_o feature planes XY, YZ, ZX"),
                    "woCube": TensorSpec(("6", "Q", "Q", "C"), "face,t,s,channel", "w_o cube-map features"),
                    "s1Grid": TensorSpec(("L", "C"), "texel,channel", "1D features of s1 in [-1, 1]"),
                    "s3Grid": TensorSpec(("L", "C"), "texel,channel", "1D features of s3 in [-1, 1]"),
                    "s12Cube": TensorSpec(("6", "Q", "Q", "C"), "face,t,s,channel", "cube-map features of d12(s1, s2)"),
                    "splineMinimums": TensorSpec(("3",), "parameter", "min bin width, min bin height, min derivative"),
                    "direct": TensorSpec(("2",), "parameter", "direct lobe rough dielectric: eta (n_in/n_out), GGX alpha"),
                },
                networks={
                    "albedo": NetworkSpec((("x", base),), (("y", "3"),), "indirect albedo RGB"),
                    "flow1": NetworkSpec((("x", base),), (("g", "G"),), "spline parameters of s1"),
                    "flow2": NetworkSpec((("x", "3*C+7"),), (("g", "G"),), "spline parameters of s2 | s1"),
                    "flow3": NetworkSpec((("x", "3*C+9"),), (("g", "G"),), "spline parameters of s3 | s1, s2"),
                    "flow4": NetworkSpec((("x", "4*C+10"),), (("g", "G"),), "spline parameters of s4 | s1, s2, s3"),
                },
            ),
            "portable": ComponentSpec(
                required=False,
                purpose="portable-evaluation",
                networks={"albedo": NetworkSpec((("x", "3"), ("wo", "3")), (("albedo", "3"),),
                                                "the albedo MLP with its encodings: raw queries to clamped albedo")},
            ),
        }

    def value_findings(self, variant, present, get_tensor, prim_of) -> list[Finding]:
        out: list[Finding] = []
        if "core" not in present:
            return out
        tensors, networks = present["core"]
        for name in tensors:
            arr = np.asarray(get_tensor("core", name), np.float64)
            if not np.isfinite(arr).all():
                out.append(Finding("KIND_CONTRACT", f"{name} holds NaN/Inf", prim_of("core", name), "values"))
        k = None
        if "flow1" in networks:
            g = int(networks["flow1"][3][0])
            k = spline_bins(g)
            if k is None:
                out.append(Finding("KIND_CONTRACT", f"flow output width {g} is not 3 (3K + 1) for an integer K >= 1",
                                   prim_of("core", "flow1"), "onnx:outputWidths"))
        if "splineMinimums" in tensors:
            m = np.asarray(get_tensor("core", "splineMinimums"), np.float64).reshape(-1)
            if np.isfinite(m).all():
                kk = k or 1
                if not (m[0] >= 0 and m[1] >= 0 and m[0] * kk < 1 and m[1] * kk < 1 and m[2] > 0):
                    out.append(Finding("KIND_CONTRACT", f"spline minimums {tuple(m)} make knots non-monotone or derivatives"
                                       f" non-positive for K={kk} (need 0 <= K m_w < 1, 0 <= K m_h < 1, m_d > 0)",
                                       prim_of("core", "splineMinimums"), "values"))
        if "direct" in tensors:
            d = np.asarray(get_tensor("core", "direct"), np.float64).reshape(-1)
            if np.isfinite(d).all() and not (d[0] > 0 and d[1] > 0):
                out.append(Finding("KIND_CONTRACT", f"direct (eta, alpha) = {tuple(d)} must both be > 0",
                                   prim_of("core", "direct"), "values"))
        return out

    def build_random(self, rng, *, variant="surface", size="small", geometry=None):
        from ..asset import AssetBuilder
        from ..geometry import MeshGeometry
        from ..networks import random_mlp
        from .rna import example_mesh

        if variant not in self.variants:
            raise UsageError(f"8dna has no variant {variant!r}")
        if size not in SIZES:
            raise UsageError(f"size must be one of {sorted(SIZES)}")
        r, c, q, ln, k, f_layers, f_width, a_layers, a_width = SIZES[size]
        b = AssetBuilder("8dna", variant=variant)
        if geometry is None:
            geometry = example_mesh()
        if not isinstance(geometry, MeshGeometry):
            geometry = MeshGeometry.from_trimesh(geometry)
        b.set_geometry(geometry)
        core = b.component("core", required=True, purpose="evaluation", quality=None)
        core.add_tensor("triplane", rng.normal(0, 0.5, (3, r, r, c)), dtype="float16", layout="plane,v,u,channel")
        core.add_tensor("woCube", rng.normal(0, 0.5, (6, q, q, c)), dtype="float16", layout="face,t,s,channel")
        core.add_tensor("s1Grid", rng.normal(0, 0.5, (ln, c)), dtype="float16", layout="texel,channel")
        core.add_tensor("s3Grid", rng.normal(0, 0.5, (ln, c)), dtype="float16", layout="texel,channel")
        core.add_tensor("s12Cube", rng.normal(0, 0.5, (6, q, q, c)), dtype="float16", layout="face,t,s,channel")
        core.add_tensor("splineMinimums", np.array([MIN_BIN_WIDTH, MIN_BIN_HEIGHT, MIN_DERIVATIVE]), dtype="float32",
                        layout="parameter")
        core.add_tensor("direct", np.array([1.5, 0.1]), dtype="float32", layout="parameter")
        g = 3 * (3 * k + 1)
        core.add_network("albedo", random_mlp(rng, [2 * c + 6] + [a_width] * a_layers + [3]))
        for name, width in zip(FLOWS, (2 * c + 6, 3 * c + 7, 3 * c + 9, 4 * c + 10), strict=True):
            core.add_network(name, random_mlp(rng, [width] + [f_width] * f_layers + [g], output_name="g"))
        b.provenance = {"generator": "random", "size": size}
        return b

    def probe_unit_columns(self, variant, component, network, input_name, width):
        """w_o of the base features and d12 of flow3 / flow4 (module docstring); the portable graph's wo."""
        if component == "portable":
            return (0,) if input_name == "wo" else ()
        k, extra = {"albedo": (2, 6), "flow1": (2, 6), "flow2": (3, 7), "flow3": (3, 9), "flow4": (4, 10)}.get(network, (0, 0))
        if not k or (width - extra) % k or width < extra:
            return ()
        c = (width - extra) // k
        return (2 * c + 3,) + ((3 * c + 6,) if network in ("flow3", "flow4") else ())

    def evaluator(self, asset, **options):
        return new_evaluator(EightDnaEvaluator, asset, options)


class FlowContext:
    """Per-row conditioning of the flow: base features [N, 2C+6] (float32) and, where the flow networks'
    first layers are split (:func:`~nasset_sdk.networks.split_first_layer`), their base-column
    pre-activations, one [N, W1_j] block per conditioner j = 1..4 (else None).

    A context of some rows (:meth:`take`) gathers each block from its parent when first read: a later
    step reads one block (conditioner 4 its own), not all five."""

    def __init__(self, base: np.ndarray, pre: list[np.ndarray] | None, *, rows: np.ndarray | None = None) -> None:
        self._src, self._rows = (base, pre), rows
        self._base = base if rows is None else None
        self._pre = None if pre is None else (list(pre) if rows is None else [None] * len(pre))
        self.s12: tuple[np.ndarray, np.ndarray] | None = None  # (s1, s2 [N, 2], their s12 cube columns [N, C + 3])

    def __len__(self) -> int:
        return len(self._src[0]) if self._rows is None else len(self._rows)

    @property
    def base(self) -> np.ndarray:
        if self._base is None:
            self._base = self._src[0][self._rows]
        return self._base

    @property
    def split(self) -> bool:
        """Whether the pre-activation blocks exist (the flows' first layers are split)."""
        return self._pre is not None

    def pre(self, j: int) -> np.ndarray:
        """[N, W1_j] pre-activation block of conditioner j (1..4); only when :attr:`split`."""
        if self._pre[j - 1] is None:
            self._pre[j - 1] = self._src[1][j - 1][self._rows]
        return self._pre[j - 1]

    def take(self, rows: np.ndarray) -> "FlowContext":
        rows = np.asarray(rows, np.int64).reshape(-1)
        # rows of rows: gather from the original blocks, once
        out = FlowContext(*self._src, rows=rows if self._rows is None else self._rows[rows])
        if self.s12 is not None:
            out.s12 = (self.s12[0][rows], self.s12[1][rows])
        return out

    def s12_columns(self, s12: np.ndarray, compute) -> np.ndarray:
        """Conditioners 3 and 4 read the same s12 cube columns: computed once per (s1, s2) of these rows."""
        if self.s12 is None or not np.array_equal(self.s12[0], s12):
            self.s12 = (np.array(s12), compute(s12))
        return self.s12[1]


class EightDnaEvaluator(Evaluator):
    """numpy + onnxruntime evaluation and sampling of an 8dna asset; object space throughout.

    The four conditioners read the same base features first: at load time each flow network's first
    layer is split into its base columns and the rest (no format change), so one matrix product per
    batch of rows serves all four and each conditioner call computes only the rest.

    ``spline_dtype`` ``"float32"`` builds the spline knots in float32 (the bins' arithmetic stays float64):
    about twice as fast, densities within ~1e-3 relative of the spec's float64 (the evaluator vectors'
    tolerance tier, not their exact tier); for renderers, whose images must match within noise.

    :meth:`radiance` (the interface every kind shares) answers for a distant light: the direct lobe
    plus the flow's density of w_i marginalised over u_i, estimated with ``light_samples`` stratified
    positions per row (fixed latents: deterministic)."""

    def __init__(self, asset, *, intra_threads: int = 0, batch: int = 65536, light_samples: int = 16,
                 fuse_first_layer: bool = True, spline_dtype: str = "float64") -> None:
        if not isinstance(light_samples, int) or not 1 <= light_samples <= 4096:
            raise UsageError(f"light_samples must be an int in 1 .. 4096, got {light_samples!r}",
                             file=str(getattr(asset, "path", "")) or None)
        if spline_dtype not in SPLINE_DTYPE_NAMES:
            raise UsageError(f"spline_dtype must be one of {sorted(SPLINE_DTYPE_NAMES)}, got {spline_dtype!r}",
                             file=str(getattr(asset, "path", "")) or None)
        self.light_samples = light_samples
        self.asset = asset
        self.lo, self.hi = asset.domain
        t = lambda name: np.asarray(asset.tensor("core", name), np.float32)  # noqa: E731
        self.planes, self.wo_cube, self.s12_cube = t("triplane"), t("woCube"), t("s12Cube")
        self.wo_table, self.s12_table = cube_table(self.wo_cube), cube_table(self.s12_cube)  # taps across seams, once
        self.s1_grid, self.s3_grid = t("s1Grid"), t("s3Grid")
        mins = np.asarray(asset.tensor("core", "splineMinimums"), np.float64).reshape(-1)
        self._check_splines(asset, mins)
        self.eta, self.alpha = boundary_params(asset.tensor("core", "direct"))
        self.albedo_session = asset.session("core", "albedo", intra_threads=intra_threads)
        self.flow_sessions = [asset.session("core", n, intra_threads=intra_threads) for n in FLOWS]
        self.head_weight = self.head_bias = self.head = self.tails = None
        if fuse_first_layer:  # off: every flow network runs whole, as stored (the evaluator vectors' exact tier)
            self._split_flows(asset, intra_threads)
        self.batch = int(batch)
        self.box = BoxParam(self.lo, self.hi)
        self.flow = BoxFlow(self.box, self._conditioner, context=self.context, min_bin_width=mins[0],
                            min_bin_height=mins[1], min_derivative=mins[2], spline_dtype=SPLINE_DTYPE_NAMES[spline_dtype])

    def _split_flows(self, asset, intra_threads: int) -> None:
        """Head matrix [2C+6, sum W1_j] + bias and the four tail sessions; None (whole networks) if any
        flow network does not start with a plain affine layer over its input."""
        self.head_weight = self.head_bias = self.head = self.tails = None
        base_width = self.planes.shape[-1] + self.wo_cube.shape[-1] + 6
        refs = asset.network_refs("core")
        for n in FLOWS:  # the split sessions run the networks' bytes too: the runtime probe first, as for asset.session
            asset.check_runtime("core", n)
        try:
            splits = [split_first_layer(asset.network_bytes("core", n), base_width) for n in FLOWS]
        except Exception:  # any graph the splitter cannot read runs whole, which is always correct
            return
        if not all(sp is not None and sp.rest_width == refs[n].info.input_widths[0] - base_width
                   for sp, n in zip(splits, FLOWS, strict=True)):
            return
        tails = []
        for sp, name in zip(splits, FLOWS, strict=True):
            loc = dict(file=str(asset.path), prim=refs[name].prim_path, attribute="onnx:model")
            try:
                session = make_session(sp.tail, intra_threads=intra_threads)
            except Exception:  # a graph onnxruntime accepts whole but not split: run it whole
                return
            tails.append((CheckedSession(session, refs[name].info, **loc), sp.tail_inputs))
        self.head_weight = np.concatenate([sp.head_weight for sp in splits], axis=1)
        self.head_bias = np.concatenate([sp.bias for sp in splits])
        self.head_cols = np.cumsum([0] + [sp.head_weight.shape[1] for sp in splits])
        # one affine layer, run by onnxruntime under the render's thread setting like the other networks
        self.head = make_session(mlp_onnx([self.head_weight], [self.head_bias], output_name="pre", name="flow_heads"),
                                 intra_threads=intra_threads)
        self.tails = tails

    @staticmethod
    def _check_splines(asset, mins: np.ndarray) -> None:
        """``KIND_CONTRACT`` (naming the tensor or network) for spline minimums or flow widths no spline accepts.

        The asset's data, not the caller, is at fault: the contract check of ``value_findings``, as a typed error."""
        refs = asset.network_refs("core")
        widths = {name: int(refs[name].info.output_widths[0]) for name in FLOWS if name in refs}
        ks = {name: spline_bins(g) for name, g in widths.items()}
        for name, k in ks.items():
            if k is None:
                raise error("KIND_CONTRACT", f"flow output width {widths[name]} is not 3 (3K + 1) for an integer K >= 1",
                            file=str(asset.path), prim=refs[name].prim_path, attribute="onnx:outputWidths")
        k = max(ks.values(), default=1)
        if mins.shape != (3,) or not (np.isfinite(mins).all() and 0 <= mins[0] * k < 1 and 0 <= mins[1] * k < 1 and mins[2] > 0):
            prim = asset.tensor_refs("core")["splineMinimums"].prim_path if "splineMinimums" in asset.tensor_refs("core") else None
            raise error("KIND_CONTRACT", f"spline minimums {tuple(mins.tolist())} make knots non-monotone or derivatives "
                        f"non-positive for K={k} (need 0 <= K m_w < 1, 0 <= K m_h < 1, m_d > 0)", file=str(asset.path),
                        prim=prim, attribute="values")

    def _run(self, session, feed: dict[str, np.ndarray]) -> np.ndarray:
        """Session output 0 [N, width] as float64 (NaN -> 0, +-inf -> +-1e30), in row batches of ``batch``."""
        return finite64(self._run32(session, feed))

    def _run32(self, session, feed: dict[str, np.ndarray]) -> np.ndarray:
        """Session output 0 [N, width] as the runtime returns it (float32), in row batches of ``batch``."""
        n = len(next(iter(feed.values())))
        outs = [session.run(None, {k: v[s:s + self.batch] for k, v in feed.items()})[0]
                for s in range(0, n, self.batch)] or [np.zeros((0, session.get_outputs()[0].shape[1]), np.float32)]
        return outs[0] if len(outs) == 1 else np.concatenate(outs, axis=0)

    def base_features(self, x, wo) -> np.ndarray:
        """[N, 2C + 6] = [triplane(xn), xn, cube_wo(w_o), w_o] (float32)."""
        x, wo = rows3(x, wo)
        xn = to_unit_box(x, self.lo, self.hi)
        wo = unit64(wo).astype(np.float32)
        return np.concatenate([triplane(self.planes, xn), xn, cubemap(self.wo_cube, wo, table=self.wo_table), wo], axis=1, dtype=np.float32)

    def context(self, x, wo) -> FlowContext:
        """Base features of (x_o [N,3], w_o [N,3]) and the flows' shared first-layer products."""
        base = self.base_features(x, wo)
        if self.tails is None:
            return FlowContext(base, None)
        h = self._run32(self.head, {"x": base})
        return FlowContext(base, [h[:, a:b] for a, b in zip(self.head_cols[:-1], self.head_cols[1:], strict=True)])

    def _s12_columns(self, s12: np.ndarray) -> np.ndarray:
        """[cube_s12(d12), d12] [N, C + 3] (float32) for s12 = (s1, s2) [N, 2]."""
        d12 = cylindrical_to_direction(s12[:, 0], s12[:, 1])
        return np.concatenate([cubemap(self.s12_cube, d12, table=self.s12_table), d12.astype(np.float32)], axis=1)

    def flow_extra(self, j: int, s_prev: np.ndarray, ctx: FlowContext | None = None) -> np.ndarray:
        """The columns of conditioner j (2..4) after the base features, from s^1..s^{j-1} [N, j-1] (float32).
        With ``ctx``, the s12 cube columns are shared between conditioners 3 and 4 of its rows."""
        if j == 2:
            parts = [grid_1d(self.s1_grid, s_prev[:, 0]), s_prev[:, :1]]
        else:
            s12 = s_prev[:, :2]
            parts = [self._s12_columns(s12) if ctx is None else ctx.s12_columns(s12, self._s12_columns)]
            if j == 4:
                parts += [grid_1d(self.s3_grid, s_prev[:, 2]), s_prev[:, 2:3]]
        return np.concatenate([np.asarray(p, np.float32) for p in parts], axis=1)

    def flow_input(self, j: int, base: np.ndarray, s_prev: np.ndarray) -> np.ndarray:
        """Input of conditioner j (1..4) given base features and s^1..s^{j-1} [N, j-1]."""
        return base if j == 1 else np.concatenate([base, self.flow_extra(j, s_prev)], axis=1)

    def _conditioner(self, j: int, ctx: FlowContext, s_prev: np.ndarray) -> np.ndarray:
        if not ctx.split or self.tails is None:
            session = self.flow_sessions[j - 1]
            x = ctx.base if j == 1 else np.concatenate([ctx.base, self.flow_extra(j, s_prev, ctx)], axis=1)
            return self._run32(session, {session.get_inputs()[0].name: x})
        session, names = self.tails[j - 1]
        feed = {names[0]: ctx.pre(j)}
        if j > 1:
            feed[names[1]] = self.flow_extra(j, s_prev, ctx)
        return self._run32(session, feed)  # the spline reads NaN / inf as the spec says (finite64)

    # -- indirect transport ----------------------------------------------------------------
    def albedo(self, x, wo, *, context: FlowContext | None = None) -> np.ndarray:
        """alpha(x_o, w_o) RGB [N,3], clamped to finite values >= 0 (``context``: :meth:`context` of x, wo)."""
        base = (context if context is not None else self.context(x, wo)).base
        y = self._run(self.albedo_session, {self.albedo_session.get_inputs()[0].name: base})
        return np.maximum(np.nan_to_num(y, posinf=0.0, neginf=0.0), 0.0).astype(np.float32)

    def sample(self, x, wo, channel, rng=None, *, u=None):
        """(u_i [N,3], w_i [N,3], pdf [N]) ~ p^channel(u_i, w_i | x_o, w_o); pdf per box area and steradian."""
        return self.flow.sample(x, wo, channel, rng, u=u)

    def sample_state(self, x, wo, channel, rng=None, *, u=None, context: FlowContext | None = None,
                     directions=None) -> FlowSample:
        """:meth:`sample` keeping what later densities at the same u_i reuse (:meth:`pdf_rgb_at`,
        :meth:`pdf_rgb_sampled`); ``directions`` (bool [N]): rows whose w_i is drawn (default all)."""
        return self.flow.sample_state(x, wo, channel, rng, u=u, context=context, directions=directions)

    def pdf_rgb_at(self, fs: FlowSample, rows, wi) -> np.ndarray:
        """p^k(u_i, w_i | x_o, w_o) [M, 3] for rows of a :meth:`sample_state` (its u_i) and new w_i [M, 3]."""
        return self.flow.pdf_rgb_at(fs, rows, wi)

    def pdf_rgb_sampled(self, fs: FlowSample, rows) -> np.ndarray:
        """p^k(u_i, w_i | x_o, w_o) [M, 3] at the sample's own (u_i, w_i) of rows [M]: no network runs."""
        return self.flow.pdf_rgb_sampled(fs, rows)

    def pdf(self, x, wo, ui, wi, channel) -> np.ndarray:
        """p^channel(u_i, w_i | x_o, w_o) [N] per unit box area at u_i and steradian at w_i."""
        return self.flow.pdf(x, wo, ui, wi, channel)

    def pdf_rgb(self, x, wo, ui, wi) -> np.ndarray:
        return self.flow.pdf_rgb(x, wo, ui, wi)

    def pdf_position(self, x, wo, ui, channel) -> np.ndarray:
        return self.flow.pdf_position(x, wo, ui, channel)

    def sample_direction(self, x, wo, ui, channel, rng=None, *, u=None):
        return self.flow.sample_direction(x, wo, ui, channel, rng, u=u)

    def pdf_direction(self, x, wo, ui, wi, channel) -> np.ndarray:
        return self.flow.pdf_direction(x, wo, ui, wi, channel)

    def transport(self, x, wo, ui, wi) -> np.ndarray:
        """F = alpha p [N,3] per unit box area and steradian (indirect part)."""
        return self.albedo(x, wo) * self.pdf_rgb(x, wo, ui, wi)

    def distant_density(self, x, wo, wi) -> np.ndarray:
        """p^k(w_i | x_o, w_o) = E_{u ~ p^k(u)}[p^k(w_i | u) [n_u . w_i > 0]] RGB [N,3] per steradian.

        The flow's density of incident direction w_i whatever the box point, i.e. the indirect transport
        of a distant light is alpha * this. Monte Carlo over ``light_samples`` positions u drawn from the
        flow with stratified latents (the same for every call); only box faces the light enters count."""
        x, wo, wi = rows3(x, wo, wi)
        wi = unit64(wi)
        n, m = len(x), self.light_samples
        i = np.arange(m)  # position latents: a rank-1 lattice, t1 stratified, t2 the golden-ratio sequence
        lat = np.stack([(i + 0.5) / m, (i * 0.6180339887498949 + 0.5) % 1.0, np.full(m, 0.5), np.full(m, 0.5)], axis=1)
        out = np.zeros((n, 3))
        step = max(1, self.batch // m)  # query rows per pass: bounded flow batches whatever N
        for s in range(0, n, step):
            k = min(n, s + step) - s
            xr, wor, wir = (np.repeat(a[s:s + k], m, axis=0) for a in (x, wo, wi))
            latr = np.tile(lat, (k, 1))
            for c in range(3):
                ch = np.full(k * m, c)
                ui, _, _ = self.sample(xr, wor, ch, u=latr)
                rel = (ui - self.box.center) / self.box.half
                axis = np.argmax(np.abs(rel), axis=1)[:, None]
                enters = np.sign(np.take_along_axis(rel, axis, 1)[:, 0]) * np.take_along_axis(wir, axis, 1)[:, 0] > 0
                p = self.pdf_direction(xr, wor, ui, wir, ch) * enters
                out[s:s + k, c] = p.reshape(k, m).mean(axis=1)
        return out

    def _radiance(self, q: Query) -> np.ndarray:
        self._no_h(q)
        direct = self.direct_eval(q.n, q.wo, q.wi) * ~q.shadowed[:, None]
        return direct + self.albedo(q.x, q.wo) * self.distant_density(q.x, q.wo, q.wi)

    # -- direct lobe -----------------------------------------------------------------------
    def direct_eval(self, n, wo, wi) -> np.ndarray:
        """Cosine-weighted direct reflection f |n.wi| RGB [N,3] (grey)."""
        n, wo, wi = rows3(n, wo, wi)
        return np.repeat(ggx_reflection(n, wo, wi, self.eta, self.alpha)[:, None], 3, axis=1).astype(np.float32)

    def direct_sample(self, n, wo, u2):
        n, wo = rows3(n, wo)
        return ggx_sample(n, wo, u2, self.alpha)

    def direct_sample_eval(self, n, wo, u2):
        """(w_i [N,3], pdf [N], :meth:`direct_eval` at w_i [N,3]) of :meth:`direct_sample`: one set of dot products."""
        n, wo = rows3(n, wo)
        wi, pdf, val = ggx_sample(n, wo, u2, self.alpha, self.eta)
        return wi, pdf, np.repeat(val[:, None], 3, axis=1).astype(np.float32)

    def direct_eval_pdf(self, n, wo, wi):
        """(:meth:`direct_eval` [N,3], :meth:`direct_pdf` [N]) from one set of dot products."""
        n, wo, wi = rows3(n, wo, wi)
        val, pdf = ggx_reflection_pdf(n, wo, wi, self.eta, self.alpha)
        return np.repeat(val[:, None], 3, axis=1).astype(np.float32), pdf

    def direct_pdf(self, n, wo, wi) -> np.ndarray:
        n, wo, wi = rows3(n, wo, wi)
        return ggx_pdf(n, wo, wi, self.alpha)


register_kind(EightDnaKind())
