"""An asset's ONNX network traced into Dr.Jit: the graph (checked by the SDK's allow-list, read once) is
interpreted column by column, so the network becomes part of the rendering kernel on every JIT backend.

A value of width w (ONNX shape [N, w]) is a list of w Dr.Jit ``Float`` columns; constants stay numpy
arrays and broadcast as rows. Affine layers (``Gemm``, ``MatMul``) run through ``drjit.nn.Linear`` on a
``CoopVec``. The operators are the ones the SDK's writers and the bakers emit (affine layers,
activations, the decoders' angular features: Slice, Concat, reductions, arithmetic); any other
operator of the format's allow-list raises SCENE_UNSUPPORTED naming it.

An affine layer with more than ``LINEAR_CHUNK`` outputs runs as several ``Linear`` of at most that many outputs
on the same ``CoopVec`` (the same sums; results equal to float32 rounding): on ``llvm_ad_rgb`` a 4 x 128 network ran at 48 G
multiply-adds/s as whole layers and at 85 G in chunks of 64, where a 3 x 64 one runs at 73-82 G (2 cores;
docs/bench-mitsuba-jit.md#linear-chunks).
"""

from __future__ import annotations

import drjit as dr
import numpy as np

from nasset_sdk.errors import error

UNARY = {
    "Identity": lambda x: x,
    "Relu": lambda x: dr.maximum(x, 0.0),
    "Sigmoid": lambda x: dr.rcp(1.0 + dr.exp(-x)),
    "Tanh": dr.tanh,
    "Softplus": lambda x: dr.select(x > 20.0, x, dr.log(1.0 + dr.exp(dr.minimum(x, 20.0)))),
    "Exp": dr.exp,
    "Log": dr.log,
    "Sqrt": dr.sqrt,
    "Abs": dr.abs,
    "Neg": lambda x: -x,
    "Reciprocal": dr.rcp,
    "Sin": dr.sin,
    "Cos": dr.cos,
}
BINARY = {
    "Add": lambda a, b: a + b,
    "Sub": lambda a, b: a - b,
    "Mul": lambda a, b: a * b,
    "Div": lambda a, b: a / b,
    "Pow": lambda a, b: dr.power(a, b),
    "Max": dr.maximum,
    "Min": dr.minimum,
}
LINEAR_CHUNK = 64  # outputs per packed Linear
REDUCE = {"ReduceSum": sum, "ReduceMean": lambda c: sum(c) / len(c), "ReduceMax": lambda c: _fold(dr.maximum, c),
          "ReduceMin": lambda c: _fold(dr.minimum, c)}


def _fold(f, cols):
    out = cols[0]
    for c in cols[1:]:
        out = f(out, c)
    return out


def _row(v) -> list:
    """A constant as a row of Python floats (its width), or a column list unchanged."""
    if isinstance(v, np.ndarray):
        if v.ndim > 2 or (v.ndim == 2 and v.shape[0] != 1):
            raise ValueError(f"constant of shape {v.shape} is not a row")
        return [float(x) for x in v.reshape(-1)]
    return v


def _broadcast(f, a, b) -> list:
    a, b = _row(a), _row(b)
    if len(a) != len(b) and 1 not in (len(a), len(b)):
        raise ValueError(f"widths {len(a)} and {len(b)} do not broadcast")
    n = max(len(a), len(b))
    return [f(a[0 if len(a) == 1 else i], b[0 if len(b) == 1 else i]) for i in range(n)]


class DrJitNetwork:
    """``__call__(list of in Floats) -> list of out Floats`` for a single-input, single-output network."""

    def __init__(self, mi, onnx_bytes: bytes, **loc) -> None:
        import onnx
        from onnx import helper, numpy_helper

        self.mi = mi
        self.loc = loc
        model = onnx.ModelProto()
        model.ParseFromString(bytes(onnx_bytes))
        g = model.graph
        if len(g.input) != 1 or len(g.output) != 1:
            raise self._unsupported(f"{len(g.input)} inputs and {len(g.output)} outputs (the plugin runs one of each)")
        self.input, self.output = g.input[0].name, g.output[0].name
        self.consts = {t.name: numpy_helper.to_array(t) for t in g.initializer}
        self.nodes = []
        for n in g.node:
            attrs = {a.name: helper.get_attribute_value(a) for a in n.attribute}
            if n.op_type == "Constant":
                self.consts[n.output[0]] = numpy_helper.to_array(attrs["value"]) if "value" in attrs else np.asarray(
                    next(iter(attrs.values())), np.float32)
                continue
            if n.op_type not in UNARY and n.op_type not in BINARY and n.op_type not in REDUCE and n.op_type not in (
                    "Gemm", "MatMul", "Concat", "Slice", "Clip", "LeakyRelu"):
                raise self._unsupported(f"operator {n.op_type}")
            self.nodes.append((n.op_type, list(n.input), list(n.output), attrs))
        self.linear = {}  # node output -> ([packed drjit.nn Linear per chunk of outputs], input width)
        for op, ins, outs, attrs in self.nodes:
            if op in ("Gemm", "MatMul"):
                self.linear[outs[0]] = self._linear(op, ins, attrs)

    def _unsupported(self, what: str):
        return error("SCENE_UNSUPPORTED", f"the network uses what the Mitsuba plugin cannot run: {what}", **self.loc)

    def _linear(self, op, ins, attrs):
        import drjit.nn as nn

        if ins[1] not in self.consts:
            raise self._unsupported(f"{op} with a computed weight")
        w = np.asarray(self.consts[ins[1]], np.float32)
        if op == "Gemm":
            w = (w.T if attrs.get("transB", 0) else w) * np.float32(attrs.get("alpha", 1.0))
            c = np.asarray(self.consts.get(ins[2], 0.0) if len(ins) > 2 and ins[2] else 0.0, np.float32)
            bias = np.broadcast_to(c.reshape(-1) * np.float32(attrs.get("beta", 1.0)), (w.shape[1],))
        else:
            bias = np.zeros(w.shape[1], np.float32)
        tensor = self.mi.TensorXf
        parts = []
        for a in range(0, w.shape[1], LINEAR_CHUNK):
            b = min(a + LINEAR_CHUNK, w.shape[1])
            lin = nn.Sequential(nn.Linear(w.shape[0], b - a)).alloc(tensor, size=w.shape[0])
            lin.layers[0].weights = tensor(np.ascontiguousarray(w[:, a:b].T))  # drjit.nn stores [out, in]
            lin.layers[0].bias = tensor(np.ascontiguousarray(bias[a:b], np.float32))
            parts.append(nn.pack(lin, layout="inference"))
        return parts, w.shape[0]

    def __call__(self, inputs: list) -> list:
        import drjit.nn as nn

        vals: dict = {self.input: list(inputs)}

        def get(name):
            return vals[name] if name in vals else self.consts[name]

        for op, ins, outs, attrs in self.nodes:
            try:
                if op in UNARY:
                    out = [UNARY[op](c) for c in _row(get(ins[0]))]
                elif op == "LeakyRelu":
                    a = float(attrs.get("alpha", 0.01))
                    out = [dr.select(c >= 0, c, a * c) for c in get(ins[0])]
                elif op in BINARY:
                    out = _broadcast(BINARY[op], get(ins[0]), get(ins[1]))
                elif op in REDUCE:
                    out = [REDUCE[op](list(get(ins[0])))]
                elif op == "Concat":
                    out = [c for i in ins for c in _row(get(i))]
                elif op == "Slice":
                    start, end = (int(np.asarray(self.consts[i]).reshape(-1)[0]) for i in ins[1:3])
                    step = int(np.asarray(self.consts[ins[4]]).reshape(-1)[0]) if len(ins) > 4 and ins[4] else 1
                    out = list(get(ins[0]))[start:end:step]
                elif op == "Clip":
                    lo = float(np.asarray(self.consts[ins[1]])) if len(ins) > 1 and ins[1] else -np.inf
                    hi = float(np.asarray(self.consts[ins[2]])) if len(ins) > 2 and ins[2] else np.inf
                    out = [dr.clip(c, lo, hi) for c in get(ins[0])]
                else:  # Gemm, MatMul
                    parts, width = self.linear[outs[0]]
                    x = get(ins[0])
                    if len(x) != width:
                        raise ValueError(f"input width {len(x)} != weight rows {width}")
                    v = nn.CoopVec(*x)
                    out = [c for net in parts for c in net(v)]
            except (ValueError, KeyError, TypeError, IndexError) as exc:
                raise self._unsupported(f"{op} node ({exc})") from None
            vals[outs[0]] = out
        return list(vals[self.output])
