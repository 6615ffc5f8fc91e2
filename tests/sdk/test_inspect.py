"""``nasset inspect``: every reported number is checked against values known from construction."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

import nasset_sdk as ns
from nasset_sdk.cli import main
from nasset_sdk.examples import example_builder
from nasset_sdk.inspect import format_report, inspect_asset
from nasset_sdk.kinds import KINDS, ComponentSpec, KindContract, NetworkSpec, TensorSpec, register_kind
from nasset_sdk.networks import random_mlp

R, C = 4, 5
HIDDEN = (8, 8)


def _mlp_params(widths) -> int:
    """Weights + biases of a dense MLP with these layer widths, counted by hand."""
    return sum(a * b + b for a, b in zip(widths[:-1], widths[1:], strict=True))


def test_mlp_param_formula_on_a_known_case():
    assert _mlp_params([17, 8, 8, 6]) == 17 * 8 + 8 + 8 * 8 + 8 + 8 * 6 + 6 == 270


@pytest.fixture(scope="module")
def known(tmp_path_factory):
    """An rna asset built by hand: 2 x 1 x 0.5 box mesh, triplane [3, R, R, C] fp16, MLP [C+12, 8, 8, 6]."""
    rng = np.random.default_rng(7)
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    b = ns.AssetBuilder("rna")
    b.set_geometry(ns.MeshGeometry.from_trimesh(box))
    b.provenance = {"generator": "test_inspect", "trainingSettings": {"steps": 3}}
    core = b.component("core", required=True, purpose="evaluation")
    core.add_tensor("triplane", rng.normal(size=(3, R, R, C)), dtype="float16", layout="plane,v,u,channel")
    widths = [C + 12, *HIDDEN, 6]
    blob = random_mlp(rng, widths)
    core.add_network("decoder", blob)
    path = tmp_path_factory.mktemp("inspect") / "known.usdc"
    b.write(path)
    return path, len(blob), widths


def _cli_json(capsys, *argv) -> dict:
    assert main(["inspect", *map(str, argv), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_json_matches_construction(known, capsys):
    path, blob_len, widths = known
    r = _cli_json(capsys, path)
    assert (r["kind"], r["variant"], r["specVersion"]) == ("rna", "surface", "0.1")  # nothing newer than 0.1 in it
    assert (r["upAxis"], r["metersPerUnit"]) == ("Y", 1.0)
    assert r["fileBytes"] == path.stat().st_size
    assert r["nearFieldFetch"] == 0.0  # not authored: the distant-light rule

    g = r["geometry"]
    assert (g["type"], g["points"], g["faces"], g["normals"]) == ("Mesh", 8, 12, True)
    assert g["bounds"] == {"min": [-1.0, -0.5, -0.25], "max": [1.0, 0.5, 0.25]}
    assert g["extent"] == g["bounds"]
    pad = 0.01 * 2.0  # builder default: 1 % of the largest edge
    np.testing.assert_allclose(r["domain"]["min"], [-1 - pad, -0.5 - pad, -0.25 - pad], rtol=1e-6)
    np.testing.assert_allclose(r["domain"]["max"], [1 + pad, 0.5 + pad, 0.25 + pad], rtol=1e-6)

    core = r["components"]["core"]
    assert core["loaded"] and core["required"] and core["purpose"] == "evaluation"
    assert core["qualities"] == [] and core["quality"] is None
    t = core["tensors"]["triplane"]
    assert t["shape"] == [3, R, R, C] and t["dtype"] == "float16" and t["layout"] == "plane,v,u,channel"
    assert t["bytes"] == 3 * R * R * C * 2
    n = core["networks"]["decoder"]
    assert n["inputs"] == [{"name": "x", "width": C + 12}] and n["outputs"] == [{"name": "y", "width": 6}]
    assert n["opset"] == 17 and n["bytes"] == blob_len
    assert n["parameters"] == _mlp_params(widths) == (17 * 8 + 8) + (8 * 8 + 8) + (8 * 6 + 6)
    assert r["totals"] == {"components": 1, "loaded": 1, "tensors": 1, "networks": 1,
                           "tensorBytes": 3 * R * R * C * 2, "networkBytes": blob_len,
                           "parameters": _mlp_params(widths)}
    assert r["provenance"] == {"generator": "test_inspect", "kind": "rna", "specVersion": "0.1",
                               "trainingSettings": {"steps": 3}}


def test_load_none_reads_no_component(known, capsys):
    path, _, _ = known
    r = _cli_json(capsys, path, "--load", "none")
    core = r["components"]["core"]
    assert core["loaded"] is False and core["required"] is True
    assert core["tensors"] == {} and core["networks"] == {}
    assert r["totals"]["loaded"] == 0 and r["totals"]["tensorBytes"] == 0 and r["totals"]["parameters"] == 0
    assert r["geometry"]["points"] == 8  # the rest of the summary is still there


def test_human_readable_table(known, capsys):
    path, blob_len, widths = known
    assert main(["inspect", str(path)]) == 0
    out = capsys.readouterr().out
    assert "kind rna  variant surface" in out
    assert "Mesh: 8 points, 12 triangles" in out
    assert f"3x{R}x{R}x{C}" in out and "float16" in out
    assert f"x[{C + 12}] -> y[6]" in out and f"{_mlp_params(widths)} params" in out
    assert format_report(inspect_asset(path)) == out.rstrip("\n")


def test_bad_load_argument_is_usage_error(known, capsys):
    path, _, _ = known
    assert main(["inspect", str(path), "--load", "some"]) == 2
    assert main(["inspect", str(path.with_name("missing.usdc"))]) == 1


def test_quality_variants_reported(tmp_path):
    path = tmp_path / "q.usdc"
    example_builder("rna", size="tiny", quality_variants=True).write(path)
    r = inspect_asset(path)
    core = r["components"]["core"]
    assert core["qualities"] == ["hq", "small"] and core["quality"] == "small"
    # 'small' holds the tiny preset (R=8, C=4, 2 x 16 hidden): only the selected variant is loaded
    assert core["tensors"]["triplane"]["shape"] == [3, 8, 8, 4]
    assert core["networks"]["decoder"]["parameters"] == _mlp_params([16, 16, 16, 6])


def test_fiber_geometry(tmp_path):
    rng = np.random.default_rng(3)
    counts = np.array([3, 2], np.int32)
    pts = np.array([[0, 0, 0], [0, 1, 0], [0, 2, 0], [1, 0, 0], [1, 0, 1]], np.float32)
    widths = np.array([0.1, 0.1, 0.2, 0.1, 0.1], np.float32)
    b = ns.AssetBuilder("rna", variant="fiber")
    b.set_geometry(ns.CurvesGeometry(pts, counts, widths))
    core = b.component("core", required=True, purpose="evaluation")
    core.add_tensor("triplane", np.zeros((3, 2, 2, 3)), dtype="float32", layout="plane,v,u,channel")
    core.add_network("decoder", random_mlp(rng, [3 + 13, 4, 6]))
    path = tmp_path / "f.usdc"
    b.write(path)
    r = inspect_asset(path)
    g = r["geometry"]
    assert (g["type"], g["points"], g["curves"]) == ("BasisCurves", 5, 2)
    assert g["widthRange"] == pytest.approx([0.1, 0.2])
    assert g["bounds"] == {"min": [0.0, 0.0, 0.0], "max": [1.0, 2.0, 1.0]}
    # extent = points grown by their half widths (0.1 at (0, 2, 0), 0.05 elsewhere)
    np.testing.assert_allclose(g["extent"]["min"], [-0.1, -0.05, -0.1], atol=1e-6)
    np.testing.assert_allclose(g["extent"]["max"], [1.05, 2.1, 1.05], atol=1e-6)
    assert r["components"]["core"]["tensors"]["triplane"]["bytes"] == 3 * 2 * 2 * 3 * 4
    assert r["components"]["core"]["networks"]["decoder"]["parameters"] == 16 * 4 + 4 + 4 * 6 + 6


def test_bad_digest_is_reported_not_fatal(tmp_path):
    path = tmp_path / "a.usda"
    example_builder("rna", size="tiny").write(path)
    text = path.read_text()
    start = text.index('onnx:sha256 = "') + len('onnx:sha256 = "')
    path.write_text(text[:start] + "0" * 64 + text[start + 64:])
    net = inspect_asset(path)["components"]["core"]["networks"]["decoder"]
    assert net["error"]["code"] == "NETWORK_DIGEST"
    assert net["bytes"] is None and net["parameters"] is None


class _TwoComponentKind(KindContract):
    """A test-only kind with a required and an optional component."""

    id = "inspect_test"
    variants = ("surface",)

    def components(self, variant):
        return {
            "core": ComponentSpec(True, "evaluation", {"grid": TensorSpec(("N", "3"), "row,xyz")}),
            "sampling": ComponentSpec(False, "importance-sampling",
                                      networks={"lobe": NetworkSpec((("x", "9"),), (("y", "1"),))}),
        }


@pytest.fixture
def two_component_asset(tmp_path):
    register_kind(_TwoComponentKind())
    try:
        b = ns.AssetBuilder("inspect_test")
        b.set_geometry(ns.MeshGeometry.from_trimesh(trimesh.creation.box()))
        b.component("core", required=True, purpose="evaluation").add_tensor("grid", np.ones((10, 3)), layout="row,xyz")
        b.component("sampling", required=False, purpose="importance-sampling").add_network(
            "lobe", random_mlp(np.random.default_rng(0), [9, 5, 1]))
        path = tmp_path / "two.usdc"
        b.write(path)
        yield path
    finally:
        KINDS.pop("inspect_test", None)


def test_optional_component_not_loaded_with_load_required(two_component_asset):
    r = inspect_asset(two_component_asset, load="required")
    core, sampling = r["components"]["core"], r["components"]["sampling"]
    assert core["loaded"] and core["tensors"]["grid"]["bytes"] == 10 * 3 * 4
    assert sampling["required"] is False and sampling["purpose"] == "importance-sampling"
    assert sampling["loaded"] is False and sampling["networks"] == {}
    assert r["totals"]["loaded"] == 1 and r["totals"]["parameters"] == 0
    full = inspect_asset(two_component_asset, load="all")
    assert full["components"]["sampling"]["networks"]["lobe"]["parameters"] == 9 * 5 + 5 + 5 * 1 + 1
    assert full["totals"]["loaded"] == 2


def test_near_field_fetch_is_reported(tmp_path, capsys):
    from nasset_sdk.examples import example_builder

    b = example_builder("rna", size="tiny")
    b.near_field_fetch = 0.4
    path = b.write(tmp_path / "f.usdc")
    r = _cli_json(capsys, path)
    assert r["nearFieldFetch"] == pytest.approx(0.4) and r["specVersion"] == "0.3"
    assert main(["inspect", str(path)]) == 0
    assert "near-field fetch f = 0.4" in capsys.readouterr().out
