"""``nasset convert-scene`` on Mitsuba 3 scene files as artists write them (spec/bake.md#scene-conversion): ids as
exporters name objects, shape groups, ... Each element is converted, warned by name or refused with a typed error."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_converters.mitsuba.usd_export import convert_scene  # noqa: E402

HEAD = """<scene version="3.0.0">
<sensor type="perspective"><float name="fov" value="45"/>
 <transform name="to_world"><lookat origin="0, 3, 4.5" target="0, 0.3, 0" up="0, 1, 0"/></transform>
 <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
</sensor>
<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
"""


def _stage(path):
    from pxr import Usd

    return Usd.Stage.Open(str(path))


def test_shapegroup_children_with_dotted_ids_are_converted(tmp_path):
    # Blender-exported ids carry dots ("Cube.001"); Mitsuba's parameter keys join ids with dots, and reading the group's
    # children by splitting those keys dropped every child of a dotted group, and every dotted child, without a word
    xml = tmp_path / "groups.xml"
    xml.write_text(HEAD + """
<shape type="shapegroup" id="Chair.v1">
  <shape type="cube" id="Seat.001"><transform name="to_world"><scale value="0.3"/></transform><bsdf type="diffuse"/></shape>
  <shape type="sphere"><float name="radius" value="0.2"/><bsdf type="diffuse"/></shape>
</shape>
<shape type="shapegroup" id="Chair">
  <shape type="cube" id="Seat"><bsdf type="diffuse"/></shape>
</shape>
<shape type="instance" id="a.1"><ref id="Chair.v1"/><transform name="to_world"><translate x="-1"/></transform></shape>
<shape type="instance" id="b.1"><ref id="Chair.v1"/><transform name="to_world"><translate x="1"/></transform></shape>
<shape type="instance" id="c"><ref id="Chair"/></shape>
</scene>""")
    res = convert_scene(xml, tmp_path / "groups.usda", check_usd=False)
    stage = _stage(res.output)
    protos = {str(p.GetPath()): sorted(c.GetName() for c in p.GetAllChildren() if c.GetName() != "Looks")
              for p in stage.GetPrimAtPath("/Prototypes").GetAllChildren()}
    assert protos == {"/Prototypes/Chair_v1": ["Seat_001", "shape_1"], "/Prototypes/Chair": ["Seat"]}
    assert stage.GetPrimAtPath("/World/Geometry/a_1").IsInstance()
    assert stage.GetPrimAtPath("/World/Geometry/a_1").GetPrototype().GetChildren()  # the instance shows its shapes


@pytest.mark.parametrize("wrap", ["repeat", "mirror", "clamp"])
@pytest.mark.parametrize("filt", ["bilinear", "nearest"])
def test_bitmap_wrap_mode_and_nearest_filter_carry_over(tmp_path, wrap, filt):
    # Mitsuba's description of a bitmap names neither its wrap_mode nor its filter_type: both were written as repeat
    # and bilinear (a clamped or mirrored texture tiled by to_uv read MSE 44x the noise: fidelity scene texture_sampling)
    import numpy as np
    from pxr import UsdShade

    from nasset_sdk.images import read_exr, write_png

    y, x = np.mgrid[0:8, 0:8]
    write_png(tmp_path / "grad.png", np.stack([x * 36, y * 36, 128 + 0 * x], -1).astype(np.uint8))
    xml = tmp_path / "tex.xml"
    xml.write_text(HEAD + f"""
<shape type="rectangle" id="floor"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">
  <string name="filename" value="grad.png"/><string name="wrap_mode" value="{wrap}"/><string name="filter_type" value="{filt}"/>
  <transform name="to_uv"><scale value="2.5"/><rotate z="1" angle="15"/><translate x="-0.7" y="-0.6"/></transform>
</texture></bsdf></shape>
</scene>""")
    res = convert_scene(xml, tmp_path / "tex.usda", check_usd=False)
    stage = _stage(res.output)
    tex = next(UsdShade.Shader(p) for p in stage.Traverse()
               if p.GetTypeName() == "Shader" and UsdShade.Shader(p).GetIdAttr().Get() == "UsdUVTexture")
    assert tex.GetInput("wrapS").Get() == wrap and tex.GetInput("wrapT").Get() == wrap
    image = read_exr(res.textures[0])
    assert image.shape[:2] == ((64, 64) if filt == "nearest" else (8, 8))  # nearest: each texel repeated 8 x 8


@pytest.mark.parametrize("integrator", ["path", "volpath", "volpathmis", "direct", "aov"])
@pytest.mark.parametrize("hide", [True, False])
def test_hide_emitters_writes_lights_hidden_from_the_camera(tmp_path, integrator, hide):
    # Mitsuba's hide_emitters (its description of the integrator does not name it) was dropped: the sky and the lights
    # in view showed in the converted scene (fidelity scene hide_emitters: ratio 8, MSE 660x the noise at 32x32, 64 spp)
    flag = f'<boolean name="hide_emitters" value="{str(hide).lower()}"/>'
    integ = (f'<integrator type="aov"><string name="aovs" value="dd.y:depth"/><integrator type="path">{flag}</integrator>'
             "</integrator>" if integrator == "aov" else f'<integrator type="{integrator}">{flag}</integrator>')
    xml = tmp_path / "hide.xml"
    xml.write_text(HEAD.replace("<sensor", integ + "\n<sensor") + """
<shape type="rectangle" id="panel"><emitter type="area"><rgb name="radiance" value="3"/></emitter></shape>
<shape type="obj" id="tri"><string name="filename" value="tri.obj"/><emitter type="area"><rgb name="radiance" value="2"/></emitter></shape>
</scene>""")
    (tmp_path / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    res = convert_scene(xml, tmp_path / "hide.usda", check_usd=False)
    stage = _stage(res.output)
    for light in ("/World/Lights/emitter_0", "/World/Lights/panel"):
        attr = stage.GetPrimAtPath(light).GetAttribute("nasset:cameraVisibility")
        assert (attr.Get() is False) if hide else not attr.HasAuthoredValue(), light
    assert res.integrator.get("hide_emitters", False) is hide
    assert any("tri" in w and "hides emitters" in w for w in res.warnings) is hide  # a mesh light cannot be hidden
    # path tracers all (volpathmis too: it was said to have no USD counterpart); direct lighting is the renderer's depth 1
    assert not any("no USD counterpart" in w for w in res.warnings)
    if integrator == "direct":
        assert res.integrator["renderer_max_depth"] == 1  # emitters in view + direct light at the first hit


GROUPED = HEAD + """
<shape type="shapegroup" id="Chair.v1">
  <shape type="cube" id="Seat.001"><bsdf type="diffuse"/></shape>
</shape>
<shape type="instance" id="left"><ref id="Chair.v1"/><transform name="to_world"><translate x="-1"/></transform></shape>
<shape type="instance" id="right"><ref id="Chair.v1"/><transform name="to_world"><translate x="1"/></transform></shape>
</scene>"""


def test_asset_inside_a_shapegroup_or_an_instance_is_refused_with_the_reason(tmp_path):
    # a shape inside a shapegroup is not a shape of the scene (Mitsuba lists the instances): the bake and --replace said
    # "no shape with id" and listed the instances; an instance was "not a triangle mesh ... convert it to ply/obj"
    import mitsuba as mi

    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import pick_shapes
    from nasset_sdk.errors import NassetError

    xml = tmp_path / "grouped.xml"
    xml.write_text(GROUPED)
    load_mitsuba()
    scene = mi.load_file(str(xml), optimize=False)
    with pytest.raises(NassetError) as e:
        pick_shapes(scene, ["Seat.001"], file=str(xml))
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN"
    assert "inside shapegroup 'Chair.v1'" in e.value.message and "['left', 'right']" in e.value.message
    with pytest.raises(NassetError) as e:
        convert_scene(xml, tmp_path / "o.usda", replace=[f"Seat.001={xml}"])
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN" and "inside shapegroup 'Chair.v1'" in e.value.message
    with pytest.raises(NassetError) as e:
        pick_shapes(scene, ["left"], file=str(xml))
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "instance of a shapegroup" in e.value.message
    with pytest.raises(NassetError) as e:
        pick_shapes(scene, ["nothere"], file=str(xml))
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN" and "['left', 'right']" in e.value.message


def test_textures_of_same_named_materials_in_two_shapegroups_keep_their_own_files(tmp_path):
    # unnamed shapes in two groups get materials of one name under each prototype; their textures were written to one
    # file, the second group's texels over the first's (MSE 49x the noise at 32x32, 64 spp)
    import numpy as np
    from pxr import Usd, UsdShade

    from nasset_sdk.images import read_exr, write_png

    write_png(tmp_path / "red.png", np.full((4, 4, 3), (200, 30, 30), np.uint8))
    write_png(tmp_path / "blue.png", np.full((4, 4, 3), (30, 30, 200), np.uint8))
    group = ('<shape type="shapegroup" id="{g}"><shape type="rectangle"><bsdf type="diffuse"><texture type="bitmap" '
             'name="reflectance"><string name="filename" value="{f}"/></texture></bsdf></shape></shape>\n'
             '<shape type="instance" id="i{g}"><ref id="{g}"/></shape>\n')
    xml = tmp_path / "groups.xml"
    xml.write_text(HEAD + group.format(g="A", f="red.png") + group.format(g="B", f="blue.png") + "</scene>")
    res = convert_scene(xml, tmp_path / "out.usda", check_usd=False)
    stage = _stage(res.output)
    files = {}
    for g in ("A", "B"):  # the prototypes are abstract (class prims): walk them with the all-prims predicate
        looks = stage.GetPrimAtPath(f"/Prototypes/{g}/Looks")
        shader = next(UsdShade.Shader(p) for p in Usd.PrimRange(looks, Usd.PrimAllPrimsPredicate)
                      if UsdShade.Shader(p) and UsdShade.Shader(p).GetIdAttr().Get() == "UsdUVTexture")
        files[g] = shader.GetInput("file").Get().resolvedPath
    assert files["A"] != files["B"]
    red, blue = (read_exr(files[g]).reshape(-1, 3).mean(0) for g in ("A", "B"))
    assert red[0] > 5 * red[2] and blue[2] > 5 * blue[0]


DEPTH_SCENE = """<scene version="3.0.0">
<integrator type="path"><integer name="max_depth" value="{depth}"/></integrator>
<sensor type="perspective"><float name="fov" value="45"/>
 <transform name="to_world"><lookat origin="0, 1, 4.5" target="0, 0.3, 0" up="0, 1, 0"/></transform>
 <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/><rfilter type="box"/></film>
</sensor>
<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>
<emitter type="point"><point name="position" x="1" y="2" z="2"/><rgb name="intensity" value="8"/></emitter>
<shape type="sphere"><bsdf type="diffuse"/></shape>
<shape type="rectangle"><transform name="to_world"><scale value="0.4"/><translate x="1.2" y="1.2" z="-0.5"/></transform>
 <emitter type="area"><rgb name="radiance" value="3"/></emitter></shape>
</scene>"""


@pytest.mark.parametrize("depth", [0, 1, 2])
def test_integrator_depths_convert_to_the_renderers_depth(tmp_path, depth):
    # Mitsuba counts path segments, the renderer scattering vertices; Mitsuba's max_depth 1 (the emitters in view
    # only) is renderer depth 0. It was written as 1 with a warning, and a scene of it rendered 5.3-5.9x too bright.
    xml = tmp_path / "d.xml"
    xml.write_text(DEPTH_SCENE.format(depth=depth))
    res = convert_scene(xml, tmp_path / "d.usda", check_usd=False)
    assert res.integrator["renderer_max_depth"] == max(depth - 1, 0)
    assert any("max_depth 0" in w for w in res.warnings) is (depth == 0)  # a black image is not drawn


@pytest.mark.parametrize("integrator, warning", [("prb", None), ("prbvolpath", None), ("prb_projective", None),
                                                  ("direct_projective", None), ("ptracer", None),
                                                  ("prb_basic", "samples no light"), ("depth", "no USD counterpart")])
def test_path_tracers_of_other_names_are_not_warned(tmp_path, integrator, warning):
    # the path-replay, projective and particle tracers render the path tracer's image (0.998-1.019 of its mean on this
    # scene at 24^2): they were warned as having no counterpart; prb_basic samples no light, so in Mitsuba a point
    # light lights nothing (1.12 of its mean here, MSE 61x the noise): that is what is warned now
    xml = tmp_path / "d.xml"
    element = ('<integrator type="depth"/>' if integrator == "depth"
               else f'<integrator type="{integrator}"><integer name="max_depth" value="3"/></integrator>')
    xml.write_text(DEPTH_SCENE.format(depth=3).replace('<integrator type="path"><integer name="max_depth" value="3"/>'
                                                       '</integrator>', element))
    res = convert_scene(xml, tmp_path / "d.usda", check_usd=False)
    said = [w for w in res.warnings if "integrator" in w]
    assert (said == []) if warning is None else any(warning in w for w in said), said


@pytest.mark.parametrize("renderer", ["reference", "plugin", "second"])
def test_the_emitters_in_view_only_render_as_in_mitsuba(tmp_path, renderer):
    """Mitsuba's max_depth 1, converted: the dome, the light surface in view and a black sphere, in the three renderers."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.fidelity import render_converted

    mi = load_mitsuba()
    xml = tmp_path / "d.xml"
    xml.write_text(DEPTH_SCENE.format(depth=1))
    ref = np.asarray(mi.render(mi.load_file(str(xml)), spp=64, seed=1), np.float64)[..., :3]
    stage = convert_scene(xml, tmp_path / "d.usda", check_usd=False).output
    if renderer == "second":
        from nasset_mitsuba_renderer.render import render

        img = np.asarray(render(str(stage), 64, width=16, height=16), np.float64)
    else:
        img = render_converted(stage, 16, 64, renderer)[0]
    sphere = ref.max(-1) < 1e-6  # Mitsuba's black pixels: the sphere (lit at depth 2, below)
    assert 10 < sphere.sum() < 200
    assert img[sphere].mean() < 5e-3, "surfaces must stay black"  # (a sample at the rim may see the dome)
    np.testing.assert_allclose(img.reshape(-1, 3).mean(0), ref.reshape(-1, 3).mean(0), rtol=0.03)
    lit_xml = tmp_path / "d2.xml"
    lit_xml.write_text(DEPTH_SCENE.format(depth=2))
    lit = np.asarray(mi.render(mi.load_file(str(lit_xml)), spp=16, seed=1), np.float64)[..., :3]
    assert lit[sphere].mean() > 0.05  # the check above can fail: at depth 2 the same pixels are lit


@pytest.mark.parametrize("far, warned", [("", False), ('<float name="far_clip" value="20"/>', True)])
def test_a_far_clip_that_cuts_the_scene_is_warned(tmp_path, far, warned):
    # Mitsuba does not draw what lies beyond far_clip (default 10000: 10 m in a millimetre scene) and the renderer ignores
    # clipping ranges: a tower beyond it showed in the converted scene without a word (MSE 2.3x the noise at 32x32)
    xml = tmp_path / "far.xml"
    xml.write_text(HEAD.replace('<float name="fov" value="45"/>', '<float name="fov" value="45"/>' + far)
                   + '<shape type="cube"><transform name="to_world"><translate z="-40"/></transform></shape></scene>')
    res = convert_scene(xml, tmp_path / "far.usda", check_usd=False)
    assert any("far_clip 20" in w for w in res.warnings) is warned


def test_a_scene_parameter_without_a_default_is_refused_with_the_fix(tmp_path):
    # the commands pass no scene parameters (Mitsuba's -D), so a $name without a <default> cannot load: the error now
    # says which default to add (it gave Mitsuba's parser message only)
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import load_scene
    from nasset_sdk.errors import NassetError

    (tmp_path / "cam.xml").write_text(HEAD.replace('value="16"', 'value="$res"') + "</scene>")
    xml = tmp_path / "main.xml"
    xml.write_text('<scene version="3.0.0"><include filename="cam.xml"/><shape type="sphere"/></scene>')
    for load in (lambda: convert_scene(xml, tmp_path / "o.usda"), lambda: load_scene(load_mitsuba(), xml)):
        with pytest.raises(NassetError) as e:
            load()
        assert e.value.code == "CONVERT_SCENE_LOAD"
        assert "$res" in e.value.message and '<default name="res"' in e.value.message


def test_a_twosided_back_reads_its_own_texture_flags(tmp_path):
    # raw flags and mesh_attribute names were read off the wrapper's description, whose first match is the front's: a raw
    # back texture was decoded from sRGB as the front's is (MSE 11.8x the noise at 32x32, 64 spp), the back's mesh
    # attribute was the front's
    import numpy as np
    from pxr import Usd, UsdShade

    from nasset_reference_renderer.textures import srgb_to_linear
    from nasset_sdk.images import read_exr, write_png

    write_png(tmp_path / "g.png", np.full((4, 4, 3), 128, np.uint8))
    tex = '<texture type="bitmap" name="reflectance"><string name="filename" value="g.png"/>{}</texture>'
    attr = '<texture type="mesh_attribute" name="reflectance"><string name="name" value="{}"/></texture>'
    xml = tmp_path / "two.xml"
    xml.write_text(HEAD + f"""
<shape type="rectangle" id="card"><bsdf type="twosided">
  <bsdf type="diffuse">{tex.format("")}</bsdf>
  <bsdf type="diffuse">{tex.format('<boolean name="raw" value="true"/>')}</bsdf></bsdf></shape>
<shape type="rectangle" id="tag"><bsdf type="twosided">
  <bsdf type="diffuse">{attr.format("vertex_front")}</bsdf><bsdf type="diffuse">{attr.format("vertex_back")}</bsdf></bsdf></shape>
</scene>""")
    res = convert_scene(xml, tmp_path / "two.usda", check_usd=False)
    stage = _stage(res.output)

    def shaders(material, shader_id):
        return [UsdShade.Shader(p) for p in Usd.PrimRange(stage.GetPrimAtPath(material))
                if UsdShade.Shader(p) and UsdShade.Shader(p).GetIdAttr().Get() == shader_id]

    front, back = (read_exr(shaders(f"/World/Looks/{m}", "UsdUVTexture")[0].GetInput("file").Get().resolvedPath)
                   for m in ("card_bsdf", "card_bsdf_back"))
    np.testing.assert_allclose(front[0, 0], srgb_to_linear(np.full(3, 128 / 255)), rtol=1e-5)
    np.testing.assert_allclose(back[0, 0], np.full(3, 128 / 255), rtol=1e-5)  # raw: the stored value
    readers = {m: shaders(f"/World/Looks/{m}", "UsdPrimvarReader_float3")[0].GetInput("varname").Get()
               for m in ("tag_bsdf", "tag_bsdf_back")}
    assert readers == {"tag_bsdf": "color_vertex_front", "tag_bsdf_back": "color_vertex_back"}


def test_nested_bsdfs_are_mapped_as_their_own_class(tmp_path):
    # a nested BSDF's class was read off the top-level description by the first match: in a blend of two twosided BSDFs
    # the second's conductor was taken for the first's diffuse (blended as a grey diffuse, without a word)
    xml = tmp_path / "blend.xml"
    xml.write_text(HEAD + """
<shape type="sphere" id="ball"><bsdf type="blendbsdf"><float name="weight" value="0.5"/>
  <bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="0.8, 0.1, 0.1"/></bsdf></bsdf>
  <bsdf type="twosided"><bsdf type="roughconductor"><string name="material" value="Au"/></bsdf></bsdf>
</bsdf></shape></scene>""")
    res = convert_scene(xml, tmp_path / "blend.usda", check_usd=False)
    text = "\n".join(res.warnings)
    assert "RoughConductor: complex Fresnel" in text and "different UsdPreviewSurface workflows" in text


def test_shapes_sharing_a_bsdf_keep_their_ids_for_bakes_and_benches(tmp_path):
    # Mitsuba's default load merges the meshes that share a BSDF (a <ref> to one material, as exporters write them)
    # into nameless meshes: a bake or an accuracy bench of such a shape said "no shape with id 'seat'; the scene has []"
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import load_scene, pick_shapes

    (tmp_path / "q.obj").write_text("v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n")
    xml = tmp_path / "shared.xml"
    xml.write_text(HEAD + """<bsdf type="diffuse" id="wood"/>
<shape type="cube" id="seat"><ref id="wood"/></shape>
<shape type="obj" id="back"><string name="filename" value="q.obj"/><ref id="wood"/></shape>
<shape type="obj"><string name="filename" value="q.obj"/><transform name="to_world"><translate y="3"/></transform>
  <ref id="wood"/></shape>
</scene>""")
    scene = load_scene(load_mitsuba(), xml)
    assert [s.id() for s in pick_shapes(scene, ["seat", "back"], file=str(xml))] == ["seat", "back"]


def test_a_non_uniformly_scaled_sphere_is_written_round_as_mitsuba_draws_it(tmp_path):
    # Mitsuba draws a sphere of radius = its to_world's x-axis scale whatever the other axes say; the converter wrote an
    # ellipsoid (MSE 4.4x the noise at 32x32, 64 spp) and an emitting one as a SphereLight of the mean scale (ratio 0.31)
    import numpy as np
    from pxr import Usd, UsdGeom, UsdLux

    xml = tmp_path / "egg.xml"
    xml.write_text(HEAD + """
<shape type="sphere" id="egg"><transform name="to_world"><scale x="0.5" y="0.25" z="0.3"/><rotate z="1" angle="30"/>
  <translate y="0.6"/></transform><bsdf type="diffuse"/></shape>
<shape type="sphere" id="bulb"><transform name="to_world"><scale x="0.3" y="0.1" z="0.1"/><translate x="2"/></transform>
  <emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>
</scene>""")
    res = convert_scene(xml, tmp_path / "egg.usda", check_usd=False)
    stage = _stage(res.output)
    m = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Geometry/egg")).ComputeLocalToWorldTransform(
        Usd.TimeCode.Default()))
    np.testing.assert_allclose(np.linalg.norm(m[:3, :3], axis=1), [0.5, 0.5, 0.5], rtol=1e-6)  # round, radius 0.5
    np.testing.assert_allclose(m[3, :3], [0, 0.6, 0], atol=1e-6)
    assert UsdLux.SphereLight(stage.GetPrimAtPath("/World/Lights/bulb")).GetRadiusAttr().Get() == pytest.approx(0.3)
    assert sum("radius 0.5 (the scale along its x axis)" in w or "radius 0.3 (the scale" in w for w in res.warnings) == 2


def test_a_baked_non_uniformly_scaled_sphere_is_the_round_sphere_mitsuba_renders(tmp_path):
    # the bake's tessellation took to_world as it is: an ellipsoid asset geometry around the round sphere that Mitsuba
    # rendered into its training views
    import numpy as np

    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.analytic import world_mesh
    from nasset_converters.mitsuba.scene import load_scene

    xml = tmp_path / "egg.xml"
    xml.write_text(HEAD + '<shape type="sphere" id="egg"><transform name="to_world"><scale x="0.5" y="0.25" z="0.3"/>'
                   '<translate y="0.6"/></transform></shape></scene>')
    mi = load_mitsuba()
    shape = next(s for s in load_scene(mi, xml).shapes() if s.id() == "egg")
    pts, _, _ = world_mesh(mi, shape)
    np.testing.assert_allclose(np.linalg.norm(pts - [0, 0.6, 0], axis=1).max(), 0.5, rtol=1e-5)
    box = shape.bbox()
    np.testing.assert_allclose(pts.min(0), np.array(box.min), atol=2e-3)  # Mitsuba's own bounds: the round sphere


def test_a_scaled_envmap_is_warned(tmp_path):
    # Mitsuba looks a scaled envmap up with unnormalised directions and lights the scene inconsistently with that lookup
    # (measured 10 % darker than a dome that follows it): it was converted without a word
    import numpy as np

    from nasset_sdk.images import write_exr

    write_exr(tmp_path / "sky.exr", np.ones((4, 8, 3), np.float32))
    xml = tmp_path / "env.xml"
    for scale, warned in (("3", True), ("1", False)):
        xml.write_text(HEAD.replace('<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>', "")
                       + f'<emitter type="envmap" id="sky"><string name="filename" value="sky.exr"/><transform '
                       f'name="to_world"><scale value="{scale}"/><rotate y="1" angle="30"/></transform></emitter></scene>')
        res = convert_scene(xml, tmp_path / "env.usda", check_usd=False)
        assert any("envmap to_world scales" in w for w in res.warnings) is warned


def test_the_converted_stage_is_written_atomically(tmp_path):
    # the output was deleted first and written in place: a conversion failing half way lost the earlier stage, and an
    # output folder that could not be created was a raw FileExistsError traceback
    import numpy as np

    from nasset_sdk.errors import NassetError
    from nasset_sdk.images import write_png

    write_png(tmp_path / "c.png", np.full((4, 4, 3), 90, np.uint8))
    xml = tmp_path / "t.xml"
    xml.write_text(HEAD + '<shape type="rectangle" id="floor"><bsdf type="diffuse"><texture type="bitmap" '
                   'name="reflectance"><string name="filename" value="c.png"/></texture></bsdf></shape></scene>')
    out = tmp_path / "out" / "t.usda"
    res = convert_scene(xml, out, check_usd=False)
    before = out.read_text()
    for tex in res.textures:  # the next conversion cannot write its texture: a folder stands in its way
        Path(tex).unlink()
        Path(tex).mkdir()
    with pytest.raises(NassetError) as e:
        convert_scene(xml, out, check_usd=False)
    assert e.value.code == "WRITE_FAILED"
    assert out.read_text() == before and sorted(p.name for p in out.parent.iterdir()) == ["t.usda", "t_textures"]
    with pytest.raises(NassetError) as e:
        convert_scene(xml, xml / "o.usda", check_usd=False)  # the output folder would be a file
    assert e.value.code == "WRITE_FAILED"


def test_sunsky_becomes_a_sky_dome_and_a_sun(tmp_path):
    # Mitsuba's sunsky was skipped with a warning (an outdoor scene went dark): it is now its sky resampled into a dome
    # and its sun a DistantLight of its aperture (fidelity scene sunsky: MSE 1.03x the noise at 32x32, 64 spp)
    import numpy as np
    from pxr import Usd, UsdGeom, UsdLux

    xml = tmp_path / "sun.xml"
    xml.write_text(HEAD.replace('<emitter type="constant"><rgb name="radiance" value="0.5"/></emitter>', "")
                   + '<emitter type="sunsky" id="sky"><vector name="sun_direction" value="0.4, 0.3, 0.6"/></emitter>'
                   '<shape type="sphere"/></scene>')
    res = convert_scene(xml, tmp_path / "sun.usda", check_usd=False)
    assert not res.warnings
    stage = _stage(res.output)
    dome = UsdLux.DomeLight(stage.GetPrimAtPath("/World/Lights/sky"))
    assert dome and dome.GetTextureFileAttr().Get().path.endswith(".exr")
    sun = UsdLux.DistantLight(stage.GetPrimAtPath("/World/Lights/sky_sun"))
    assert sun.GetAngleAttr().Get() == pytest.approx(0.5358, rel=1e-4)
    m = np.array(UsdGeom.Xformable(sun.GetPrim()).ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
    toward = np.array([0.4, 0.3, 0.6]) / np.linalg.norm([0.4, 0.3, 0.6])
    np.testing.assert_allclose(m[2, :3] / np.linalg.norm(m[2, :3]), toward, atol=1e-6)  # +Z toward the sun
    assert sun.GetIntensityAttr().Get() > 0.1


def test_a_textured_blend_weight_is_warned(tmp_path):
    # a bitmap (or procedural) blendbsdf weight was replaced by its mean without a word (the blend branch returned before
    # the per-parameter texture notes)
    import numpy as np

    from nasset_sdk.images import write_png

    write_png(tmp_path / "w.png", np.where(np.arange(16)[:, None] % 2, 255, 0).repeat(16, 1)[..., None].repeat(3, -1)
              .astype(np.uint8))
    for weight, warned in (('<texture type="bitmap" name="weight"><string name="filename" value="w.png"/></texture>', True),
                           ('<texture type="checkerboard" name="weight"/>', True), ('<float name="weight" value="0.3"/>', False)):
        xml = tmp_path / "blend.xml"
        xml.write_text(HEAD + f'<shape type="sphere"><bsdf type="blendbsdf">{weight}<bsdf type="diffuse"/>'
                       '<bsdf type="diffuse"><rgb name="reflectance" value="0.9, 0.1, 0.1"/></bsdf></bsdf></shape></scene>')
        res = convert_scene(xml, tmp_path / "blend.usda", check_usd=False)
        assert any("blendbsdf weight is a texture" in w for w in res.warnings) is warned, weight


def test_a_procedural_mask_opacity_is_its_image_or_warned(tmp_path):
    """A non-bitmap opacity was replaced by its mean without a word; it is warned, and a checkerboard (which Mitsuba
    evaluates from uv alone) is written as the image of the float values Mitsuba's mask reads (``eval_1``)."""
    from pxr import Usd, UsdShade

    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.usd_export import RASTERIZED_TEXELS
    from nasset_sdk.images import read_exr

    xml = tmp_path / "mask.xml"
    xml.write_text(HEAD + '<shape type="rectangle"><bsdf type="mask" id="cut"><texture type="checkerboard" '
                   'name="opacity"/><bsdf type="diffuse"/></bsdf></shape></scene>')
    res = convert_scene(xml, tmp_path / "mask.usda", check_usd=False)
    assert not any("cannot map" in w for w in res.warnings), res.warnings
    stage = Usd.Stage.Open(str(tmp_path / "mask.usda"))
    src = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/cut/PreviewSurface")).GetInput("opacity")
    texels = read_exr(UsdShade.Shader(src.GetConnectedSource()[0].GetPrim()).GetInput("file").Get().resolvedPath)
    mi = load_mitsuba(None)
    g = (np.arange(RASTERIZED_TEXELS) + 0.5) / RASTERIZED_TEXELS
    v, u = np.meshgrid(g, g, indexing="ij")
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(u.ravel().astype(np.float32), v.ravel().astype(np.float32))
    want = np.asarray(mi.load_dict({"type": "checkerboard"}).eval_1(si)).reshape(u.shape)
    np.testing.assert_allclose(texels[..., 0], want, atol=1e-6)

    # a texture the converter cannot evaluate from uv (a mesh attribute): its mean, warned
    xml.write_text(HEAD + '<shape type="rectangle"><bsdf type="mask"><texture type="mesh_attribute" name="opacity">'
                   '<string name="name" value="vertex_color"/></texture><bsdf type="diffuse"/></bsdf></shape></scene>')
    res = convert_scene(xml, tmp_path / "mask2.usda", check_usd=False)
    assert any("mask opacity is a texture the converter cannot map" in w for w in res.warnings), res.warnings


def test_a_hair_bsdf_keeps_the_colour_of_its_absorption(tmp_path):
    """A ``hair`` BSDF was grey 0.5 (curves of three hair BSDFs against Mitsuba at 48², 64 spp: MSE / noise 3.4-10.6;
    1.5-3.0 now). Its absorption is written as the colour Chiang et al.'s mapping c -> sigma_a = (ln c / f(beta_n))²
    takes to it: the absorption made from a colour here gives that colour back, plus the cuticle's Fresnel F0."""
    from pxr import Gf, Usd, UsdShade

    beta = 0.3
    f = 5.969 - 0.215 * beta + 2.532 * beta**2 - 10.73 * beta**3 + 5.574 * beta**4 + 0.245 * beta**5
    colour = np.array([0.6, 0.35, 0.15])
    sigma_a = (np.log(colour) / f) ** 2
    xml = tmp_path / "hair.xml"
    xml.write_text(HEAD + '<shape type="rectangle"><bsdf type="hair" id="fibre"><rgb name="sigma_a" value="'
                   + ", ".join(f"{x:.9g}" for x in sigma_a) + '"/></bsdf></shape>'
                   '<shape type="rectangle"><transform name="to_world"><translate x="3"/></transform>'
                   '<bsdf type="hair" id="brown"/></shape></scene>')
    res = convert_scene(xml, tmp_path / "hair.usda", check_usd=False)
    assert any("hair BSDF written as a diffuse surface" in w for w in res.warnings), res.warnings
    stage = Usd.Stage.Open(str(tmp_path / "hair.usda"))

    def surface(name):
        return UsdShade.Shader(stage.GetPrimAtPath(f"/World/Looks/{name}/PreviewSurface"))

    np.testing.assert_allclose(surface("fibre").GetInput("diffuseColor").Get(), colour, rtol=1e-4)
    f0 = ((1.55 - 1) / 2.55) ** 2  # Mitsuba's default eta 1.55 (stored as 1.549)
    np.testing.assert_allclose(surface("fibre").GetInput("specularColor").Get(), Gf.Vec3f(f0, f0, f0), rtol=5e-3)
    brown = np.array(surface("brown").GetInput("diffuseColor").Get())  # Mitsuba's default melanin: a dark brown
    assert brown[0] > brown[1] > brown[2] and brown[0] < 0.1
