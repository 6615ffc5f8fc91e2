"""Stages written by other USD tools: everyday USD features render as USD defines them, or are warned by name.

The probe is a diffuse floor seen from above under a delta DistantLight of irradiance E at angle theta, whose
radiance has the closed form ``albedo E cos(theta) / pi`` (spec/renderer.md#lights; the specular workflow with
``specularColor = 0`` leaves a Fresnel term below 1e-6 here)."""

from __future__ import annotations

import contextlib

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from tests.stage_scenes import RED, THETA, E, hidden_camera_scene, product_camera_scene  # noqa: F401
from tests.stage_scenes import floor_scene as _floor_scene
from tests.stage_scenes import plain_geometry_layer as _plain_geometry_layer
from tests.stage_scenes import render_settings as _settings
from tests.stage_scenes import two_camera_scene as _two_camera_scene


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


# -- render settings: which camera, which settings prim (UsdRender) ---------------------------------------------------

def test_render_settings_camera_is_the_camera_rendered(tmp_path):
    """``RenderSettings.camera`` names the camera (Houdini, Omniverse and the converters write it); the first camera
    in traversal order was rendered instead, with a warning that there were two."""
    b = _two_camera_scene()
    _settings(b, "/Render/Settings", "/World/Below")
    scene = load_scene(b.write(tmp_path / "s.usda"))
    assert scene.camera.prim == "/World/Below"
    assert not any("cameras" in m for m in scene.warnings)


def test_render_product_camera_wins_over_the_settings_camera(tmp_path):
    assert load_scene(product_camera_scene().write(tmp_path / "s.usda")).camera.prim == "/World/Below"


def test_render_settings_prim_path_chooses_the_settings(tmp_path):
    """The stage's ``renderSettingsPrimPath`` metadata names the settings to use (several are common: preview and
    final); the first in traversal order was used."""
    b = _two_camera_scene()
    _settings(b, "/Render/Preview", "/World/Top", resolution=(4, 4))
    _settings(b, "/Render/Final", "/World/Below", resolution=(6, 3))
    b.stage.SetMetadata("renderSettingsPrimPath", "/Render/Final")
    scene = load_scene(b.write(tmp_path / "s.usda"))
    assert (scene.camera.prim, scene.camera.resolution) == ("/World/Below", (6, 3))


def test_inactive_render_settings_are_not_read(tmp_path):
    """A deactivated settings prim is not part of the composed stage; its resolution was used."""
    b = _two_camera_scene()
    _settings(b, "/Render/Off", resolution=(4, 2)).GetPrim().SetActive(False)
    _settings(b, "/Render/On", resolution=(6, 6))
    assert load_scene(b.write(tmp_path / "s.usda")).camera.resolution == (6, 6)


def test_render_settings_camera_that_is_not_a_camera_is_scene_invalid(tmp_path):
    from nasset_sdk.errors import SceneError

    b = _two_camera_scene()
    _settings(b, "/Render/Settings", "/World/Floor")
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_INVALID" and "/Render/Settings" in str(info.value) and "camera" in str(info.value)


def test_unhonoured_render_settings_are_warned_by_name(tmp_path):
    """``pixelAspectRatio``, ``dataWindowNDC`` and an aspect-ratio conform policy that would frame the image otherwise
    than the horizontal fit were ignored without a word."""
    from pxr import Gf

    b = _two_camera_scene()
    _settings(b, "/Render/Settings", "/World/Top", resolution=(16, 8), pixelAspectRatio=2.0,
              dataWindowNDC=Gf.Vec4f(0.25, 0.25, 0.75, 0.75))  # a square aperture, a wide image: expandAperture differs
    with pytest.warns(UserWarning):
        said = load_scene(b.write(tmp_path / "s.usda")).warnings
    for word in ("pixelAspectRatio", "dataWindowNDC", "aspectRatioConformPolicy 'expandAperture'"):
        assert any(word in m and "/Render/Settings" in m for m in said), (word, said)


# -- composition: what USD could not compose, and untyped prims placing plain USD -------------------------------------

@pytest.mark.parametrize("arc", ["reference", "payload"])
def test_untyped_prim_referencing_plain_usd_renders_it(tmp_path, arc):
    """An untyped ``def "Set" (references = @geo.usda@)`` whose layer is ordinary geometry (an asset library's
    untyped root) renders that geometry, as in usdview; it was SCENE_INVALID ``referenced asset file not found, or
    it is not a neural asset`` although the file exists."""
    _plain_geometry_layer(tmp_path / "geo.usda")
    b, floor = _floor_scene()
    b.stage.RemovePrim(floor.GetPath())
    prim = b.stage.DefinePrim("/World/Set")
    arcs = prim.GetReferences() if arc == "reference" else prim.GetPayloads()
    arcs.AddReference("./geo.usda") if arc == "reference" else arcs.AddPayload("./geo.usda")
    image, _ = _render(b, tmp_path)  # the floor's own material: 0.6, not the unbound grey
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)


def test_untyped_prim_with_a_missing_reference_stays_scene_invalid(tmp_path):
    from nasset_sdk.errors import SceneError

    b, _ = _floor_scene()
    b.stage.DefinePrim("/World/Chair").GetReferences().AddReference("./chair.usdc")
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_INVALID" and "/World/Chair" in str(info.value) and "chair.usdc" in str(info.value)


@pytest.mark.parametrize("arc", ["reference", "payload", "sublayer", "prim path"])
def test_what_usd_cannot_compose_is_warned_naming_the_prim(tmp_path, arc):
    """A missing referenced, payloaded or sublayered file, or a reference to a prim the file lacks, leaves that part
    out of the composed stage (USD's rule: usdview draws the rest); the renderer said nothing of it (USD's own
    diagnostic went to stderr only)."""
    _plain_geometry_layer(tmp_path / "geo.usda")
    b, _ = _floor_scene()
    prim = b.stage.DefinePrim("/World/Set", "Xform")
    if arc == "reference":
        prim.GetReferences().AddReference("./missing.usda")
    elif arc == "payload":
        prim.GetPayloads().AddPayload("./missing.usda")
    elif arc == "sublayer":
        b.stage.GetRootLayer().subLayerPaths.append("./missing.usda")
    else:
        prim.GetReferences().AddReference("./geo.usda", "/Nope")
    with pytest.warns(UserWarning):
        scene = load_scene(b.write(tmp_path / "s.usda"))
    hit = [m for m in scene.warnings if "cannot reach" in m]
    assert hit and ("/Nope" in hit[0] if arc == "prim path" else "missing.usda" in hit[0]), scene.warnings
    assert arc == "sublayer" or "/World/Set" in hit[0]


@pytest.mark.parametrize("body, names", [
    ('def Mesh "M" {\n    point3f[] points = [(0, 0, 0), (1, 1)]\n  }', "</W/M.points>"),
    ('def Mesh "M" {\n    float3 xformOp:rotateY = 30\n  }', "s.usda:4:"),
])
def test_usda_syntax_error_names_where(tmp_path, body, names):
    """A hand-edited ``.usda`` that does not parse is SCENE_INVALID with the parser's message (prim, attribute, line
    and column); the message was a lone quote or USD's generic ``Failed to open layer``."""
    from nasset_sdk.errors import NassetError

    path = tmp_path / "s.usda"
    path.write_text(f'#usda 1.0\ndef Xform "W" {{\n  {body}\n}}\n')
    with pytest.raises(NassetError) as info:  # SCENE_INVALID, or FILE_UNREADABLE from a reader's probe of the file
        load_scene(str(path))
    assert info.value.code in ("SCENE_INVALID", "FILE_UNREADABLE") and names in str(info.value), str(info.value)


# -- what a light or camera authors that the renderer does not honour is said, by name --------------------------------

def test_light_input_connected_to_a_shader_is_warned(tmp_path):
    """A light input fed by a shader network (a texture or a primvar reader on ``inputs:color``, Houdini and RenderMan
    light shaders) used its own value without a word."""
    from pxr import Sdf, UsdShade

    b, _ = _floor_scene()
    tex = UsdShade.Shader.Define(b.stage, "/World/Looks/LightTex")
    tex.CreateIdAttr("UsdUVTexture")
    color = b.stage.GetPrimAtPath("/World/Sun").GetAttribute("inputs:color")
    color.AddConnection(Sdf.Path("/World/Looks/LightTex.outputs:rgb"))
    with pytest.warns(UserWarning):
        image, said = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)  # the authored white
    assert any("/World/Sun" in m and "inputs:color connected" in m for m in said), said


def test_light_filters_are_warned(tmp_path):
    from pxr import UsdLux

    b, _ = _floor_scene()
    UsdLux.LightFilter.Define(b.stage, "/World/Barn")
    UsdLux.LightAPI(b.stage.GetPrimAtPath("/World/Sun")).GetFiltersRel().SetTargets(["/World/Barn"])
    with pytest.warns(UserWarning):
        _, said = _render(b, tmp_path)
    assert any("/World/Sun" in m and "light:filters /World/Barn" in m for m in said), said


@pytest.mark.parametrize("clip, warned", [((5.0, 100.0), True), ((0.1, 2.0), True), ((0.1, 100.0), False)])
def test_camera_clipping_that_would_cut_geometry_is_warned(tmp_path, clip, warned):
    """USD cuts what lies outside a camera's ``clippingRange``; the renderer clips nothing. It now says so when the
    range would cut the scene's geometry (the floor lies 3 units below the camera), and stays quiet otherwise."""
    from pxr import Gf, UsdGeom

    b, _ = _floor_scene()
    UsdGeom.Camera(b.stage.GetPrimAtPath("/World/Camera")).CreateClippingRangeAttr(Gf.Vec2f(*clip))
    scene = load_scene(b.write(tmp_path / "s.usda"))
    assert any("clippingRange" in m and "/World/Camera" in m for m in scene.warnings) == warned, scene.warnings


@pytest.mark.parametrize("variant", ["surface", "fiber"])
def test_clipping_warning_reads_an_assets_points(tmp_path, variant):
    """A neural asset's depth range comes from the world points its faces use (a fibre's prisms have five corners per
    point): the warned range is the brute-force range over every triangle corner in front of the camera."""
    import re

    from pxr import Gf, UsdGeom

    from nasset_reference_renderer.testscenes import SceneBuilder
    from nasset_sdk.examples import example_builder

    asset = example_builder("rna", variant=variant, size="tiny", seed=0).write(tmp_path / "a.usdc")
    b = SceneBuilder()
    b.camera((0.3, 0.5, 2.5), (0, 0.3, 0))
    b.distant("Sun", (0.5, 1.0, 0.35), 3.0)
    M = np.diag([1.3, 0.8, 1.1, 1.0])
    M[3, :3] = (0.2, -0.1, 0.4)
    b.asset("Asset", asset, M)
    UsdGeom.Camera(b.stage.GetPrimAtPath("/World/Camera")).CreateClippingRangeAttr(Gf.Vec2f(5.0, 100.0))
    scene = load_scene(b.write(tmp_path / "s.usda"))
    (said,) = [m for m in scene.warnings if "clippingRange" in m]
    lo, hi = (float(v) for v in re.search(r"depths (\S+) to (\S+),", said).groups())
    corners = scene.triangles.reshape(-1, 3)
    C = scene.camera.to_world
    depth = -((corners - C[3, :3]) @ np.linalg.inv(C[:3, :3])[:, 2])
    depth = depth[depth > 0]
    assert (lo, hi) == (float(f"{depth.min():.4g}"), float(f"{depth.max():.4g}"))


def test_missing_texture_file_is_said_to_be_missing(tmp_path):
    """A UsdUVTexture whose PNG is not there was reported as a format the renderer does not read."""
    b, _ = _floor_scene()
    b.texture("FloorMat", {"diffuseColor": "rgb"}, "gone.png")
    with pytest.warns(UserWarning):
        said = load_scene(b.write(tmp_path / "s.usda")).warnings
    assert any("gone.png not found" in m and "/World/Looks/FloorMat/tex_" in m for m in said), said
    assert not any("only OpenEXR" in m for m in said), said


def test_normals_with_indices_out_of_range_are_warned(tmp_path):
    """``primvars:normals:indices`` pointing past the values: USD flattens nothing (its diagnostic goes to stderr);
    the renderer dropped the normals without a word."""
    from pxr import Sdf, UsdGeom

    b, floor = _floor_scene()
    pv = UsdGeom.PrimvarsAPI(floor).CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray, UsdGeom.Tokens.faceVarying)
    pv.Set([(0.0, 1.0, 0.0)])
    pv.SetIndices([0, 0, 0, 5])
    with pytest.warns(UserWarning):
        image, said = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)
    assert any("/World/Floor" in m and "primvars:normals has indices" in m for m in said), said


# -- prim types the renderer does not draw ---------------------------------------------------------------------------

@pytest.mark.parametrize("tname", ["Cylinder_1", "Capsule_1", "ParticleField3DGaussianSplat", "Volume"])
def test_every_other_geometry_type_is_scene_unsupported(tmp_path, tname):
    """Any UsdGeom.Gprim the renderer does not draw is refused naming the prim; types newer than the renderer's list
    (USD 24's Cylinder_1 and Capsule_1, Gaussian splats) rendered nothing without a word."""
    from nasset_sdk.errors import SceneError

    b, _ = _floor_scene()
    b.stage.DefinePrim("/World/Thing", tname)
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_UNSUPPORTED" and "/World/Thing" in str(info.value) and tname in str(info.value)


def test_prim_types_without_a_schema_are_warned_once_per_type(tmp_path):
    """A DCC's own prim type (RealityKit's ``Preliminary_Text``, Houdini's ``HoudiniLayerInfo``) whose plugin is not
    loaded is not drawn; that is said once per type, and its children are still traversed."""
    b, floor = _floor_scene()
    for name in ("A", "B"):
        b.stage.DefinePrim(f"/World/{name}", "Preliminary_Text")
    with pytest.warns(UserWarning):
        scene = load_scene(b.write(tmp_path / "s.usda"))
    said = [m for m in scene.warnings if "Preliminary_Text" in m]
    assert len(said) == 1 and "/World/A" in said[0], scene.warnings


# -- Omniverse materials: MDL beside UsdPreviewSurface ----------------------------------------------------------------

def _add_mdl_shader(b, material_path, *, universal: bool):
    """Omniverse's pattern: an MDL shader named by a bare ``info:mdl:sourceAsset = @OmniPBR.mdl@`` (a built-in found on
    MDL search paths, never a file next to the scene) on ``outputs:mdl:surface``; ``universal``: also on
    ``outputs:surface`` instead of the UsdPreviewSurface."""
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material(b.stage.GetPrimAtPath(material_path))
    mdl = UsdShade.Shader.Define(b.stage, f"{material_path}/Omni")
    mdl.SetSourceAsset(Sdf.AssetPath("OmniPBR.mdl"), "mdl")
    out = mdl.CreateOutput("out", Sdf.ValueTypeNames.Token)
    mat.CreateSurfaceOutput("mdl").ConnectToSource(out)
    if universal:
        mat.GetSurfaceOutput().ConnectToSource(out)


def test_mdl_source_asset_beside_a_preview_surface_renders_the_preview(tmp_path):
    """The bare ``OmniPBR.mdl`` is no arc (composition never opens it, nor does the renderer): it made the whole scene
    SCENE_INVALID ``bare search-path form ... anchor it with './'``. The material's UsdPreviewSurface renders."""
    b, _ = _floor_scene()
    _add_mdl_shader(b, "/World/Looks/FloorMat", universal=False)
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)


def test_mdl_only_material_is_unsupported_naming_the_mdl(tmp_path):
    from nasset_sdk.errors import SceneError

    b, _ = _floor_scene()
    _add_mdl_shader(b, "/World/Looks/FloorMat", universal=True)
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_UNSUPPORTED" and "info:mdl:sourceAsset OmniPBR.mdl" in str(info.value), str(info.value)


def test_bare_texture_path_that_resolves_nowhere_is_a_missing_texture(tmp_path):
    """``inputs:file = @textures/wood.png@`` (a bare path, as DCCs write) whose file is not there: a missing texture
    (warned, the input's own value), no longer a refusal of the scene."""
    from pxr import Sdf

    b, _ = _floor_scene()
    node = b.texture("FloorMat", {"diffuseColor": "rgb"}, "x.png")
    node.GetInput("file").Set(Sdf.AssetPath("textures/wood.png"))
    with pytest.warns(UserWarning):
        image, said = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)
    assert any("textures/wood.png not found" in m for m in said), said


def test_bare_reference_that_resolves_nowhere_stays_refused(tmp_path):
    """Arcs keep the rule: a bare reference the resolver does not find is SCENE_INVALID before anything composes."""
    from nasset_sdk.errors import SceneError

    b, _ = _floor_scene()
    b.stage.DefinePrim("/World/Set", "Xform").GetReferences().AddReference("sets/kitchen.usd")
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_INVALID" and "bare search-path" in str(info.value)


def test_primvar_reader_fallback_gives_st_where_the_mesh_has_none(tmp_path):
    """``UsdPrimvarReader_float2.inputs:fallback`` is what the reader returns when the mesh lacks the primvar (USD's
    definition); the renderer looked the texture up at (0, 0) instead. Texture: red texel left, blue right; fallback
    st = (0.75, 0.5), the blue texel's centre."""
    from pxr import Gf, Sdf, UsdShade

    from nasset_reference_renderer.film import write_exr

    write_exr(str(tmp_path / "rb.exr"), np.array([[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]], np.float32))
    b, _ = _floor_scene()
    b.texture("FloorMat", {"diffuseColor": "rgb"}, "rb.exr")
    reader = UsdShade.Shader(b.stage.GetPrimAtPath("/World/Looks/FloorMat/st"))
    reader.CreateInput("fallback", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(0.75, 0.5))
    with pytest.warns(UserWarning):
        image, said = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.0, 0.0, 1.0)), rtol=1e-4, atol=1e-5)  # red, green: Fresnel < 1e-5
    assert any("/World/Floor" in m and "fallback (0.75, 0.5)" in m for m in said), said


def test_udim_texture_set_is_warned_as_udim(tmp_path):
    """A ``<UDIM>`` tile set (Houdini, Maya, Substance) was reported as a file of an unsupported format."""
    from pxr import Sdf

    from nasset_reference_renderer.film import write_exr

    write_exr(str(tmp_path / "wood.1001.exr"), np.full((2, 2, 3), 0.5, np.float32))
    b, _ = _floor_scene()
    b.texture("FloorMat", {"diffuseColor": "rgb"}, "x.exr").GetInput("file").Set(Sdf.AssetPath("./wood.<UDIM>.exr"))
    with pytest.warns(UserWarning):
        said = load_scene(b.write(tmp_path / "s.usda")).warnings
    assert any("UDIM texture ./wood.<UDIM>.exr is not read" in m for m in said), said


# -- the render settings' purposes (UsdRender.Settings includedPurposes, materialBindingPurposes) --------------------

def test_material_binding_purposes_of_the_settings_choose_the_binding(tmp_path):
    """Settings that ask for ``preview`` bindings (a quick look-dev render) render the preview material; the renderer
    always read the all-purpose one."""
    from pxr import UsdShade

    b, floor = _floor_scene()
    red = b.material("Red", diffuse=RED, specular=(0, 0, 0))
    UsdShade.MaterialBindingAPI(floor).Bind(red, materialPurpose=UsdShade.Tokens.preview)
    _settings(b, "/Render/Settings").CreateMaterialBindingPurposesAttr(["preview", ""])
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit(RED), rtol=1e-4)


def test_included_purposes_of_the_settings_choose_what_renders(tmp_path):
    """A proxy-purpose quad (albedo 0.5) between the camera and the floor (0.6): left out by default, rendered when
    the settings' ``includedPurposes`` list ``proxy``; the renderer always left proxies out."""
    from pxr import UsdGeom

    def floor_radiance(included):
        b, _ = _floor_scene()
        occluder = b.quad("Occluder", (0, 1, 0), 20.0)
        UsdGeom.Imageable(occluder).CreatePurposeAttr(UsdGeom.Tokens.proxy)
        settings = _settings(b, "/Render/Settings")
        if included:
            settings.CreateIncludedPurposesAttr(included)
        return _render(b, tmp_path, f"s{len(included or [])}.usda")[0]

    np.testing.assert_allclose(floor_radiance(None), _lit((0.6, 0.6, 0.6)), rtol=1e-4)
    np.testing.assert_allclose(floor_radiance(["default", "render", "proxy"]), _lit((0.5, 0.5, 0.5)), rtol=1e-4)


@pytest.mark.parametrize("fallback", [(0.9, 0.2, 0.1, 1.0), (0.9, 0.2, 0.1)])  # float4, or float3 (alpha keeps 1)
def test_unread_texture_gives_its_authored_fallback(tmp_path, fallback):
    """A UsdUVTexture whose file is not there gives its ``inputs:fallback`` (USD's value for a texture that cannot
    be read); the renderer used the connected input's own value (here the diffuse 0.6 grey)."""
    from pxr import Gf, Sdf

    b, _ = _floor_scene()
    node = b.texture("FloorMat", {"diffuseColor": "rgb"}, "gone.png")
    kind = Sdf.ValueTypeNames.Float4 if len(fallback) == 4 else Sdf.ValueTypeNames.Float3
    node.CreateInput("fallback", kind).Set((Gf.Vec4f if len(fallback) == 4 else Gf.Vec3f)(*fallback))
    with pytest.warns(UserWarning):
        image, said = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit(RED), rtol=1e-4)
    assert any("gone.png not found; its inputs:fallback is used" in m for m in said), said


@pytest.mark.parametrize("hide", ["visibility", "purpose"])
def test_hidden_camera_is_still_the_camera(tmp_path, hide):
    """Visibility and purpose hide a camera's gizmo in a viewport (Maya exports hidden camera shapes invisible, rigs
    put cameras under guide groups); rendering through it is unaffected. Such a camera was not found: 'the scene
    has no UsdGeom.Camera'."""
    b, _ = hidden_camera_scene(hide)
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)


def test_display_opacity_of_an_unbound_mesh_is_its_presence(tmp_path):
    """An unbound mesh's ``primvars:displayOpacity`` (usdview draws it translucent) is the presence of the fallback
    surface, as a material's opacity is (spec/renderer.md#cutouts); it rendered opaque. An occluder of opacity 0 over
    the floor leaves the floor's closed form."""
    from pxr import Sdf, UsdGeom, UsdShade

    b, _ = _floor_scene()
    occluder = b.quad("Occluder", (0, 1, 0), 20.0)
    UsdShade.MaterialBindingAPI(occluder.GetPrim()).UnbindAllBindings()
    pv = UsdGeom.PrimvarsAPI(occluder).CreatePrimvar("displayOpacity", Sdf.ValueTypeNames.FloatArray,
                                                     UsdGeom.Tokens.constant)
    pv.Set([0.0])
    image, _ = _render(b, tmp_path)
    np.testing.assert_allclose(image, _lit((0.6, 0.6, 0.6)), rtol=1e-4)


@pytest.mark.parametrize("scale, warned", [(1.0, True), (100.0, False)])
def test_asset_in_other_units_without_the_converting_scale_is_warned(tmp_path, scale, warned):
    """A metre asset (metersPerUnit 1) placed in a centimetre stage (Maya's and Omniverse's metersPerUnit 0.01)
    renders 100 x too small unless its placement scales it by 100; nothing said so."""
    from pxr import UsdGeom

    from nasset_reference_renderer.testscenes import constant_rna_asset

    constant_rna_asset(tmp_path / "ball.usdc")
    b, _ = _floor_scene()
    UsdGeom.SetStageMetersPerUnit(b.stage, 0.01)
    b.asset("Ball", "./ball.usdc", np.diag([scale, scale, scale, 1.0]), typed="Xform")
    scene = load_scene(b.write(tmp_path / "s.usda"))
    assert any("/World/Ball" in m and "metersPerUnit" in m for m in scene.warnings) == warned, scene.warnings
