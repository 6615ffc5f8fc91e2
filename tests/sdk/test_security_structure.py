"""An asset layer's structure is bounded: specs, time samples and nesting (spec/security.md#bounds).

Readers walk every spec of a layer in Python and compose it, and a crate stores an empty prim in ~9 bytes:
a 1.8 MB asset of 200 000 empty prims validated clean in 30 s at 406 MB (ten times the prims: minutes and GBs),
bounded only by the probe's time limit. Internal arcs amplify further: ten prims referencing a class of ten
that reference the next class, six levels deep, is a 13 KB file composing to 10^6 prims (validate: 88 s, 1.8 GB).
The probe now counts an asset's specs first, stopping at ``limits.MAX_ASSET_SPECS``, and bounds the prims it
composes to from its specs before composing; scenes, where many prims are legitimate, are not held to either.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from nasset_sdk import limits
from nasset_sdk.asset import Asset
from nasset_sdk.errors import NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.safeopen import composition_problem, structure_problem
from nasset_sdk.validate import validate_file


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    return example_builder("rna", variant="surface", size="tiny", seed=0).write(tmp_path_factory.mktemp("structure") / "base.usdc")


def _layer(base: Path):
    from pxr import Sdf

    return Sdf.Layer.OpenAsAnonymous(str(base))


def _junk(layer, parent: str = "/Asset"):
    from pxr import Sdf

    found = layer.GetPrimAtPath(f"{parent}/Junk")
    return found or Sdf.PrimSpec(layer.GetPrimAtPath(parent), "Junk", Sdf.SpecifierDef, "Scope")


def _prims(layer, n: int, parent: str = "/Asset"):
    from pxr import Sdf

    junk = _junk(layer, parent)
    with Sdf.ChangeBlock():
        for i in range(n):
            Sdf.PrimSpec(junk, f"p{i}", Sdf.SpecifierDef)
    return layer


def _properties(layer, n: int):
    from pxr import Sdf

    junk = _junk(layer)
    with Sdf.ChangeBlock():
        for i in range(n):
            Sdf.AttributeSpec(junk, f"a{i}", Sdf.ValueTypeNames.Float)
    return layer


def _time_samples(layer, n: int):
    from pxr import Sdf

    attr = Sdf.AttributeSpec(_junk(layer), "a", Sdf.ValueTypeNames.Float)
    with Sdf.ChangeBlock():
        for i in range(n):
            layer.SetTimeSample(attr.path, float(i), 1.0)
    return layer


def _targets(layer, n: int):
    from pxr import Sdf

    rel = Sdf.RelationshipSpec(_junk(layer), "r")
    rel.targetPathList.explicitItems = [Sdf.Path(f"/Asset/t{i}") for i in range(n)]
    return layer


def _variants(layer, n: int):
    from pxr import Sdf

    vset = Sdf.VariantSetSpec(_junk(layer), "v")
    for i in range(n):
        Sdf.VariantSpec(vset, f"x{i}")
    return layer


def _deep(layer, n: int):
    from pxr import Sdf

    spec = layer.GetPrimAtPath("/Asset")
    for _ in range(n):
        spec = Sdf.PrimSpec(spec, "d", Sdf.SpecifierDef)
    return layer


def _laughs(layer, levels: int, fan: int = 10):
    """Class /L<k> holds ``fan`` prims, each referencing /L<k+1>; /Asset/Junk references /L0: fan^levels prims."""
    from pxr import Sdf

    for k in range(levels):
        cls = Sdf.PrimSpec(layer, f"L{k}", Sdf.SpecifierClass)
        for i in range(fan):
            child = Sdf.PrimSpec(cls, f"c{i}", Sdf.SpecifierDef)
            if k + 1 < levels:
                child.referenceList.prependedItems.append(Sdf.Reference("", f"/L{k + 1}"))
    _junk(layer).referenceList.prependedItems.append(Sdf.Reference("", "/L0"))
    return layer


@pytest.mark.parametrize("make", [_prims, _properties, _time_samples, _targets, _variants])
def test_each_kind_of_spec_counts_towards_the_bound(base, make):
    legit = _layer(base)
    assert structure_problem(legit) is None
    bound = 500  # the walk is the same at any bound: a small one keeps the test fast
    assert structure_problem(make(_layer(base), 100), max_specs=bound) is None
    why = structure_problem(make(_layer(base), bound), max_specs=bound)
    assert why is not None and f"> {bound}" in why


def test_prims_nested_past_the_depth_bound_are_refused(base):
    assert structure_problem(_deep(_layer(base), limits.MAX_ASSET_DEPTH - 1)) is None
    why = structure_problem(_deep(_layer(base), limits.MAX_ASSET_DEPTH))
    assert why is not None and f"more than {limits.MAX_ASSET_DEPTH} deep" in why


def test_internal_arcs_that_repeat_subtrees_are_bounded_before_composing(base):
    from pxr import Sdf

    assert composition_problem(_layer(base)) is None
    assert composition_problem(_laughs(_layer(base), 2), max_prims=500) is None  # ~110 prims
    why = composition_problem(_laughs(_layer(base), 3), max_prims=500)  # 1 110 prims
    assert why is not None and "more than 500 prims" in why
    variants = _layer(base)  # a variant counts what it brings, like an arc
    vset = Sdf.VariantSetSpec(_junk(variants), "v")
    for i in range(3):
        Sdf.VariantSpec(vset, f"x{i}").primSpec.referenceList.prependedItems.append(Sdf.Reference("", "/L0"))
    _laughs(variants, 2)
    assert composition_problem(variants, max_prims=250) is not None
    cycle = _layer(base)  # composition refuses a cycle: it adds nothing
    _junk(cycle).inheritPathList.prependedItems.append(Sdf.Path("/Asset"))
    assert composition_problem(cycle) is None


@pytest.mark.parametrize("kind", ["rna", "neupress", "8dna"])
def test_what_the_sdk_writes_is_far_below_the_bounds(tmp_path, kind):
    """The largest written asset (8dna) has ~120 specs and prims 4 deep: a hundredth of the bound."""
    from pxr import Sdf

    path = example_builder(kind, size="tiny", seed=0, quality_variants=kind == "rna").write(tmp_path / "a.usdc")
    layer = Sdf.Layer.FindOrOpen(str(path))
    assert structure_problem(layer, max_specs=limits.MAX_ASSET_SPECS // 50, max_depth=4) is None
    assert composition_problem(layer, max_prims=limits.MAX_ASSET_SPECS // 200, max_depth=8) is None


@pytest.mark.parametrize("suffix", [".usdc", ".usda", ".usdz"])
def test_an_asset_over_the_spec_bound_is_refused_by_every_reader(base, tmp_path, suffix):
    """Before: validated clean (ten times this: minutes and GBs); now ARRAY_TOO_LARGE from the probe, naming the count."""
    from pxr import UsdUtils

    layer = _prims(_layer(base), limits.MAX_ASSET_SPECS)
    path = tmp_path / f"many{suffix}"
    if suffix == ".usdz":
        inner = tmp_path / "many_inner.usdc"
        assert layer.Export(str(inner))
        assert UsdUtils.CreateNewUsdzPackage(str(inner), str(path))
    else:
        assert layer.Export(str(path))
    report = validate_file(path)
    assert report.codes("error") == {"ARRAY_TOO_LARGE"}, [str(f) for f in report.findings]
    assert f"> {limits.MAX_ASSET_SPECS}" in report.errors[0].message
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "ARRAY_TOO_LARGE" and str(path) in str(exc.value)


def test_an_asset_composing_to_more_prims_than_the_bound_is_refused_before_composing(base, tmp_path):
    """Before: ten prims per class, five classes deep (11 111 prims from a 13 KB file) took validate 11 s and a
    level more 88 s at 1.8 GB; now ARRAY_TOO_LARGE from the probe before anything composes."""
    path = tmp_path / "laughs.usdc"
    assert _laughs(_layer(base), 5).Export(str(path))
    report = validate_file(path)
    assert report.codes("error") == {"ARRAY_TOO_LARGE"}, [str(f) for f in report.findings][:5]
    assert f"more than {limits.MAX_ASSET_SPECS} prims" in report.errors[0].message
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "ARRAY_TOO_LARGE"


def test_a_file_read_as_an_asset_is_held_to_the_bound_whatever_it_declares(base, tmp_path):
    """A layer whose defaultPrim is not a NeuralAsset, given to validate: before, the probe read every spec and
    composed it (the cost of the whole file) before ROOT_MISSING; now it stops at the bound."""
    layer = _prims(_layer(base), limits.MAX_ASSET_SPECS)
    layer.defaultPrim = "Asset"
    layer.GetPrimAtPath("/Asset").typeName = "Scope"
    path = tmp_path / "not_asset.usdc"
    assert layer.Export(str(path))
    assert validate_file(path).codes("error") == {"ARRAY_TOO_LARGE"}


def test_a_scene_is_not_held_to_the_asset_bound(tmp_path):
    """Many prims are legitimate in a scene: its own layers are probed without the asset bound."""
    from pxr import Sdf

    from nasset_sdk.paths import check_layer_tree

    layer = Sdf.Layer.CreateAnonymous()
    _prims(layer, limits.MAX_ASSET_SPECS + 1, parent=Sdf.PrimSpec(layer, "World", Sdf.SpecifierDef, "Xform").path.pathString)
    path = tmp_path / "scene.usdc"
    assert layer.Export(str(path))
    assert check_layer_tree(path, scene=True) == []


def _layer_chain(folder: Path, levels: int, fan: int = 10) -> str:
    """b1.usda ... b<levels>.usda: /L holds ``fan`` prims, each referencing the next file's /L. Returns b1's name."""
    from pxr import Sdf

    for k in range(1, levels + 1):
        layer = Sdf.Layer.CreateNew(str(folder / f"b{k}.usda"))
        top = Sdf.PrimSpec(layer, "L", Sdf.SpecifierDef, "Xform")
        layer.defaultPrim = "L"
        for i in range(fan):
            child = Sdf.PrimSpec(top, f"c{i}", Sdf.SpecifierDef, "Xform")
            if k < levels:
                child.referenceList.prependedItems.append(Sdf.Reference(f"./b{k + 1}.usda", "/L"))
        assert layer.Save()
    return "./b1.usda"


def test_an_asset_whose_layers_repeat_each_other_is_refused_before_composing_in_process(base, tmp_path):
    """Each in-package layer passes its own probe (arcs to other files are stripped there): before, Asset.open composed
    ten references to a chain of three files of ten prims (11 110 prims; a chain of seven: 10^8) in-process. Now the
    tree is composed once in a bounded child first, held to the asset bound."""
    from pxr import Sdf

    layer = _layer(base)
    target = _layer_chain(tmp_path, 3)
    junk = _junk(layer)
    for i in range(10):
        Sdf.PrimSpec(junk, f"r{i}", Sdf.SpecifierDef).referenceList.prependedItems.append(Sdf.Reference(target, "/L"))
    path = tmp_path / "asset.usda"
    assert layer.Export(str(path))
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "ARRAY_TOO_LARGE" and f"more than {limits.MAX_ASSET_SPECS} prims" in str(exc.value)


def test_a_scene_whose_layers_repeat_each_other_is_composed_once_in_a_child_and_not_held_to_the_asset_bound(tmp_path):
    from pxr import Usd, UsdGeom

    from nasset_sdk.paths import open_checked_stage

    target = _layer_chain(tmp_path, 3)
    stage = Usd.Stage.CreateNew(str(tmp_path / "scene.usda"))
    UsdGeom.Xform.Define(stage, "/World")
    for i in range(10):
        stage.DefinePrim(f"/World/r{i}", "Xform").GetReferences().AddReference(target, "/L")
    stage.GetRootLayer().Save()
    opened = open_checked_stage(tmp_path / "scene.usda", Usd.Stage.LoadAll, scene=True)
    assert sum(1 for _ in opened.Traverse()) > limits.MAX_ASSET_SPECS
