"""An ONNX network traced into Dr.Jit (``nasset_mitsuba_plugin.network``) against onnxruntime, at layer widths
below, at and above the chunk of outputs each packed ``Linear`` takes."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import network  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_sdk.networks import make_session, mlp_onnx  # noqa: E402


@pytest.mark.parametrize("widths", [(7, 16, 5), (22, 64, 64, 147), (42, 128, 128, 150), (5, 65, 3)])
def test_mlp_matches_onnxruntime(widths):
    mi = jit_mitsuba()
    rng = np.random.default_rng(sum(widths))
    ws = [rng.normal(0, 1 / np.sqrt(a), (a, b)).astype(np.float32) for a, b in zip(widths[:-1], widths[1:], strict=True)]
    bs = [rng.normal(0, 0.1, b).astype(np.float32) for b in widths[1:]]
    data = mlp_onnx(ws, bs, output_name="y")
    net = network.DrJitNetwork(mi, data)
    outs = [w.shape[1] for w in ws]
    # each layer is split into packed Linears of at most LINEAR_CHUNK outputs
    assert [len(p) for p, _ in net.linear.values()] == [-(-o // network.LINEAR_CHUNK) for o in outs]
    x = rng.normal(0, 1, (1000, widths[0])).astype(np.float32)
    got = net([mi.Float(np.ascontiguousarray(x[:, k])) for k in range(widths[0])])
    got = np.stack([np.asarray(c) for c in got], 1)
    sess = make_session(data)
    want = sess.run(None, {sess.get_inputs()[0].name: x})[0]
    assert got.shape == want.shape
    scale = np.abs(want).max()
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-5 * scale)
