"""Portable evaluation graphs (spec/format.md#portable-evaluation-graphs): the graph written by
``add_portable`` reproduces the kind's numpy + onnxruntime evaluator (rna, neupress; 8dna's albedo) on
random queries, texel borders, box faces, poles, grazing directions, cube-map edges and corners and
non-finite input; the written asset validates; the allow-list admits
the graph's operators only under their row rules."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_sdk import Asset, portable
from nasset_sdk.errors import NassetError, UsageError
from nasset_sdk.examples import example_builder
from nasset_sdk.networks import check_model_bytes
from nasset_sdk.validate import validate_file

#: |portable - evaluator| bounds. rna: the same float32 operations in the same order except
#: to_unit_box (float64 there) and the normalisation (float64 there): a few ulp of the inputs, amplified
#: by the decoder's Lipschitz constant (~10 for these random MLPs). neupress: the Fourier phase
#: 2 pi G v (|G v| up to ~130 cycles) is rounded to float32 in the graph, float64 in the evaluator:
#: ~1e-5 cycle = 6e-5 rad per feature.
ATOL = {"rna": 1e-4, "neupress": 1e-3, "8dna": 1e-4}
N = 2048


def _pair(tmp_path, kind, variant, size="small"):
    src = tmp_path / f"{kind}_{variant}.usdc"
    example_builder(kind, variant=variant, size=size, seed=3).write(src)
    dst = tmp_path / f"{kind}_{variant}_portable.usdc"
    report = portable.add_portable(src, dst)
    return Asset.open(dst, load="all"), report


def _nonfinite_rows(q: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The first rows of each query made hostile: NaN / Inf points, zero / Inf / tiny / huge directions, NaN h."""
    q = {k: v.copy() for k, v in q.items()}
    bad3 = np.array([[np.nan, 0, 0], [np.inf, 1, 0], [0, 0, 0], [1e-30, 0, 0], [3e38, -3e38, 1], [-0.0, -0.0, -1.0],
                     [0.0, 0.0, -0.0], [-np.inf, 0, 0]], np.float32)
    for i, v in enumerate(q.values()):
        if v.shape[1] == 3:
            v[:len(bad3)] = np.roll(bad3, 3 * i, axis=0)  # a different hostile row per input in each row
        else:
            v[:3, 0] = [np.nan, np.inf, -np.inf]
    return q


CASES = [("rna", "surface"), ("rna", "fiber"), ("neupress", "surface"), ("8dna", "surface")]


@pytest.mark.parametrize("kind,variant", CASES)
def test_portable_graph_matches_the_evaluator(tmp_path, kind, variant):
    asset, report = _pair(tmp_path, kind, variant)
    ev = portable.PortableEvaluator(asset)
    (name,) = ev.sessions
    rng = np.random.default_rng(7)
    q = portable.random_queries(asset, N, rng)
    # the queries really reach the edges: texel borders / box faces, poles, grazing directions
    if kind == "rna":
        r = asset.tensor_refs("core")["triplane"].shape[1]
        lo, hi = (np.asarray(a) for a in asset.domain)
        t = ((q["x"] - lo) / (hi - lo) * 2 - 1 + 1) * 0.5 * r
        assert np.isclose(t, np.round(t), atol=1e-4).any(axis=1).mean() > 0.2
        assert (np.abs(q["x"] - lo) < 1e-6).any() or (np.abs(q["x"] - hi) < 1e-6).any()
    if kind == "8dna":  # w_o on cube-map edges: two components of equal magnitude, the largest
        a = np.sort(np.abs(q["wo"]), axis=1)
        assert (a[:, 2] - a[:, 1] < 2e-3 * a[:, 2]).mean() > 0.2
    else:
        assert (np.abs(q["wi"][:, 2]) < 1e-3).mean() > 0.2
    got = ev.run(name, **q)
    want = portable.reference_outputs(asset, q)
    assert set(got) == set(want)
    for out, ref in want.items():
        assert got[out].shape == ref.shape and np.isfinite(got[out]).all()
        assert np.abs(ref).max() > 0.1  # a non-trivial reference (random decoders give O(1) transport)
        np.testing.assert_allclose(got[out], ref, rtol=0, atol=ATOL[kind], err_msg=f"{kind}/{variant} {out}")
        # the report's parity (its own random draw) is within the same bound
        assert report["graphs"][name]["parity"][out]["max_abs"] <= ATOL[kind]
    # hostile rows: the same outputs, finite
    qb = _nonfinite_rows(q)
    got_b = ev.run(name, **qb)
    with np.errstate(over="ignore", invalid="ignore"):  # the evaluator's float64 overflow on 3e38 is by design
        want_b = portable.reference_outputs(asset, qb)
    for out, ref in want_b.items():
        assert np.isfinite(got_b[out]).all()
        np.testing.assert_allclose(got_b[out], ref, rtol=0, atol=ATOL[kind], err_msg=f"{kind}/{variant} {out} (hostile rows)")


def test_portable_asset_validates_and_keeps_its_content(tmp_path):
    asset, report = _pair(tmp_path, "rna", "fiber", size="tiny")
    rep = validate_file(asset.path)
    assert rep.ok, rep.format_text()
    src = Asset.open(tmp_path / "rna_fiber.usdc", load="all")
    np.testing.assert_array_equal(asset.tensor("core", "triplane"), src.tensor("core", "triplane"))
    assert asset.network_bytes("core", "decoder") == src.network_bytes("core", "decoder")
    assert asset.components()["portable"].required is False
    assert report["graphs"]["decoder"]["inputs"] == {"x": 3, "frame": 3, "wo": 3, "wi": 3, "h": 1}
    # adding again replaces the component (one portable graph per network)
    again = portable.add_portable(asset.path, tmp_path / "again.usdc")
    assert list(again["graphs"]) == ["decoder"]


def test_portable_refusals(tmp_path):
    src = tmp_path / "q.usdc"
    example_builder("rna", size="tiny", seed=1, quality_variants=True).write(src)
    with pytest.raises(UsageError, match="quality variants"):
        portable.add_portable(src, tmp_path / "out.usdc")
    plain = tmp_path / "plain.usdc"
    example_builder("rna", size="tiny", seed=1).write(plain)
    with pytest.raises(NassetError) as e:
        portable.PortableEvaluator(Asset.open(plain, load="all"))
    assert e.value.code == "COMPONENT_MISSING"
    asset, _ = _pair(tmp_path, "rna", "surface", size="tiny")
    ev = portable.PortableEvaluator(asset)
    with pytest.raises(UsageError, match="takes inputs"):
        ev.run("decoder", x=np.zeros((2, 3)))
    with pytest.raises(UsageError, match="must be"):
        ev.run("decoder", x=np.zeros((2, 3)), frame=np.zeros((2, 3)), wo=np.zeros((2, 3)), wi=np.zeros((3, 3)))


def test_gather_elements_rules(tmp_path):
    """The graph's table lookups pass the allow-list; the same lookup on a computed table, or along
    axis 1, is refused (rows would mix)."""
    import onnx

    asset, _ = _pair(tmp_path, "rna", "surface", size="tiny")
    blob = asset.network_bytes("portable", "decoder")
    check_model_bytes(blob)
    model = onnx.ModelProto()
    model.ParseFromString(blob)
    node = next(n for n in model.graph.node if n.op_type == "GatherElements")
    for mutate, why in ((lambda n: n.attribute[0].__setattr__("i", 1), "axis must be 0"),
                        (lambda n: n.input.__setitem__(0, n.input[1]), "data must be an initializer")):
        m = onnx.ModelProto()
        m.CopyFrom(model)
        target = next(n for n in m.graph.node if n.name == node.name)
        mutate(target)
        with pytest.raises(NassetError) as e:
            check_model_bytes(m.SerializeToString())
        assert e.value.code == "NETWORK_OP_FORBIDDEN" and why in str(e.value)
