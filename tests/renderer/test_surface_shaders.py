"""Surface shaders (spec/renderer.md#materials): their inputs are checked, and MaterialX surfaces are read.

MaterialX surfaces: a material whose only surface is a MaterialX standard_surface or
open_pbr_surface on outputs:mtlx:surface renders as the UsdPreviewSurface of the same base colour, metalness,
roughness, IOR and emission. Before, the whole scene was SCENE_UNSUPPORTED."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, UsdShade

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder


def _floor_scene(tmp_path, name, make_material):
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=20)
    quad = b.quad("Floor", (0, 0, 0), 4.0)
    mat = make_material(b.stage)
    UsdShade.MaterialBindingAPI.Apply(quad.GetPrim()).Bind(mat)
    b.distant("Sun", (0.3, 1.0, 0.2), 2.0)
    return load_scene(b.write(tmp_path / f"{name}.usda"))


@pytest.mark.parametrize("sid, inputs", [
    ("ND_standard_surface_surfaceshader", {"base": 0.5, "base_color": (0.8, 0.4, 0.2), "metalness": 0.3,
                                           "specular_roughness": 0.6, "specular_IOR": 1.4, "emission": 0.5,
                                           "emission_color": (0.2, 0.2, 0.4)}),
    ("ND_open_pbr_surface_surfaceshader", {"base_weight": 0.5, "base_color": (0.8, 0.4, 0.2), "base_metalness": 0.3,
                                           "specular_roughness": 0.6, "specular_ior": 1.4, "emission_luminance": 0.5,
                                           "emission_color": (0.2, 0.2, 0.4)})])
def test_mtlx_surface_renders_as_its_preview_surface(tmp_path, sid, inputs):
    def mtlx(stage):
        mat = UsdShade.Material.Define(stage, "/World/Looks/Mx")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Mx/Surface")
        sh.CreateIdAttr(sid)
        for k, v in inputs.items():
            sh.CreateInput(k, Sdf.ValueTypeNames.Color3f if isinstance(v, tuple) else Sdf.ValueTypeNames.Float).Set(v)
        mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")
        return mat

    def preview(stage):
        mat = UsdShade.Material.Define(stage, "/World/Looks/Preview")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Preview/Surface")
        sh.CreateIdAttr("UsdPreviewSurface")
        for k, v in (("diffuseColor", (0.4, 0.2, 0.1)), ("emissiveColor", (0.1, 0.1, 0.2))):
            sh.CreateInput(k, Sdf.ValueTypeNames.Color3f).Set(v)
        for k, v in (("metallic", 0.3), ("roughness", 0.6), ("ior", 1.4)):
            sh.CreateInput(k, Sdf.ValueTypeNames.Float).Set(v)
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        return mat

    settings = RenderSettings(spp=2, width=8, height=8, max_depth=1, seed=1)
    a = render(_floor_scene(tmp_path, "mx", mtlx), settings).image
    b = render(_floor_scene(tmp_path, "preview", preview), settings).image
    assert a.mean() > 0.05
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


def test_mtlx_lobes_without_a_preview_counterpart_are_warned(tmp_path):
    def mtlx(stage):
        mat = UsdShade.Material.Define(stage, "/World/Looks/Mx")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Mx/Surface")
        sh.CreateIdAttr("ND_standard_surface_surfaceshader")
        sh.CreateInput("coat", Sdf.ValueTypeNames.Float).Set(0.8)
        mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")
        return mat

    with pytest.warns(UserWarning, match="coat is dropped"):
        _floor_scene(tmp_path, "mx", mtlx)


def test_a_mtlx_input_that_is_not_a_finite_number_is_a_scene_error(tmp_path):
    from nasset_sdk.errors import SceneError

    def mtlx(stage):
        mat = UsdShade.Material.Define(stage, "/World/Looks/Mx")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Mx/Surface")
        sh.CreateIdAttr("ND_standard_surface_surfaceshader")
        sh.CreateInput("metalness", Sdf.ValueTypeNames.String).Set("shiny")
        sh.CreateInput("base", Sdf.ValueTypeNames.Float).Set(float("nan"))
        mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")
        return mat

    with pytest.raises(SceneError) as exc:
        _floor_scene(tmp_path, "mx", mtlx)
    assert exc.value.code == "SCENE_INVALID" and "inputs:" in str(exc.value)


@pytest.mark.parametrize("name, value_type, value", [("roughness", "String", "rough"), ("diffuseColor", "Color3f",
                                                                                         (float("nan"), 0.1, 0.1)),
                                                     ("ior", "Float", -1.0)])
def test_preview_surface_inputs_that_are_not_usable_numbers_are_scene_errors(tmp_path, name, value_type, value):
    """Before: a string was a numpy traceback, a NaN colour went on to the render, ior -1 divided by zero."""
    from nasset_sdk.errors import SceneError

    def preview(stage):
        mat = UsdShade.Material.Define(stage, "/World/Looks/Preview")
        sh = UsdShade.Shader.Define(stage, "/World/Looks/Preview/Surface")
        sh.CreateIdAttr("UsdPreviewSurface")
        sh.CreateInput(name, getattr(Sdf.ValueTypeNames, value_type)).Set(value)
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        return mat

    with pytest.raises(SceneError) as exc:
        _floor_scene(tmp_path, "bad", preview)
    assert exc.value.code == "SCENE_INVALID" and f"inputs:{name}" in str(exc.value)
