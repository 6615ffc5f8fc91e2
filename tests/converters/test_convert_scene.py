"""``nasset convert-scene``: Mitsuba 3 scene -> USD stage (spec/bake.md#scene-conversion).

Each convertible element lands in USD with the values Mitsuba loaded; unsupported ones are
warnings; ``--replace`` writes a NeuralAsset reference with a relative path; failures are typed;
and the reference renderer's image of a converted scene matches Mitsuba's own render.
"""

from __future__ import annotations

import json
import math
import warnings
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_converters.mitsuba.usd_export import convert_scene, fresnel_dielectric, plastic_diffuse_scale  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402

ALL_XML = """<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="6"/></integrator>
<sensor type="perspective" id="cam"><float name="fov" value="40"/>
  <transform name="to_world"><lookat origin="1, 2, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="64"/><integer name="height" value="32"/><rfilter type="box"/></film></sensor>
<bsdf type="roughplastic" id="rp"><rgb name="diffuse_reflectance" value="0.7, 0.3, 0.1"/><float name="alpha" value="0.25"/>
  <string name="distribution" value="ggx"/></bsdf>
<shape type="ply" id="box"><string name="filename" value="box.ply"/><ref id="rp"/>
  <transform name="to_world"><translate x="5"/></transform></shape>
<shape type="obj" id="tri"><string name="filename" value="tri.obj"/>
  <bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="env.exr"/></texture></bsdf></shape>
<shape type="rectangle" id="floor"><transform name="to_world"><scale value="2"/><rotate x="1" angle="-90"/></transform>
  <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.4, 0.6"/></bsdf></shape>
<shape type="sphere" id="ball"><point name="center" x="1" y="0.5" z="0"/><float name="radius" value="0.5"/>
  <bsdf type="roughconductor"><string name="material" value="Au"/><float name="alpha" value="0.09"/></bsdf></shape>
<shape type="cube" id="cube"><transform name="to_world"><scale value="0.25"/><translate y="3"/></transform>
  <bsdf type="principled"><rgb name="base_color" value="0.5, 0.2, 0.1"/><float name="roughness" value="0.3"/>
  <float name="metallic" value="0.2"/></bsdf></shape>
<shape type="disk" id="disk"><bsdf type="conductor"/></shape>
<shape type="cylinder" id="cyl"><bsdf type="diffuse"/></shape>
<shape type="sphere" id="glass"><float name="radius" value="0.1"/><bsdf type="dielectric"/>
  <medium type="homogeneous" name="interior"><float name="sigma_t" value="2"/></medium></shape>
<shape type="sphere" id="bulb"><point name="center" x="0" y="4" z="0"/><float name="radius" value="0.2"/>
  <emitter type="area"><rgb name="radiance" value="5, 5, 4"/></emitter></shape>
<shape type="rectangle" id="panel"><transform name="to_world"><rotate x="1" angle="90"/><translate y="5"/></transform>
  <emitter type="area"><rgb name="radiance" value="2, 2, 2"/></emitter></shape>
<emitter type="point" id="pt"><point name="position" x="1" y="2" z="3"/><rgb name="intensity" value="10, 8, 6"/></emitter>
<emitter type="spot" id="spot"><transform name="to_world"><lookat origin="0, 3, 0" target="0, 0, 0" up="0, 0, 1"/></transform>
  <rgb name="intensity" value="10, 10, 10"/><float name="cutoff_angle" value="30"/></emitter>
<emitter type="directional" id="sun"><vector name="direction" value="0, -1, -1"/><rgb name="irradiance" value="3, 2, 1"/></emitter>
<emitter type="envmap" id="env"><string name="filename" value="env.exr"/><float name="scale" value="2"/></emitter>
</scene>"""


def _env_image(h=8, w=16):
    img = np.zeros((h, w, 3), np.float32)
    img[:, : w // 2, 0] = 1.0
    img[: h // 2, :, 1] = 2.0
    img[..., 2] = np.linspace(0.1, 0.9, w)[None]
    return img


def _write_assets(folder: Path) -> None:
    import trimesh

    from nasset_reference_renderer.film import write_exr

    trimesh.creation.box().export(folder / "box.ply")
    (folder / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    write_exr(folder / "env.exr", _env_image())


@pytest.fixture(scope="module")
def converted(tmp_path_factory):
    from pxr import Usd

    d = tmp_path_factory.mktemp("convert")
    _write_assets(d)
    (d / "all.xml").write_text(ALL_XML)
    res = convert_scene(d / "all.xml", d / "out" / "all.usda")
    return res, Usd.Stage.Open(str(res.output)), d


def _xf(stage, path):
    from pxr import Usd, UsdGeom

    return np.array(UsdGeom.Xformable(stage.GetPrimAtPath(path)).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))


def _shader_inputs(stage, mat_path):
    from pxr import UsdShade

    sh = UsdShade.Shader(stage.GetPrimAtPath(mat_path + "/PreviewSurface"))
    return {i.GetBaseName(): i.Get() for i in sh.GetInputs()}


def _bound(stage, prim_path):
    from pxr import UsdShade

    mat, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(prim_path)).ComputeBoundMaterial()
    return str(mat.GetPath())


def test_stage_metadata_and_usd_validators(converted):
    from pxr import UsdGeom

    res, stage, _ = converted
    assert stage.GetDefaultPrim().GetPath() == "/World"
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.y
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert [c for c in res.usd_checks if c["severity"] == "error"] == []
    assert res.resolution == (64, 32)


def test_camera(converted):
    from pxr import UsdGeom, UsdRender

    _, stage, _ = converted
    cam = UsdGeom.Camera(stage.GetPrimAtPath("/World/cam"))
    fl, ha, va = cam.GetFocalLengthAttr().Get(), cam.GetHorizontalApertureAttr().Get(), cam.GetVerticalApertureAttr().Get()
    assert math.degrees(2 * math.atan(ha / (2 * fl))) == pytest.approx(40.0, abs=1e-3)  # fov_axis x (default)
    assert va / ha == pytest.approx(32 / 64)
    m = _xf(stage, "/World/cam")
    np.testing.assert_allclose(m[3, :3], [1, 2, 3], atol=1e-5)
    fwd = -m[2, :3] / np.linalg.norm(m[2, :3])  # USD camera looks down -Z
    np.testing.assert_allclose(fwd, -np.array([1, 2, 3]) / math.sqrt(14), atol=1e-5)
    right = m[0, :3]
    expect = np.cross(fwd, [0, 1, 0])
    assert right @ expect / np.linalg.norm(expect) > 0.999  # image right = forward x up, not mirrored
    settings = UsdRender.Settings(stage.GetPrimAtPath("/Render/Settings"))
    assert tuple(settings.GetResolutionAttr().Get()) == (64, 32)
    # the integrator's depth where the renderer reads it: Mitsuba max_depth 6 counts segments, the renderer vertices
    assert settings.GetPrim().GetAttribute("nasset:maxDepth").Get() == 5
    assert settings.GetPrim().GetAttribute("nasset:pixelFilter").Get() == "box"


@pytest.mark.parametrize("integrator, rfilter, depth, filt", [
    ('<integrator type="path"><integer name="max_depth" value="-1"/></integrator>', "", -1, ("gaussian", 0.5)),
    ('<integrator type="path"/>', '<rfilter type="gaussian"><float name="stddev" value="0.7"/></rfilter>', -1,
     ("gaussian", 0.7)),
    ('<integrator type="path"><integer name="max_depth" value="3"/></integrator>', '<rfilter type="box"/>', 2, ("box", None)),
])
def test_render_settings_carry_depth_and_filter(tmp_path, integrator, rfilter, depth, filt):
    from pxr import Usd

    from nasset_reference_renderer import load_scene
    from nasset_reference_renderer.integrator import MAX_DEPTH, RenderSettings, resolve_settings

    xml = tmp_path / "s.xml"
    xml.write_text(f"""<scene version="3.0.0">{integrator}<sensor type="perspective"><film type="hdrfilm">
        <integer name="width" value="8"/><integer name="height" value="8"/>{rfilter}</film></sensor>
        <shape type="sphere"/><emitter type="constant"/></scene>""")
    res = convert_scene(xml, tmp_path / "s.usda", check_usd=False)
    stage = Usd.Stage.Open(str(res.output))
    prim = stage.GetPrimAtPath("/Render/Settings")
    assert prim.GetAttribute("nasset:maxDepth").Get() == depth
    assert (prim.GetAttribute("nasset:pixelFilter").Get(), prim.GetAttribute("nasset:pixelFilterStddev").Get()) == \
        (filt[0], pytest.approx(filt[1]) if filt[1] else None)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(str(res.output))
    assert resolve_settings(RenderSettings(), scene).max_depth == (MAX_DEPTH if depth < 0 else depth)
    assert resolve_settings(RenderSettings(max_depth=7), scene).max_depth == 7  # an explicit depth wins


def test_lights(converted):
    from pxr import UsdLux

    _, stage, _ = converted

    def radiance(path):
        api = UsdLux.LightAPI(stage.GetPrimAtPath(path))
        return np.array(api.GetColorAttr().Get()) * api.GetIntensityAttr().Get() * 2.0 ** api.GetExposureAttr().Get()

    sun = UsdLux.DistantLight(stage.GetPrimAtPath("/World/Lights/sun"))
    assert sun.GetAngleAttr().Get() == 0.0
    np.testing.assert_allclose(radiance("/World/Lights/sun"), [3, 2, 1], rtol=1e-6)
    np.testing.assert_allclose(_xf(stage, "/World/Lights/sun")[2, :3], np.array([0, 1, 1]) / math.sqrt(2), atol=1e-6)

    pt = UsdLux.SphereLight(stage.GetPrimAtPath("/World/Lights/pt"))
    assert pt.GetRadiusAttr().Get() == 0.0 and pt.GetTreatAsPointAttr().Get()
    np.testing.assert_allclose(radiance("/World/Lights/pt"), [10, 8, 6], rtol=1e-6)
    np.testing.assert_allclose(_xf(stage, "/World/Lights/pt")[3, :3], [1, 2, 3], atol=1e-6)

    spot = stage.GetPrimAtPath("/World/Lights/spot")
    assert UsdLux.ShapingAPI(spot).GetShapingConeAngleAttr().Get() == pytest.approx(30.0)
    np.testing.assert_allclose(-_xf(stage, "/World/Lights/spot")[2, :3], [0, -1, 0], atol=1e-6)  # emits along -Z

    bulb = UsdLux.SphereLight(stage.GetPrimAtPath("/World/Lights/bulb"))
    assert bulb.GetRadiusAttr().Get() == pytest.approx(0.2)
    np.testing.assert_allclose(_xf(stage, "/World/Lights/bulb")[3, :3], [0, 4, 0], atol=1e-6)
    np.testing.assert_allclose(radiance("/World/Lights/bulb"), [5, 5, 4], rtol=1e-6)

    panel = UsdLux.RectLight(stage.GetPrimAtPath("/World/Lights/panel"))
    assert (panel.GetWidthAttr().Get(), panel.GetHeightAttr().Get()) == (2.0, 2.0)
    m = _xf(stage, "/World/Lights/panel")
    np.testing.assert_allclose(m[3, :3], [0, 5, 0], atol=1e-6)
    # rectangle rotated +90 deg about X: its +Z normal (Mitsuba's emitting side) points to -Y; the RectLight emits to -Z
    np.testing.assert_allclose(-m[2, :3], [0, -1, 0], atol=1e-6)


def test_emitter_shapes_keep_their_surface_behind_their_light(converted):
    """Mitsuba's emitter shapes are opaque (they shadow other lights and show their back); a UsdLux light occludes
    nothing, so each one's surface is written too, just behind the light's emitting side: the bulb's sphere shrunk by
    1e-3 of its radius about its centre, the panel's quad 1e-3 of its size above the light (it emits down, -Y).
    Before, neither had a surface: a light seen from behind showed what lies beyond it."""
    from pxr import UsdGeom

    _, stage, _ = converted
    bulb = UsdGeom.Sphere(stage.GetPrimAtPath("/World/Geometry/bulb"))
    m = _xf(stage, "/World/Geometry/bulb")
    assert bulb.GetRadiusAttr().Get() * np.linalg.norm(m[0, :3]) == pytest.approx(0.2 * (1 - 1e-3), rel=1e-6)
    np.testing.assert_allclose(m[3, :3], [0, 4, 0], atol=1e-6)
    panel = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/panel"))
    world = np.c_[np.array(panel.GetPointsAttr().Get()), np.ones(4)] @ _xf(stage, "/World/Geometry/panel")
    np.testing.assert_allclose(world[:, 1], 5.0 + 1e-3, atol=1e-6)
    np.testing.assert_allclose(np.abs(world[:, [0, 2]]), 1.0, atol=1e-6)
    assert not panel.GetDoubleSidedAttr().Get()  # Mitsuba's default diffuse is one-sided: its back is black


def test_envmap_texture_written_and_referenced(converted):
    from pxr import UsdLux

    from nasset_reference_renderer.film import read_exr

    res, stage, _ = converted
    dome = UsdLux.DomeLight(stage.GetPrimAtPath("/World/Lights/env"))
    tex = dome.GetTextureFileAttr().Get()
    assert not Path(tex.path).is_absolute()
    assert dome.GetTextureFormatAttr().Get() == "latlong"
    assert dome.GetIntensityAttr().Get() == pytest.approx(2.0)
    # written at 8x its size, resampled with Mitsuba's bilinear lookup at the renderer's texel centres (nearest
    # lookup then follows Mitsuba); the dome's 180 deg turn absorbs the renderer's u offset: source column k is block k
    fine = read_exr(tex.resolvedPath)
    assert fine.shape == (64, 128, 3)
    red = fine[..., 0].reshape(8, 8, 16, 8).mean(axis=(1, 3))
    np.testing.assert_allclose(red[:, 2:6], 1.0, atol=1e-4)  # source red = 1 in columns 0 .. 7
    np.testing.assert_allclose(red[:, 10:14], 0.0, atol=1e-4)  # and 0 in columns 8 .. 15
    assert fine[..., 1].mean() == pytest.approx(_env_image()[..., 1].mean(), rel=0.1)
    # rotated 180 deg about +Y (Mitsuba u = 0 at -Z; the renderer's u = 0.5 at -Z)
    np.testing.assert_allclose(_xf(stage, "/World/Lights/env")[:3, :3], np.diag([-1.0, 1.0, -1.0]), atol=1e-9)


def test_shapes_and_materials(converted):
    from pxr import UsdGeom

    _, stage, _ = converted
    box = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/box"))
    pts = np.array(box.GetPointsAttr().Get())
    np.testing.assert_allclose(pts.mean(0), [5, 0, 0], atol=1e-5)  # world space (to_world applied by Mitsuba)
    assert len(box.GetFaceVertexCountsAttr().Get()) == 12
    assert box.GetSubdivisionSchemeAttr().Get() == "none"

    floor = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/floor"))
    m = _xf(stage, "/World/Geometry/floor")
    world = np.c_[np.array(floor.GetPointsAttr().Get()), np.ones(4)] @ m
    np.testing.assert_allclose(np.abs(world[:, [0, 2]]), 2.0, atol=1e-6)
    np.testing.assert_allclose(world[:, 1], 0.0, atol=1e-6)

    ball = UsdGeom.Sphere(stage.GetPrimAtPath("/World/Geometry/ball"))
    m = _xf(stage, "/World/Geometry/ball")
    assert ball.GetRadiusAttr().Get() * np.linalg.norm(m[0, :3]) == pytest.approx(0.5)
    np.testing.assert_allclose(m[3, :3], [1, 0.5, 0], atol=1e-6)
    assert len(UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/disk")).GetFaceVertexCountsAttr().Get()) == 192
    cyl = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/cyl"))  # world space, Mitsuba's unit tube z 0..1
    pts, nrm = np.array(cyl.GetPointsAttr().Get()), np.array(cyl.GetNormalsAttr().Get())
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1]), 1.0, atol=1e-6)
    assert pts[:, 2].min() == pytest.approx(0.0) and pts[:, 2].max() == pytest.approx(1.0)
    np.testing.assert_allclose(nrm[:, :2], pts[:, :2], atol=1e-6)

    rp = _shader_inputs(stage, _bound(stage, "/World/Geometry/box"))
    assert rp["roughness"] == pytest.approx(0.5)  # sqrt(alpha 0.25)
    np.testing.assert_allclose(rp["specularColor"], [((1.49 - 1) / 2.49) ** 2] * 3, rtol=2e-3)
    np.testing.assert_allclose(rp["diffuseColor"], np.array([0.7, 0.3, 0.1]) * _plastic_scale_by_quadrature(1.4896), rtol=2e-3)

    au = _shader_inputs(stage, _bound(stage, "/World/Geometry/ball"))
    # Mitsuba's default Beckmann alpha 0.09, written as itself with nasset:microfacet (spec/bake.md#materials)
    assert au["metallic"] == 1.0 and au["roughness"] == pytest.approx(0.3)
    ball_shader = stage.GetPrimAtPath(_bound(stage, "/World/Geometry/ball") + "/PreviewSurface")
    assert ball_shader.GetAttribute("nasset:microfacet").Get() == "beckmann"
    assert au["diffuseColor"][0] > au["diffuseColor"][2]  # gold: red > blue F0

    pr = _shader_inputs(stage, _bound(stage, "/World/Geometry/cube"))
    np.testing.assert_allclose(pr["diffuseColor"], [0.5, 0.2, 0.1], rtol=1e-6)
    assert (pr["metallic"], pr["roughness"]) == (pytest.approx(0.2), pytest.approx(0.3))
    assert ((pr["ior"] - 1) / (pr["ior"] + 1)) ** 2 == pytest.approx(0.04, rel=1e-4)  # specular 0.5 -> F0 0.04

    # a float bitmap becomes a UsdUVTexture on an OpenEXR file holding the same (linear) texels
    from pxr import UsdShade

    from nasset_sdk.images import read_exr

    surf = UsdShade.Shader(stage.GetPrimAtPath(_bound(stage, "/World/Geometry/tri") + "/PreviewSurface"))
    node = UsdShade.Shader(surf.GetInput("diffuseColor").GetConnectedSource()[0].GetPrim())
    assert node.GetIdAttr().Get() == "UsdUVTexture" and node.GetInput("sourceColorSpace").Get() == "raw"
    np.testing.assert_allclose(read_exr(node.GetInput("file").Get().resolvedPath), _env_image(), rtol=1e-6)
    reader = UsdShade.Shader(node.GetInput("st").GetConnectedSource()[0].GetPrim())
    assert reader.GetIdAttr().Get() == "UsdPrimvarReader_float2" and reader.GetInput("varname").Get() == "st"
    assert not UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/tri")).GetDoubleSidedAttr().Get()  # one-sided diffuse


def test_mesh_without_texture_coordinates_reads_mitsubas_barycentrics(converted):
    """Mitsuba's uv on a mesh without texture coordinates is the hit's barycentric (b1, b2); the OBJ triangle (0, 0, 0),
    (1, 0, 0), (0, 1, 0) has b1 = x and b2 = y, so whatever winding the converter writes, the corner at point p reads
    st = (p.x, 1 - p.y) (USD's t runs up the image). Before, the mesh had no st and read the texture's corner texel."""
    from pxr import UsdGeom

    _, stage, _ = converted
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/World/Geometry/tri"))
    pv = UsdGeom.PrimvarsAPI(mesh).GetPrimvar("st")
    assert pv.GetInterpolation() == UsdGeom.Tokens.faceVarying
    pts = np.asarray(mesh.GetPointsAttr().Get())[np.asarray(mesh.GetFaceVertexIndicesAttr().Get())]
    np.testing.assert_allclose(np.asarray(pv.Get()), np.c_[pts[:, 0], 1.0 - pts[:, 1]], atol=1e-7)


def _plastic_scale_by_quadrature(eta, n=200_000):
    """Lambertian albedo per unit plastic ``diffuse_reflectance``, (1 - Fdr(eta))^2 / (eta^2 (1 - Fdr(1 / eta))), with
    Fdr the cosine-weighted hemispherical mean of the exact unpolarised dielectric Fresnel term, written out here
    (independent of the converter's helpers)."""
    c = (np.arange(n) + 0.5) / n

    def fdr(e):
        s2 = (1 - c * c) / (e * e)
        ct = np.sqrt(np.maximum(0.0, 1 - s2))
        rs, rp = (c - e * ct) / (c + e * ct), (e * c - ct) / (e * c + ct)
        return float((np.where(s2 >= 1, 1.0, 0.5 * (rs * rs + rp * rp)) * 2 * c).sum() / n)

    return (1 - fdr(eta)) ** 2 / (eta * eta * (1 - fdr(1 / eta)))


def test_unsupported_elements_warn(converted):
    res, _, _ = converted
    text = "\n".join(res.warnings)
    for needle in ("cyl: cylinder tessellated", "glass: interior medium", "SmoothDielectric: smooth glass approximated by GGX"):
        assert needle in text, needle


def test_plastic_mapping_helpers():
    assert fresnel_dielectric(np.array([1.0]), 1.5)[0] == pytest.approx(0.04)
    assert float(plastic_diffuse_scale(1.49)) == pytest.approx(0.91, abs=0.01)


# -- replace, errors, CLI ------------------------------------------------------------------------
SIMPLE_XML = """<scene version="3.0.0">
<sensor type="perspective"><float name="fov" value="35"/>
  <transform name="to_world"><lookat origin="0, 1, 4" target="0, 0.3, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film></sensor>
<shape type="ply" id="obj"><string name="filename" value="obj.ply"/></shape>
<shape type="ply" id="obj2"><string name="filename" value="obj.ply"/></shape>
<shape type="rectangle" id="ground"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/></transform></shape>
<emitter type="directional"><vector name="direction" value="0, -1, 0"/></emitter>
<emitter type="constant" id="sky"><rgb name="radiance" value="0.2, 0.3, 0.4"/></emitter>
</scene>"""


@pytest.fixture
def simple_scene(tmp_path):
    import trimesh

    trimesh.creation.icosphere(subdivisions=1, radius=0.3).export(tmp_path / "obj.ply")
    (tmp_path / "s.xml").write_text(SIMPLE_XML)
    return tmp_path / "s.xml"


def test_replace_writes_relative_neural_asset_reference(simple_scene, rna_asset_path, tmp_path):
    import shutil

    from pxr import Usd

    from nasset_reference_renderer import load_scene

    asset = tmp_path / "assets" / "obj.usdc"
    asset.parent.mkdir()
    shutil.copy(rna_asset_path, asset)
    out = tmp_path / "deep" / "scene.usda"
    res = convert_scene(simple_scene, out, replace=["obj,obj2=" + str(asset)])
    assert list(res.replaced.values()) == [{"asset": "../assets/obj.usdc", "shapes": ["obj", "obj2"]}]
    stage = Usd.Stage.Open(str(out))
    prim = stage.GetPrimAtPath("/World/Assets/obj_obj2")
    assert prim.GetTypeName() == "Xform"  # the recommended pattern: plain USD tools keep its transform
    from nasset_sdk.references import asset_source

    assert asset_source(prim).layer == str(asset)  # the asset's root reached through composition
    refs = prim.GetPrimStack()[0].referenceList.prependedItems
    assert [r.assetPath for r in refs] == ["../assets/obj.usdc"]
    assert not stage.GetPrimAtPath("/World/Geometry/obj") and not stage.GetPrimAtPath("/World/Geometry/obj2")
    assert _xf(stage, "/World/Assets/obj_obj2").tolist() == np.eye(4).tolist()  # asset space == scene space
    assert [c for c in res.usd_checks if c["severity"] == "error"] == []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(str(out))
    assert [i.kind for i in scene.instances].count("neural") == 1
    dome = [light for light in scene.lights if light.prim == "/World/Lights/sky"][0]
    np.testing.assert_allclose(dome.scale, [0.2, 0.3, 0.4], rtol=1e-6)  # constant emitter -> DomeLight radiance


def test_typed_errors(simple_scene, tmp_path):
    with pytest.raises(NassetError) as e:
        convert_scene(tmp_path / "nope.xml", tmp_path / "o.usda")
    assert e.value.code == "CONVERT_SCENE_MISSING"
    with pytest.raises(NassetError) as e:
        convert_scene(simple_scene, tmp_path / "o.usda", replace=["nothere=x.usdc"])
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN" and "obj" in e.value.message
    with pytest.raises(NassetError) as e:
        convert_scene(simple_scene, tmp_path / "o.usda", replace=[f"obj={simple_scene}"])
    assert e.value.code == "CONVERT_ASSET_REFERENCE"
    with pytest.raises(NassetError) as e:
        convert_scene(simple_scene, tmp_path / "o.usda", replace=["obj"])
    assert e.value.code == "USAGE"
    bad = tmp_path / "bad.xml"
    bad.write_text("<scene version='3.0.0'><shape type='nonesuch'/></scene>")
    with pytest.raises(NassetError) as e:
        convert_scene(bad, tmp_path / "o.usda")
    assert e.value.code == "CONVERT_SCENE_LOAD"


def test_an_asset_of_other_shapes_is_warned(simple_scene, tmp_path):
    """``--replace ground=ASSET`` with an asset baked from ``obj``: the stage showed the object where the ground was,
    without a word (only ``bench accuracy`` checked the bounds); now a warning names the ids and the asset's shapes."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_sdk.examples import example_builder

    mi = load_mitsuba()
    b = example_builder("rna", size="tiny", seed=2)
    b.set_geometry(msc.mesh_geometry(mi, msc.pick_shapes(msc.load_scene(mi, simple_scene), ["obj"])))
    asset = b.write(tmp_path / "obj_asset.usdc")
    good = convert_scene(simple_scene, tmp_path / "a.usda", replace=[f"obj={asset}"])
    assert not [w for w in good.warnings if "baked from" in w]
    bad = convert_scene(simple_scene, tmp_path / "b.usda", replace=[f"ground={asset}"])
    assert [w for w in bad.warnings if "ground" in w and "not baked from" in w]


def test_cli_json_and_exit_codes(simple_scene, tmp_path, capsys):
    from nasset_sdk.cli import main

    assert main(["convert-scene", str(simple_scene), "-o", str(tmp_path / "c.usda"), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["ok"] and "/World/Geometry/ground" in out["prims"] and isinstance(out["warnings"], list)
    assert main(["convert-scene", str(simple_scene), "-o", str(tmp_path / "c.usda"), "--replace", "zzz=a.usdc"]) == 1
    assert "CONVERT_SHAPE_UNKNOWN" in capsys.readouterr().err
    assert main(["convert-scene", str(simple_scene), "-o", str(tmp_path / "c.txt")]) == 2
    assert main(["convert-scene", str(simple_scene), "--example", "-o", str(tmp_path / "c.usda")]) == 2
    assert main(["convert-scene", "-o", str(tmp_path / "c.usda")]) == 2


def test_cli_example_scene_with_asset(rna_asset_path, tmp_path, capsys):
    from pxr import Usd

    from nasset_sdk.cli import main

    out = tmp_path / "ex" / "scene.usda"
    out.parent.mkdir()
    assert main(["convert-scene", "--example", "-o", str(out), "--replace", f"shell,jelly={rna_asset_path}", "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert (tmp_path / "ex" / "example_scene" / "scene.xml").is_file()
    assert report["replaced"] and "/World/Geometry/ground" in report["prims"]
    stage = Usd.Stage.Open(str(out))
    from nasset_sdk.references import asset_source

    assert [p.GetTypeName() for p in stage.Traverse() if asset_source(p)] == ["Xform"]


# -- the converted scene renders like the original ----------------------------------------------------------
MATCH_XML = """<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="4"/></integrator>
<sensor type="perspective"><float name="fov" value="35"/>
 <transform name="to_world"><lookat origin="1.6, 1.1, 1.9" target="0.1, 0.18, 0" up="0, 1, 0"/></transform>
 <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/><rfilter type="box"/></film></sensor>
<shape type="ply" id="shell"><string name="filename" value="shell.ply"/>{shell_bsdf}</shape>
<shape type="sphere" id="ball"><point name="center" x="0.55" y="0.15" z="0.3"/><float name="radius" value="0.15"/>
 <bsdf type="diffuse"><rgb name="reflectance" value="0.2, 0.5, 0.8"/></bsdf></shape>
<shape type="rectangle" id="ground"><transform name="to_world"><rotate x="1" angle="-90"/><scale value="3"/></transform>
 <bsdf type="diffuse"><rgb name="reflectance" value="0.45, 0.45, 0.45"/></bsdf></shape>
<emitter type="directional" id="sun"><vector name="direction" value="-0.45, -0.8, -0.35"/><rgb name="irradiance" value="3.0, 2.9, 2.7"/></emitter>
{sky}
</scene>"""
DIFFUSE = '<bsdf type="diffuse"><rgb name="reflectance" value="0.75, 0.32, 0.08"/></bsdf>'
ROUGHPLASTIC = '<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="0.75, 0.32, 0.08"/><float name="alpha" value="0.25"/></bsdf>'
CONSTANT = '<emitter type="constant" id="sky"><rgb name="radiance" value="0.25, 0.3, 0.4"/></emitter>'
ENVMAP = ('<emitter type="envmap" id="sky"><string name="filename" value="sky.exr"/><float name="scale" value="0.5"/>'
          '<transform name="to_world"><rotate y="1" angle="60"/></transform></emitter>')


def _sky_exr(path):
    from nasset_reference_renderer.film import write_exr

    h, w = 32, 64
    v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    img = np.stack([0.3 + 0.7 * (u < 0.5), 0.2 + 0.8 * u, 0.2 + 0.6 * (1 - v)], -1).astype(np.float32)
    write_exr(path, img)


def _match(tmp_path, shell_bsdf, sky, spp=128):
    """(Mitsuba image, second Mitsuba image, reference-renderer result) of the same scene at 32x32."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.examples import example_meshes, write_ply
    from nasset_reference_renderer import RenderSettings, load_scene, render

    shell = dict(example_meshes())["shell"]
    write_ply(tmp_path / "shell.ply", shell.vertices, shell.faces, shell.vertex_normals)
    _sky_exr(tmp_path / "sky.exr")
    xml = tmp_path / "m.xml"
    xml.write_text(MATCH_XML.format(shell_bsdf=shell_bsdf, sky=sky))
    mi = load_mitsuba()
    scene = mi.load_file(str(xml))
    a = np.asarray(mi.render(scene, spp=spp, seed=1), np.float64)[..., :3]
    b = np.asarray(mi.render(scene, spp=spp, seed=2), np.float64)[..., :3]
    res = convert_scene(xml, tmp_path / "m.usda", check_usd=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        usd = load_scene(str(res.output))
    out = render(usd, RenderSettings(spp=spp, width=32, height=32, seed=5))  # depth from the stage's render settings
    return a, b, out


def _stats(a, b, out):
    """Relative error of the mean per channel, and MSE(ref vs Mitsuba) / the MSE expected from noise alone."""
    img = out.image
    mean_rel = img.reshape(-1, 3).mean(0) / a.reshape(-1, 3).mean(0) - 1.0
    noise = np.mean((a - b) ** 2) / 2.0 + out.variance.mean()  # var(Mitsuba, one render) + var(reference)
    return mean_rel, float(np.mean((img - a) ** 2) / noise)


# Tolerances from measurements at 32x32, 128-130 spp, 3 seeds each (mean error per channel; MSE ratio):
#   diffuse + constant: |mean| <= 0.2 %, ratio 1.03-1.07
#   rough-plastic ring + constant (Beckmann -> GGX, exact Fresnel -> Schlick, averaged coating
#   transmission): mean +1.4 % red, +0.5 % green, ratio 1.19-1.27
#   diffuse + envmap rotated 60 deg (before envmaps were resampled with Mitsuba's bilinear lookup): |mean| <= 0.3 %,
#   ratio 1.02-1.06
# A horizontally mirrored camera raises the diffuse scene's MSE ~60x (measured), far past these bounds.
@pytest.mark.parametrize("case, bsdf, sky, mean_tol, ratio_tol", [
    ("diffuse+constant", DIFFUSE, CONSTANT, 0.01, 1.3),
    ("roughplastic+constant", ROUGHPLASTIC, CONSTANT, 0.025, 1.6),
    ("diffuse+envmap", DIFFUSE, ENVMAP, 0.01, 1.3),
], ids=["diffuse+constant", "roughplastic+constant", "diffuse+envmap"])
def test_converted_scene_matches_mitsuba(tmp_path, case, bsdf, sky, mean_tol, ratio_tol):
    a, b, out = _match(tmp_path, bsdf, sky)
    mean_rel, ratio = _stats(a, b, out)
    assert np.all(np.abs(mean_rel) < mean_tol), (case, mean_rel)
    assert ratio < ratio_tol, (case, ratio)


def test_renderer_takes_resolution_from_render_settings(converted):
    from nasset_reference_renderer import load_scene

    res, _, _ = converted
    camera = load_scene(str(res.output)).camera
    assert camera.default_resolution(None, None) == (64, 32)
    assert camera.default_resolution(20, None) == (20, 10)  # explicit size wins, aspect from the aperture


def test_python_api_paths_that_are_not_paths_are_usage_errors(tmp_path):
    """convert_scene's scene, output and replace files, and bench accuracy's replace files, given as None: USAGE naming
    the argument (they were bare TypeErrors)."""
    from nasset_benchmarks.accuracy import bench_accuracy
    from nasset_converters.mitsuba.usd_export import convert_scene
    from nasset_sdk.errors import UsageError

    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><sensor type="perspective"/><shape type="sphere" id="ball"/></scene>')
    with pytest.raises(UsageError, match="convert_scene: the scene must be a file path"):
        convert_scene(None, tmp_path / "o.usda")
    with pytest.raises(UsageError, match="convert_scene: the output must be a file path"):
        convert_scene(xml, None)
    for run in (lambda: convert_scene(xml, tmp_path / "o.usda", replace={"ball": None}),
                lambda: bench_accuracy(xml, {"ball": None}, tmp_path / "acc", quiet=True)):
        with pytest.raises(UsageError, match="--replace ball: the asset must be a file path"):
            run()
    assert convert_scene(xml, tmp_path / "o.usda").output.is_file()


GLASS_XML = """<scene version="3.0.0">
<sensor type="perspective"><transform name="to_world"><lookat origin="0, 1, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
  <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>
<shape type="sphere" id="ball"><bsdf type="dielectric"><float name="int_ior" value="1.33"/></bsdf></shape>
<shape type="rectangle" id="pane"><bsdf type="thindielectric"><rgb name="specular_transmittance" value="0.5, 0.8, 1"/>
  </bsdf></shape>
<shape type="cube" id="frosted"><bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf></shape>
<shape type="cube" id="half"><transform name="to_world"><translate x="3"/></transform><bsdf type="blendbsdf">
  <float name="weight" value="0.25"/><bsdf type="dielectric"/><bsdf type="diffuse"><rgb name="reflectance" value="0.6, 0.2, 0.1"/>
  </bsdf></bsdf></shape>
<emitter type="constant"/>
</scene>"""


def test_dielectrics_become_materialx_glass_that_usd_checks_accept(tmp_path):
    """dielectric, thindielectric, roughdielectric (Beckmann by default: its GGX counterpart) and a blendbsdf holding one
    are written as a MaterialX standard_surface with transmission on outputs:mtlx:surface beside the opaque
    UsdPreviewSurface; OpenUSD's validators raise no error (a registry without MaterialX nodes: a warning)."""
    from pxr import Usd, UsdShade

    from nasset_converters.mitsuba.usd_export import ggx_alpha_of_beckmann
    from nasset_sdk import stage_rules

    xml = tmp_path / "glass.xml"
    xml.write_text(GLASS_XML)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = convert_scene(xml, tmp_path / "glass.usda")
    assert [c for c in res.usd_checks if c["severity"] == "error"] == [], res.usd_checks
    stage = Usd.Stage.Open(str(tmp_path / "glass.usda"))

    def surface(shape):
        mat, _ = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath(f"/World/Geometry/{shape}")).ComputeBoundMaterial()
        assert mat.GetSurfaceOutput().HasConnectedSource()  # the opaque fallback stays
        sh = stage_rules.surface_shader(mat)
        assert sh.GetIdAttr().Get() == "ND_standard_surface_surfaceshader"
        return {i.GetBaseName(): i.Get() for i in sh.GetInputs()}

    ball, pane, frosted, half = (surface(s) for s in ("ball", "pane", "frosted", "half"))
    assert ball["transmission"] == 1.0 and not ball["thin_walled"] and ball["specular_IOR"] == pytest.approx(1.33 / 1.000277, rel=1e-4)
    assert pane["thin_walled"] and tuple(pane["transmission_color"]) == pytest.approx((0.5, 0.8, 1.0))
    assert frosted["specular_roughness"] == pytest.approx(math.sqrt(ggx_alpha_of_beckmann(0.2)), rel=1e-5)
    assert half["transmission"] == pytest.approx(0.75) and tuple(half["base_color"]) == pytest.approx((0.6, 0.2, 0.1))
