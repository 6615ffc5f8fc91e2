"""The second implementation reads a stage by the rules of spec/renderer.md (render settings, camera, image size,
prim purposes, visibility, material binding purposes, inherited displayColor, composition errors) as the reference
renderer does: both call nasset_sdk.stage_rules.

The probe is the reference's (tests/renderer/test_usd_stages.py): a diffuse floor seen from above under a delta
DistantLight of irradiance E at angle theta, radiance ``albedo E cos(theta) / pi``."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_renderer.usdscene import read_scene  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402
from nasset_sdk.errors import SceneError  # noqa: E402
from tests.stage_scenes import RED, THETA, E, check_gaussian_pixel_filter, check_settings_max_depth, hidden_camera_scene, product_camera_scene  # noqa: E402, F401  # noqa: E402
from tests.stage_scenes import floor_scene as _floor_scene  # noqa: E402
from tests.stage_scenes import render_settings as _settings  # noqa: E402
from tests.stage_scenes import two_camera_scene as _two_camera_scene  # noqa: E402


def _plain_geometry_layer(path):
    from tests.stage_scenes import plain_geometry_layer

    return plain_geometry_layer(path, untyped=False)


def _kd(desc, prim):
    return [m.material.kd for m in desc.meshes if m.prim == prim]


# -- render settings: camera, settings prim, image size -------------------------------------------------------------

def test_render_settings_camera_is_the_camera_rendered(tmp_path):
    """``RenderSettings.camera`` names the camera; the first camera in traversal was rendered instead."""
    b = _two_camera_scene()
    _settings(b, "/Render/Settings", "/World/Below")
    assert read_scene(b.write(tmp_path / "s.usda")).camera.prim == "/World/Below"


def test_render_product_camera_wins_over_the_settings_camera(tmp_path):
    assert read_scene(product_camera_scene().write(tmp_path / "s.usda")).camera.prim == "/World/Below"


def test_render_settings_prim_path_chooses_the_settings_and_their_size(tmp_path):
    """The stage's ``renderSettingsPrimPath`` names the settings; without --width/--height their resolution is the
    image size (the implementation rendered 256 wide through the first camera)."""
    b = _two_camera_scene()
    _settings(b, "/Render/Preview", "/World/Top", resolution=(4, 4))
    _settings(b, "/Render/Final", "/World/Below", resolution=(6, 3))
    b.stage.SetMetadata("renderSettingsPrimPath", "/Render/Final")
    desc = read_scene(b.write(tmp_path / "s.usda"))
    assert desc.camera.prim == "/World/Below"
    assert desc.camera.resolution(None, None) == (6, 3)
    assert desc.camera.resolution(16, 16) == (16, 16)  # the caller's size wins


def test_inactive_render_settings_are_not_read(tmp_path):
    b, _ = _floor_scene()
    _settings(b, "/Render/Off", resolution=(4, 2)).GetPrim().SetActive(False)
    _settings(b, "/Render/On", resolution=(6, 6))
    assert read_scene(b.write(tmp_path / "s.usda")).camera.resolution(None, None) == (6, 6)


def test_render_settings_camera_that_is_not_a_camera_is_scene_invalid(tmp_path):
    b = _two_camera_scene()
    _settings(b, "/Render/Settings", "/World/Floor")
    with pytest.raises(SceneError) as info:
        read_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_INVALID" and "/World/Floor" in str(info.value) and "/Render/Settings" in str(info.value)


def test_several_cameras_without_settings_are_warned(tmp_path):
    b = _two_camera_scene()
    with pytest.warns(UserWarning, match="2 cameras; rendering through the first, /World/Top"):
        assert read_scene(b.write(tmp_path / "s.usda")).camera.prim == "/World/Top"


@pytest.mark.parametrize("hide", ["visibility", "purpose"])
def test_hidden_camera_is_still_the_camera(tmp_path, hide):
    b, where = hidden_camera_scene(hide)
    assert read_scene(b.write(tmp_path / "s.usda")).camera.prim == where


# -- traversal: visibility and prim purposes --------------------------------------------------------------------------

def test_invisible_prims_are_left_out(tmp_path):
    """An invisible mesh (or one under an invisible Xform) is not rendered; it was."""
    from pxr import UsdGeom

    b, _ = _floor_scene()
    UsdGeom.Imageable(b.quad("Hidden", (0, 1, 0), 20.0)).CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    UsdGeom.Xform.Define(b.stage, "/World/Group").CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    b.mesh("Group/Inner", [(0, 1, 0), (1, 1, 0), (0, 1, 1)], [(0, 1, 2)])
    prims = {m.prim for m in read_scene(b.write(tmp_path / "s.usda")).meshes}
    assert prims == {"/World/Floor"}


@pytest.mark.parametrize("included, rendered", [
    (None, {"/World/Floor", "/World/Render"}),
    (["default", "render", "proxy"], {"/World/Floor", "/World/Render", "/World/Proxy"}),
    (["default"], {"/World/Floor"}),
])
def test_included_purposes_of_the_settings_choose_what_renders(tmp_path, included, rendered):
    """Prims of purpose guide and proxy are left out unless the settings' ``includedPurposes`` list them (fallback
    default, render); every purpose was rendered."""
    from pxr import UsdGeom

    b, _ = _floor_scene()
    for name, purpose in (("Guide", "guide"), ("Proxy", "proxy"), ("Render", "render")):
        UsdGeom.Imageable(b.quad(name, (0, 1, 0), 1.0)).CreatePurposeAttr(purpose)
    settings = _settings(b, "/Render/Settings")
    if included:
        settings.CreateIncludedPurposesAttr(included)
    assert {m.prim for m in read_scene(b.write(tmp_path / "s.usda")).meshes} == rendered


# -- material binding purposes ------------------------------------------------------------------------------------

def test_material_binding_purposes_of_the_settings_choose_the_binding(tmp_path):
    """Settings asking for ``preview`` bindings render the preview material; the full/all-purpose one was read."""
    from pxr import UsdShade

    b, floor = _floor_scene()
    red = b.material("Red", diffuse=RED, specular=(0, 0, 0))
    UsdShade.MaterialBindingAPI(floor).Bind(red, materialPurpose=UsdShade.Tokens.preview)
    _settings(b, "/Render/Settings").CreateMaterialBindingPurposesAttr(["preview", ""])
    np.testing.assert_allclose(_kd(read_scene(b.write(tmp_path / "s.usda")), "/World/Floor")[0], RED)


def test_preview_only_binding_is_warned_by_name(tmp_path):
    from pxr import UsdShade

    b, floor = _floor_scene()
    api = UsdShade.MaterialBindingAPI(floor)
    api.UnbindAllBindings()
    api.Bind(b.material("Red", diffuse=RED), materialPurpose=UsdShade.Tokens.preview)
    with pytest.warns(UserWarning, match="/World/Floor: bound to /World/Looks/Red only for purpose preview"):
        desc = read_scene(b.write(tmp_path / "s.usda"))
    np.testing.assert_allclose(_kd(desc, "/World/Floor")[0], 0.18)


# -- unbound meshes: displayColor, also an ancestor's --------------------------------------------------------------

@pytest.mark.parametrize("on_parent", [False, True])
def test_display_color_of_an_unbound_mesh(tmp_path, on_parent):
    """An unbound mesh's constant ``displayColor`` (its own or an ancestor's) is its diffuse colour; it was 0.18 grey."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    b, floor = _floor_scene()
    UsdShade.MaterialBindingAPI(floor).UnbindAllBindings()
    holder = floor.GetParent() if on_parent else floor
    pv = UsdGeom.PrimvarsAPI(holder).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.constant)
    pv.Set([Gf.Vec3f(*RED)])
    np.testing.assert_allclose(_kd(read_scene(b.write(tmp_path / "s.usda")), "/World/Floor")[0], RED, rtol=1e-6)


# -- composition errors -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("arc", ["reference", "sublayer"])
def test_what_usd_cannot_compose_is_warned_naming_the_prim(tmp_path, arc):
    b, _ = _floor_scene()
    prim = b.stage.DefinePrim("/World/Set", "Xform")
    if arc == "reference":
        prim.GetReferences().AddReference("./missing.usda")
    else:
        b.stage.GetRootLayer().subLayerPaths.append("./missing.usda")
    with pytest.warns(UserWarning, match="cannot reach.*missing.usda"):
        read_scene(b.write(tmp_path / "s.usda"))


# -- end to end: the rendered image agrees with the closed form and the reference renderer -------------------------

def test_settings_camera_purposes_and_display_color_render_as_the_reference(tmp_path):
    """One stage exercising the rules at once: the settings' camera (the second in traversal), an inherited red
    displayColor on the unbound floor, a proxy quad the settings leave out between the camera and the floor."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    from nasset_mitsuba_renderer import render as mitsuba
    from nasset_reference_renderer import RenderSettings, load_scene, render

    b, floor = _floor_scene()
    b.camera((0, -3, 0.01), (0, 0, 0), focal=50, name="Below")
    b.camera((0, 3, 0.01), (0, 0, 0), focal=50, name="Top")
    b.stage.RemovePrim("/World/Camera")
    UsdShade.MaterialBindingAPI(floor).UnbindAllBindings()
    pv = UsdGeom.PrimvarsAPI(floor.GetParent()).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray,
                                                             UsdGeom.Tokens.constant)
    pv.Set([Gf.Vec3f(*RED)])
    UsdGeom.Imageable(b.quad("Occluder", (0, 1, 0), 20.0)).CreatePurposeAttr(UsdGeom.Tokens.proxy)
    _settings(b, "/Render/Settings", "/World/Top", resolution=(8, 6))
    scene = b.write(tmp_path / "s.usda")
    img = mitsuba.render(scene, 2, seed=1)
    ref = render(load_scene(scene), RenderSettings(spp=2)).image
    assert img.shape == ref.shape == (6, 8, 3)
    # red diffuse closed form plus the unbound fallback's GGX lobe (F0 0.04, roughness 0.5), which is grey
    glossy = img - np.asarray(RED) * E * np.cos(THETA) / np.pi
    np.testing.assert_allclose(glossy, np.broadcast_to(glossy[..., :1], glossy.shape), atol=1e-5)
    assert 0.0 < glossy.min() and glossy.max() < 0.1
    # the glossy lobe varies across a pixel, whose 2 jittered samples differ between the renderers
    np.testing.assert_allclose(img, ref, atol=0.02)
    np.testing.assert_allclose(img.mean((0, 1)), ref.mean((0, 1)), atol=2e-3)


# -- payloads and references of plain USD -----------------------------------------------------------------------------

@pytest.mark.parametrize("type_name", ["", "Xform"])
@pytest.mark.parametrize("arc", ["reference", "payload"])
def test_plain_geometry_placed_with_a_payload_renders(tmp_path, arc, type_name):
    """Geometry a scene places with a payload is part of the scene (spec/renderer.md#traversal, every payload loaded);
    the stage was opened with payloads unloaded and the floor left out without a word."""
    _plain_geometry_layer(tmp_path / "geo.usda")
    b, floor = _floor_scene()
    b.stage.RemovePrim(floor.GetPath())
    prim = b.stage.DefinePrim("/World/Set", type_name)
    prim.GetReferences().AddReference("./geo.usda") if arc == "reference" else prim.GetPayloads().AddPayload("./geo.usda")
    desc = read_scene(b.write(tmp_path / "s.usda"))
    np.testing.assert_allclose(_kd(desc, "/World/Set/Floor")[0], 0.6, rtol=1e-6)


def test_untyped_prim_with_a_missing_reference_is_scene_invalid(tmp_path):
    """An untyped prim whose reference USD cannot compose is a NeuralAsset prim whose asset is missing
    (spec/renderer.md#scene-input); it was left out without a word."""
    b, _ = _floor_scene()
    b.stage.DefinePrim("/World/Chair").GetReferences().AddReference("./chair.usdc")
    with pytest.warns(UserWarning), pytest.raises(SceneError) as info:
        read_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_INVALID" and "/World/Chair" in str(info.value) and "chair.usdc" in str(info.value)


def test_asset_placed_with_a_payload_renders_as_with_a_reference(tmp_path):
    from nasset_mitsuba_renderer import render as mitsuba
    from nasset_reference_renderer.testscenes import constant_rna_asset

    asset = str(constant_rna_asset(tmp_path / "const.usda", unshadowed=(1.0, 0.5, 0.25), shadowed=(0.1, 0.2, 0.3)))
    images = []
    for arc in ("reference", "payload"):
        b = SceneBuilder()
        b.camera((0, 0, 3), (0, 0, 0))
        b.distant("Sun", (0, 0, 1), 2.0)
        prim = b.stage.DefinePrim("/World/A", "Xform")
        prim.GetReferences().AddReference(asset) if arc == "reference" else prim.GetPayloads().AddPayload(asset)
        images.append(mitsuba.render(b.write(tmp_path / f"{arc}.usda"), 2, width=16, height=16, seed=1))
    assert images[0].max() > 0
    np.testing.assert_array_equal(images[1], images[0])


# -- custom render settings (spec/renderer.md#render-settings) ------------------------------------------------------

def test_gaussian_pixel_filter_of_the_settings_is_applied(tmp_path):
    """``nasset:pixelFilter = "gaussian"`` spreads an edge as the truncated Gaussian's CDF says (stage_scenes); the box
    filter was used."""
    from nasset_mitsuba_renderer import render as mitsuba

    check_gaussian_pixel_filter(mitsuba.render, tmp_path)


def test_max_depth_of_the_settings_is_the_default(tmp_path):
    """``nasset:maxDepth`` is the bounce limit when the caller gives none (the CLI's --max-depth absent); a caller's
    limit wins. It was ignored (5 bounces)."""
    from nasset_mitsuba_renderer import render as mitsuba

    check_settings_max_depth(mitsuba.render, tmp_path)


def test_geom_subset_of_another_element_type_is_warned(tmp_path):
    """A materialBind GeomSubset of element type point is not a per-face material: ignored, with a warning naming it
    (spec/renderer.md#materials); it was ignored without a word."""
    from pxr import UsdShade

    b, floor = _floor_scene()
    subset = UsdShade.MaterialBindingAPI(floor).CreateMaterialBindSubset("Points", [0], "point")
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(b.material("Red", diffuse=RED))
    with pytest.warns(UserWarning, match="/World/Floor/Points: GeomSubset of an element type other than face ignored"):
        desc = read_scene(b.write(tmp_path / "s.usda"))
    np.testing.assert_allclose(_kd(desc, "/World/Floor")[0], 0.6, rtol=1e-6)


@pytest.mark.parametrize("scale, warned", [(1.0, True), (100.0, False)])
def test_asset_in_other_units_without_the_converting_scale_is_warned(tmp_path, scale, warned):
    """A metre asset placed in a centimetre stage without the scale 100 renders 100 x too small: said, naming the
    prim (spec/renderer.md#traversal); it was not."""
    import warnings

    from pxr import UsdGeom

    from nasset_reference_renderer.testscenes import constant_rna_asset

    constant_rna_asset(tmp_path / "ball.usdc")
    b, _ = _floor_scene()
    UsdGeom.SetStageMetersPerUnit(b.stage, 0.01)
    b.asset("Ball", "./ball.usdc", np.diag([scale, scale, scale, 1.0]), typed="Xform")
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        read_scene(b.write(tmp_path / "s.usda"))
    hit = [str(w.message) for w in said if "/World/Ball" in str(w.message) and "metersPerUnit" in str(w.message)]
    assert bool(hit) == warned, [str(w.message) for w in said]


# -- light features this implementation does not render are warned by name ------------------------------------------

@pytest.mark.parametrize("feature", ["shaping", "filters"])
def test_unrendered_light_features_are_warned_by_name(tmp_path, feature):
    """Light filters are read by the reference renderer and not rendered here; a spot cone on a light that is not a
    sphere or point light (a RectLight) is ignored (spec/renderer.md#spot-lights). Both were said by name. (Spot cones on
    point lights and spheres, and lights hidden from camera rays, are rendered: test_mitsuba_impl.py and
    test_floor_under_a_sphere_spot_matches_the_quadrature.)"""
    from pxr import UsdLux

    b, _ = _floor_scene()
    if feature == "shaping":
        bulb = UsdLux.RectLight.Define(b.stage, "/World/Bulb").GetPrim()
    else:
        bulb = b.sphere_light("Bulb", (0, 2, 0), 0.0, 5.0).GetPrim()
    if feature == "shaping":
        UsdLux.ShapingAPI.Apply(bulb).CreateShapingConeAngleAttr(30.0)
        expect = "/World/Bulb: UsdLux.ShapingAPI ignored"
    else:
        UsdLux.LightFilter.Define(b.stage, "/World/Barn")
        UsdLux.LightAPI(bulb).GetFiltersRel().SetTargets(["/World/Barn"])
        expect = "/World/Bulb: light:filters /World/Barn ignored"
    with pytest.warns(UserWarning, match=expect):
        read_scene(b.write(tmp_path / "s.usda"))


# -- shader inputs connected to a material's interface ----------------------------------------------------------------

def test_input_connected_to_the_material_interface_reads_its_value(tmp_path):
    """``inputs:diffuseColor.connect = </Mat.inputs:baseColor>`` (Houdini, Omniverse and USD's own UsdPreviewSurface
    example expose inputs on the material) is the interface input's value; it was read as a texture: default 0.18
    grey, warned as an ignored texture."""
    from pxr import Sdf, UsdShade

    b, floor = _floor_scene()
    mat = UsdShade.Material.Define(b.stage, "/World/Looks/Exposed")
    shader = UsdShade.Shader.Define(b.stage, "/World/Looks/Exposed/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    base = mat.CreateInput("baseColor", Sdf.ValueTypeNames.Color3f)
    base.Set(RED)
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(base)
    UsdShade.MaterialBindingAPI(floor).Bind(mat)
    np.testing.assert_allclose(_kd(read_scene(b.write(tmp_path / "s.usda")), "/World/Floor")[0], RED, rtol=1e-6)


# -- surface shaders and input values (spec/renderer.md#limits) ------------------------------------------------------

def _material_with(b, floor, output: str, shader_id: str, **inputs):
    from pxr import Sdf, UsdShade

    mat = UsdShade.Material.Define(b.stage, "/World/Looks/Probe")
    if shader_id:
        shader = UsdShade.Shader.Define(b.stage, "/World/Looks/Probe/Surface")
        shader.CreateIdAttr(shader_id)
        for name, value in inputs.items():
            kind = Sdf.ValueTypeNames.Color3f if isinstance(value, tuple) else Sdf.ValueTypeNames.Float
            shader.CreateInput(name, kind).Set(value)
        out = mat.CreateSurfaceOutput("mtlx") if output == "mtlx" else mat.CreateSurfaceOutput()
        out.ConnectToSource(shader.ConnectableAPI(), "out" if output == "mtlx" else "surface")
    UsdShade.MaterialBindingAPI(floor).Bind(mat)


def test_materialx_preview_surface_on_the_mtlx_output_is_read(tmp_path):
    """``outputs:mtlx:surface`` with ``ND_UsdPreviewSurface_surfaceshader`` (MaterialX's UsdPreviewSurface) is read
    as the UsdPreviewSurface; the material was taken to have no surface (0.18 grey, a warning)."""
    b, floor = _floor_scene()
    _material_with(b, floor, "mtlx", "ND_UsdPreviewSurface_surfaceshader", diffuseColor=RED)
    np.testing.assert_allclose(_kd(read_scene(b.write(tmp_path / "s.usda")), "/World/Floor")[0], RED, rtol=1e-6)


def test_material_without_a_surface_shader_is_unsupported(tmp_path):
    b, floor = _floor_scene()
    _material_with(b, floor, "", "")
    with pytest.raises(SceneError) as info:
        read_scene(b.write(tmp_path / "s.usda"))
    assert info.value.code == "SCENE_UNSUPPORTED" and "/World/Looks/Probe" in str(info.value)


@pytest.mark.parametrize("value, expect", [(2.5, 1.0), (-1.0, 0.0), (float("nan"), None)])
def test_preview_surface_inputs_are_clamped_or_invalid(tmp_path, value, expect):
    """diffuseColor outside [0, 1] is clamped, a NaN is SCENE_INVALID naming the input; it was used as authored."""
    b, floor = _floor_scene()
    _material_with(b, floor, "", "UsdPreviewSurface", diffuseColor=(value, value, value))
    scene = b.write(tmp_path / "s.usda")
    if expect is None:
        with pytest.raises(SceneError) as info:
            read_scene(scene)
        assert info.value.code == "SCENE_INVALID" and "inputs:diffuseColor" in str(info.value)
    else:
        np.testing.assert_allclose(_kd(read_scene(scene), "/World/Floor")[0], expect)


def test_connected_input_uses_its_own_authored_value(tmp_path):
    """A diffuseColor fed by a texture that cannot be read (no such file) keeps the input's own authored value
    (spec/renderer.md#textures), with a warning; the 0.18 fallback was used. An input fed by an output this reader does
    not read (a texture on specularColor) does the same."""
    b, _ = _floor_scene()
    b.texture("FloorMat", {"diffuseColor": "rgb", "specularColor": "rgb"}, "wood.png")
    with pytest.warns(UserWarning, match="wood.png is not found") as seen:
        desc = read_scene(b.write(tmp_path / "s.usda"))
    assert any("inputs:specularColor is connected" in str(w.message) for w in seen)
    np.testing.assert_allclose(_kd(desc, "/World/Floor")[0], 0.6, rtol=1e-6)
    assert desc.meshes[0].material.per_hit is None


def test_textures_are_read_and_warned_as_not_rendered_here(tmp_path):
    """A readable texture is read onto the material and its texture coordinates onto the mesh (the Mitsuba plugin renders
    them, tests/mitsuba_plugin/test_textures.py); this implementation renders the input's own value and says so."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import textured_scene

    scene = textured_scene(tmp_path, "repeat")
    mesh = next(m for m in read_scene(scene).meshes if m.prim == "/World/Quad")
    tex = mesh.material.per_hit.textures["diffuseColor"]
    assert tex.image.shape == (16, 24, 3) and tex.wrap == ("repeat", "repeat") and mesh.corner_st.shape == (len(mesh.faces), 3, 2)
    with pytest.warns(UserWarning, match="textures and primvar colours are not rendered by this implementation"):
        mitsuba.render(scene, 1, width=8, height=8)


@pytest.mark.parametrize("feature", ["one-sided", "back material", "bad back material"])
def test_sidedness_is_read(tmp_path, feature):
    """spec/renderer.md#sidedness: a one-sided mesh and a back material are read onto the mesh, without a warning (they
    were warned as not rendered); a back material target that is not a Material is SCENE_INVALID naming it."""
    import warnings

    from pxr import UsdGeom

    b, floor = _floor_scene()
    if feature == "one-sided":
        UsdGeom.Mesh(floor).CreateDoubleSidedAttr(False)
    elif feature == "back material":
        floor.CreateRelationship("nasset:backMaterial").SetTargets([b.material("Back", diffuse=(0.1, 0.9, 0.2)).GetPath()])
    else:
        floor.CreateRelationship("nasset:backMaterial").SetTargets(["/World/Floor"])
    scene = b.write(tmp_path / "s.usda")
    if feature == "bad back material":
        with pytest.raises(SceneError) as info:
            read_scene(scene)
        assert info.value.code == "SCENE_INVALID" and "nasset:backMaterial" in str(info.value)
        return
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        desc = read_scene(scene)
    mesh = next(m for m in desc.meshes if m.prim == "/World/Floor")
    assert mesh.one_sided == (feature == "one-sided")
    if feature == "back material":
        np.testing.assert_allclose(mesh.back_material.kd, (0.1, 0.9, 0.2), rtol=1e-6)


def test_authored_normals_shade_the_surface(tmp_path):
    """Shading normals (spec/renderer.md#shading-normals) on a floor lit by a sun: tilted, zero and leftHanded cases.
    A leftHanded prim's normals were flipped against its front and shaded faceted."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import check_shading_normals

    check_shading_normals(mitsuba.render, tmp_path)


def test_a_subdivision_cage_shades_smooth(tmp_path):
    """A mesh of the schema's fallback scheme (catmullClark) without normals shades with its cage's smooth normals, as
    the reference renderer does; it was faceted."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import check_cage_normals

    check_cage_normals(mitsuba.render, tmp_path)


def test_implicit_prims_and_curves_render(tmp_path):
    """Implicit prims, BasisCurves and Points are tessellated by the SDK's rules (nasset_sdk.implicit, nasset_sdk.curves)
    and render as the reference renderer renders them; they were SCENE_UNSUPPORTED."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import check_implicit_prims_and_curves

    check_implicit_prims_and_curves(mitsuba.render, tmp_path, spp=64)


def test_singular_transforms_flatten_or_collapse_geometry(tmp_path):
    """Zero scales (tests/stage_scenes.py::check_singular_transforms): the reader raised numpy's LinAlgError."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import check_singular_transforms

    check_singular_transforms(mitsuba.render, tmp_path, spp=64)


def test_materialx_surfaces_are_read_as_preview_surface_values(tmp_path):
    """A MaterialX standard_surface or open_pbr_surface (spec/renderer.md#materials) is read as the reference renderer
    reads it: kd = base x base_color x (1 - metalness), F0 = (1 - m) ((1 - ior) / (1 + ior))^2 + m c, alpha =
    roughness^2, emission x colour; a coat that is on is warned about. Both Mitsuba implementations refused them
    (SCENE_UNSUPPORTED), so a scene from a MaterialX pipeline did not load."""
    from pxr import Gf, Sdf, UsdShade

    for sid, names in (("ND_standard_surface_surfaceshader", ("base", "base_color", "metalness", "specular_roughness",
                                                              "specular_IOR", "emission", "emission_color", "coat")),
                       ("ND_open_pbr_surface_surfaceshader", ("base_weight", "base_color", "base_metalness",
                                                              "specular_roughness", "specular_ior", "emission_luminance",
                                                              "emission_color", "coat_weight"))):
        b, floor = _floor_scene()
        mat = UsdShade.Material.Define(b.stage, "/World/Looks/X")
        sh = UsdShade.Shader.Define(b.stage, "/World/Looks/X/Surface")
        sh.CreateIdAttr(sid)
        f, c3 = Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Color3f
        for name, kind, value in zip(names, (f, c3, f, f, f, f, c3, f),
                                     (0.8, Gf.Vec3f(0.5, 0.25, 1.0), 0.25, 0.6, 1.8, 2.0, Gf.Vec3f(0.1, 0.2, 0.3), 1.0), strict=True):
            sh.CreateInput(name, kind).Set(value)
        mat.CreateOutput("mtlx:surface", Sdf.ValueTypeNames.Token).ConnectToSource(sh.ConnectableAPI(), "out")
        UsdShade.MaterialBindingAPI(floor).Bind(mat)
        with pytest.warns(UserWarning, match="dropped"):
            m = read_scene(b.write(tmp_path / f"{sid}.usda")).meshes[0].material
        c = 0.8 * np.array([0.5, 0.25, 1.0])
        r0 = ((1 - 1.8) / (1 + 1.8)) ** 2
        np.testing.assert_allclose(m.kd, c * 0.75, rtol=1e-6)
        np.testing.assert_allclose(m.f0, 0.75 * r0 + 0.25 * c, rtol=1e-6)
        np.testing.assert_allclose([m.alpha], [0.36], rtol=1e-6)
        np.testing.assert_allclose(m.emission, [0.2, 0.4, 0.6], rtol=1e-6)


def test_dome_texture_inside_a_usdz_package_is_read(tmp_path):
    """A dome's OpenEXR inside a usdz (``scene.usdz[sky.exr]``) is read through USD's resolver, the same pixels as the loose
    file, which is deleted first. Before, the Mitsuba implementations refused it (SCENE_INVALID: does not exist)."""
    from pxr import Sdf, UsdUtils

    from nasset_sdk.images import write_exr

    sky = np.random.default_rng(0).random((8, 16, 3)).astype(np.float32)
    write_exr(tmp_path / "sky.exr", sky)
    b, _ = _floor_scene()
    b.dome("Dome", 1.0, texture="./sky.exr")
    loose = b.write(tmp_path / "scene.usda")
    package = tmp_path / "scene.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(loose)), str(package))
    (tmp_path / "sky.exr").unlink()
    dome = next(lt for lt in read_scene(str(package)).lights if lt.prim == "/World/Dome")
    np.testing.assert_array_equal(dome.texture, sky)


def test_dome_light_1_pole_axis_turns_the_texture(tmp_path):
    """DomeLight_1 (USD 24) with poleAxis Z turns the texture's top pole (+Y) onto +Z (spec/renderer.md#lights); with Y,
    or scene on a Y-up stage, it is a DomeLight. Both Mitsuba implementations refused DomeLight_1. A RectLight's
    texture:file is ignored with a warning, as in the reference renderer (it was SCENE_UNSUPPORTED)."""
    from pxr import Sdf, UsdLux

    def light(pole):
        b, _ = _floor_scene()
        d = UsdLux.DomeLight_1.Define(b.stage, "/World/Dome")
        if pole is not None:
            d.GetPrim().CreateAttribute("poleAxis", Sdf.ValueTypeNames.Token).Set(pole)
        return next(lt for lt in read_scene(b.write(tmp_path / f"d_{pole}.usda")).lights if lt.prim == "/World/Dome")

    turned = light("Z")
    assert turned.type == "DomeLight"
    up = np.array([0.0, 1.0, 0.0]) @ turned.to_world[:3, :3]  # the texture's +Y pole in the world (row vectors)
    np.testing.assert_allclose(up, [0.0, 0.0, 1.0], atol=1e-12)
    for pole in ("Y", "scene", None):
        np.testing.assert_allclose(light(pole).to_world[:3, :3], np.eye(3), atol=1e-12)
    b, _ = _floor_scene()
    r = b.rect_light("Panel", (0, 2, 0), 1.0, 1.0, (0, -1, 0), 2.0)
    r.GetPrim().CreateAttribute("inputs:texture:file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("./t.exr"))
    with pytest.warns(UserWarning, match="texture:file is ignored"):
        assert any(lt.type == "RectLight" for lt in read_scene(b.write(tmp_path / "rect.usda")).lights)


def test_light_surfaces_occlude_nothing(tmp_path):
    """A ray goes on past every light surface it meets (spec/renderer.md#light-surfaces); this implementation's rays
    ended on the first one, so a faint area light between a dome and a floor darkened the floor under it to 48 %."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.stage_scenes import check_light_surfaces_occlude_nothing

    check_light_surfaces_occlude_nothing(mitsuba.render, tmp_path, spp=32)


def _bad_world(tmp_path, what):
    """(scene, the prim the error must name) of a scene with one bad value (test below)."""
    from pxr import Gf, Sdf, UsdGeom

    b, _ = _floor_scene()
    if what == "nan points":
        b.mesh("Bad", [(0, 0, 0), (float("nan"), 0, 0), (0, 1, 0)], [[0, 1, 2]], diffuse=(0.5, 0.5, 0.5))
    elif what == "huge points":
        b.mesh("Bad", [(0, 0, 0), (1e30, 0, 0), (0, 1, 0)], [[0, 1, 2]], diffuse=(0.5, 0.5, 0.5))
    elif what == "nan transform":
        UsdGeom.Xformable(UsdGeom.Cube.Define(b.stage, "/World/Bad")).AddTranslateOp().Set(Gf.Vec3d(float("nan"), 0, 0))
    elif what == "huge transform":
        UsdGeom.Xformable(UsdGeom.Cube.Define(b.stage, "/World/Bad")).AddScaleOp().Set(Gf.Vec3f(1e16, 1, 1))
    elif what == "nan light transform":
        light = b.rect_light("Bad", (0, 2, 0), 1.0, 1.0, (0, -1, 0), 2.0)
        UsdGeom.Xformable(light).AddTranslateOp(opSuffix="nan").Set(Gf.Vec3d(0, float("inf"), 0))
    elif what.startswith("light "):  # "light <attribute> <value>" on a sphere light
        _, name, value = what.split(" ")
        b.sphere_light("Bad", (0, 2, 0), 0.3, 2.0).GetPrim().GetAttribute(name).Set(
            Gf.Vec3f(float(value), 1.0, 1.0) if name == "inputs:color" else float(value))
    elif what.startswith("cylinder ") or what.startswith("disk "):
        from pxr import UsdLux

        light = (UsdLux.CylinderLight if what.startswith("cylinder") else UsdLux.DiskLight).Define(b.stage, "/World/Bad")
        light.GetPrim().CreateAttribute(what.split(" ")[1], Sdf.ValueTypeNames.Float).Set(-1.0)
    elif what == "ior -1, specular workflow":
        b.mesh("Bad", [(0, 0, 0), (1, 0, 0), (0, 1, 0)], [[0, 1, 2]], diffuse=(0.5, 0.5, 0.5))
        shader = next(p for p in b.stage.Traverse() if p.GetTypeName() == "Shader" and "Bad" in str(p.GetPath()))
        shader.CreateAttribute("inputs:useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
        shader.CreateAttribute("inputs:ior", Sdf.ValueTypeNames.Float).Set(-1.0)
        return b.write(tmp_path / "bad.usda"), str(shader.GetPath())
    elif what == "subset outside the mesh":
        from pxr import UsdShade

        binding = UsdShade.MaterialBindingAPI.Apply(b.stage.GetPrimAtPath("/World/Floor"))
        subset = binding.CreateMaterialBindSubset("Bad", [0, 7], UsdGeom.Tokens.face)
        return b.write(tmp_path / "bad.usda"), str(subset.GetPath())
    elif what == "dome texture missing":
        from pxr import UsdLux

        UsdLux.DomeLight.Define(b.stage, "/World/Bad").CreateTextureFileAttr("./nope.exr")
    elif what.startswith("camera "):
        b.stage.GetPrimAtPath("/World/Camera").GetAttribute(what.split(" ")[1]).Set(0.0)
        return b.write(tmp_path / "bad.usda"), "/World/Camera"
    return b.write(tmp_path / "bad.usda"), "/World/Bad"


@pytest.mark.parametrize("what, attribute", [
    ("nan points", "points"), ("huge points", "xformOpOrder"), ("nan transform", "xformOpOrder"),
    ("huge transform", "xformOpOrder"), ("nan light transform", "xformOpOrder"),
    ("light inputs:intensity -2", "inputs:intensity"), ("light inputs:color nan", "inputs:intensity"),
    ("light inputs:exposure 2000", "inputs:exposure"), ("light inputs:radius -1", "inputs:radius"),
    ("cylinder inputs:length", "inputs:radius"), ("disk inputs:radius", "inputs:radius"),
    ("ior -1, specular workflow", "inputs:ior"), ("camera focalLength", "focalLength"),
    ("camera horizontalAperture", "horizontalAperture"), ("subset outside the mesh", "indices"),
    ("dome texture missing", "inputs:texture:file")])
def test_bad_values_are_refused_as_the_reference_renderer_refuses_them(tmp_path, what, attribute):
    """spec/renderer.md#limits and #materials: SCENE_INVALID naming the prim and attribute, from the Mitsuba reader and
    the reference renderer alike (16 scenes). Before, the Mitsuba reader passed on NaN geometry and transforms (the second
    implementation rendered them silently, the plugin failed in Mitsuba's parser without naming the prim), negative or
    NaN light values (a NaN image), an exposure of 2000 (OverflowError), and named no camera attribute; the reference
    renderer divided by zero on ior = -1 in the specular workflow (the spec refuses ior <= 0 in either)."""
    from nasset_reference_renderer import load_scene

    scene, prim = _bad_world(tmp_path, what)
    with pytest.raises(SceneError) as ref:
        load_scene(scene)
    with pytest.raises(SceneError) as ours:
        read_scene(scene)
    assert ref.value.code == ours.value.code == "SCENE_INVALID"
    assert ours.value.prim == ref.value.prim == prim and ours.value.attribute == ref.value.attribute == attribute, \
        (str(ours.value), str(ref.value))


@pytest.mark.parametrize("authored, said", [
    ({"inputs:diffuse": 0.0}, "inputs:diffuse = 0.0"),
    ({"inputs:specular": 2.5, "inputs:diffuse": 1.0}, "inputs:specular = 2.5"),
    ({"inputs:shadow:enable": False}, "inputs:shadow:enable = False"),
    ({"inputs:diffuse": 1.0, "inputs:specular": 1.0, "inputs:shadow:enable": True}, None),
])
def test_light_inputs_no_renderer_honours_are_warned_alike(tmp_path, authored, said):
    """spec/renderer.md#lights: a diffuse / specular multiplier other than 1 or shadows turned off is not rendered and is
    warned by both readers, naming the light and the input (the reference renderer accepted diffuse and specular
    silently, and the Mitsuba reader all three); neutral values say nothing."""
    import warnings

    from pxr import Sdf

    from nasset_reference_renderer import load_scene

    b, _ = _floor_scene()
    sun = b.stage.GetPrimAtPath("/World/Sun")
    for name, value in authored.items():
        kind = Sdf.ValueTypeNames.Bool if isinstance(value, bool) else Sdf.ValueTypeNames.Float
        sun.CreateAttribute(name, kind).Set(value)
    scene = b.write(tmp_path / "lights.usda")
    for read in (load_scene, read_scene):
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            read(scene)
        messages = [str(w.message) for w in caught if "not rendered" in str(w.message)]
        if said is None:
            assert messages == [], (read, messages)
        else:
            assert len(messages) == 1 and said in messages[0] and "/World/Sun" in messages[0], (read, messages)


@pytest.mark.parametrize("light", ["rect", "disk"])
def test_floor_beside_a_spread_light_matches_the_quadrature(tmp_path, light):
    """nasset:spread (spec/renderer.md#lights) in the second implementation: the floor 0.3 beside the centre of a light
    of spread 70 deg reads kd / pi times the quadrature of Cycles' profile (4x what a Lambertian light gives there);
    the same stage as the reference renderer's test. Two seeds bound the noise."""
    import math

    from nasset_mitsuba_renderer import render as mitsuba
    from tests.renderer.test_light_spread import spread_stage

    path, expect = spread_stage(tmp_path / "s.usda", math.radians(70), light)
    a, b = (mitsuba.render(path, 256, width=4, height=4, max_depth=2, seed=s).mean() for s in (1, 2))
    assert abs(0.5 * (a + b) - expect) < 3 * abs(a - b) + 0.02 * expect, (a, b, expect)


@pytest.mark.parametrize("x", [0.0, 0.7])
def test_floor_under_a_sphere_spot_matches_the_quadrature(tmp_path, x):
    """A spot with a radius (spec/renderer.md#spot-lights) in the second implementation: the floor under its centre and
    near its cone's edge reads kd / pi times the quadrature of the shaped sphere, as in the reference renderer's test."""
    from nasset_mitsuba_renderer import render as mitsuba
    from tests.renderer.test_sphere_spot import sphere_spot_stage

    path, expect = sphere_spot_stage(tmp_path / "s.usda", x)
    a, b = (mitsuba.render(path, 256, width=4, height=4, max_depth=2, seed=s).mean() for s in (1, 2))
    assert abs(0.5 * (a + b) - expect) < 3 * abs(a - b) + 0.02 * expect, (a, b, expect)
