"""Embedded ONNX networks: build plain MLP graphs, check untrusted model bytes, run them.

The format's networks are MLP-only graphs of standard operators with float32 inputs and
outputs of shape [N, width] (spec/format.md#networks). Everything else (encodings, spline
math) is done by the SDK in numpy.
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


def check_model_bytes(data: bytes, declared: NetworkInfo | None = None, **loc):
    """Parse and check untrusted ONNX bytes; return the ModelProto or raise a typed error.

    Checks (spec/security.md#networks): size bound, parse, no external data, only default
    operator domains, opset in range and equal to the declaration, onnx.checker, I/O names and
    widths equal to ``declared``.
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

    def tensors_of(graph):
        yield from graph.initializer
        for node in graph.node:
            for attr in node.attribute:
                if attr.HasField("t"):
                    yield attr.t
                yield from attr.tensors
                if attr.HasField("g"):
                    yield from tensors_of(attr.g)
                for g in attr.graphs:
                    yield from tensors_of(g)

    for t in tensors_of(model.graph):
        if t.data_location == TensorProto.EXTERNAL or len(t.external_data):
            raise error("NETWORK_EXTERNAL_DATA", f"tensor {t.name!r} references external data", **loc)
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
    try:
        onnx.checker.check_model(model)
    except Exception as exc:
        raise error("NETWORK_PARSE", f"onnx.checker rejects the model: {str(exc).splitlines()[0][:200]}", **loc) from None
    init_names = {t.name for t in model.graph.initializer}
    inputs = [v for v in model.graph.input if v.name not in init_names]
    outputs = list(model.graph.output)
    for v in inputs + outputs:
        tt = v.type.tensor_type
        if tt.elem_type != TensorProto.FLOAT or len(tt.shape.dim) != 2:
            raise error("NETWORK_IO", f"{v.name!r} must be float32 of rank 2 [N, width]", **loc)
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
    return model


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
