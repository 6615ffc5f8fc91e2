"""AssetBuilder.from_asset: rewrite an asset losslessly, edit one thing (spec/format.md#editing)."""

from __future__ import annotations

import numpy as np
import pytest

import nasset_sdk as ns
from nasset_sdk.asset import FALLBACK
from nasset_sdk.examples import example_builder
from nasset_sdk.validate import validate_file

CASES = (("rna", "surface", False), ("rna", "fiber", False), ("neupress", "surface", False), ("8dna", "surface", False),
         ("rna", "surface", True))


def _snapshot(path) -> dict:
    """Everything the format stores, read back through USD and the reader, for every quality level."""
    asset = ns.Asset.open(path, load="all")
    out = {
        "kind": asset.kind, "variant": asset.variant, "provenance": asset.provenance,
        "domain": tuple(np.asarray(d).tobytes() for d in asset.domain),
        "metersPerUnit": asset.stage.GetMetadata("metersPerUnit"), "upAxis": asset.stage.GetMetadata("upAxis"),
    }
    shader = asset.stage.GetPrimAtPath(FALLBACK + "/PreviewSurface")
    out["fallback"] = (tuple(shader.GetAttribute("inputs:diffuseColor").Get()), shader.GetAttribute("inputs:roughness").Get())
    geo = asset.geometry()
    out["geometry"] = {k: np.asarray(v).tobytes() for k, v in vars(geo).items() if v is not None}
    comps = {}
    for name, info in asset.components().items():
        for q in info.qualities or (None,):
            a = ns.Asset.open(path, load="all", quality={name: q}) if q else asset
            comps[name, q] = {
                "required": info.required, "purpose": info.purpose, "default": info.quality,
                "tensors": {t: (r.dtype, r.layout, r.shape, a.tensor(name, t).tobytes()) for t, r in a.tensor_refs(name).items()},
                "networks": {n: a.network_bytes(name, n) for n in a.network_refs(name)},
            }
    out["components"] = comps
    return out


@pytest.mark.parametrize("kind,variant,qualities", CASES)
def test_round_trip_is_lossless(tmp_path, kind, variant, qualities):
    src = example_builder(kind, variant=variant, size="tiny", seed=5, quality_variants=qualities).write(tmp_path / "a.usdc")
    b = ns.AssetBuilder.from_asset(ns.Asset.open(src))
    out = b.write(tmp_path / "b.usdc")
    before, after = _snapshot(src), _snapshot(out)
    assert after == before
    assert sum(len(c["tensors"]) for c in before["components"].values()) > 0
    assert validate_file(out, probe=False).ok


def test_round_trip_keeps_non_default_metadata_and_the_files_default_quality(tmp_path):
    b = example_builder("rna", size="tiny", seed=2, quality_variants=True)
    b.fallback_color, b.fallback_roughness, b.meters_per_unit = (0.1, 0.2, 0.3), 0.7, 0.01
    b.provenance = {"generator": "test", "nested": {"a": [1, 2]}}
    b.default_quality["core"] = "hq"
    src = b.write(tmp_path / "a.usdc")
    # opened with another quality selected: the rewrite still keeps the file's default
    copy = ns.AssetBuilder.from_asset(ns.Asset.open(src, quality="small")).write(tmp_path / "b.usdc")
    assert _snapshot(copy) == _snapshot(src)
    assert ns.Asset.open(copy, load="none").components()["core"].quality == "hq"
    assert ns.Asset.open(copy).provenance["nested"] == {"a": [1, 2]}


def test_editing_one_tensor_changes_only_that_tensor(tmp_path):
    src = example_builder("neupress", size="tiny", seed=4).write(tmp_path / "a.usdc")
    b = ns.AssetBuilder.from_asset(ns.Asset.open(src))
    arr, dtype, layout = b.component("core").tensors["fourier"]
    b.component("core").add_tensor("fourier", arr * 2.0, dtype=dtype, layout=layout)
    out = b.write(tmp_path / "b.usdc")
    before, after = _snapshot(src), _snapshot(out)
    t_before = before["components"]["core", None]["tensors"].pop("fourier")
    t_after = after["components"]["core", None]["tensors"].pop("fourier")
    assert t_after[:3] == t_before[:3]
    np.testing.assert_array_equal(np.frombuffer(t_after[3], np.dtype(dtype)), np.frombuffer(t_before[3], np.dtype(dtype)) * 2.0)
    assert after == before  # everything else unchanged
    assert validate_file(out, probe=False).ok


def test_builder_component_without_required_gets_existing_levels_only(tmp_path):
    b = example_builder("rna", size="tiny")
    assert b.component("core") is b.components["core"][""]
    with pytest.raises(ns.UsageError, match="'sampling' does not exist"):
        b.component("sampling")
    with pytest.raises(ns.UsageError, match="from_asset takes an opened nasset_sdk.Asset"):
        ns.AssetBuilder.from_asset(tmp_path / "a.usdc")
