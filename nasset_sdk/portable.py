"""Portable evaluation graphs (spec/format.md#portable-evaluation-graphs): one self-contained ONNX
model per network that includes the kind's input encodings, so a host with onnxruntime alone (C,
C#, Rust, onnxruntime-web in a browser) can shade an asset from raw queries.

The graphs use only operators of the network allow-list (spec/security.md#networks): texel lookups
are ``GatherElements`` rows of a constant table with indices from ``Floor``/``Cast``, angles come
from ``Atan`` with octant reduction, non-finite input is mapped with ``IsNaN``/``IsInf``/``Where``.
All arithmetic is float32. The wrapped MLP is inlined node for node, at its own opset.

:func:`build_portable` makes the graphs of an opened asset, :func:`add_portable` writes a copy of an
asset file with the optional component ``portable`` added (and reports the measured parity), and
:class:`PortableEvaluator` evaluates through the stored graphs.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import UsageError, error

#: the optional component holding the graphs
COMPONENT = "portable"
#: float32 holds integers exactly up to 2^24: texel indices of a table with more rows would round
MAX_TABLE_ROWS = 1 << 24
#: queries :func:`add_portable` draws to measure parity with the kind's evaluator
PARITY_QUERIES = 4096
#: rows per onnxruntime call of :class:`PortableEvaluator`: the graphs' many [rows, w] temporaries stay in
#: cache (measured ~2.5x faster per row than 65536-row calls on a 2-core machine); results do not depend on it
CHUNK = 2048


class _Graph:
    """Accumulates ONNX nodes and float32 / int64 initializers with unique names."""

    def __init__(self) -> None:
        self.nodes: list = []
        self.inits: list = []
        self._count = 0

    def name(self, prefix: str) -> str:
        self._count += 1
        return f"{prefix}_{self._count}"

    def const(self, value, dtype=np.float32) -> str:
        from onnx import numpy_helper

        n = self.name("k")
        self.inits.append(numpy_helper.from_array(np.asarray(value, dtype), n))
        return n

    def op(self, op_type: str, *inputs: str, **attrs) -> str:
        from onnx import helper

        out = self.name(op_type.lower())
        self.nodes.append(helper.make_node(op_type, list(inputs), [out], name=out, **attrs))
        return out

    # -- small building blocks ([N, w] float32 values unless said otherwise) ----------------
    def col(self, v: str, start: int, stop: int | None = None) -> str:
        """Columns start:stop (default one column) of v."""
        stop = start + 1 if stop is None else stop
        return self.op("Slice", v, self.const([start], np.int64), self.const([stop], np.int64), self.const([1], np.int64))

    def finite_or(self, v: str, fill: float) -> str:
        """v with NaN and +-Inf replaced by ``fill``."""
        bad = self.op("Or", self.op("IsNaN", v), self.op("IsInf", v))
        return self.op("Where", bad, self.const(np.float32(fill)), v)

    def nan_to(self, v: str, fill: float) -> str:
        return self.op("Where", self.op("IsNaN", v), self.const(np.float32(fill)), v)

    def is_negative(self, v: str) -> str:
        """Bool: v < 0 or v = -0 (the sign bit, as atan2 reads it)."""
        neg_zero = self.op("Less", self.op("Div", self.const(np.float32(1.0)), v), self.const(np.float32(0.0)))
        return self.op("Or", self.op("Less", v, self.const(np.float32(0.0))), neg_zero)

    def unit(self, v: str) -> str:
        """safe_normalize of v [N,3] (spec/kinds/encodings.md#normalisation): non-finite components -> 0,
        then v / |v|, or (0, 0, 1) when |v| <= 1e-20. v is first divided by max |v_k| so |v|^2 cannot overflow."""
        return self.unit_signed(v)[0]

    def unit_signed(self, v: str) -> tuple[str, str]:
        """(unit(v), bool [N,3]: the sign bit of each component of unit(v)). onnxruntime's ``Where`` may
        turn -0 into +0, so the sign bits are derived from v (finite component of a row that is not
        replaced by the fallback) rather than read from the result."""
        neg = self.op("And", self.is_negative(v), self.op("Not", self.op("IsInf", v)))
        v = self.finite_or(v, 0.0)
        a = self.op("Abs", v)
        m = self.op("Max", self.op("Max", self.col(a, 0), self.col(a, 1)), self.col(a, 2))
        pos = self.op("Greater", m, self.const(np.float32(0.0)))
        s = self.op("Div", v, self.op("Where", pos, m, self.const(np.float32(1.0))))
        ns = self.op("Sqrt", self.op("MatMul", self.op("Mul", s, s), self.const(np.ones((3, 1)))))  # in [1, sqrt 3] when m > 0
        ok = self.op("Greater", self.op("Mul", m, ns), self.const(np.float32(1e-20)))
        u = self.op("Div", s, self.op("Max", ns, self.const(np.float32(1.0))))
        return self.op("Where", ok, u, self.const(np.array([[0.0, 0.0, 1.0]]))), self.op("And", neg, ok)

    def unit_box(self, x: str, lo, hi) -> str:
        """to_unit_box: 2 (x - lo) / (hi - lo) - 1, x [N,3]."""
        lo = np.asarray(lo, np.float64)
        span = np.maximum(np.asarray(hi, np.float64) - lo, 1e-30)
        d = self.op("Mul", self.op("Sub", x, self.const(lo.reshape(1, 3))), self.const(np.float32(2.0)))
        return self.op("Sub", self.op("Div", d, self.const(span.reshape(1, 3))), self.const(np.float32(1.0)))

    def texel(self, u: str, n: int) -> tuple[str, str, str]:
        """(i0, i1, a) [N,1] float32 of the clamped texel coordinate of u in [-1, 1] on n texels (NaN -> 0)."""
        f = self.op("Add", u, self.const(np.float32(1.0)))
        f = self.op("Mul", f, self.const(np.float32(0.5)))
        f = self.op("Mul", f, self.const(np.float32(n)))
        f = self.op("Sub", f, self.const(np.float32(0.5)))
        f = self.op("Clip", self.nan_to(f, 0.0), self.const(np.float32(0.0)), self.const(np.float32(n - 1)))
        i0 = self.op("Floor", f)
        i1 = self.op("Min", self.op("Add", i0, self.const(np.float32(1.0))), self.const(np.float32(n - 1)))
        return i0, i1, self.op("Sub", f, i0)

    def rows(self, table: str, index: str, channels: int) -> str:
        """Rows ``index`` [N,1] (float32 holding integers) of a constant table [K, C] -> [N, C]."""
        wide = self.op("Mul", index, self.const(np.ones((1, channels))))
        return self.op("GatherElements", table, self.op("Cast", wide, to=7), axis=0)  # 7 = INT64

    def lerp(self, p0: str, p1: str, a: str) -> str:
        """p0 (1 - a) + p1 a, in this order (the SDK's bilinear lookups)."""
        b = self.op("Sub", self.const(np.float32(1.0)), a)
        return self.op("Add", self.op("Mul", p0, b), self.op("Mul", p1, a))

    def triplane(self, planes: np.ndarray, xn: str) -> str:
        """Sum of the bilinear lookups of planes [3, R, R, C] (XY, YZ, ZX) at xn [N,3] -> [N, C]
        (spec/kinds/encodings.md#triplane); the three planes form one table [3 R R, C]."""
        from .kinds.encodings import TRIPLANE_AXES

        planes = np.asarray(planes, np.float32)
        k, h, w, c = planes.shape
        if k * h * w > MAX_TABLE_ROWS:
            raise UsageError(f"triplane [{k}, {h}, {w}, {c}] has more than 2^24 texels: float32 indices would round")
        table = self.const(planes.reshape(k * h * w, c))
        out = None
        for p, (ua, va) in enumerate(TRIPLANE_AXES):
            u0, u1, au = self.texel(self.col(xn, ua), w)
            v0, v1, av = self.texel(self.col(xn, va), h)
            r0 = self.op("Add", self.op("Mul", v0, self.const(np.float32(w))), self.const(np.float32(p * h * w)))
            r1 = self.op("Add", self.op("Mul", v1, self.const(np.float32(w))), self.const(np.float32(p * h * w)))
            tap = lambda r, u: self.rows(table, self.op("Add", r, u), c)  # noqa: E731
            top = self.lerp(tap(r0, u0), tap(r0, u1), au)
            bot = self.lerp(tap(r1, u0), tap(r1, u1), au)
            f = self.lerp(top, bot, av)
            out = f if out is None else self.op("Add", out, f)
        return out

    def cubemap(self, grid: np.ndarray, d: str) -> str:
        """Seam-safe bilinear cube-map lookup of grid [6, Q, Q, C] at unit directions d [N,3] -> [N, C]
        (spec/kinds/encodings.md#cubemap). The taps outside a face are re-projected once, here: an extended
        table [6 (Q+2)^2, C] holds every face's texels bordered by the texels the re-projection reads (and,
        at the four corners, the mean of the three adjacent taps), so the graph does a plain bilinear lookup
        in it. Face choice: the largest |d_k|, ties to the lower axis; the face is negative when d_k < 0."""
        from .kinds.encodings import CUBE_FACES

        ext = cube_extended_table(grid)
        q = grid.shape[1]
        c = grid.shape[-1]
        e = q + 2
        if 6 * e * e > MAX_TABLE_ROWS:
            raise UsageError(f"cube map [6, {q}, {q}, {c}] is too large for float32 texel indices")
        table = self.const(ext.reshape(6 * e * e, c))
        a = self.op("Abs", d)
        ax, ay, az = self.col(a, 0), self.col(a, 1), self.col(a, 2)
        is_x = self.op("And", self.op("Not", self.op("Less", ax, ay)), self.op("Not", self.op("Less", ax, az)))
        is_y = self.op("And", self.op("Not", is_x), self.op("Not", self.op("Less", ay, az)))
        pick = lambda vx, vy, vz: self.op("Where", is_x, vx, self.op("Where", is_y, vy, vz))  # noqa: E731
        dk = pick(self.col(d, 0), self.col(d, 1), self.col(d, 2))
        ma = self.op("Max", pick(ax, ay, az), self.const(np.float32(1e-30)))
        axis = pick(self.const(np.float32(0.0)), self.const(np.float32(1.0)), self.const(np.float32(2.0)))
        neg = self.op("Cast", self.op("Less", dk, self.const(np.float32(0.0))), to=1)  # 1 = FLOAT
        face = self.op("Add", self.op("Mul", axis, self.const(np.float32(2.0))), neg)
        onehot = self.op("Cast", self.op("Equal", face, self.const(np.arange(6, dtype=np.float32).reshape(1, 6))), to=1)
        ms, mt = np.zeros((3, 6)), np.zeros((3, 6))
        for f, (_, _, (sa, ss), (ta, ts)) in enumerate(CUBE_FACES):
            ms[sa, f], mt[ta, f] = ss, ts
        ones6 = self.const(np.ones((6, 1)))
        sc = self.op("MatMul", self.op("Mul", onehot, self.op("MatMul", d, self.const(ms))), ones6)
        tc = self.op("MatMul", self.op("Mul", onehot, self.op("MatMul", d, self.const(mt))), ones6)

        def coord(v):  # (i0 + 1 as float, fraction) on the extended face
            st = self.op("Mul", self.op("Add", self.op("Div", v, ma), self.const(np.float32(1.0))), self.const(np.float32(0.5)))
            st = self.op("Clip", st, self.const(np.float32(0.0)), self.const(np.float32(1.0)))
            fs = self.op("Sub", self.op("Mul", st, self.const(np.float32(q))), self.const(np.float32(0.5)))
            i0 = self.op("Floor", fs)
            return self.op("Add", i0, self.const(np.float32(1.0))), self.op("Sub", fs, i0)

        i1, a_s = coord(sc)
        j1, a_t = coord(tc)
        row = self.op("Add", self.op("Add", self.op("Mul", face, self.const(np.float32(e * e))),
                                     self.op("Mul", j1, self.const(np.float32(e)))), i1)
        tap = lambda off: self.rows(table, self.op("Add", row, self.const(np.float32(off))), c)  # noqa: E731
        top = self.lerp(tap(0), tap(1), a_s)
        bot = self.lerp(tap(e), tap(e + 1), a_s)
        return self.lerp(top, bot, a_t)

    def atan2(self, y: str, x: str, y_neg: str, x_neg: str) -> str:
        """atan2(y, x) [N,1] in [-pi, pi] with the signed-zero conventions of C's atan2, given the sign bits
        ``y_neg``, ``x_neg`` (bool [N,1]) of y and x (octant reduction around Atan on [0, 1], so no
        division by zero and no loss near the axes)."""
        ax, ay = self.op("Abs", x), self.op("Abs", y)
        big = self.op("Max", ax, ay)
        pos = self.op("Greater", big, self.const(np.float32(0.0)))
        r = self.op("Atan", self.op("Div", self.op("Min", ax, ay), self.op("Where", pos, big, self.const(np.float32(1.0)))))
        r = self.op("Where", self.op("Greater", ay, ax), self.op("Sub", self.const(np.float32(np.pi / 2)), r), r)
        r = self.op("Where", x_neg, self.op("Sub", self.const(np.float32(np.pi)), r), r)
        return self.op("Where", y_neg, self.op("Neg", r), r)

    def spherical(self, w: str) -> str:
        """spherical_coords of w [N,3] -> [N,2] (theta / pi, phi / 2 pi); theta from atan2(|w_xy|, w_z),
        which equals acos(w_z) for unit w and stays accurate at the poles."""
        u, neg = self.unit_signed(w)
        x, y, z = self.col(u, 0), self.col(u, 1), self.col(u, 2)
        nx, ny, nz = (self.col(neg, i) for i in range(3))
        rho = self.op("Sqrt", self.op("Add", self.op("Mul", x, x), self.op("Mul", y, y)))
        theta = self.op("Mul", self.atan2(rho, z, self.op("Less", rho, self.const(np.float32(0.0))), nz),
                        self.const(np.float32(1.0 / np.pi)))
        phi = self.op("Mul", self.atan2(y, x, ny, nx), self.const(np.float32(0.5 / np.pi)))
        return self.op("Concat", theta, phi, axis=1)

    def fourier(self, G: np.ndarray, v: str) -> str:
        """[cos(2 pi G v), sin(2 pi G v)] of v [N, n] with G [M, n] -> [N, 2M]. As nan_to_num in the evaluator:
        NaN -> 0 and +-Inf -> the largest finite value (whose products overflow), then non-finite phase -> 0."""
        G = np.asarray(G, np.float64)
        big = np.finfo(np.float32).max
        v = self.op("Clip", self.nan_to(v, 0.0), self.const(np.float32(-big)), self.const(np.float32(big)))
        phase = self.op("MatMul", v, self.const((2.0 * np.pi * G).T))
        phase = self.finite_or(phase, 0.0)
        return self.op("Concat", self.op("Cos", phase), self.op("Sin", phase), axis=1)

    def clamp_output(self, y: str) -> str:
        """NaN/Inf -> 0, then max(0, y) (the kinds' output clamp)."""
        return self.op("Relu", self.finite_or(y, 0.0))

    def inline(self, model_bytes: bytes, feeds: dict[str, str]) -> list[str]:
        """Copy a network's nodes and initializers in, with its inputs bound to ``feeds``; returns its outputs."""
        import onnx

        m = onnx.ModelProto()
        m.ParseFromString(bytes(model_bytes))
        prefix = self.name("net") + "/"
        init_names = {t.name for t in m.graph.initializer}
        ren = {name: value for name, value in feeds.items()}
        rename = lambda n: n if not n else ren.setdefault(n, prefix + n)  # noqa: E731
        for t in m.graph.initializer:
            t2 = onnx.TensorProto()
            t2.CopyFrom(t)
            t2.name = rename(t.name)
            self.inits.append(t2)
        for node in m.graph.node:
            n2 = onnx.NodeProto()
            n2.CopyFrom(node)
            n2.name = prefix + (node.name or node.output[0])
            n2.input[:] = [rename(i) for i in node.input]
            n2.output[:] = [rename(o) for o in node.output]
            self.nodes.append(n2)
        missing = [v.name for v in m.graph.input if v.name not in init_names and v.name not in feeds]
        if missing:
            raise UsageError(f"inline: network inputs {missing} are not bound")
        return [rename(v.name) for v in m.graph.output]

    def model(self, inputs: dict[str, int], outputs: dict[str, tuple[str, int]], opset: int, name: str) -> bytes:
        """Serialize: graph inputs ``name -> width``, outputs ``name -> (value, width)``, all float32 [N, width]."""
        import onnx
        from onnx import TensorProto, helper

        for out, (value, _) in outputs.items():
            self.nodes.append(helper.make_node("Identity", [value], [out], name=f"out/{out}"))
        graph = helper.make_graph(
            self.nodes, name,
            [helper.make_tensor_value_info(n, TensorProto.FLOAT, ["N", w]) for n, w in inputs.items()],
            [helper.make_tensor_value_info(n, TensorProto.FLOAT, ["N", w]) for n, (_, w) in outputs.items()],
            self.inits,
        )
        model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", int(opset))], producer_name="nasset_sdk.portable")
        model.ir_version = 8
        onnx.checker.check_model(model)
        return model.SerializeToString()


def cube_extended_table(grid: np.ndarray) -> np.ndarray:
    """[6, Q+2, Q+2, C] float32: entry (f, j + 1, i + 1) is the value the SDK's cube-map lookup reads for tap
    (i, j) of face f, i, j in [-1, Q]: the texel itself inside the face, the re-projected texel across an edge,
    and the mean of the three adjacent taps beyond a corner (spec/kinds/encodings.md#cubemap)."""
    from .kinds.encodings import cube_table

    return cube_table(grid).astype(np.float32)


def _opset(asset, component: str, network: str) -> int:
    return int(asset.network_refs(component)[network].info.opset)


# ----------------------------------------------------------------------------------------
# per kind: the graphs and how to call the kind's evaluator with the same queries


def _rna_graphs(asset) -> dict[str, bytes]:
    fiber = asset.variant == "fiber"
    g = _Graph()
    lo, hi = asset.domain
    xn = g.unit_box("x", lo, hi)
    inputs = {"x": 3, "frame": 3, "wo": 3, "wi": 3}
    parts = [g.triplane(asset.tensor("core", "triplane"), xn), xn, g.unit("frame")]
    if fiber:
        inputs["h"] = 1
        parts.append(g.op("Clip", g.nan_to("h", 0.0), g.const(np.float32(-1.0)), g.const(np.float32(1.0))))
    parts += [g.unit("wo"), g.unit("wi")]
    (y,) = g.inline(asset.network_bytes("core", "decoder"), {"x": g.op("Concat", *parts, axis=1)})
    y = g.clamp_output(y)
    outputs = {"unshadowed": (g.col(y, 0, 3), 3), "shadowed": (g.col(y, 3, 6), 3)}
    return {"decoder": g.model(inputs, outputs, _opset(asset, "core", "decoder"), f"rna_{asset.variant}_portable")}


def _neupress_graphs(asset) -> dict[str, bytes]:
    g = _Graph()
    lo, hi = asset.domain
    v = g.op("Concat", g.unit_box("x", lo, hi), g.spherical("wo"), g.spherical("wi"), axis=1)
    (y,) = g.inline(asset.network_bytes("core", "appearance"), {"x": g.fourier(asset.tensor("core", "fourier"), v)})
    outputs = {"transport": (g.clamp_output(y), 3)}
    return {"appearance": g.model({"x": 3, "wo": 3, "wi": 3}, outputs, _opset(asset, "core", "appearance"), "neupress_portable")}


def _eightdna_graphs(asset) -> dict[str, bytes]:
    g = _Graph()
    lo, hi = asset.domain
    xn = g.unit_box("x", lo, hi)
    wo = g.unit("wo")
    base = g.op("Concat", g.triplane(asset.tensor("core", "triplane"), xn), xn, g.cubemap(asset.tensor("core", "woCube"), wo), wo,
                axis=1)
    (y,) = g.inline(asset.network_bytes("core", "albedo"), {"x": base})
    # the evaluator: NaN -> 0, +-Inf -> +-1e30, then max(0, y)
    y = g.op("Relu", g.op("Clip", g.nan_to(y, 0.0), g.const(np.float32(-1e30)), g.const(np.float32(1e30))))
    return {"albedo": g.model({"x": 3, "wo": 3}, {"albedo": (y, 3)}, _opset(asset, "core", "albedo"), "eightdna_albedo_portable")}


def _eightdna_reference(asset, q: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {"albedo": asset.evaluator().albedo(q["x"], q["wo"])}


def _rna_reference(asset, q: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    ev = asset.evaluator()
    un, sh = ev.evaluate(q["x"], q["frame"], q["wo"], q["wi"], q["h"][:, 0] if "h" in q else None)
    return {"unshadowed": un, "shadowed": sh}


def _neupress_reference(asset, q: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    return {"transport": asset.evaluator().evaluate(q["x"], np.tile([[0.0, 0.0, 1.0]], (len(q["x"]), 1)), q["wo"], q["wi"])}


#: kind -> (graph builder, reference call with the same named queries). 8dna: the albedo only; its spline
#: flow (sampling, pdf) is not expressed in ONNX here
BUILDERS = {"rna": (_rna_graphs, _rna_reference), "neupress": (_neupress_graphs, _neupress_reference),
            "8dna": (_eightdna_graphs, _eightdna_reference)}


def _kind_entry(asset):
    if asset.kind not in BUILDERS:
        raise UsageError(f"kind {asset.kind!r} has no portable evaluation graph (supported: {sorted(BUILDERS)})",
                         file=str(asset.path))
    return BUILDERS[asset.kind]


def build_portable(asset) -> dict[str, bytes]:
    """Portable graphs of an asset opened with its ``core`` loaded: network name -> ONNX model bytes
    (inputs and outputs per spec/kinds/<kind>.md#component-portable)."""
    return _kind_entry(asset)[0](asset)


def reference_outputs(asset, queries: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The kind evaluator's outputs for the portable graph's named queries (float arrays [N, w])."""
    return _kind_entry(asset)[1](asset, queries)


def random_queries(asset, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Named float32 queries [n, w] for the portable graph of ``asset``: points in and slightly beyond the
    encoding box (rna: a quarter on texel borders and box faces), unit directions (a quarter grazing: within
    1e-3 of the plane z = 0 of ``frame``, half of those w_o exactly on a pole, -0 components included; 8dna:
    another quarter of w_o within 1e-3 of cube-map edges and corners), fibre offsets in [-1.2, 1.2]."""
    lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
    t = rng.uniform(-1.05, 1.05, (n, 3))
    k = n // 4
    if asset.kind == "rna" and k:
        r = asset.tensor_refs("core")["triplane"].shape[1]
        t[:k] = (rng.integers(0, r + 1, (k, 3)) / r) * 2.0 - 1.0  # texel borders, including -1 and +1
        t[:k:3, 0] = rng.choice([-1.0, 1.0], len(t[:k:3]))
    x = lo + (t + 1.0) * 0.5 * (hi - lo)

    def dirs():
        d = rng.normal(size=(n, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return d

    frame, wo, wi = dirs(), dirs(), dirs()
    if k:
        wi[:k, 2] = rng.uniform(-1e-3, 1e-3, k)  # grazing with respect to the frame (0, 0, 1) below
        frame[:k] = [0.0, 0.0, 1.0]
        wo[:k // 2] = rng.choice([-1.0, 1.0], (k // 2, 1)) * np.array([0.0, 0.0, 1.0])  # poles of spherical_coords
    if asset.kind == "8dna" and k:  # w_o near cube-map edges and corners (taps re-projected across faces)
        corner = rng.choice([-1.0, 1.0], (k, 3)) * (1.0 + rng.uniform(-1e-3, 1e-3, (k, 3)))
        corner[: k // 2, 0] *= rng.uniform(0.0, 1.0, k // 2)  # half on an edge only
        wo[-k:] = corner / np.linalg.norm(corner, axis=1, keepdims=True)
    q = {"x": x, "wo": wo}
    if asset.kind != "8dna":
        q["wi"] = wi
    if asset.kind == "rna":
        q["frame"] = frame
        if asset.variant == "fiber":
            q["h"] = rng.uniform(-1.2, 1.2, (n, 1))
    return {name: v.astype(np.float32) for name, v in q.items()}


def parity(asset, session, queries: dict[str, np.ndarray]) -> dict[str, dict[str, float]]:
    """Max abs and max relative (|a - b| / max(|b|, 1e-3)) difference per output between a portable
    graph's session and the kind evaluator on ``queries``."""
    got = dict(zip([o.name for o in session.get_outputs()], session.run(None, queries), strict=True))
    want = reference_outputs(asset, queries)
    out = {}
    for name, ref in want.items():
        d = np.abs(np.asarray(got[name], np.float64) - np.asarray(ref, np.float64))
        out[name] = {"max_abs": float(d.max(initial=0.0)),
                     "max_rel": float((d / np.maximum(np.abs(ref), 1e-3)).max(initial=0.0)),
                     "max_ref": float(np.abs(ref).max(initial=0.0))}
    return out


def add_portable(src_path: str | os.PathLike, dst_path: str | os.PathLike, *, seed: int = 0) -> dict:
    """Write ``dst_path``: a copy of the asset at ``src_path`` with the optional component ``portable``
    (one graph per network, :func:`build_portable`) added or replaced. Returns a report: the output
    path, and per graph its bytes, node count, opset and the parity with the kind's evaluator on
    :data:`PARITY_QUERIES` random queries (:func:`random_queries`, :func:`parity`).

    Assets with quality variants are refused (one graph would serve one level only).
    """
    from .asset import Asset, AssetBuilder
    from .networks import info_from_model, make_session

    src = Asset.open(src_path, load="all")
    if any(c.qualities for c in src.components().values()):
        raise UsageError("portable graphs of assets with quality variants are not supported", file=str(src.path))
    graphs = build_portable(src)
    b = AssetBuilder.from_asset(src)
    b.components.pop(COMPONENT, None)  # replaced, never merged
    b.default_quality.pop(COMPONENT, None)
    comp = b.component(COMPONENT, required=False, purpose="portable-evaluation")
    for name, blob in graphs.items():
        comp.add_network(name, blob)
    out = b.write(dst_path)
    rng = np.random.default_rng(seed)
    report = {"path": str(out), "kind": src.kind, "variant": src.variant, "graphs": {}}
    for name, blob in graphs.items():
        info = info_from_model(blob)
        q = random_queries(src, PARITY_QUERIES, rng)
        report["graphs"][name] = {"bytes": len(blob), "nodes": _node_count(blob), "opset": info.opset,
                                  "inputs": dict(zip(info.input_names, info.input_widths, strict=True)),
                                  "outputs": dict(zip(info.output_names, info.output_widths, strict=True)),
                                  "parity": parity(src, make_session(blob), q)}
    return report


def _node_count(blob: bytes) -> int:
    import onnx

    m = onnx.ModelProto()
    m.ParseFromString(blob)
    return len(m.graph.node)


class PortableEvaluator:
    """Evaluates an asset through its stored ``portable`` graphs (what a non-Python host does)."""

    def __init__(self, asset, *, intra_threads: int = 0) -> None:
        comps = asset.components()
        if COMPONENT not in comps or not comps[COMPONENT].loaded:
            raise error("COMPONENT_MISSING", f"component {COMPONENT!r} is absent or not loaded (open with load='all' "
                        f"or load(['core', {COMPONENT!r}]))", file=str(asset.path))
        self.asset = asset
        self.sessions = {n: asset.session(COMPONENT, n, intra_threads=intra_threads) for n in asset.network_refs(COMPONENT)}

    def run(self, network: str, **inputs) -> dict[str, np.ndarray]:
        """Named float32 inputs [N, w] -> named outputs [N, w] of graph ``network``."""
        if network not in self.sessions:
            raise UsageError(f"no portable graph {network!r}; have {sorted(self.sessions)}", file=str(self.asset.path))
        s = self.sessions[network]
        want = {i.name: int(i.shape[1]) for i in s.get_inputs()}
        if set(inputs) != set(want):
            raise UsageError(f"portable graph {network!r} takes inputs {sorted(want)}, got {sorted(inputs)}")
        feed = {}
        rows = None
        for name, v in inputs.items():
            a = np.ascontiguousarray(np.asarray(v, np.float32).reshape(len(v), -1))
            if a.shape[1] != want[name] or (rows is not None and len(a) != rows):
                raise UsageError(f"input {name!r} must be [N, {want[name]}] with one N for all inputs, got {a.shape}")
            rows = len(a)
            feed[name] = a
        names = [o.name for o in s.get_outputs()]
        parts = [s.run(None, {k: v[i:i + CHUNK] for k, v in feed.items()}) for i in range(0, max(rows, 1), CHUNK)]
        return {name: np.concatenate([p[j] for p in parts]) for j, name in enumerate(names)}


def write_model(path: str | os.PathLike, blob: bytes) -> Path:
    """Write model bytes to ``path`` atomically (temp + rename), e.g. for a host that loads .onnx files."""
    from .images import atomic_output

    with atomic_output(path, "ONNX model") as tmp:
        Path(tmp).write_bytes(blob)
    return Path(path)
