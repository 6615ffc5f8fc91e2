"""Undeclared tensors and networks (spec/kinds/README.md#reading-a-contract): readers ignore them and
evaluate the asset; the validator warns; the writer refuses them."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, Usd, Vt

from nasset_sdk.asset import Asset
from nasset_sdk.errors import UsageError
from nasset_sdk.examples import example_builder
from nasset_sdk.validate import validate_file


def _with_extra_tensor(src, dst):
    stage = Usd.Stage.Open(str(src))
    prim = stage.DefinePrim("/_NassetPayloads/core/futureTensor", "NeuralTensor")
    prim.CreateAttribute("shape", Sdf.ValueTypeNames.IntArray, custom=False).Set(Vt.IntArray([2]))
    prim.CreateAttribute("dtype", Sdf.ValueTypeNames.Token, custom=False).Set("float32")
    prim.CreateAttribute("layout", Sdf.ValueTypeNames.String, custom=False).Set("parameter")
    prim.CreateAttribute("values", Sdf.ValueTypeNames.FloatArray, custom=True).Set(Vt.FloatArray([1.0, 2.0]))
    stage.GetRootLayer().Export(str(dst))


def test_undeclared_tensor_is_a_warning_and_ignored_by_the_evaluator(tmp_path, rng):
    plain = example_builder("rna", size="tiny", seed=3).write(tmp_path / "plain.usda")
    extra = tmp_path / "extra.usda"
    _with_extra_tensor(plain, extra)
    rep = validate_file(extra)
    assert rep.ok, rep.format_text()
    assert "TENSOR_CONTRACT" in rep.codes("warning") and "TENSOR_CONTRACT" not in rep.codes("error")
    assert "futureTensor" in rep.format_text()
    x, n, wo, wi = (rng.normal(size=(16, 3)) * 0.3 for _ in range(4))
    want = Asset.open(plain).evaluator().evaluate(x, n, wo, wi)
    got = Asset.open(extra).evaluator().evaluate(x, n, wo, wi)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])


def test_writer_refuses_undeclared_tensor(tmp_path):
    b = example_builder("rna", size="tiny")
    b.components["core"][""].add_tensor("futureTensor", np.zeros(2), dtype="float32")
    with pytest.raises(UsageError, match="futureTensor"):
        b.write(tmp_path / "a.usdc")
