"""nasset_sdk.stage_rules.Hiding: each prim's visibility and purpose passed down from its parent's equal USD's own
per-prim computation (which walks every ancestor) on random stages."""

from __future__ import annotations

import random

import pytest

from nasset_sdk.stage_rules import Hiding, Purposes, is_hidden

_TYPES = ("Xform", "Xform", "Scope", "", "Mesh", "Cube", "GeomSubset", "Material")


def _random_tree(seed: int, decorate, root: str | None = None):
    """(stage, rng): 300 prims of imageable and non-imageable types 1-12 deep under ``root`` (default the pseudo-root),
    each new prim passed to ``decorate(stage, prim, rng, paths, i)`` as it is defined."""
    from pxr import Sdf, Usd

    rng = random.Random(seed)
    stage = Usd.Stage.CreateInMemory()
    paths = [Sdf.Path(root) if root else Sdf.Path.absoluteRootPath]
    if root:
        stage.DefinePrim(paths[0], "Xform")
    for i in range(300):
        parent = rng.choice(paths)
        if parent.pathElementCount >= 12:
            continue
        prim = stage.DefinePrim(parent.AppendChild(f"P{i}"), rng.choice(_TYPES))
        paths.append(prim.GetPath())
        decorate(stage, prim, rng, paths, i)
    return stage, rng


def _random_stage(seed: int):
    """Visibility and purpose authored at random on some prims (non-imageable prims included, as plain
    attributes; a few visibilities only as time samples)."""
    from pxr import Sdf, UsdGeom

    def decorate(stage, prim, rng, paths, i):
        if rng.random() < 0.15:
            attr = prim.CreateAttribute("visibility", Sdf.ValueTypeNames.Token)
            value = rng.choice((UsdGeom.Tokens.invisible, UsdGeom.Tokens.inherited))
            attr.Set(value, 1.0) if rng.random() < 0.3 else attr.Set(value)
        if rng.random() < 0.2:
            prim.CreateAttribute("purpose", Sdf.ValueTypeNames.Token).Set(
                rng.choice(("default", "render", "proxy", "guide")))

    return _random_tree(seed, decorate)[0]


@pytest.mark.parametrize("seed", range(6))
def test_hiding_equals_usds_per_prim_computation(seed):
    from pxr import Usd

    stage = _random_stage(seed)
    prims = list(stage.Traverse())
    rng = random.Random(seed)
    for included in ({"default", "render"}, {"default", "proxy"}, {"render", "guide"}):
        purposes = Purposes(frozenset(included), "full")
        for time in (Usd.TimeCode.Default(), Usd.TimeCode(1.0)):
            want = {p.GetPath(): is_hidden(p, time, purposes) for p in prims}
            in_order = Hiding(time, purposes)  # traversal order: each parent already known
            assert {p.GetPath(): in_order.is_hidden(p) for p in prims} == want
            shuffled = Hiding(time, purposes)  # any order: a prim's unknown ancestors computed on the way
            order = rng.sample(prims, len(prims))
            assert {p.GetPath(): shuffled.is_hidden(p) for p in order} == want
    assert any(is_hidden(p, Usd.TimeCode.Default(), Purposes(frozenset({"default"}), "")) for p in prims)


def _random_primvar_stage(seed: int):
    """Primvars of three names authored at random: constant or vertex, with a value or only declared, on imageable
    and non-imageable prims."""
    from pxr import Sdf, UsdGeom

    def decorate(stage, prim, rng, paths, i):
        for name in _PRIMVARS:
            if rng.random() < 0.15:
                interpolation = rng.choice((UsdGeom.Tokens.constant, UsdGeom.Tokens.constant, UsdGeom.Tokens.vertex))
                kind, value = {"displayColor": (Sdf.ValueTypeNames.Color3fArray, [(rng.random(), 0.0, 0.0)]),
                               "displayOpacity": (Sdf.ValueTypeNames.FloatArray, [rng.random()]),
                               "st": (Sdf.ValueTypeNames.TexCoord2fArray, [(rng.random(), 0.0)])}[name]
                pv = UsdGeom.PrimvarsAPI(prim).CreatePrimvar(name, kind, interpolation)
                if rng.random() < 0.8:
                    pv.Set(value)

    return _random_tree(seed, decorate)[0]


_PRIMVARS = ("displayColor", "displayOpacity", "st")


@pytest.mark.parametrize("seed", range(6))
def test_inherited_primvars_equal_usds_per_prim_search(seed):
    from pxr import UsdGeom

    from nasset_sdk.stage_rules import InheritedPrimvars

    stage = _random_primvar_stage(seed)
    prims = list(stage.Traverse())
    for order in (prims, random.Random(seed).sample(prims, len(prims))):
        primvars = InheritedPrimvars()
        for prim in order:
            for name in _PRIMVARS:
                want = UsdGeom.PrimvarsAPI(prim).FindPrimvarWithInheritance(name)
                want = want.GetAttr().GetPath() if want and want.HasAuthoredValue() else None
                got = primvars.find(prim, name)
                assert (got.GetAttr().GetPath() if got is not None else None) == want, (prim.GetPath(), name)


def _random_binding_stage(seed: int, collections: bool):
    """Direct bindings at random: all-purpose, full or preview, weaker or stronger than descendants, to a Material,
    to a prim that is not one or to nothing there; through the MaterialBindingAPI or as a bare relationship; with
    ``collections``, a few collection-based bindings too."""
    from pxr import Sdf, Usd, UsdShade

    targets: list = []

    def decorate(stage, prim, rng, paths, i):
        if not targets:
            targets.extend(UsdShade.Material.Define(stage, f"/Looks/M{k}").GetPath() for k in range(4))
            targets.extend([stage.DefinePrim("/Looks/NotAMaterial", "Xform").GetPath(), Sdf.Path("/Looks/Missing")])
        for purpose in ("", "full", "preview"):
            if rng.random() < 0.12:
                name = "material:binding" + (f":{purpose}" if purpose else "")
                if rng.random() < 0.8:
                    UsdShade.MaterialBindingAPI.Apply(prim)
                rel = prim.CreateRelationship(name, False)
                rel.SetTargets([rng.choice(targets)])
                if rng.random() < 0.3:
                    UsdShade.MaterialBindingAPI.SetMaterialBindingStrength(rel, UsdShade.Tokens.strongerThanDescendants)
        if collections and rng.random() < 0.02:
            members = [p for p in paths if p.HasPrefix(prim.GetPath())]
            coll = Usd.CollectionAPI.Apply(prim, f"c{i}")
            coll.CreateIncludesRel().SetTargets(rng.sample(members, min(3, len(members))))
            api = UsdShade.MaterialBindingAPI.Apply(prim)
            api.Bind(coll, UsdShade.Material(stage.GetPrimAtPath(targets[rng.randrange(4)])), f"b{i}")

    return _random_tree(seed, decorate, root="/World")[0]


@pytest.mark.parametrize("seed", range(6))
@pytest.mark.parametrize("collections", [False, True])
def test_material_bindings_equal_usds_per_prim_computation(seed, collections):
    from pxr import UsdShade

    from nasset_sdk.stage_rules import MaterialBindings

    stage = _random_binding_stage(seed, collections)
    prims = list(stage.Traverse())
    for purpose in ("", "full", "preview"):
        want = {p.GetPath(): UsdShade.MaterialBindingAPI(p).ComputeBoundMaterial(purpose)[0] for p in prims}
        want = {k: m.GetPath() if m else None for k, m in want.items()}
        for order in (prims, random.Random(seed).sample(prims, len(prims))):
            bindings = MaterialBindings()
            got = {p.GetPath(): bindings.compute(p, purpose) for p in order}
            assert {k: m.GetPath() if m else None for k, m in got.items()} == want
    assert len(set(want.values())) > 2  # several materials, and unbound prims


def test_normal_matrix_is_the_inverse_transpose_up_to_length_and_exists_when_it_does_not():
    """stage_rules.normal_matrix: on random regular transforms (mirroring ones included) the unit normals are those of
    inv(M)^T; on a transform that flattens along y a y-normal stays +y and an x-normal goes to zero; a stack of matrices
    gives the stack of their matrices."""
    import numpy as np

    from nasset_sdk.stage_rules import normal_matrix

    rng = np.random.default_rng(1)
    for _ in range(20):
        m, n = rng.normal(size=(3, 3)), rng.normal(size=(8, 3))
        a, b = n @ np.linalg.inv(m).T, n @ normal_matrix(m)
        np.testing.assert_allclose(b / np.linalg.norm(b, axis=1, keepdims=True), a / np.linalg.norm(a, axis=1, keepdims=True),
                                   atol=1e-10)
    flat = normal_matrix(np.diag([2.0, 0.0, 3.0]))
    np.testing.assert_allclose(np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0]]) @ flat, [[0.0, 6.0, 0.0], [0.0, 0.0, 0.0]])
    stack = rng.normal(size=(5, 3, 3))
    np.testing.assert_allclose(normal_matrix(stack), np.stack([normal_matrix(m) for m in stack]))
