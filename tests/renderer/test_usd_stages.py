"""Stages written by other USD tools: everyday USD features render as USD defines them, or are warned by name.

The probe is a diffuse floor seen from above under a delta DistantLight of irradiance E at angle theta, whose
radiance has the closed form ``albedo E cos(theta) / pi`` (spec/renderer.md#lights; the specular workflow with
``specularColor = 0`` leaves a Fresnel term below 1e-6 here)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder

E, THETA = 3.0, np.radians(35)
RED = (0.9, 0.2, 0.1)


def _floor_scene(albedo=(0.6, 0.6, 0.6)):
    b = SceneBuilder()
    b.camera((0, 3, 0.01), (0, 0, 0), focal=50)
    floor = b.quad("Floor", (0, 0, 0), 10.0, diffuse=albedo)
    b.distant("Sun", (np.sin(THETA), np.cos(THETA), 0), E)
    return b, floor.GetPrim()


def _render(b, tmp_path, name="s.usda", expect_warning=False):
    with pytest.warns(UserWarning) if expect_warning else contextlib.nullcontext():
        scene = load_scene(b.write(tmp_path / name))
    return render(scene, RenderSettings(width=8, height=8, spp=2)).image, scene.warnings


def _lit(albedo):
    return np.broadcast_to(np.asarray(albedo) * E * np.cos(THETA) / np.pi, (8, 8, 3))


# -- material binding purposes (UsdShade "Material Purpose") ----------------------------------------------------------

@pytest.mark.parametrize("with_all_purpose", [True, False])
def test_full_purpose_binding_is_the_final_renders_material(tmp_path, with_all_purpose):
    """A final render reads ``material:binding:full`` before the all-purpose binding (Houdini and Omniverse write
    both: a preview material for the viewport, the full one for the render); it was ignored for the all-purpose
    material, or the prim rendered unbound when it had only a full binding."""
    from pxr import UsdShade

    b, floor = _floor_scene()
    red = b.material("Red", diffuse=RED, specular=(0, 0, 0))
    api = UsdShade.MaterialBindingAPI(floor)
    if not with_all_purpose:
        api.UnbindAllBindings()
    api.Bind(red, materialPurpose=UsdShade.Tokens.full)
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit(RED), rtol=1e-4)


def test_preview_only_binding_is_warned_by_name(tmp_path):
    """A prim bound only for ``preview`` is unbound in a final render (USD's purpose fallback is all-purpose, never
    preview); that is said, naming the prim and the material."""
    from pxr import UsdShade

    b, floor = _floor_scene()
    red = b.material("Red", diffuse=RED)
    api = UsdShade.MaterialBindingAPI(floor)
    api.UnbindAllBindings()
    api.Bind(red, materialPurpose=UsdShade.Tokens.preview)
    _, said = _render(b, tmp_path, expect_warning=True)
    assert any("/World/Floor" in m and "/World/Looks/Red" in m and "preview" in m for m in said), said


def test_full_purpose_binding_of_a_geom_subset(tmp_path):
    """Per-face materials follow the same purpose rule."""
    from pxr import UsdGeom, UsdShade

    b, floor = _floor_scene()
    red = b.material("Red", diffuse=RED, specular=(0, 0, 0))
    subset = UsdShade.MaterialBindingAPI(floor).CreateMaterialBindSubset("Faces", [0], UsdGeom.Tokens.face)
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(red, materialPurpose=UsdShade.Tokens.full)
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit(RED), rtol=1e-4)


# -- primvar inheritance (UsdGeomPrimvarsAPI: constant primvars are inherited down namespace) -------------------------

def _unbound_floor(tmp_path, name, on_parent: bool):
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    b, floor = _floor_scene()
    UsdShade.MaterialBindingAPI(floor).UnbindAllBindings()
    holder = floor.GetParent() if on_parent else floor
    pv = UsdGeom.PrimvarsAPI(holder).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.constant)
    pv.Set([Gf.Vec3f(*RED)])
    return _render(b, tmp_path, name)[0]


def test_display_color_of_an_ancestor_is_inherited(tmp_path):
    """An unbound mesh under an Xform that authors a constant ``primvars:displayColor`` takes that colour, as in
    usdview (exporters put one colour on a group); it rendered the 0.18 grey of a mesh without one."""
    own = _unbound_floor(tmp_path, "own.usda", on_parent=False)
    inherited = _unbound_floor(tmp_path, "inherited.usda", on_parent=True)
    np.testing.assert_array_equal(inherited, own)
    assert own[..., 0].mean() > 2 * own[..., 1].mean()  # red, not grey
