"""8dna evaluation in fewer, larger calls (spec/kinds/8dna.md#flow): the load-time split of the flow
networks' first layers and the reuse of a flow sample's conditioners give the densities of the stored,
unsplit networks run one dimension at a time through onnxruntime, with the spline written out here
from the spec's formulas, to float32 rounding."""

from __future__ import annotations

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper

from nasset_sdk.asset import Asset
from nasset_sdk.kinds import get_kind
from nasset_sdk.kinds.eightdna import FLOWS
from nasset_sdk.networks import make_session, mlp_onnx, split_first_layer

#: log-density agreement: float32 network outputs (relative rounding ~1e-7 of values up to ~10)
#: propagate through softmax / softplus into log derivatives of O(1); 1e-4 is 100x that rounding
LOG_ATOL = 1e-4


def _spline_log_inverse(g: np.ndarray, t: np.ndarray, mins) -> np.ndarray:
    """log|dz/dt| of the spec's rational-quadratic spline, one row at a time (g [N, 3K+1], t [N])."""
    mw, mh, md = mins
    k = (g.shape[1] - 1) // 3
    out = np.empty(len(t))
    for n in range(len(t)):
        row = g[n].astype(np.float64)
        w = mw + (1 - k * mw) * np.exp(row[:k] - row[:k].max()) / np.exp(row[:k] - row[:k].max()).sum()
        h = mh + (1 - k * mh) * np.exp(row[k:2 * k] - row[k:2 * k].max()) / np.exp(row[k:2 * k] - row[k:2 * k].max()).sum()
        d = md + np.log1p(np.exp(row[2 * k:]))
        xk = np.concatenate([[0.0], np.cumsum(w)])
        yk = np.concatenate([[0.0], np.cumsum(h)])
        xk[-1] = yk[-1] = 1.0
        y = min(max(t[n], 0.0), 1.0)
        b = int(np.sum(y >= yk[1:-1]))
        wb, hb = xk[b + 1] - xk[b], yk[b + 1] - yk[b]
        s = hb / wb
        dy, delta = y - yk[b], d[b + 1] + d[b] - 2 * s
        qa, qb, qc = hb * (s - d[b]) + dy * delta, hb * d[b] - dy * delta, -s * dy
        den = -qb - np.sqrt(max(qb * qb - 4 * qa * qc, 0.0))
        xi = min(max(2 * qc / den if den < 0 else 0.0, 0.0), 1.0)
        deriv = s * s * (d[b + 1] * xi * xi + 2 * s * xi * (1 - xi) + d[b] * (1 - xi) ** 2) / (s + delta * xi * (1 - xi)) ** 2
        out[n] = -np.log(deriv)
    return out


class PerDimension:
    """The unsplit reference: each stored flow network whole, one conditioner at a time, rows not shared."""

    def __init__(self, asset, ev) -> None:
        self.ev = ev
        self.sessions = [make_session(asset.network_bytes("core", n)) for n in FLOWS]
        self.mins = np.asarray(asset.tensor("core", "splineMinimums"), np.float64)

    def log_steps(self, x, wo, ui, wi, channel: int, steps=(1, 2, 3, 4)) -> np.ndarray:
        """Sum over steps of log|dz_j/dt_j| of one channel at given (u_i, w_i); [N]."""
        ev = self.ev
        s, _ = ev.box.from_rays(ui, wi)
        t = ev.box.t_from_s(s)
        base = ev.base_features(x, wo)
        total = np.zeros(len(x))
        for j in steps:
            g = self.sessions[j - 1].run(None, {"x": ev.flow_input(j, base, s[:, : j - 1])})[0]
            p = g.shape[1] // 3
            total += _spline_log_inverse(g[:, channel * p:(channel + 1) * p], t[:, j - 1], self.mins)
        return total


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("8dna_fused") / "small.usdc"
    get_kind("8dna").build_random(np.random.default_rng(3), size="small").write(path)
    asset = Asset.open(path)
    ev = asset.evaluator()
    return asset, ev, PerDimension(asset, ev)


def _queries(ev, rng, n):
    x = ev.box.center + rng.uniform(-1, 1, (n, 3)) * ev.box.half
    wo = rng.normal(size=(n, 3))
    return x, wo / np.linalg.norm(wo, axis=1, keepdims=True)


def test_flows_are_split(small):
    _, ev, _ = small
    assert ev.tails is not None and len(ev.tails) == 4  # the fast path is the one under test


@pytest.mark.parametrize("split", [True, False])
def test_sample_state_densities_match_per_dimension(small, rng, split):
    asset, ev, ref = small
    if not split:  # the whole-network fallback (graphs that do not start with one affine layer)
        ev = type(ev)(asset)
        ev.tails = None
    n = 40
    x, wo = _queries(ev, rng, n)
    ch = rng.integers(0, 3, n)
    u = rng.random((n, 4))
    fs = ev.sample_state(x, wo, ch, u=u)
    # sampled channel's joint density, per-channel position densities
    for c in range(3):
        mine = ch == c
        lp = ref.log_steps(x[mine], wo[mine], fs.ui[mine], fs.wi[mine], c)
        jac = ev.box.from_rays(fs.ui[mine], fs.wi[mine])[1]
        np.testing.assert_allclose(np.log(fs.pdf[mine]), lp + np.log(jac / (16 * np.pi ** 2)), atol=LOG_ATOL, rtol=0)
        lpos = ref.log_steps(x, wo, fs.ui, fs.wi, c, steps=(1, 2))
        np.testing.assert_allclose(np.log(fs.pdf_position_rgb()[:, c]), lpos + np.log(jac_all(ev, fs) / (4 * np.pi)),
                                   atol=LOG_ATOL, rtol=0)
    # new directions at some rows' u_i (rows repeat, as light samples and continuations share u_i)
    rows = rng.integers(0, n, 60)
    wi = rng.normal(size=(60, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    got = ev.pdf_rgb_at(fs, rows, wi)
    jac = ev.box.from_rays(fs.ui[rows], wi)[1]
    for c in range(3):
        lp = ref.log_steps(x[rows], wo[rows], fs.ui[rows], wi, c)
        np.testing.assert_allclose(np.log(got[:, c]), lp + np.log(jac / (16 * np.pi ** 2)), atol=LOG_ATOL, rtol=0)
    # the general entry points agree with the reused ones
    np.testing.assert_allclose(np.log(ev.pdf_rgb(x[rows], wo[rows], fs.ui[rows], wi)), np.log(got), atol=LOG_ATOL, rtol=0)
    # position densities built on demand, for the asked rows only, equal those built for every row
    lazy = ev.sample_state(x, wo, ch, u=u)
    np.testing.assert_array_equal(ev.pdf_rgb_at(lazy, rows, wi), got)
    assert np.isnan(lazy._log_pos[:, 0]).sum() == n - len(np.unique(rows))  # nothing built for the other rows
    np.testing.assert_array_equal(lazy.pdf_position_rgb(rows[::-1]), fs.pdf_position_rgb()[rows[::-1]])
    np.testing.assert_array_equal(lazy.pdf_position_rgb(), fs.pdf_position_rgb())


def test_directions_mask_and_sampled_densities(small, rng):
    """``directions``: rows whose w_i is drawn get the full sample's w_i and pdf, the others u_i only (conditioner 4
    runs for the drawn rows alone); pdf_rgb_sampled at the sample's own (u_i, w_i), which reuses its conditioner
    outputs, equals the per-dimension reference."""
    from nasset_sdk.errors import UsageError

    _, ev, ref = small
    n = 40
    x, wo = _queries(ev, rng, n)
    ch, u = rng.integers(0, 3, n), rng.random((n, 4))
    mask = rng.random(n) < 0.5
    full = ev.sample_state(x, wo, ch, u=u)
    rows_run, orig = {}, ev.flow.conditioner

    def counted(j, ctx, s_prev):
        rows_run[j] = rows_run.get(j, 0) + len(s_prev)
        return orig(j, ctx, s_prev)

    ev.flow.conditioner = counted
    try:
        part = ev.sample_state(x, wo, ch, u=u, directions=mask)
    finally:
        ev.flow.conditioner = orig
    assert rows_run == {1: n, 2: n, 3: n, 4: mask.sum()}  # conditioner 4 ran for the drawn rows only
    np.testing.assert_array_equal(part.ui, full.ui)
    np.testing.assert_allclose(part.wi[mask], full.wi[mask], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(part.pdf[mask], full.pdf[mask], rtol=1e-6)
    assert (part.wi[~mask] == 0).all() and (part.pdf[~mask] == 0).all()
    assert len(part.raw4) == mask.sum()
    rows = rng.choice(np.nonzero(mask)[0], 30)  # repeats, any order
    got = ev.pdf_rgb_sampled(part, rows)
    jac = ev.box.from_rays(full.ui[rows], full.wi[rows])[1]
    for c in range(3):
        lp = ref.log_steps(x[rows], wo[rows], full.ui[rows], full.wi[rows], c)
        np.testing.assert_allclose(np.log(got[:, c]), lp + np.log(jac / (16 * np.pi ** 2)), atol=LOG_ATOL, rtol=0)
    np.testing.assert_allclose(got[np.arange(len(rows)), ch[rows]], full.pdf[rows], rtol=1e-6)
    with pytest.raises(UsageError):  # a row whose w_i was not drawn
        ev.pdf_rgb_sampled(part, [np.nonzero(~mask)[0][0]])
    with pytest.raises(UsageError):
        ev.sample_state(x, wo, ch, u=u, directions=mask[:-1])


def jac_all(ev, fs):
    return ev.box.from_rays(fs.ui, fs.wi)[1]


def test_albedo_matches_whole_network(small, rng):
    asset, ev, _ = small
    x, wo = _queries(ev, rng, 50)
    whole = make_session(asset.network_bytes("core", "albedo")).run(None, {"x": ev.base_features(x, wo)})[0]
    np.testing.assert_allclose(ev.albedo(x, wo, context=ev.context(x, wo)), np.maximum(whole, 0), rtol=1e-6, atol=1e-6)


def _gemm_model(w, b, *, trans_b: bool, alpha: float, beta: float, matmul: bool) -> bytes:
    """One hidden layer then an output layer; the first layer as Gemm (transB, alpha, beta) or MatMul + Add."""
    w2 = np.random.default_rng(1).normal(size=(w.shape[1], 5)).astype(np.float32)
    inits = [numpy_helper.from_array(w.T.copy() if trans_b else w, "W"), numpy_helper.from_array(b, "B"),
             numpy_helper.from_array(w2, "W2")]
    if matmul:
        nodes = [helper.make_node("MatMul", ["x", "W"], ["m"]), helper.make_node("Add", ["m", "B"], ["h"])]
    else:
        nodes = [helper.make_node("Gemm", ["x", "W", "B"], ["h"], transB=int(trans_b), alpha=alpha, beta=beta)]
    nodes += [helper.make_node("Relu", ["h"], ["a"]), helper.make_node("MatMul", ["a", "W2"], ["y"])]
    graph = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, ["N", w.shape[0]])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, ["N", 5])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model.SerializeToString()


@pytest.mark.parametrize("form", ["gemm", "gemm_transb_scaled", "matmul_add"])
@pytest.mark.parametrize("head", [3, 7])
def test_split_first_layer_equals_whole(rng, form, head):
    w = rng.normal(size=(7, 16)).astype(np.float32)
    b = rng.normal(size=16).astype(np.float32)
    data = _gemm_model(w, b, trans_b=form == "gemm_transb_scaled", alpha=0.7 if form == "gemm_transb_scaled" else 1.0,
                       beta=1.3 if form == "gemm_transb_scaled" else 1.0, matmul=form == "matmul_add")
    sp = split_first_layer(data, head)
    assert sp is not None and sp.rest_width == 7 - head
    x = rng.normal(size=(33, 7)).astype(np.float32)
    whole = make_session(data).run(None, {"x": x})[0]
    feed = {sp.tail_inputs[0]: (x[:, :head] @ sp.head_weight + sp.bias).astype(np.float32)}
    if sp.rest_width:
        feed[sp.tail_inputs[1]] = x[:, head:]
    np.testing.assert_allclose(make_session(sp.tail).run(None, feed)[0], whole, rtol=1e-5, atol=1e-5)


def test_split_first_layer_declines_other_graphs(rng):
    # the input also feeds a skip connection: no single affine layer reads it alone
    w = [rng.normal(size=(6, 8)).astype(np.float32), rng.normal(size=(14, 3)).astype(np.float32)]
    data = mlp_onnx(w, [np.zeros(8, np.float32), np.zeros(3, np.float32)], skips=[(0, 1)])
    assert split_first_layer(data, 4) is None


def test_pdf_rgb_at_rejects_rows_outside_the_sample(small, rng):
    from nasset_sdk.errors import UsageError

    _, ev, _ = small
    x, wo = _queries(ev, rng, 4)
    fs = ev.sample_state(x, wo, 0, u=rng.random((4, 4)))
    with pytest.raises(UsageError):
        ev.pdf_rgb_at(fs, [0, 4], np.tile([0.0, 0.0, 1.0], (2, 1)))
    with pytest.raises(UsageError):
        ev.pdf_rgb_at(fs, [0], np.tile([0.0, 0.0, 1.0], (2, 1)))


def test_taken_context_gathers_each_block_as_read(small, rng):
    """A context of some rows gathers its base features and pre-activation blocks from the parent when read, and
    rows of rows index the parent's rows: the same arrays as gathering every block at once."""
    _, ev, _ = small
    n = 50
    x, wo = _queries(ev, rng, n)
    ctx = ev.context(x, wo)
    full = ev._run32(ev.head, {"x": ctx.base})
    rows = rng.integers(0, n, 30)
    sub = rng.integers(0, 30, 12)
    for c, r in ((ctx.take(rows), rows), (ctx.take(rows).take(sub), rows[sub])):
        assert len(c) == len(r)
        for j in (4, 1, 3, 2):  # any order, each block once
            np.testing.assert_array_equal(c.pre(j), full[:, ev.head_cols[j - 1]:ev.head_cols[j]][r])
        np.testing.assert_array_equal(c.base, ctx.base[r])
    s12 = rng.uniform(-1, 1, (n, 2))
    ctx.s12_columns(s12, ev._s12_columns)
    np.testing.assert_array_equal(ctx.take(rows).take(sub).s12[1], ev._s12_columns(s12)[rows[sub]])


def test_direct_lobe_fused_calls_equal_the_separate_ones(small, rng):
    """direct_eval_pdf and direct_sample_eval (one set of dot products) return what direct_eval, direct_pdf and
    direct_sample return, bit for bit."""
    _, ev, _ = small
    n = 300
    nrm = rng.normal(size=(n, 3))
    wo, wi = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    f, pdf = ev.direct_eval_pdf(nrm, wo, wi)
    np.testing.assert_array_equal(f, ev.direct_eval(nrm, wo, wi))
    np.testing.assert_array_equal(pdf, ev.direct_pdf(nrm, wo, wi))
    u2 = rng.random((n, 2))
    wd, pd, fd = ev.direct_sample_eval(nrm, wo, u2)
    wd2, pd2 = ev.direct_sample(nrm, wo, u2)
    np.testing.assert_array_equal(wd, wd2)
    np.testing.assert_array_equal(pd, pd2)
    np.testing.assert_array_equal(fd, ev.direct_eval(nrm, wo, wd))
    assert (pd > 0).any() and (fd > 0).any()
