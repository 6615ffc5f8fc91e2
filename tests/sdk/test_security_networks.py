"""Hostile networks (spec/security.md#networks): every generated case is refused with its own code by
the validator (and, for the static codes, by the reader); a seeded, time-bounded fuzz of ONNX graphs
drawn from the allow-list and outside it; evaluation failures are typed at render time."""

from __future__ import annotations

import time

import numpy as np
import pytest

from nasset_sdk import Asset
from nasset_sdk.errors import CODES, NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.netprobe import ProbeJob, check_outputs, probe_inputs, probe_networks
from nasset_sdk.networks import ALLOWED_OPS, NetworkInfo, check_model_bytes, make_session
from nasset_sdk.validate import validate_file
from tests.corpus.gen_networks import FAMILIES, TIME_CASE_TIMEOUT_S, case_name_of, family_models, make_cases

MODELS = family_models()
STATIC = {"NETWORK_EXTERNAL_DATA", "NETWORK_OP_FORBIDDEN", "NETWORK_SHAPE", "NETWORK_IO"}


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    return {c.name: c for c in make_cases(tmp_path_factory.mktemp("netcorpus"))}


def test_families_are_large():
    per_family: dict[str, int] = {}
    for family, _, _ in MODELS.values():
        per_family[family] = per_family.get(family, 0) + 1
    assert set(per_family) == set(FAMILIES)
    assert len(MODELS) >= 100, per_family
    assert all(n >= 4 for f, n in per_family.items() if f not in ("sparse tensors", "time bound", "memory per row")), per_family


@pytest.mark.parametrize("name", sorted(MODELS))
def test_case_is_refused_with_its_code(cases, name):
    case = cases[case_name_of(name)]
    report = validate_file(case.path, probe=False, network_probe_timeout=TIME_CASE_TIMEOUT_S)
    assert case.code in report.codes("error"), report.format_text()
    assert not report.ok and "CHECK_FAILED" not in report.codes(), report.format_text()
    if case.code in STATIC:  # readers run the same static check before any runtime sees the bytes
        asset = Asset.open(case.path)
        with pytest.raises(NassetError) as info:
            asset.session("core", "decoder")
        assert info.value.code == case.code and info.value.prim and info.value.file == str(case.path)


def test_static_cases_never_reach_a_runtime():
    """check_model_bytes alone (no onnxruntime involved) refuses every static case with its code."""
    import onnx

    for name, (_, code, blob) in MODELS.items():
        if code not in STATIC:
            continue
        opset = max((o.version for o in onnx.load_from_string(blob).opset_import if o.domain == ""), default=17)
        with pytest.raises(NassetError) as err:
            check_model_bytes(blob, NetworkInfo(("x",), ("y",), (16,), (6,), opset))
        assert err.value.code == code, (name, err.value)


def test_probe_bounds_time_and_reports_runtime():
    job = ProbeJob("slow", MODELS["time_deep_shared_weights"][2], ("x",), (16,), ("y",), (6,))
    t0 = time.perf_counter()
    found = probe_networks([job], timeout=2.0)
    assert found["slow"][0][0] == "NETWORK_RUNTIME" and "did not finish" in found["slow"][0][1]
    assert time.perf_counter() - t0 < 10


def test_checked_session_runs_at_most_the_rows_the_probe_ran():
    """A batch larger than limits.MAX_NETWORK_ROWS is run in parts (the probe bounded memory at that size), same result."""
    from nasset_sdk import limits
    from nasset_sdk.networks import CheckedSession, make_session, random_mlp

    blob = random_mlp(np.random.default_rng(0), [16, 32, 6])
    direct = make_session(blob, intra_threads=1)
    info = NetworkInfo(("x",), ("y",), (16,), (6,), 17)
    x = np.random.default_rng(1).uniform(-1, 1, (2 * limits.MAX_NETWORK_ROWS + 5, 16)).astype(np.float32)
    seen = []

    class Rows:  # records the rows of each run it is given (the wrapped session is a real onnxruntime one)
        def run(self, names, feed, options=None):
            seen.append(len(feed["x"]))
            return direct.run(names, feed, options)

    out = CheckedSession(Rows(), info, file="f").run(None, {"x": x})[0]
    assert max(seen) <= limits.MAX_NETWORK_ROWS and sum(seen) == len(x)
    assert np.allclose(out, direct.run(None, {"x": x})[0], rtol=1e-6, atol=1e-7)


def test_render_time_failures_are_typed(tmp_path):
    path = example_builder("rna", size="tiny", seed=0).write(tmp_path / "a.usdc")
    asset = Asset.open(path)
    session = asset.session("core", "decoder")
    with pytest.raises(NassetError) as info:  # a wrong-width batch: onnxruntime raises, the SDK types it
        session.run(None, {"x": np.zeros((4, 5), np.float32)})
    assert info.value.code == "NETWORK_RUNTIME"
    assert info.value.prim.endswith("/core/decoder") and info.value.attribute == "onnx:model" and info.value.file == str(path)
    ev = asset.evaluator()
    n = 8
    d = np.tile([[0.0, 0.0, 1.0]], (n, 1))
    unshadowed, _ = ev.evaluate(np.zeros((n, 3)), d, d, d)  # normal evaluation goes through the same wrapper
    assert unshadowed.shape == (n, 3) and np.isfinite(unshadowed).all()


# -- ONNX graph fuzz -------------------------------------------------------------------------

FUZZ_GRAPHS = 500
FUZZ_BUDGET_S = 30.0
_UNARY = ["Relu", "LeakyRelu", "Sigmoid", "Tanh", "Softplus", "Exp", "Abs", "Neg", "Sin", "Cos", "Sqrt", "Log", "Erf", "Elu",
          "Selu", "HardSigmoid", "Softsign", "Reciprocal", "Identity"]
_BINARY = ["Add", "Sub", "Mul", "Div", "Max", "Min", "Pow"]
_OUTSIDE = ["Transpose", "Reshape", "Flatten", "Shape", "Tile", "Expand", "CumSum", "Hardmax", "Ceil", "Dropout", "Gather"]


def _random_graph(rng: np.random.Generator):
    """A random graph x [N, 16] -> y [N, 6] from allowed operators with random attributes, and
    sometimes operators outside the allow-list or widths that do not fit."""
    from onnx import TensorProto, helper, numpy_helper

    opset = int(rng.choice([17, 18]))
    nodes, inits = [], []
    values = [("x", 16)]
    counter = [0]

    def name(p):
        counter[0] += 1
        return f"{p}{counter[0]}"

    def const(arr, dtype=np.float32):
        n = name("c")
        inits.append(numpy_helper.from_array(np.asarray(arr, dtype), n))
        return n

    def pick():
        return values[int(rng.integers(len(values)))]

    def axis():
        return int(rng.choice([1, -1, 1, -1, 1, 0, -2]))

    for _ in range(int(rng.integers(1, 9))):
        v, w = pick()
        kind = rng.choice(["unary", "binary", "gemm", "matmul", "concat", "slice", "reduce", "softmax", "layernorm", "clip",
                           "outside", "bad"], p=[.18, .16, .14, .06, .08, .08, .08, .05, .04, .04, .05, .04])
        out = name("v")
        if kind == "unary":
            nodes.append(helper.make_node(str(rng.choice(_UNARY)), [v], [out]))
        elif kind == "binary":
            other = rng.choice(["same", "row", "vec", "scalar"])
            cands = [n for n, ww in values if ww == w]
            b = (str(rng.choice(cands)) if other == "same" else const(rng.normal(0, 1, (1, w))) if other == "row"
                 else const(rng.normal(0, 1, w)) if other == "vec" else const(rng.normal(0, 1)))
            nodes.append(helper.make_node(str(rng.choice(_BINARY)), [v, b], [out]))
        elif kind in ("gemm", "matmul"):
            k = int(rng.integers(1, 33))
            if kind == "gemm":
                ta, tb = int(rng.random() < 0.15), int(rng.random() < 0.5)
                wt = rng.normal(0, 1 / np.sqrt(w), (k, w) if tb else (w, k))
                nodes.append(helper.make_node("Gemm", [v, const(wt), const(np.zeros(k))], [out], transA=ta, transB=tb))
            else:
                nodes.append(helper.make_node("MatMul", [v, const(rng.normal(0, 1 / np.sqrt(w), (w, k)))], [out]))
            w = k
        elif kind == "concat":
            u, uw = pick()
            ax = axis()
            nodes.append(helper.make_node("Concat", [v, u], [out], axis=ax))
            w = w + uw if ax in (1, -1) else w
        elif kind == "slice":
            a = int(rng.integers(0, w))
            b = int(rng.integers(a + 1, w + 1))
            ins = [v, const([a], np.int64), const([b], np.int64)]
            if rng.random() < 0.85:
                ins.append(const([axis()], np.int64))
            nodes.append(helper.make_node("Slice", ins, [out]))
            w = b - a
        elif kind == "reduce":
            op = str(rng.choice(["ReduceSum", "ReduceMean", "ReduceMax", "ReduceMin", "ReduceL2"]))
            keep = int(rng.random() < 0.85)
            ax = [axis()] if rng.random() < 0.9 else None
            if op == "ReduceSum" or opset >= 18:
                nodes.append(helper.make_node(op, [v] + ([const(ax, np.int64)] if ax else []), [out], keepdims=keep))
            else:
                nodes.append(helper.make_node(op, [v], [out], keepdims=keep, **({"axes": ax} if ax else {})))
            w = 1
        elif kind == "softmax":
            nodes.append(helper.make_node(str(rng.choice(["Softmax", "LogSoftmax"])), [v], [out], axis=axis()))
        elif kind == "layernorm":
            nodes.append(helper.make_node("LayerNormalization", [v, const(np.ones(w)), const(np.zeros(w))], [out], axis=axis()))
        elif kind == "clip":
            nodes.append(helper.make_node("Clip", [v, const(-1.0), const(1.0)], [out]))
        elif kind == "outside":
            op = str(rng.choice(_OUTSIDE))
            ins = {"Reshape": [v, const([-1, w], np.int64)], "Tile": [v, const([1, 1], np.int64)],
                   "Expand": [v, const([1, w], np.int64)], "CumSum": [v, const(0, np.int64)],
                   "Gather": [v, const([0], np.int64)]}.get(op, [v])
            attrs = {"Transpose": {"perm": [1, 0]}, "Hardmax": {"axis": 0}}.get(op, {})
            nodes.append(helper.make_node(op, ins, [out], **attrs))
        else:  # widths that do not fit: Add of two different widths, a Gemm whose weights expect another width
            if rng.random() < 0.5:
                nodes.append(helper.make_node("Add", [v, const(np.zeros((1, w + 1)))], [out]))
            else:
                nodes.append(helper.make_node("Gemm", [v, const(np.zeros((w + 2, 4))), const(np.zeros(4))], [out]))
                w = 4
        values.append((out, w))
    v, w = values[-1]
    out_w = 6 if rng.random() < 0.9 else 5
    nodes.append(helper.make_node("Gemm", [v, const(rng.normal(0, 1 / np.sqrt(w), (w, out_w))), const(np.zeros(out_w))], ["y"]))
    graph = helper.make_graph(nodes, "fuzz", [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", 16])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["N", 6])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset)])
    model.ir_version = 8
    return model, opset


def test_onnx_graph_fuzz():
    """Every random graph is refused with a typed error, or it runs at batch 1/7/64 with outputs of the
    declared width whose rows do not depend on each other (NaN where the math says so is the probe's job)."""
    rng = np.random.default_rng(20250611)
    outcomes: dict[str, int] = {}
    used_outside = 0
    t0 = time.perf_counter()
    for i in range(FUZZ_GRAPHS):
        model, opset = _random_graph(rng)
        used_outside += any(n.op_type not in ALLOWED_OPS for n in model.graph.node)
        info = NetworkInfo(("x",), ("y",), (16,), (6,), opset)
        try:
            check_model_bytes(model.SerializeToString(), info)
        except NassetError as exc:
            assert exc.code in CODES
            outcomes[exc.code] = outcomes.get(exc.code, 0) + 1
            continue
        session = make_session(model.SerializeToString(), intra_threads=1)
        x = probe_inputs((16,), (), 64, np.random.default_rng(i))[0]
        run = lambda a, s=session: s.run(["y"], {"x": a})[0]  # noqa: E731
        full = run(x)
        for n in (1, 7, 64):
            part = run(x[:n])
            assert part.shape == (n, 6), (i, n, part.shape)
            np.testing.assert_allclose(part, full[:n], rtol=1e-3, atol=1e-4, equal_nan=True, err_msg=f"graph {i}: rows mix at batch {n}")
        for r in (0, 5, 63):
            np.testing.assert_allclose(run(x[r:r + 1]), full[r:r + 1], rtol=1e-3, atol=1e-4, equal_nan=True, err_msg=f"graph {i}: row {r}")
        job = ProbeJob("g", b"", ("x",), (16,), ("y",), (6,))
        found = check_outputs(lambda feeds, s=session: s.run(["y"], feeds), job, seed=i)
        assert all(code == "NETWORK_OUTPUT" for code, _ in found), (i, found)
        key = "passed" if not found else "NETWORK_OUTPUT (probe)"
        outcomes[key] = outcomes.get(key, 0) + 1
    elapsed = time.perf_counter() - t0
    print(f"\nONNX graph fuzz: {FUZZ_GRAPHS} graphs ({used_outside} with operators outside the allow-list) in {elapsed:.1f} s: {outcomes}")
    assert outcomes.get("passed", 0) >= 20 and sum(v for k, v in outcomes.items() if k.startswith("NETWORK_")) >= 20, outcomes
    assert elapsed < FUZZ_BUDGET_S * 2
