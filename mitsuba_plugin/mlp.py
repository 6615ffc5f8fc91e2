"""An asset's ONNX decoder as a Dr.Jit MLP: the initializers are read once, the graph checked to be
a chain of affine layers and ReLUs (what ``nasset_sdk.networks.mlp_onnx`` and the bakers write).

Layers are evaluated with ``drjit.nn`` (``Linear`` + ``ReLU`` on a ``CoopVec``), so the network is
fused into the rendering kernel on every JIT backend.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nasset_sdk.errors import error


@dataclass(frozen=True)
class Layer:
    """y = x @ weight + bias, then ReLU when ``relu``; weight [in, out], bias [out] float32."""

    weight: np.ndarray
    bias: np.ndarray
    relu: bool


def _unsupported(what: str, **loc):
    return error("SCENE_UNSUPPORTED", f"the decoder is not a plain MLP the Mitsuba plugin can run: {what}", **loc)


def mlp_layers(onnx_bytes: bytes, **loc) -> list[Layer]:
    """Affine layers of a single-input, single-output ONNX MLP (Gemm | MatMul [+ Add]) [-> Relu] ...;
    anything else (Concat skips, other activations, dynamic weights) raises SCENE_UNSUPPORTED."""
    import onnx
    from onnx import helper, numpy_helper

    model = onnx.ModelProto()
    model.ParseFromString(bytes(onnx_bytes))
    g = model.graph
    inits = {t.name: numpy_helper.to_array(t).astype(np.float32) for t in g.initializer}
    for n in g.node:
        if n.op_type == "Constant":
            inits[n.output[0]] = numpy_helper.to_array(helper.get_attribute_value(n.attribute[0])).astype(np.float32)
    if len(g.input) != 1 or len(g.output) != 1:
        raise _unsupported(f"{len(g.input)} inputs and {len(g.output)} outputs (expected 1 and 1)", **loc)
    cur = g.input[0].name
    layers: list[Layer] = []
    for n in (n for n in g.node if n.op_type != "Constant"):
        if n.input[0] != cur:
            raise _unsupported(f"node {n.name or n.op_type} does not continue the chain", **loc)
        if n.op_type == "Gemm":
            a = {x.name: helper.get_attribute_value(x) for x in n.attribute}
            if a.get("transA", 0) or n.input[1] not in inits:
                raise _unsupported("Gemm with transA or a non-constant weight", **loc)
            w = inits[n.input[1]]
            w = (w.T if a.get("transB", 0) else w) * np.float32(a.get("alpha", 1.0))
            b = inits[n.input[2]] * np.float32(a.get("beta", 1.0)) if len(n.input) > 2 and n.input[2] else np.zeros(w.shape[1], np.float32)
            layers.append(Layer(w, np.broadcast_to(b.reshape(-1), (w.shape[1],)).astype(np.float32), False))
        elif n.op_type == "MatMul":
            if n.input[1] not in inits:
                raise _unsupported("MatMul with a non-constant weight", **loc)
            w = inits[n.input[1]]
            layers.append(Layer(w, np.zeros(w.shape[1], np.float32), False))
        elif n.op_type == "Add" and layers and not layers[-1].relu and n.input[1] in inits:
            last = layers.pop()
            layers.append(Layer(last.weight, (last.bias + inits[n.input[1]].reshape(-1)).astype(np.float32), False))
        elif n.op_type == "Relu" and layers and not layers[-1].relu:
            last = layers.pop()
            layers.append(Layer(last.weight, last.bias, True))
        elif n.op_type != "Identity":
            raise _unsupported(f"operator {n.op_type}", **loc)
        cur = n.output[0]
    if cur != g.output[0].name or not layers:
        raise _unsupported("the chain does not end at the output", **loc)
    for a, b in zip(layers[:-1], layers[1:], strict=False):
        if a.weight.ndim != 2 or b.weight.ndim != 2 or a.weight.shape[1] != b.weight.shape[0]:
            raise _unsupported("layer widths do not chain", **loc)
    return layers


class DrJitMLP:
    """The decoder in Dr.Jit: ``__call__(list of in Floats) -> list of out Floats`` (one kernel, no host round trip)."""

    def __init__(self, mi, layers: list[Layer]) -> None:
        import drjit.nn as nn

        tensor = mi.TensorXf
        mods = []
        for lay in layers:
            mods.append(nn.Linear(lay.weight.shape[0], lay.weight.shape[1]))
            if lay.relu:
                mods.append(nn.ReLU())
        net = nn.Sequential(*mods).alloc(tensor, size=layers[0].weight.shape[0])
        k = 0
        for m in net.layers:
            if isinstance(m, nn.Linear):
                m.weights = tensor(np.ascontiguousarray(layers[k].weight.T))  # drjit.nn stores [out, in]
                m.bias = tensor(np.ascontiguousarray(layers[k].bias))
                k += 1
        self.net = nn.pack(net, layout="inference")
        self.n_in = int(layers[0].weight.shape[0])
        self.n_out = int(layers[-1].weight.shape[1])

    def __call__(self, inputs: list) -> list:
        import drjit.nn as nn

        return list(self.net(nn.CoopVec(*inputs)))
