"""Writer and reader behaviour of nasset_sdk.asset that the corpus tests do not cover."""

from __future__ import annotations

import json

import numpy as np
import pytest

import nasset_sdk as ns
from nasset_sdk.errors import CODES, NassetError, UsageError, error
from nasset_sdk.examples import example_builder


def test_every_code_has_category_and_spec_anchor():
    for code, c in CODES.items():
        assert c.code == code
        assert "#" in c.spec or c.spec.endswith(".md")
        assert isinstance(error(code, "x"), NassetError)


def test_error_message_names_location():
    exc = error("TENSOR_SHAPE", "bad", file="a.usdc", prim="/Asset/x", attribute="shape")
    assert str(exc) == "[TENSOR_SHAPE] a.usdc:/Asset/x.shape: bad"
    assert isinstance(exc, ns.AssetFormatError)
    assert json.loads(json.dumps(exc.to_dict()))["attribute"] == "shape"


def test_builder_rejects_bad_arguments(rng):
    b = ns.AssetBuilder("rna")
    with pytest.raises(UsageError):
        b.component("bad name", required=True)
    core = b.component("core", required=True)
    with pytest.raises(UsageError):
        core.add_tensor("t", np.ones(3), dtype="float64")
    with pytest.raises(UsageError):
        core.add_tensor("t", np.full(3, 1e6), dtype="float16")  # overflows fp16 to inf
    with pytest.raises(UsageError):
        b.write("/tmp/x.usdc")  # no geometry
    with pytest.raises(ns.NassetError) as info:
        ns.AssetBuilder("nope")
    assert info.value.code == "KIND_UNKNOWN"
    with pytest.raises(UsageError):
        ns.AssetBuilder("rna", variant="volume")


@pytest.mark.parametrize("bad", [[["a", "b", "c"]] * 3, np.zeros((3, 3), bool), np.full((3, 3), None), np.zeros((3, 3), complex)])
def test_api_arrays_that_hold_no_real_numbers_are_usage_errors(bad):
    """Tensors, mesh and curve arrays built from strings, booleans, objects or complex numbers: USAGE naming the
    array (strings and lists used to fail as bare numpy ValueError / TypeError / AttributeError)."""
    core = ns.AssetBuilder("rna").component("core", required=True)
    with pytest.raises(UsageError, match="tensor 't': expected a real number array"):
        core.add_tensor("t", bad, dtype="float32")
    with pytest.raises(UsageError, match="mesh points must be a real number array"):
        ns.MeshGeometry(bad, np.array([[0, 1, 2]], np.int32))
    with pytest.raises(UsageError, match="mesh faces must be an integer array"):
        ns.MeshGeometry(np.eye(3), bad)
    with pytest.raises(UsageError, match="curve widths must be a real number array"):
        ns.CurvesGeometry(np.zeros((3, 3)), np.array([3]), bad)
    with pytest.raises(UsageError, match="mesh faces must be an integer array"):
        ns.MeshGeometry(np.eye(3), np.array([[0, 1, 2.5]]))
    # plain lists of numbers are arrays like any other, and whole-number float indices are indices
    assert ns.MeshGeometry(np.eye(3), np.array([[0.0, 1.0, 2.0]])).faces.dtype.kind == "i"
    g = ns.MeshGeometry([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    g.validate()
    lo, hi = g.bounds()
    assert list(hi) == [1, 1, 0] and list(lo) == [0, 0, 0]


def test_open_and_evaluator_refuse_arguments_of_the_wrong_type(tmp_path):
    for bad in (5, None, 1.5):
        with pytest.raises(UsageError, match="Asset.open: the asset must be a file path"):
            ns.Asset.open(bad)
    path = example_builder("rna", size="tiny", seed=1).write(tmp_path / "a.usdc")
    asset = ns.Asset.open(path, load="all")
    with pytest.raises(UsageError, match="does not take these options.*bogus.*it takes intra_threads, batch") as info:
        asset.evaluator(bogus=1)
    assert info.value.file == str(path)
    assert asset.evaluator() is not None


def test_new_evaluator_tells_a_bad_option_from_a_type_error_inside():
    """Options are bound to the constructor's signature before it runs: an option it does not take is USAGE, a
    TypeError raised by the constructor's own code is not turned into one."""
    from nasset_sdk.kinds import new_evaluator

    class Broken:
        def __init__(self, asset, *, batch: int = 1) -> None:
            raise TypeError("inside the constructor")

    with pytest.raises(UsageError, match="does not take these options.*it takes batch"):
        new_evaluator(Broken, object(), {"bogus": 1})
    with pytest.raises(TypeError, match="inside the constructor"):
        new_evaluator(Broken, object(), {"batch": 2})


def test_builder_enforces_kind_contract(tmp_path, rng):
    b = example_builder("rna", size="tiny")
    core = b.components["core"][""]
    core.add_tensor("triplane", np.zeros((2, 8, 8, 4)), dtype="float32")  # 2 planes, contract says 3
    with pytest.raises(UsageError, match="TENSOR_CONTRACT"):
        b.write(tmp_path / "a.usdc")
    assert not (tmp_path / "a.usdc").exists()


def test_open_errors(tmp_path):
    with pytest.raises(ns.AssetReadError) as info:
        ns.Asset.open(tmp_path / "missing.usdc")
    assert info.value.code == "FILE_NOT_FOUND"


def test_lazy_components_and_quality(tmp_path):
    path = example_builder("rna", size="tiny", quality_variants=True).write(tmp_path / "q.usdc")
    lazy = ns.Asset.open(path, load="none")
    info = lazy.components()["core"]
    assert not info.loaded and info.qualities == ("hq", "small") and info.quality == "small"
    with pytest.raises(UsageError):
        lazy.tensor("core", "triplane")
    small = ns.Asset.open(path).tensor("core", "triplane")
    hq = ns.Asset.open(path, quality="hq").tensor("core", "triplane")
    assert small.shape[1] == 8 and hq.shape[1] == 128  # tiny preset R=8, hq preset R=128
    with pytest.raises(UsageError):
        ns.Asset.open(path, quality="ultra")
    # selecting a quality does not edit the file
    assert ns.Asset.open(path, load="none").components()["core"].quality == "small"


def test_tensor_is_readonly_view(rna_asset_path):
    t = ns.Asset.open(rna_asset_path).tensor("core", "triplane")
    assert not t.flags.writeable
    with pytest.raises(ValueError):
        t[0, 0, 0, 0] = 1.0


def test_usda_and_usd_extensions(tmp_path):
    b = example_builder("rna", size="tiny")
    for name in ("a.usda", "a.usd"):
        ns.Asset.open(b.write(tmp_path / name)).tensor("core", "triplane")
    assert (tmp_path / "a.usd").read_bytes()[:8] == b"PXR-USDC"  # .usd is written as crate
    with pytest.raises(UsageError):
        b.write(tmp_path / "a.txt")


def test_sdk_entry_points_refuse_paths_that_are_not_paths(tmp_path):
    """validate_file, inspect_asset, optimize, merge_quality and the web export given None (or a number) for a file:
    USAGE naming the argument (they were bare TypeErrors); optimize's options must be an OptimizeOptions."""
    from nasset_sdk.inspect import inspect_asset
    from nasset_sdk.optimize import optimize
    from nasset_sdk.quality import merge_quality
    from nasset_sdk.validate import validate_file
    from nasset_sdk.web import export

    a = example_builder("rna", size="tiny", seed=1).write(tmp_path / "a.usdc")
    b = example_builder("rna", size="tiny", seed=2).write(tmp_path / "b.usdc")
    for call, words in ((lambda: validate_file(None), "validate_file: the asset must be a file path"),
                        (lambda: validate_file(5), "validate_file: the asset must be a file path"),
                        (lambda: inspect_asset(None), "inspect: the asset must be a file path"),
                        (lambda: optimize(None, tmp_path / "o.usdc"), "optimize: the input must be a file path"),
                        (lambda: optimize(a, None), "optimize: the output must be a file path"),
                        (lambda: optimize(a, tmp_path / "o.usdc", {"dtype": "float16"}), "opts must be an OptimizeOptions"),
                        (lambda: merge_quality(None, tmp_path / "m.usdc"), "at least two"),
                        (lambda: merge_quality({"small": a, "hq": None}, tmp_path / "m.usdc"), "level 'hq' must be a file path"),
                        (lambda: merge_quality({"small": a, "hq": b}, None), "the output must be a file path"),
                        (lambda: export(None, tmp_path / "w"), "web: the asset must be a file path"),
                        (lambda: ns.Asset.open(a, load=5), "load: 'required', 'all', 'none' or component names")):
        with pytest.raises(UsageError, match=words):
            call()
    assert validate_file(a).ok
