"""Embedded ONNX networks: build plain MLP graphs, check untrusted model bytes, run them.

The format's networks are MLP-only graphs of standard operators with float32 inputs and
outputs of shape [N, width] (spec/format.md#networks). Everything else (encodings, spline
math) is done by the SDK in numpy; the optional portable graphs (nasset_sdk.portable) repeat a
network with its encodings using the same allow-list.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from . import limits
from .errors import error


@dataclass(frozen=True)
class NetworkInfo:
    """What a network prim declares about its model."""

    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_widths: tuple[int, ...]
    output_widths: tuple[int, ...]
    opset: int


def sha256_hex(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def mlp_onnx(
    weights: Sequence[np.ndarray],
    biases: Sequence[np.ndarray],
    *,
    activation: str = "Relu",
    output_activation: str | None = None,
    skips: Sequence[tuple[int, int]] = (),
    input_name: str = "x",
    output_name: str = "y",
    opset: int = 17,
    name: str = "mlp",
) -> bytes:
    """Serialize an MLP as an ONNX model: ``y = L_k(act(... act(L_1(x))))``.

    weights[i]: [in_i, out_i] float32; biases[i]: [out_i]. ``skips`` lists (src, dst) layer
    indices: the activation entering layer ``src`` is concatenated to the input of layer
    ``dst`` (NeuPreSS-style skip connections); weights[dst] must include those rows.
    """
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    if len(weights) != len(biases) or not weights:
        raise ValueError("mlp_onnx needs as many biases as weights, at least one layer")
    inits, nodes = [], []
    layer_inputs: list[str] = []
    h = input_name
    skip_src = {dst: src for src, dst in skips}
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        w = np.asarray(w, np.float32)
        b = np.asarray(b, np.float32)
        layer_inputs.append(h)
        if i in skip_src:
            cat = f"cat{i}"
            nodes.append(helper.make_node("Concat", [h, layer_inputs[skip_src[i]]], [cat], axis=1))
            h = cat
        inits += [numpy_helper.from_array(w, f"W{i}"), numpy_helper.from_array(b, f"B{i}")]
        out = f"h{i}"
        nodes.append(helper.make_node("Gemm", [h, f"W{i}", f"B{i}"], [out]))
        last = i == len(weights) - 1
        act = output_activation if last else activation
        if act:
            nodes.append(helper.make_node(act, [out], [out + "a"]))
            out = out + "a"
        h = out
    nodes.append(helper.make_node("Identity", [h], [output_name]))
    in_w = int(np.asarray(weights[0]).shape[0])
    out_w = int(np.asarray(weights[-1]).shape[1])
    graph = helper.make_graph(
        nodes,
        name,
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, ["N", in_w])],
        [helper.make_tensor_value_info(output_name, TensorProto.FLOAT, ["N", out_w])],
        inits,
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)],
                              producer_name="nasset_sdk")
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model.SerializeToString()


def random_mlp(rng: np.random.Generator, widths: Sequence[int], **kw) -> bytes:
    """An MLP with He-initialised random weights; widths = [in, hidden..., out]."""
    ws, bs = [], []
    for a, b in zip(widths[:-1], widths[1:], strict=True):
        ws.append(rng.normal(0.0, np.sqrt(2.0 / a), (a, b)).astype(np.float32))
        bs.append(rng.normal(0.0, 0.05, b).astype(np.float32))
    return mlp_onnx(ws, bs, **kw)


def _dim_value(d) -> int | None:
    return int(d.dim_value) if d.HasField("dim_value") else None


#: Operators a network may use (default domain; spec/security.md#networks). Each keeps output row i a
#: function of input row i alone and every shape independent of input values, given the attribute and
#: input rules of :func:`check_graph`. Elementwise ops broadcast; the rest are checked per op below.
ELEMENTWISE_OPS = frozenset({
    "Identity", "Relu", "LeakyRelu", "PRelu", "Elu", "Selu", "Celu", "Sigmoid", "HardSigmoid", "HardSwish", "Tanh",
    "Softplus", "Softsign", "Mish", "Gelu", "Erf", "Exp", "Log", "Sqrt", "Abs", "Neg", "Reciprocal", "Sin", "Cos",
    "Add", "Sub", "Mul", "Div", "Pow", "Max", "Min", "Sum", "Mean", "Clip", "Cast",
    # the portable evaluation graph's encodings (spec/format.md#portable): texel and angle arithmetic
    "Floor", "Atan", "IsNaN", "IsInf", "Where", "Less", "Greater", "Equal", "And", "Or", "Not",
})
ROW_OPS = frozenset({
    "Gemm", "MatMul", "Concat", "Split", "Slice", "ReduceSum", "ReduceMean", "ReduceMax", "ReduceMin", "ReduceL2",
    "Softmax", "LogSoftmax", "LayerNormalization", "Constant", "GatherElements",
})
ALLOWED_OPS = ELEMENTWISE_OPS | ROW_OPS
#: The symbolic batch dimension given to every graph input before shape inference.
BATCH_DIM = "nasset_batch"
#: Elements of any value computed from constants only (bounds broadcasting of two large constants).
MAX_STATIC_ELEMENTS = 1 << 24


def _tensor_places(model):
    """Every TensorProto in the model: (where, tensor, sparse). Sparse tensors yield their values and indices.

    Covers graph initializers and sparse initializers, node attributes t / tensors / sparse_tensor /
    sparse_tensors, subgraphs g / graphs recursively, local function bodies and training_info graphs.
    """
    def of_sparse(s, where):
        yield f"{where} (values)", s.values, True
        yield f"{where} (indices)", s.indices, True

    def of_nodes(nodes, where):
        for node in nodes:
            for attr in node.attribute:
                at = f"{where}/{node.op_type} {node.name!r} attribute {attr.name!r}"
                if attr.HasField("t"):
                    yield at, attr.t, False
                for t in attr.tensors:
                    yield at, t, False
                if attr.HasField("sparse_tensor"):
                    yield from of_sparse(attr.sparse_tensor, at)
                for sp in attr.sparse_tensors:
                    yield from of_sparse(sp, at)
                if attr.HasField("g"):
                    yield from of_graph(attr.g, at)
                for g in attr.graphs:
                    yield from of_graph(g, at)

    def of_graph(graph, where):
        for t in graph.initializer:
            yield f"{where} initializer", t, False
        for sp in graph.sparse_initializer:
            yield from of_sparse(sp, f"{where} sparse initializer")
        yield from of_nodes(graph.node, where)

    yield from of_graph(model.graph, "graph")
    for f in model.functions:
        yield from of_nodes(f.node, f"function {f.name!r}")
    for i, ti in enumerate(model.training_info):
        yield from of_graph(ti.initialization, f"training_info[{i}].initialization")
        yield from of_graph(ti.algorithm, f"training_info[{i}].algorithm")


def check_model_bytes(data: bytes, declared: NetworkInfo | None = None, **loc):
    """Parse and check untrusted ONNX bytes; return the ModelProto or raise a typed error.

    Checks (spec/security.md#networks): size bound, parse, no external data anywhere, no sparse
    tensors, only default operator domains, opset in range and equal to the declaration, onnx.checker,
    I/O names and widths equal to ``declared`` with a symbolic batch axis, then :func:`check_graph`
    (operator allow-list, attribute rules, shapes [N, fixed width] throughout).
    """
    import onnx
    from onnx import TensorProto

    if len(data) > limits.MAX_NETWORK_BYTES:
        raise error("NETWORK_TOO_LARGE", f"model is {len(data)} bytes, bound {limits.MAX_NETWORK_BYTES}", **loc)
    model = onnx.ModelProto()
    try:
        model.ParseFromString(bytes(data))
    except Exception as exc:  # protobuf DecodeError and friends
        raise error("NETWORK_PARSE", f"bytes are not an ONNX model ({type(exc).__name__})", **loc) from None
    if not model.HasField("graph") or not model.graph.node:
        raise error("NETWORK_PARSE", "model has no graph nodes", **loc)

    sparse_at = None
    for where, t, sparse in _tensor_places(model):
        if t.data_location == TensorProto.EXTERNAL or len(t.external_data):
            raise error("NETWORK_EXTERNAL_DATA", f"tensor {t.name!r} in {where} references external data", **loc)
        if sparse and sparse_at is None:
            sparse_at = where
    if sparse_at is not None:
        raise error("NETWORK_OP_FORBIDDEN", f"sparse tensor in {sparse_at}: the format has no sparse tensors", **loc)
    if len(model.training_info):
        raise error("NETWORK_OP_FORBIDDEN", "model carries training_info graphs", **loc)
    domains = {o.domain for o in model.opset_import}
    domains |= {n.domain for n in model.graph.node}
    bad = sorted(d for d in domains if d not in limits.ALLOWED_OP_DOMAINS)
    if bad or len(model.functions):
        raise error("NETWORK_CUSTOM_DOMAIN", f"custom operator domains {bad or 'functions'} are not allowed", **loc)
    opsets = [o.version for o in model.opset_import if o.domain in limits.ALLOWED_OP_DOMAINS]
    opset = max(opsets) if opsets else -1
    if not (limits.OPSET_MIN <= opset <= limits.OPSET_MAX):
        raise error("NETWORK_OPSET", f"opset {opset} outside [{limits.OPSET_MIN}, {limits.OPSET_MAX}]", **loc)
    if declared is not None and declared.opset != opset:
        raise error("NETWORK_OPSET", f"model opset {opset} differs from declared onnx:opset {declared.opset}", **loc)
    if len(model.graph.node) > limits.MAX_NETWORK_NODES:
        raise error("NETWORK_TOO_LARGE", f"graph has {len(model.graph.node)} nodes, bound {limits.MAX_NETWORK_NODES}", **loc)
    try:
        onnx.checker.check_model(model)
    except Exception as exc:
        raise error("NETWORK_PARSE", f"onnx.checker rejects the model: {str(exc).splitlines()[0][:200]}", **loc) from None
    init_names = {t.name for t in model.graph.initializer}
    inputs = [v for v in model.graph.input if v.name not in init_names]
    outputs = list(model.graph.output)
    if not inputs or not outputs:
        raise error("NETWORK_IO", "model needs at least one input and one output", **loc)
    for v in inputs + outputs:
        tt = v.type.tensor_type
        if tt.elem_type != TensorProto.FLOAT or len(tt.shape.dim) != 2:
            raise error("NETWORK_IO", f"{v.name!r} must be float32 of rank 2 [N, width]", **loc)
        if tt.shape.dim[0].HasField("dim_value"):
            raise error("NETWORK_IO", f"{v.name!r} has a fixed batch axis ({tt.shape.dim[0].dim_value}); axis 0 must be symbolic", **loc)
        width = _dim_value(tt.shape.dim[1])
        if width is None or not 1 <= width <= limits.MAX_NETWORK_WIDTH:
            raise error("NETWORK_IO", f"{v.name!r} width must be fixed, in [1, {limits.MAX_NETWORK_WIDTH}]; got {width}", **loc)
    if declared is not None:
        got_in = tuple(v.name for v in inputs)
        got_out = tuple(v.name for v in outputs)
        if got_in != declared.input_names or got_out != declared.output_names:
            raise error("NETWORK_IO", f"model I/O {got_in}->{got_out} differs from declared "
                        f"{declared.input_names}->{declared.output_names}", **loc)
        w_in = tuple(_dim_value(v.type.tensor_type.shape.dim[1]) for v in inputs)
        w_out = tuple(_dim_value(v.type.tensor_type.shape.dim[1]) for v in outputs)
        if w_in != declared.input_widths or w_out != declared.output_widths:
            raise error("NETWORK_IO", f"model widths {w_in}->{w_out} differ from declared "
                        f"{declared.input_widths}->{declared.output_widths}", **loc)
    check_graph(model, **loc)
    return model


def _static_sources(graph) -> dict:
    """Name -> TensorProto or Constant AttributeProto of every initializer and Constant output."""
    out: dict = {t.name: t for t in graph.initializer}
    for node in graph.node:
        if node.op_type == "Constant" and node.output and len(node.attribute) == 1:
            out[node.output[0]] = node.attribute[0]
    return out


def _static_value(src, **loc) -> np.ndarray:
    """The numpy value of a constant source (raises NETWORK_PARSE for an undecodable tensor)."""
    from onnx import AttributeProto, helper, numpy_helper

    try:
        if isinstance(src, AttributeProto):
            return numpy_helper.to_array(src.t) if src.name == "value" else np.asarray(helper.get_attribute_value(src))
        return numpy_helper.to_array(src)
    except Exception as exc:  # inconsistent raw_data length and the like
        raise error("NETWORK_PARSE", f"constant tensor cannot be decoded ({type(exc).__name__})", **loc) from None


def check_graph(model, **loc) -> None:
    """Operator allow-list, attribute/input rules and shape inference (spec/security.md#networks).

    Raises ``NETWORK_OP_FORBIDDEN`` for an operator, attribute or input outside the rules and
    ``NETWORK_SHAPE`` unless shape inference proves every value computed from the inputs to be
    [N, w] (N the batch, w fixed in [1, MAX_NETWORK_WIDTH]) and every constant to be small and fixed.
    """
    from onnx import TensorProto

    graph = model.graph
    static = _static_sources(graph)
    forbid = lambda node, why: error("NETWORK_OP_FORBIDDEN", f"{node.op_type} node {node.name!r}: {why}", **loc)  # noqa: E731

    def need_static(node, i, what):
        name = node.input[i] if len(node.input) > i else ""
        if name and name not in static:
            raise forbid(node, f"{what} must be an initializer or a Constant, not a computed value")
        return _static_value(static[name], **loc) if name else None

    def axes_ok(node, axes, what):
        if axes is None or np.size(axes) == 0 or not set(np.asarray(axes).reshape(-1).tolist()) <= {1, -1}:
            raise forbid(node, f"{what} must be axis 1 (the width); got {None if axes is None else np.asarray(axes).tolist()}")

    for node in graph.node:
        op = node.op_type
        if op not in ALLOWED_OPS:
            raise forbid(node, f"operator not in the allow-list of an MLP network ({', '.join(sorted(ALLOWED_OPS))})")
        attrs = {a.name: a for a in node.attribute}
        ival = lambda name, default: int(attrs[name].i) if name in attrs else default  # noqa: B023, E731
        if op == "Constant":
            kinds = set(attrs) - {"value", "value_float", "value_floats", "value_int", "value_ints"}
            if kinds:
                raise forbid(node, f"attribute {sorted(kinds)[0]!r} is not allowed (dense numeric constants only)")
        elif op == "Gemm":
            if ival("transA", 0) != 0:
                raise forbid(node, "transA must be 0 (the batch stays on axis 0)")
            for name in ("alpha", "beta"):
                if name in attrs and not np.isfinite(attrs[name].f):
                    raise forbid(node, f"{name} must be finite")
            need_static(node, 1, "B")
            need_static(node, 2, "C")
        elif op == "MatMul":
            need_static(node, 1, "B")
        elif op in ("Concat", "Softmax", "LogSoftmax", "LayerNormalization", "Split"):
            axes_ok(node, [ival("axis", 1 if op == "Concat" else (0 if op == "Split" else -1))], "axis")
            if op == "LayerNormalization":
                need_static(node, 1, "Scale")
                need_static(node, 2, "B")
            if op == "Split":
                need_static(node, 1, "split")
        elif op == "Slice":
            if len(node.input) < 4 or not node.input[3]:
                raise forbid(node, "axes must be given (without them Slice cuts the batch axis)")
            for i, what in ((1, "starts"), (2, "ends"), (4, "steps")):
                need_static(node, i, what)
            axes_ok(node, need_static(node, 3, "axes"), "axes")
        elif op.startswith("Reduce"):
            if "axes" in attrs:
                axes = list(attrs["axes"].ints)
            else:
                axes = need_static(node, 1, "axes")
            axes_ok(node, axes, "axes")
            if ival("keepdims", 1) != 1:
                raise forbid(node, "keepdims must be 1 (values stay [N, width])")
        elif op == "Clip":
            need_static(node, 1, "min")
            need_static(node, 2, "max")
        elif op == "Cast" and ival("to", 0) not in (TensorProto.FLOAT, TensorProto.INT64):
            raise forbid(node, "Cast may only produce float32 or int64 (texel indices)")
        elif op == "GatherElements":
            # out[i, j] = data[indices[i, j], j]: row i reads row i of the indices and a constant table only
            if ival("axis", 0) != 0:
                raise forbid(node, "axis must be 0 (rows of a constant table)")
            if not node.input or node.input[0] not in static:
                raise forbid(node, "data must be an initializer or a Constant (a lookup table), not a computed value")
    _check_shapes(model, **loc)


def _check_shapes(model, **loc) -> None:
    """Strict shape inference with the batch axis symbolic: values from inputs are [N, w], constants fixed."""
    import onnx

    m = onnx.ModelProto()
    m.CopyFrom(model)
    del m.graph.value_info[:]  # inferred here, never taken from the file
    init_names = {t.name for t in m.graph.initializer}
    row = {v.name for v in m.graph.input if v.name not in init_names}
    for v in [*(v for v in m.graph.input if v.name in row), *m.graph.output]:
        d0 = v.type.tensor_type.shape.dim[0]
        d0.Clear()
        d0.dim_param = BATCH_DIM
    try:
        inferred = onnx.shape_inference.infer_shapes(m, check_type=True, strict_mode=True, data_prop=True)
    except Exception as exc:
        raise error("NETWORK_SHAPE", f"shape inference fails: {(str(exc).strip().splitlines() or ['?'])[0][:200]}", **loc) from None
    types = {v.name: v.type for v in [*inferred.graph.input, *inferred.graph.value_info, *inferred.graph.output]}

    def dims(name):
        t = types.get(name)
        if t is None or not t.HasField("tensor_type") or not t.tensor_type.HasField("shape"):
            return None
        return [(d.dim_value if d.HasField("dim_value") else (d.dim_param or None)) for d in t.tensor_type.shape.dim]

    for node in m.graph.node:
        from_input = any(i in row for i in node.input if i)
        for out in node.output:
            if not out:
                continue
            shape = dims(out)
            if from_input:
                row.add(out)
                ok = (shape is not None and len(shape) == 2 and shape[0] == BATCH_DIM and isinstance(shape[1], int)
                      and 1 <= shape[1] <= limits.MAX_NETWORK_WIDTH)
                if not ok:
                    raise error("NETWORK_SHAPE", f"{node.op_type} output {out!r} has shape {shape}; values computed from the "
                                f"inputs must be [N, w], w fixed in [1, {limits.MAX_NETWORK_WIDTH}]", **loc)
            else:
                ok = (shape is not None and len(shape) <= 2 and all(isinstance(d, int) for d in shape)
                      and float(np.prod(shape, dtype=np.float64)) <= MAX_STATIC_ELEMENTS)
                if not ok:
                    raise error("NETWORK_SHAPE", f"{node.op_type} output {out!r} (constant) has shape {shape}; constants "
                                f"must be fixed, rank <= 2, at most {MAX_STATIC_ELEMENTS} elements", **loc)
    for v in model.graph.output:
        if v.name not in row:
            raise error("NETWORK_SHAPE", f"output {v.name!r} does not depend on the inputs", **loc)


def info_from_model(data: bytes) -> NetworkInfo:
    """Read names, widths and opset from model bytes (used when writing)."""
    model = check_model_bytes(data)
    init_names = {t.name for t in model.graph.initializer}
    inputs = [v for v in model.graph.input if v.name not in init_names]
    widths = lambda vs: tuple(_dim_value(v.type.tensor_type.shape.dim[1]) or -1 for v in vs)  # noqa: E731
    opset = max(o.version for o in model.opset_import if o.domain in limits.ALLOWED_OP_DOMAINS)
    return NetworkInfo(
        tuple(v.name for v in inputs), tuple(v.name for v in model.graph.output),
        widths(inputs), widths(model.graph.output), int(opset),
    )


def parameter_count(data: bytes) -> int:
    """Number of scalar weights in the model's initializers."""
    import onnx

    model = onnx.ModelProto()
    model.ParseFromString(bytes(data))
    return int(sum(int(np.prod(t.dims)) for t in model.graph.initializer))


@dataclass(frozen=True)
class FirstLayerSplit:
    """An MLP whose first affine layer is split by input columns: ``x @ W + b`` with
    ``x = [head (H), rest]`` becomes ``(head @ head_weight + bias) + rest @ W_rest``.

    ``head_weight`` [H, W1] and ``bias`` [W1] (float32) are applied by the caller, so several
    networks that read the same head columns share one matrix product; ``tail`` is an ONNX model
    with inputs ``tail_inputs[0]`` [N, W1] (that pre-activation) and, if the network has columns after
    the head, ``tail_inputs[1]`` [N, in - H], and the original outputs."""

    head_weight: np.ndarray
    bias: np.ndarray
    tail: bytes
    rest_width: int
    tail_inputs: tuple[str, ...]


def split_first_layer(data: bytes, head: int) -> FirstLayerSplit | None:
    """Split a checked single-input network at input column ``head`` (see :class:`FirstLayerSplit`).

    None when the graph does not start with one affine layer that alone reads the input (a Gemm
    with transA = 0 or a MatMul, with a constant weight): callers then run the whole network."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.ModelProto()
    model.ParseFromString(bytes(data))
    g = model.graph
    if len(g.input) != 1:
        return None
    x = g.input[0].name
    users = [n for n in g.node if x in n.input]
    if len(users) != 1 or users[0].op_type not in ("Gemm", "MatMul") or users[0].input[0] != x:
        return None
    first = users[0]
    static = _static_sources(g)
    if len(first.input) < 2 or first.input[1] not in static:
        return None
    attrs = {a.name: helper.get_attribute_value(a) for a in first.attribute}
    if attrs.get("transA", 0):
        return None
    w = np.asarray(_static_value(static[first.input[1]]), np.float32)
    if w.ndim != 2:
        return None
    if attrs.get("transB", 0):
        w = w.T
    w = w * np.float32(attrs.get("alpha", 1.0))
    bias = np.zeros(w.shape[1], np.float32)
    if first.op_type == "Gemm" and len(first.input) > 2 and first.input[2]:
        if first.input[2] not in static:
            return None
        c = np.asarray(_static_value(static[first.input[2]]), np.float32) * np.float32(attrs.get("beta", 1.0))
        if c.size not in (1, w.shape[1]):
            return None
        bias = np.broadcast_to(c.reshape(-1), (w.shape[1],)).astype(np.float32)
    if not 0 < head <= w.shape[0]:
        return None
    rest = w.shape[0] - head
    taken = {t.name for t in g.initializer} | {o for n in g.node for o in n.output} | {x}
    pre, xe, wr, mm = (_fresh(stem, taken) for stem in ("split_pre", "split_rest", "split_rest_weight", "split_rest_mm"))
    nodes = []
    inputs = [helper.make_tensor_value_info(pre, onnx.TensorProto.FLOAT, ["N", w.shape[1]])]
    inits = [t for t in g.initializer]
    if rest:
        inputs.append(helper.make_tensor_value_info(xe, onnx.TensorProto.FLOAT, ["N", rest]))
        inits.append(numpy_helper.from_array(np.ascontiguousarray(w[head:]), wr))
        nodes += [helper.make_node("MatMul", [xe, wr], [mm]), helper.make_node("Add", [pre, mm], [first.output[0]])]
    else:
        nodes.append(helper.make_node("Identity", [pre], [first.output[0]]))
    nodes += [n for n in g.node if n is not first]
    used = {i for n in nodes for i in n.input}
    graph = helper.make_graph(nodes, g.name + "_tail", inputs, list(g.output), [t for t in inits if t.name in used])
    tail = helper.make_model(graph, opset_imports=list(model.opset_import), producer_name="nasset_sdk")
    tail.ir_version = model.ir_version
    return FirstLayerSplit(np.ascontiguousarray(w[:head]), bias, tail.SerializeToString(), rest,
                           (pre, xe) if rest else (pre,))


def _fresh(stem: str, taken: set[str]) -> str:
    """stem, or stem_1, stem_2, ...: the first not in ``taken`` (which it joins)."""
    name, i = stem, 0
    while name in taken:
        i += 1
        name = f"{stem}_{i}"
    taken.add(name)
    return name


def make_session(data: bytes, *, intra_threads: int = 0, inter_threads: int = 1):
    """An onnxruntime CPU session; ``intra_threads=0`` lets onnxruntime choose."""
    import onnxruntime as ort

    opts = ort.SessionOptions()
    opts.intra_op_num_threads = int(intra_threads)
    opts.inter_op_num_threads = int(inter_threads)
    opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    opts.log_severity_level = 3
    # idle worker threads spinning compete with the caller's numpy work on small machines
    opts.add_session_config_entry("session.intra_op.allow_spinning", "0")
    return ort.InferenceSession(bytes(data), sess_options=opts, providers=["CPUExecutionProvider"])


class CheckedSession:
    """An onnxruntime session whose failures are typed: ``run`` raises ``NETWORK_RUNTIME`` naming the
    network (file, prim, attribute) for any runtime exception or an output that is not [n, declared width].
    Other attributes (``get_inputs``, ``get_outputs``, ...) are the wrapped session's."""

    def __init__(self, session, info: NetworkInfo | None = None, **loc) -> None:
        self.session = session
        self.info = info
        self.loc = loc

    def run(self, output_names, input_feed, run_options=None):
        rows = len(next(iter(input_feed.values()))) if input_feed else 0
        if rows > limits.MAX_NETWORK_ROWS:  # the most rows the runtime probe ran it at: memory grows with the rows
            parts = [self.run(output_names, {k: v[s:s + limits.MAX_NETWORK_ROWS] for k, v in input_feed.items()}, run_options)
                     for s in range(0, rows, limits.MAX_NETWORK_ROWS)]
            return [np.concatenate(outs) for outs in zip(*parts, strict=True)]
        try:
            outs = self.session.run(output_names, input_feed, run_options)
        except Exception as exc:  # onnxruntime raises its own exception types
            raise error("NETWORK_RUNTIME", f"onnxruntime failed to evaluate it: {(str(exc).strip() or type(exc).__name__)[:200]}",
                        **self.loc) from None
        if self.info is not None and input_feed:
            rows = len(next(iter(input_feed.values())))
            names = list(output_names) if output_names else list(self.info.output_names)
            widths = dict(zip(self.info.output_names, self.info.output_widths, strict=True))
            for name, out in zip(names, outs, strict=False):
                if np.shape(out) != (rows, widths.get(name, -1)):
                    raise error("NETWORK_RUNTIME", f"output {name!r} has shape {np.shape(out)} for {rows} rows, "
                                f"declared [n, {widths.get(name)}]", **self.loc)
        return outs

    def __getattr__(self, name):
        return getattr(self.session, name)
