"""Hostile-network corpus: families of ONNX models that must not validate (spec/security.md#networks).

``python -m tests.corpus.gen_networks OUT_DIR`` writes every case; :func:`make_cases` returns them
with the code the validator must report. Each case swaps the decoder of a valid tiny ``rna``
asset for one model (input ``x`` [N, 16], output ``y`` [N, 6], as declared) and updates its digest
and opset, so the network check is the only thing that fails. Families:

* ``ext_*``     external data wherever a tensor can live (NETWORK_EXTERNAL_DATA)
* ``sparse_*``  inline sparse tensors (NETWORK_OP_FORBIDDEN: the format has none)
* ``op_*``      one operator outside the allow-list each (NETWORK_OP_FORBIDDEN)
* ``attr_*``    allowed operators with row-mixing attributes or computed parameters (NETWORK_OP_FORBIDDEN)
* ``shape_*``   values that shape inference cannot prove [N, fixed width] (NETWORK_SHAPE)
* ``batch_*``   a fixed batch dimension on an input or output (NETWORK_IO)
* ``out_*``     statically fine, but huge, Inf or NaN outputs on probe inputs (NETWORK_OUTPUT)
* ``time_*``    statically fine, but too slow for the probe's time bound (NETWORK_RUNTIME)
* ``mem_*``     statically fine and at 256 rows, but out of the probe's memory bound at the rows a reader runs (NETWORK_RUNTIME)
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable

import numpy as np

from tests.corpus.make_corpus import Case, _io, _set_model

DEC = "/_NassetPayloads/core/decoder"
IN_W = 16  # tiny rna surface decoder: C (4) + 12
OUT_W = 6
#: the probe timeout a test should pass for the time_* family (a legitimate tiny asset needs < 1 s)
TIME_CASE_TIMEOUT_S = 8.0


def _model(nodes, inits=(), *, opset=17, inputs=None, outputs=None, sparse=(), functions=(), value_info=()):
    from onnx import helper

    graph = helper.make_graph(nodes, "g", inputs or [_io("x", IN_W)], outputs or [_io("y", OUT_W)], list(inits),
                              sparse_initializer=list(sparse), value_info=list(value_info))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)], functions=list(functions))
    model.ir_version = 8
    return model


def _t(name, arr):
    from onnx import numpy_helper

    return numpy_helper.from_array(np.asarray(arr), name)


def _w(in_w=IN_W, out_w=OUT_W, scale=0.1, seed=0):
    rng = np.random.default_rng(seed)
    return [_t("W", (rng.normal(0, scale, (in_w, out_w))).astype(np.float32)), _t("B", np.zeros(out_w, np.float32))]


def _gemm(inp="x", out="y", w="W", b="B", **attrs):
    from onnx import helper

    return helper.make_node("Gemm", [inp, w, b], [out], **attrs)


def _externalize(t, location="secret.bin"):  # relative to the runtime's working folder
    from onnx import TensorProto

    t.ClearField("raw_data")
    t.ClearField("float_data")
    t.ClearField("int64_data")
    t.data_location = TensorProto.EXTERNAL
    t.external_data.add(key="location", value=location)
    t.external_data.add(key="offset", value="0")
    t.external_data.add(key="length", value=str(4 * max(1, int(np.prod(t.dims)))))
    return t


def _sparse(values, indices, dims, name):
    from onnx import helper

    return helper.make_sparse_tensor(_t(name, np.asarray(values, np.float32)), _t(name + "_idx", np.asarray(indices, np.int64)), dims)


def _ext_family() -> dict[str, object]:
    from onnx import AttributeProto, TensorProto, helper

    cases = {}
    # graph.sparse_initializer: values, then indices, in external data (the reported hole)
    for part in ("values", "indices"):
        sp = _sparse(np.ones(4), [0, 17, 34, 51], [IN_W, OUT_W], "W")
        _externalize(getattr(sp, part))
        cases[f"ext_sparse_initializer_{part}"] = _model([_gemm()], [_t("B", np.zeros(OUT_W, np.float32))], sparse=[sp])
    # Constant with sparse_value in external data
    sp = _sparse(np.ones(4), [0, 17, 34, 51], [IN_W, OUT_W], "Wc")
    _externalize(sp.values)
    cases["ext_constant_sparse_value"] = _model(
        [helper.make_node("Constant", [], ["W"], sparse_value=sp), _gemm()], [_t("B", np.zeros(OUT_W, np.float32))])
    # Constant value (attribute t) in external data
    t = _externalize(_t("Wt", np.zeros((IN_W, OUT_W), np.float32)))
    cases["ext_constant_value_t"] = _model([helper.make_node("Constant", [], ["W"], value=t), _gemm()], [_t("B", np.zeros(OUT_W, np.float32))])
    # a dense initializer, with and without data_location set
    w, b = _w()
    cases["ext_initializer"] = _model([_gemm()], [_externalize(w), b])
    w, b = _w()
    w.external_data.add(key="location", value="weights.bin")  # entries without data_location = EXTERNAL
    cases["ext_initializer_entries_only"] = _model([_gemm()], [w, b])
    # attribute lists: tensors, sparse_tensor, sparse_tensors (odd attributes on an otherwise fine graph)
    for kind in ("tensors", "sparse_tensor", "sparse_tensors"):
        node = helper.make_node("Identity", ["h"], ["y"])
        attr = node.attribute.add()
        attr.name = "payload"
        if kind == "tensors":
            attr.type = AttributeProto.TENSORS
            attr.tensors.append(_externalize(_t("p", np.zeros(4, np.float32))))
        else:
            sp = _sparse(np.ones(1), [0], [4], "p")
            _externalize(sp.values)
            if kind == "sparse_tensor":
                attr.type = AttributeProto.SPARSE_TENSOR
                attr.sparse_tensor.CopyFrom(sp)
            else:
                attr.type = AttributeProto.SPARSE_TENSORS
                attr.sparse_tensors.append(sp)
        cases[f"ext_attribute_{kind}"] = _model([_gemm(out="h"), node], _w())

    # subgraphs: If branches holding external initializers / sparse initializers / nested Ifs
    def branch(out, inits=(), sparse=(), nodes=None):
        return helper.make_graph(nodes or [helper.make_node("Identity", ["W"], [out])], f"b_{out}", [],
                                 [helper.make_tensor_value_info(out, TensorProto.FLOAT, [IN_W, OUT_W])], list(inits),
                                 sparse_initializer=list(sparse))

    def if_model(then_g, else_g):
        cond = _t("cond", np.array(True))
        return _model([helper.make_node("If", ["cond"], ["Wsel"], then_branch=then_g, else_branch=else_g),
                       _gemm(w="Wsel")], [cond, *_w()])

    cases["ext_subgraph_initializer"] = if_model(
        branch("t", [_externalize(_t("Wx", np.zeros((IN_W, OUT_W), np.float32)))], nodes=[helper.make_node("Identity", ["Wx"], ["t"])]),
        branch("e"))
    sp = _sparse(np.ones(2), [0, 1], [IN_W, OUT_W], "Ws")
    _externalize(sp.values)
    cases["ext_subgraph_sparse_initializer"] = if_model(branch("t", sparse=[sp], nodes=[helper.make_node("Identity", ["Ws"], ["t"])]),
                                                        branch("e"))
    inner = branch("t2", [_externalize(_t("Wx", np.zeros((IN_W, OUT_W), np.float32)))], nodes=[helper.make_node("Identity", ["Wx"], ["t2"])])
    nested = helper.make_graph([helper.make_node("If", ["cond"], ["t"], then_branch=inner, else_branch=branch("e2"))], "mid", [],
                               [helper.make_tensor_value_info("t", TensorProto.FLOAT, [IN_W, OUT_W])])
    cases["ext_subgraph_nested_twice"] = if_model(nested, branch("e"))
    sp = _sparse(np.ones(2), [0, 1], [IN_W, OUT_W], "Wc2")
    _externalize(sp.values)
    cases["ext_subgraph_constant_sparse"] = if_model(
        branch("t", nodes=[helper.make_node("Constant", [], ["t"], sparse_value=sp)]), branch("e"))
    # Loop body with an external Constant
    body = helper.make_graph(
        [helper.make_node("Identity", ["c_in"], ["c_out"]),
         helper.make_node("Constant", [], ["k"], value=_externalize(_t("k", np.zeros((1, OUT_W), np.float32)))),
         helper.make_node("Add", ["v_in", "k"], ["v_out"])],
        "body", [helper.make_tensor_value_info("i", TensorProto.INT64, []), helper.make_tensor_value_info("c_in", TensorProto.BOOL, []),
                 helper.make_tensor_value_info("v_in", TensorProto.FLOAT, ["N", OUT_W])],
        [helper.make_tensor_value_info("c_out", TensorProto.BOOL, []), helper.make_tensor_value_info("v_out", TensorProto.FLOAT, ["N", OUT_W])])
    cases["ext_loop_body_constant"] = _model(
        [_gemm(out="h"), helper.make_node("Loop", ["trip", "cond", "h"], ["y"], body=body)],
        [*_w(), _t("trip", np.array(1, np.int64)), _t("cond", np.array(True))])
    # a local function body holding an external Constant
    fn = helper.make_function("local", "Bias", ["a"], ["b"], [
        helper.make_node("Constant", [], ["k"], value=_externalize(_t("k", np.zeros((1, OUT_W), np.float32)))),
        helper.make_node("Add", ["a", "k"], ["b"])], [helper.make_opsetid("", 17)])
    m = _model([_gemm(out="h"), helper.make_node("Bias", ["h"], ["y"], domain="local")], _w(), functions=[fn])
    m.opset_import.append(helper.make_opsetid("local", 1))
    cases["ext_function_body"] = m
    # training_info graphs
    m = _model([_gemm()], _w())
    ti = m.training_info.add()
    ti.initialization.CopyFrom(helper.make_graph([], "init", [], [], [_externalize(_t("Wt", np.zeros((IN_W, OUT_W), np.float32)))]))
    cases["ext_training_info"] = m
    return cases


def _sparse_family() -> dict[str, object]:
    from onnx import helper

    sp = _sparse(np.full(4, 0.1), [0, 17, 34, 51], [IN_W, OUT_W], "W")
    return {
        "sparse_initializer_inline": _model([_gemm()], [_t("B", np.zeros(OUT_W, np.float32))], sparse=[sp]),
        "sparse_constant_inline": _model([helper.make_node("Constant", [], ["W"], sparse_value=sp), _gemm()],
                                         [_t("B", np.zeros(OUT_W, np.float32))]),
    }


def _op_family() -> dict[str, object]:
    """Operators outside the allow-list, each in a structurally valid model (onnx.checker passes)."""
    from onnx import TensorProto, helper

    i64 = lambda name, v: _t(name, np.asarray(v, np.int64))  # noqa: E731
    f32 = lambda name, v: _t(name, np.asarray(v, np.float32))  # noqa: E731
    mk = helper.make_node
    ops: dict[str, tuple[list, list]] = {
        "Reshape": ([mk("Reshape", ["h", "s"], ["y"])], [i64("s", [-1, OUT_W])]),
        "Transpose": ([mk("Transpose", ["h"], ["t"]), mk("Transpose", ["t"], ["y"], perm=[1, 0])], []),
        "Flatten": ([mk("Flatten", ["h"], ["y"], axis=0)], []),
        "Unsqueeze": ([mk("Unsqueeze", ["h", "a"], ["u"]), mk("Squeeze", ["u", "a"], ["y"])], [i64("a", [0])]),
        "Squeeze": ([mk("Squeeze", ["h"], ["y"])], []),
        "Expand": ([mk("Expand", ["h", "s"], ["y"])], [i64("s", [1, OUT_W])]),
        "Tile": ([mk("Tile", ["h", "r"], ["y"])], [i64("r", [1, 1])]),
        "Shape_ConstantOfShape": ([mk("Shape", ["h"], ["s"]), mk("ConstantOfShape", ["s"], ["z"]), mk("Add", ["h", "z"], ["y"])], []),
        "ConstantOfShape_sized_by_input": ([mk("ReduceMax", ["x"], ["m"], keepdims=0), mk("Cast", ["m"], ["mi"], to=TensorProto.INT64),
                                            mk("Unsqueeze", ["mi", "a"], ["s"]), mk("ConstantOfShape", ["s"], ["z"]),
                                            mk("Add", ["h", "z"], ["y"])], [i64("a", [0])]),
        "Range": ([mk("Range", ["a", "b", "c"], ["r"]), mk("Add", ["h", "r"], ["y"])], [f32("a", 0), f32("b", 6), f32("c", 1)]),
        "NonZero": ([mk("NonZero", ["h"], ["nz"]), mk("Cast", ["nz"], ["y"], to=TensorProto.FLOAT)], []),
        "TopK": ([mk("TopK", ["h", "k"], ["y", "idx"], axis=0)], [i64("k", [1])]),
        "Gather": ([mk("Gather", ["h", "i"], ["y"], axis=0)], [i64("i", [0])]),
        "GatherElements": ([mk("GatherElements", ["h", "i"], ["y"], axis=0)], [i64("i", np.zeros((1, OUT_W)))]),
        "ArgMax": ([mk("ArgMax", ["h"], ["am"], axis=0), mk("Cast", ["am"], ["c"], to=TensorProto.FLOAT), mk("Add", ["h", "c"], ["y"])], []),
        "Einsum": ([mk("Einsum", ["h", "h"], ["y"], equation="ij,kj->ij")], []),
        "Resize": ([mk("Resize", ["h", "", "sc"], ["y"])], [f32("sc", [2.0, 1.0])]),
        "Pad": ([mk("Pad", ["h", "p"], ["y"])], [i64("p", [1, 0, 0, 0])]),
        "CumSum": ([mk("CumSum", ["h", "ax"], ["y"])], [i64("ax", 0)]),
        "Hardmax": ([mk("Hardmax", ["h"], ["y"], axis=0)], []),
        "LpNormalization": ([mk("LpNormalization", ["h"], ["y"], axis=0)], []),
        "MeanVarianceNormalization": ([mk("MeanVarianceNormalization", ["h"], ["y"], axes=[0])], []),
        "InstanceNormalization": ([mk("InstanceNormalization", ["h", "s", "b"], ["y"])], [f32("s", np.ones(OUT_W)), f32("b", np.zeros(OUT_W))]),
        "BatchNormalization": ([mk("BatchNormalization", ["h", "s", "b", "m", "v"], ["y"], training_mode=0)],
                               [f32("s", np.ones(OUT_W)), f32("b", np.zeros(OUT_W)), f32("m", np.zeros(OUT_W)), f32("v", np.ones(OUT_W))]),
        "Dropout": ([mk("Dropout", ["h"], ["y"])], []),
        "RandomNormalLike": ([mk("RandomNormalLike", ["h"], ["r"]), mk("Add", ["h", "r"], ["y"])], []),
        "RandomUniformLike": ([mk("RandomUniformLike", ["h"], ["r"]), mk("Add", ["h", "r"], ["y"])], []),
        "Bernoulli": ([mk("Sigmoid", ["h"], ["p"]), mk("Bernoulli", ["p"], ["y"])], []),
        "Conv": ([mk("Conv", ["h", "k"], ["y"])], [f32("k", np.ones((OUT_W, OUT_W)))]),
        "MaxPool": ([mk("MaxPool", ["h"], ["y"], kernel_shape=[2])], []),
        "Compress": ([mk("Compress", ["h", "keep"], ["y"], axis=0)], [_t("keep", np.array([True]))]),
        "Unique": ([mk("Unique", ["h"], ["y"], axis=0)], []),
        "Trilu": ([mk("Trilu", ["h"], ["y"])], []),
        "ScatterElements": ([mk("ScatterElements", ["h", "i", "u"], ["y"], axis=0)], [i64("i", np.zeros((1, OUT_W))), f32("u", np.ones((1, OUT_W)))]),
        "Mod": ([mk("Mod", ["h", "d"], ["y"], fmod=1)], [f32("d", 0.0)]),
        "Sign": ([mk("Sign", ["h"], ["y"])], []),
        "Ceil": ([mk("Ceil", ["h"], ["y"])], []),
        "Asin": ([mk("Asin", ["h"], ["y"])], []),
        "GlobalAveragePool": ([mk("GlobalAveragePool", ["h"], ["y"])], []),
        "DepthToSpace": ([mk("DepthToSpace", ["h"], ["y"], blocksize=2)], []),
    }
    cases = {}
    for op, (nodes, inits) in ops.items():
        cases[f"op_{op.lower()}"] = _model([_gemm(out="h"), *nodes], [*_w(), *inits])
    # control flow: Loop whose trip count comes from the input; If on an input value; Scan over the batch
    body = helper.make_graph(
        [helper.make_node("Identity", ["c_in"], ["c_out"]), helper.make_node("Add", ["v_in", "v_in"], ["v_out"])],
        "body", [helper.make_tensor_value_info("i", TensorProto.INT64, []), helper.make_tensor_value_info("c_in", TensorProto.BOOL, []),
                 helper.make_tensor_value_info("v_in", TensorProto.FLOAT, ["N", OUT_W])],
        [helper.make_tensor_value_info("c_out", TensorProto.BOOL, []), helper.make_tensor_value_info("v_out", TensorProto.FLOAT, ["N", OUT_W])])
    cases["op_loop_trip_from_input"] = _model(
        [_gemm(out="h"), mk("ReduceMax", ["x"], ["m"], keepdims=0), mk("Mul", ["m", "big"], ["mb"]),
         mk("Cast", ["mb"], ["trip"], to=TensorProto.INT64), mk("Loop", ["trip", "", "h"], ["y"], body=body)],
        [*_w(), f32("big", 1e9)])
    branch = lambda out, op: helper.make_graph([mk(op, ["h"], [out])], f"b{out}", [],  # noqa: E731
                                               [helper.make_tensor_value_info(out, TensorProto.FLOAT, ["N", OUT_W])])
    cases["op_if_on_input_value"] = _model(
        [_gemm(out="h"), mk("ReduceMax", ["x"], ["m"], keepdims=0), mk("Greater", ["m", "z"], ["c"]),
         mk("If", ["c"], ["y"], then_branch=branch("t", "Relu"), else_branch=branch("e", "Sigmoid"))], [*_w(), f32("z", 0.5)])
    sbody = helper.make_graph([mk("Add", ["s_in", "row"], ["s_out"]), mk("Identity", ["s_out"], ["o"])], "sb",
                              [helper.make_tensor_value_info("s_in", TensorProto.FLOAT, [OUT_W]),
                               helper.make_tensor_value_info("row", TensorProto.FLOAT, [OUT_W])],
                              [helper.make_tensor_value_info("s_out", TensorProto.FLOAT, [OUT_W]),
                               helper.make_tensor_value_info("o", TensorProto.FLOAT, [OUT_W])])
    cases["op_scan_over_batch"] = _model(
        [_gemm(out="h"), mk("Scan", ["s0", "h"], ["s", "y"], body=sbody, num_scan_inputs=1)], [*_w(), f32("s0", np.zeros(OUT_W))])
    return cases


def _attr_family() -> dict[str, object]:
    """Allowed operators used across rows, with computed parameters, or with forbidden attributes."""
    from onnx import TensorProto, helper

    mk = helper.make_node
    i64 = lambda name, v: _t(name, np.asarray(v, np.int64))  # noqa: E731
    f32 = lambda name, v: _t(name, np.asarray(v, np.float32))  # noqa: E731
    half = [_t("W", np.zeros((IN_W, 3), np.float32)), _t("B", np.zeros(3, np.float32))]
    c = {
        "attr_concat_axis0": ([_gemm(out="h"), mk("Concat", ["h", "h"], ["y"], axis=0)], _w()),
        "attr_gemm_transA": ([mk("Gemm", ["x", "Wt", "B"], ["y"], transA=1)], [f32("Wt", np.zeros((OUT_W, OUT_W))), f32("B", np.zeros(OUT_W))]),
        "attr_gemm_B_from_input": ([mk("Gemm", ["x", "x"], ["g"], transB=1), mk("Slice", ["g", "s", "e", "a"], ["y"])],
                                   [i64("s", [0]), i64("e", [OUT_W]), i64("a", [1])]),
        "attr_gemm_alpha_inf": ([_gemm(alpha=float("inf"))], _w()),
        "attr_matmul_B_computed": ([_gemm(out="h"), mk("Relu", ["W"], ["Wr"]), mk("MatMul", ["x", "Wr"], ["m"]), mk("Add", ["m", "h"], ["y"])],
                                   _w()),
        "attr_softmax_axis0": ([_gemm(out="h"), mk("Softmax", ["h"], ["y"], axis=0)], _w()),
        "attr_logsoftmax_axis0": ([_gemm(out="h"), mk("LogSoftmax", ["h"], ["y"], axis=0)], _w()),
        "attr_layernorm_axis0": ([_gemm(out="h"), mk("LayerNormalization", ["h", "s"], ["y"], axis=0)], [*_w(), f32("s", np.ones(OUT_W))]),
        "attr_reducesum_axis0": ([_gemm(out="h"), mk("ReduceSum", ["h", "a"], ["r"]), mk("Add", ["h", "r"], ["y"])], [*_w(), i64("a", [0])]),
        "attr_reducesum_no_axes": ([_gemm(out="h"), mk("ReduceSum", ["h"], ["r"]), mk("Add", ["h", "r"], ["y"])], _w()),
        "attr_reducesum_keepdims0": ([_gemm(out="h"), mk("ReduceSum", ["h", "a"], ["r"], keepdims=0), mk("Add", ["h", "r"], ["y"])],
                                     [*_w(), i64("a", [1])]),
        "attr_reducemean_axis0_attr": ([_gemm(out="h"), mk("ReduceMean", ["h"], ["r"], axes=[0]), mk("Sub", ["h", "r"], ["y"])], _w()),
        "attr_reducemax_axes_computed": ([_gemm(out="h"), mk("Add", ["a", "z"], ["ac"]), mk("ReduceMax", ["h", "ac"], ["r"], keepdims=1),
                                          mk("Sub", ["h", "r"], ["y"])], [*_w(), i64("a", [1]), i64("z", [0]), 18]),
        "attr_slice_no_axes": ([_gemm(out="h"), mk("Slice", ["h", "s", "e"], ["y"])], [*_w(), i64("s", [0]), i64("e", [1])]),
        "attr_slice_axis0": ([_gemm(out="h"), mk("Slice", ["h", "s", "e", "a"], ["y"])], [*_w(), i64("s", [0]), i64("e", [1]), i64("a", [0])]),
        "attr_slice_ends_computed": ([_gemm(out="h"), mk("Add", ["e", "z"], ["ec"]), mk("Slice", ["h", "s", "ec", "a"], ["y"])],
                                     [*_w(), i64("s", [0]), i64("e", [OUT_W]), i64("z", [0]), i64("a", [1])]),
        "attr_split_axis0": ([_gemm(out="h"), mk("Split", ["h"], ["y", "rest"], axis=0)], _w()),
        "attr_clip_min_computed": ([_gemm(out="h"), mk("ReduceMin", ["h", "a"], ["m"]), mk("Clip", ["h", "m"], ["y"])], [*_w(), i64("a", [1]), 18]),
        "attr_cast_to_int32": ([_gemm(out="h"), mk("Cast", ["h"], ["hi"], to=TensorProto.INT32), mk("Cast", ["hi"], ["y"], to=TensorProto.FLOAT)],
                               _w()),
        # GatherElements reads rows of a constant table only: computed data would let row i read row j
        "attr_gatherelements_data_computed": ([_gemm(out="h"), mk("Cast", ["h"], ["hi"], to=TensorProto.INT64),
                                               mk("Abs", ["hi"], ["ha"]), mk("Min", ["ha", "z"], ["i"]),
                                               mk("GatherElements", ["h", "i"], ["y"], axis=0)], [*_w(), i64("z", 0)]),
        "attr_gatherelements_axis1": ([_gemm(out="h"), mk("Mul", ["h", "z"], ["hz"]), mk("Cast", ["hz"], ["i"], to=TensorProto.INT64),
                                       mk("GatherElements", ["t", "i"], ["y"], axis=1)],
                                      [*_w(), f32("z", 0.0), f32("t", np.ones((4, OUT_W)))]),
        "attr_constant_string": ([_gemm(), mk("Constant", [], ["s"], value_string="x")], _w()),
        "attr_concat_axis_minus2": ([_gemm(out="h3"), mk("Concat", ["h3", "h3"], ["y"], axis=-2)], half),
    }
    out = {}
    for name, (nodes, inits) in c.items():  # a trailing int in the initializer list is the opset
        opset = inits[-1] if isinstance(inits[-1], int) else 17
        out[name] = _model(nodes, [i for i in inits if not isinstance(i, int)], opset=opset)
    return out


def _shape_family() -> dict[str, object]:
    """Allowed operators whose values are not [N, fixed width] with N the batch."""
    from onnx import helper

    mk = helper.make_node
    f32 = lambda name, v: _t(name, np.asarray(v, np.float32))  # noqa: E731
    rng = np.random.default_rng(1)
    c = {
        "shape_fixed_batch_broadcast": ([_gemm(out="h"), mk("Add", ["h", "k"], ["y"])], [*_w(), f32("k", np.zeros((7, OUT_W)))]),
        "shape_concat_constant_row": ([_gemm(out="h", w="W5", b="B5"), mk("Concat", ["h", "k"], ["y"], axis=1)],
                                      [f32("W5", rng.normal(0, .1, (IN_W, 5))), f32("B5", np.zeros(5)), f32("k", np.zeros((1, 1)))]),
        "shape_matmul_rank3": ([mk("MatMul", ["x", "W3"], ["y"])], [f32("W3", np.zeros((2, IN_W, OUT_W)))]),
        "shape_width_differs_from_declared": ([_gemm(w="W5", b="B5")], [f32("W5", np.zeros((IN_W, 5))), f32("B5", np.zeros(5))]),
        "shape_gemm_weights_do_not_fit": ([_gemm(w="Wb")], [f32("Wb", np.zeros((IN_W + 5, OUT_W))), f32("B", np.zeros(OUT_W))]),
        "shape_hidden_too_wide": ([_gemm(out="h", w="Wh", b="Bh"), _gemm(inp="h", w="W2", b="B")],
                                  [f32("Wh", np.zeros((IN_W, 5000))), f32("Bh", np.zeros(5000)), f32("W2", np.zeros((5000, OUT_W))),
                                   f32("B", np.zeros(OUT_W))]),
        "shape_constant_broadcast_blowup": ([mk("Mul", ["a", "b"], ["ab"]), _gemm()],  # 2^26 elements from two 8192-vectors
                                            [*_w(), f32("a", np.ones((8192, 1))), f32("b", np.ones((1, 8192)))]),
        "shape_output_is_constant": ([_gemm(out="h"), mk("Constant", [], ["y"], value=f32("c", np.zeros((1, OUT_W))))], _w()),
        "shape_elementwise_rank3": ([_gemm(out="h"), mk("Add", ["h", "k"], ["y"])], [*_w(), f32("k", np.zeros((2, 1, OUT_W)))]),
    }
    return {name: _model(nodes, inits) for name, (nodes, inits) in c.items()}


def _batch_family() -> dict[str, object]:
    from onnx import TensorProto, helper

    fixed = lambda name, n, w: helper.make_tensor_value_info(name, TensorProto.FLOAT, [n, w])  # noqa: E731
    return {
        "batch_input_fixed_1": _model([_gemm()], _w(), inputs=[fixed("x", 1, IN_W)]),
        "batch_input_fixed_7": _model([_gemm()], _w(), inputs=[fixed("x", 7, IN_W)]),
        "batch_output_fixed_256": _model([_gemm()], _w(), outputs=[fixed("y", 256, OUT_W)]),
        "batch_both_fixed_2": _model([_gemm()], _w(), inputs=[fixed("x", 2, IN_W)], outputs=[fixed("y", 2, OUT_W)]),
    }


def _output_family() -> dict[str, object]:
    """Statically fine graphs whose outputs on probe inputs are huge, Inf or NaN."""
    from onnx import helper

    mk = helper.make_node
    f32 = lambda name, v: _t(name, np.asarray(v, np.float32))  # noqa: E731
    c = {
        "out_weights_near_float_max": ([_gemm()], _w(scale=3e37)),
        "out_bias_near_float_max": ([_gemm()], [_w()[0], f32("B", np.full(OUT_W, 3e38))]),
        "out_weights_1e12": ([_gemm()], _w(scale=1e12)),
        "out_just_above_bound": ([_gemm(out="h"), mk("Add", ["h", "k"], ["y"])], [*_w(), f32("k", np.full((1, OUT_W), 2e8))]),
        "out_exp_overflow": ([_gemm(out="h"), mk("Mul", ["h", "k"], ["hk"]), mk("Exp", ["hk"], ["y"])], [*_w(scale=1.0), f32("k", 1000.0)]),
        "out_mul_overflow_inf": ([_gemm(out="h"), mk("Mul", ["h", "k"], ["hk"]), mk("Mul", ["hk", "k"], ["y"])], [*_w(scale=1.0), f32("k", 1e30)]),
        "out_log_negative_nan": ([_gemm(out="h"), mk("Log", ["h"], ["y"])], _w(scale=1.0)),
        "out_sqrt_negative_nan": ([_gemm(out="h"), mk("Sqrt", ["h"], ["y"])], _w(scale=1.0)),
        "out_div_zero_by_zero": ([_gemm(out="h"), mk("Sub", ["h", "h"], ["z"]), mk("Div", ["z", "z"], ["y"])], _w()),
        "out_pow_negative_half": ([_gemm(out="h"), mk("Pow", ["h", "p"], ["y"])], [*_w(scale=1.0), f32("p", 0.5)]),
        "out_huge_in_a_region": ([mk("Gemm", ["x", "W", "B"], ["h"]), mk("Relu", ["h"], ["r"]), mk("Mul", ["r", "k"], ["y"])],
                                 [f32("W", np.eye(IN_W, OUT_W)), f32("B", np.full(OUT_W, -0.5)), f32("k", 1e12)]),
        "out_reciprocal_of_zero": ([_gemm(out="h"), mk("Sub", ["h", "h"], ["z"]), mk("Reciprocal", ["z"], ["y"])], _w()),
    }
    return {name: _model(nodes, inits) for name, (nodes, inits) in c.items()}


def _time_family() -> dict[str, object]:
    """Statically fine, but far beyond the probe's time bound (minutes per 256-row batch on one core)."""
    from onnx import helper

    rng = np.random.default_rng(2)
    width, layers = 2048, 4000  # ~9 TFLOP per 256-row batch
    nodes = [_gemm(out="h0", w="Win", b="Bh")]
    for i in range(1, layers):
        nodes.append(helper.make_node("Gemm", [f"h{i - 1}", "Wh", "Bh"], [f"h{i}"]))
    nodes.append(_gemm(inp=f"h{layers - 1}", w="Wout", b="B"))
    inits = [_t("Win", rng.normal(0, 0.1, (IN_W, width)).astype(np.float32)), _t("Bh", np.zeros(width, np.float32)),
             _t("Wh", (np.eye(width) * 0.999).astype(np.float32)),
             _t("Wout", rng.normal(0, 0.1, (width, OUT_W)).astype(np.float32)), _t("B", np.zeros(OUT_W, np.float32))]
    return {"time_deep_shared_weights": _model(nodes, inits)}


def _memory_family() -> dict[str, object]:
    """Statically fine and fine at 256 rows, but megabytes of live activations per row: 100 parallel [N, 4096] branches
    summed at the end (~1.6 MB a row: 430 MB at 256 rows, 6.7 GB at the 4096 rows a reader runs at once)."""
    from onnx import helper

    rng = np.random.default_rng(3)
    width, branches = 4096, 100
    nodes = [helper.make_node("Gemm", ["x", "Wb", "Bb"], [f"h{i}"], alpha=1.0 + 1e-3 * i) for i in range(branches)]
    nodes += [helper.make_node("Sum", [f"h{i}" for i in range(branches)], ["s"]), _gemm(inp="s", w="Wo", b="B")]
    inits = [_t("Wb", rng.normal(0, 0.01, (IN_W, width)).astype(np.float32)), _t("Bb", np.zeros(width, np.float32)),
             _t("Wo", rng.normal(0, 0.01, (width, OUT_W)).astype(np.float32)), _t("B", np.zeros(OUT_W, np.float32))]
    return {"mem_wide_parallel_branches": _model(nodes, inits)}


FAMILIES: dict[str, tuple[str, Callable[[], dict]]] = {
    "external data": ("NETWORK_EXTERNAL_DATA", _ext_family),
    "sparse tensors": ("NETWORK_OP_FORBIDDEN", _sparse_family),
    "operators outside the allow-list": ("NETWORK_OP_FORBIDDEN", _op_family),
    "row-mixing attributes / computed parameters": ("NETWORK_OP_FORBIDDEN", _attr_family),
    "shapes not [N, fixed width]": ("NETWORK_SHAPE", _shape_family),
    "fixed batch dimension": ("NETWORK_IO", _batch_family),
    "huge / non-finite outputs": ("NETWORK_OUTPUT", _output_family),
    "time bound": ("NETWORK_RUNTIME", _time_family),
    "memory per row": ("NETWORK_RUNTIME", _memory_family),
}


def family_models() -> dict[str, tuple[str, str, bytes]]:
    """name -> (family, expected code, model bytes) for every case."""
    out = {}
    for family, (code, make) in FAMILIES.items():
        for name, model in make().items():
            out[name] = (family, code, model.SerializeToString())
    return out


def case_name_of(model_name: str) -> str:
    """Corpus case name: ``r1_`` (issue class 1, external data and sparse tensors) or ``r4_`` (class 4)."""
    return ("r1_" if model_name.startswith(("ext_", "sparse_")) else "r4_") + model_name


def make_cases(out_dir: Path) -> list[Case]:
    """Write every case (an rna tiny asset with the decoder replaced) into ``out_dir``; return the cases."""
    from pxr import Sdf, Usd

    from nasset_sdk.examples import example_builder

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    base = example_builder("rna", variant="surface", size="tiny", seed=0).write(out / "_base_networks.usdc")
    cases = []
    for name, (_, code, blob) in family_models().items():
        layer = Sdf.Layer.OpenAsAnonymous(str(base))
        stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
        with Usd.EditContext(stage, layer):
            _set_model(stage, DEC, blob)
            from onnx import ModelProto

            m = ModelProto()
            m.ParseFromString(blob)
            opset = max((o.version for o in m.opset_import if o.domain in ("", "ai.onnx")), default=17)
            stage.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(int(opset))
        case_name = case_name_of(name)
        path = out / f"{case_name}.usdc"
        if not layer.Export(str(path)):
            raise RuntimeError(f"case {name} did not export")
        # a network past the probe's time bound: only the validator with its probe (a child it can stop) judges it;
        # the corpus's in-process pass would only run into its own 15 s bound first
        cases.append(Case(case_name, path, code, probe=name.startswith("time_")))
    return cases


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "generated_networks")
    for case in make_cases(target):
        print(f"{case.code:<24} {case.path.name}")
