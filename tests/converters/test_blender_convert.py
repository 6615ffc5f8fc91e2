"""``nasset convert-scene`` for Blender scenes: camera, lights, world, meshes, materials, warnings.

Needs Blender's Python module (``pip install bpy``, installed in CI); skipped without it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")

from nasset_converters.blender.examples import build_example, write_example_blend  # noqa: E402
from nasset_converters.blender.usd_export import (  # noqa: E402
    DOME_ROWS,
    convert_scene,
    cycles_pixel_filter,
    map_material,
    principled_diffuse_scale,
)
from nasset_sdk.errors import NassetError  # noqa: E402


def _attr(stage, path, name):
    return stage.GetPrimAtPath(path).GetAttribute(name).Get()


@pytest.mark.parametrize("example", ["blender-surface", "blender-hair"])
def test_examples_convert_and_pass_usd_checks(example, tmp_path):
    from pxr import Usd

    res = convert_scene(None, tmp_path / "s.usda", example=example)
    assert not [c for c in res.usd_checks if c["severity"] == "error"], res.usd_checks
    stage = Usd.Stage.Open(str(res.output))
    assert stage.GetPrimAtPath("/World/Camera").GetTypeName() == "Camera"
    assert res.resolution == (128, 128)
    ha, fl = _attr(stage, "/World/Camera", "horizontalAperture"), _attr(stage, "/World/Camera", "focalLength")
    assert np.isclose(2 * math.degrees(math.atan(ha / (2 * fl))), 40.0, atol=1e-3)  # 40 deg fov
    # USD's lens unit is a tenth of a scene unit: the camera's lens in mm / 100 in a metre scene
    import bpy

    assert np.isclose(fl, bpy.data.objects["Camera"].data.lens / 100.0, rtol=1e-6)
    # sun: irradiance 3 W/m^2, angular diameter 1 deg
    assert np.isclose(_attr(stage, "/World/Lights/Sun", "inputs:intensity"), 3.0)
    assert np.isclose(_attr(stage, "/World/Lights/Sun", "inputs:angle"), 1.0, atol=1e-4)
    # area light: 40 W over 1 x 0.6 m -> radiance 40 / (pi 0.6)
    assert np.isclose(_attr(stage, "/World/Lights/Fill", "inputs:intensity"), 40.0 / (math.pi * 0.6), rtol=1e-5)
    assert stage.GetPrimAtPath("/World/Lights/World").GetTypeName() == "DomeLight"
    assert stage.GetPrimAtPath("/World/Geometry/Ground").GetTypeName() == "Mesh"
    if example == "blender-surface":  # the subsurface Monkey stays a mesh, with a warning
        assert stage.GetPrimAtPath("/World/Geometry/Monkey").IsValid()
        assert any("Subsurface" in w for w in res.warnings)
    else:
        assert any("hair curves outside an asset" in w for w in res.warnings)


def test_camera_and_sun_directions_match_blender(tmp_path):
    """The converted camera looks where Blender's does and the sun shines from where Blender's does
    (both checked against Blender's own matrices, converted to +Y up)."""
    from pxr import Usd, UsdGeom

    build_example("blender-surface")
    sc = bpy.context.scene
    cam_dir_b = -np.array(sc.camera.matrix_world, np.float64)[:3, 2]
    sun_to_b = np.array(sc.objects["Sun"].matrix_world, np.float64)[:3, 2]
    res = convert_scene(None, tmp_path / "s.usda", example="blender-surface")
    stage = Usd.Stage.Open(str(res.output))
    m = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Camera")).ComputeLocalToWorldTransform(0))
    look = -m[2, :3] / np.linalg.norm(m[2, :3])
    assert np.allclose(look, [cam_dir_b[0], cam_dir_b[2], -cam_dir_b[1]], atol=1e-6)
    ms = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Lights/Sun")).ComputeLocalToWorldTransform(0))
    assert np.allclose(ms[2, :3] / np.linalg.norm(ms[2, :3]), [sun_to_b[0], sun_to_b[2], -sun_to_b[1]], atol=1e-6)


def test_point_spot_lights_and_materials(tmp_path):
    build_example("blender-surface")
    for kind, name in (("POINT", "Bulb"), ("SPOT", "Spot")):
        lt = bpy.data.lights.new(name, kind)
        lt.energy = 100.0
        lt.shadow_soft_size = 0.1
        ob = bpy.data.objects.new(name, lt)
        bpy.context.scene.collection.objects.link(ob)
        ob.location = (1.0, 2.0, 3.0)
    bpy.context.view_layer.update()
    blend = tmp_path / "lights.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    from pxr import Usd

    res = convert_scene(blend, tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    L = 100.0 / (4 * math.pi ** 2 * 0.01)  # sphere light radiance P / (4 pi^2 r^2)
    assert np.isclose(_attr(stage, "/World/Lights/Bulb", "inputs:intensity"), L, rtol=1e-5)
    assert np.isclose(_attr(stage, "/World/Lights/Bulb", "inputs:radius"), 0.1, rtol=1e-6)
    # the spot of radius 0.1 is the same sphere, shaped (renderer.md#spot-lights); it was a point spot before
    assert not any("Spot" in w and "point spot" in w for w in res.warnings)
    spot = stage.GetPrimAtPath("/World/Lights/Spot")
    assert not spot.GetAttribute("treatAsPoint").Get() and np.isclose(spot.GetAttribute("inputs:intensity").Get(), L, rtol=1e-5)
    assert np.isclose(spot.GetAttribute("inputs:radius").Get(), 0.1, rtol=1e-6)
    assert spot.GetAttribute("nasset:shaping:falloff").Get() == "smoothstep"
    assert np.isclose(spot.GetAttribute("inputs:shaping:cone:angle").Get(), 22.5, rtol=1e-5)  # spot_size 45 deg / 2
    assert not stage.GetPrimAtPath("/World/Lights/Bulb").GetAttribute("nasset:cameraVisibility").Get()
    from pxr import UsdGeom

    pos = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Lights/Bulb")).ComputeLocalToWorldTransform(0))[3, :3]
    assert np.allclose(pos, [1.0, 3.0, -2.0])  # (x, z, -y)
    mat = bpy.data.materials["SubsurfaceSkin"]
    inputs, notes = map_material(mat)
    k = principled_diffuse_scale(0.35, 1.5)
    assert np.allclose(inputs["diffuseColor"], np.array((0.9, 0.5, 0.3)) * k) and np.isclose(inputs["roughness"], 0.35)
    assert any("x 0." in n and "albedo" in n for n in notes)
    assert any("Subsurface Weight" in n for n in notes)
    ground, notes = map_material(bpy.data.materials["GroundGrey"])
    assert ground["useSpecularWorkflow"] == 1 and tuple(ground["specularColor"]) == (0.0, 0.0, 0.0) and not notes


def test_dome_rotation_maps_blender_equirect_to_renderer_latlong():
    """A Blender world direction D (Z up) has equirect u = 1/2 - atan2(D.y, D.x)/2pi (+X at the image's centre
    column, +Y a quarter to its left) and image row v = acos(D.z)/pi from the top, as Cycles renders it (the
    fidelity suite's hdri scene: with the previous, mirrored mapping its mean green was 1.49x Cycles'); the
    renderer's lookup through the written dome rotation agrees."""
    from nasset_reference_renderer.lights import DomeLight

    rng = np.random.default_rng(3)
    D = rng.normal(size=(64, 3))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    u_b = np.mod(0.5 - np.arctan2(D[:, 1], D[:, 0]) / (2 * np.pi), 1.0)
    v_b = np.arccos(D[:, 2]) / np.pi
    d_world = np.stack([D[:, 0], D[:, 2], -D[:, 1]], 1)
    R = DOME_ROWS[:3, :3]
    uv = DomeLight.dir_to_uv(d_world @ np.linalg.inv(R))
    du = np.abs(uv[:, 0] - u_b)
    assert np.all(np.minimum(du, 1 - du) < 1e-9) and np.allclose(uv[:, 1], v_b)


def test_replace_and_errors(tmp_path):
    blend = write_example_blend("blender-hair", tmp_path)
    with pytest.raises(NassetError) as e:
        convert_scene(blend, tmp_path / "s.usda", replace=["Nobody=x.usdc"])
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN"
    with pytest.raises(NassetError) as e:
        convert_scene(blend, tmp_path / "s.usda", replace=[f"Hair={tmp_path / 'missing.usdc'}"])
    assert e.value.code == "CONVERT_ASSET_REFERENCE"
    with pytest.raises(NassetError) as e:
        convert_scene(tmp_path / "none.blend", tmp_path / "s.usda")
    assert e.value.code == "CONVERT_SCENE_MISSING"


def test_an_asset_of_other_objects_is_warned(tmp_path):
    """``--replace Ground=ASSET`` with an asset baked from ``Monkey``: placed without a word before; now warned."""
    from nasset_converters.blender import scene as bsc
    from nasset_converters.blender.scene import open_blend
    from nasset_sdk.examples import example_builder

    blend = write_example_blend("blender-surface", tmp_path)
    open_blend(blend)
    b = example_builder("rna", size="tiny", seed=2)
    b.set_geometry(bsc.asset_geometry(bsc.pick_objects(["Monkey"]))[1])
    asset = b.write(tmp_path / "monkey.usdc")
    good = convert_scene(blend, tmp_path / "a.usda", replace=[f"Monkey={asset}"])
    assert not [w for w in good.warnings if "baked from" in w]
    bad = convert_scene(blend, tmp_path / "b.usda", replace=[f"Ground={asset}"])
    assert [w for w in bad.warnings if "Ground" in w and "not baked from" in w]


def test_principled_diffuse_scale_against_smooth_limit():
    """A smooth lobe (alpha at the renderer's minimum) has the cosine-weighted mean Schlick reflectance as albedo:
    2 int_0^1 (f0 + (1 - f0)(1 - mu)^5) mu dmu = f0 + (1 - f0) / 21; rougher lobes lose albedo (G2 < G1)."""
    f0 = 0.04
    assert principled_diffuse_scale(0.0, 1.5) == pytest.approx(1.0 - (f0 + (1 - f0) / 21.0), abs=1e-3)
    ks = [principled_diffuse_scale(r, 1.5) for r in (0.0, 0.3, 0.6, 1.0)]
    assert all(a < b for a, b in zip(ks, ks[1:], strict=False)) and ks[-1] < 1.0


def test_cycles_pixel_filter_widths():
    """Cycles' Gaussian exp(-2 (6x/w)^2) has stddev w/12; the Blackman-Harris window over [-w/2, w/2] has a
    stddev of 0.1385 w (numerical integral of the 4-term window, independent of the converter's grid)."""
    assert cycles_pixel_filter("GAUSSIAN", 1.5) == ("gaussian", pytest.approx(0.125))
    from scipy.integrate import quad

    c = (0.35875, -0.48829, 0.14128, -0.01168)
    bh = lambda x: sum(a * math.cos(2 * math.pi * k * (x + 0.5)) for k, a in enumerate(c))  # noqa: E731
    sd = math.sqrt(quad(lambda x: bh(x) * x * x, -0.5, 0.5)[0] / quad(bh, -0.5, 0.5)[0])
    kind, got = cycles_pixel_filter("BLACKMAN_HARRIS", 2.0)
    assert kind == "gaussian" and got == pytest.approx(2.0 * sd, rel=1e-4)
    assert cycles_pixel_filter("BOX", 1.0) == ("box", None)


def test_instances_and_linked_duplicates_become_instanceable_prims(tmp_path):
    """The fidelity suite's instances scene: 3 collection instances of (Head, Body) and 2 objects sharing the
    Pebble mesh -> 3 class prototypes and 8 instanceable Xforms; the excluded collection's own objects are not
    written as plain meshes."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("instances", tmp_path, 8), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    protos = stage.GetPrimAtPath("/Prototypes").GetAllChildren()  # class prims: abstract
    assert len(protos) == 3 and all(p.IsAbstract() for p in protos), protos
    inst = [p for p in stage.GetPrimAtPath("/World/Geometry").GetChildren() if p.IsInstance()]
    assert len(inst) == 8
    plain = [p.GetName() for p in stage.GetPrimAtPath("/World/Geometry").GetChildren() if not p.IsInstance()]
    assert plain == ["Floor"], plain


def test_curves_text_surfaces_and_metaballs_become_one_mesh_each(tmp_path):
    """Objects that are not meshes but render as surfaces (a bevelled curve, text, a NURBS surface, a metaball) are
    written as their evaluated mesh, once: they used to be skipped (the fidelity suite's surface_types scene then read
    a noise ratio of 81), and their evaluated geometry is also listed among the depsgraph's instances."""
    from pxr import Usd, UsdGeom

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("surface_types", tmp_path, 8), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    children = stage.GetPrimAtPath("/World/Geometry").GetChildren()
    assert sorted(p.GetName() for p in children) == ["AutoSmoothBox", "Blob", "Floor", "Label", "Nurbs", "Ring"]
    faces = {p.GetName(): len(UsdGeom.Mesh(p).GetFaceVertexCountsAttr().Get()) for p in children if p.IsA(UsdGeom.Mesh)}
    assert len(faces) == 6 and min(n for name, n in faces.items() if name != "Floor") >= 12, faces
    assert not stage.GetPrimAtPath("/Prototypes") and not res.warnings, res.warnings


def test_emissive_mesh_too_large_to_light_sample_is_warned(tmp_path):
    from nasset_converters.blender.fidelity import _material

    build_example("blender-surface")
    glow = _material(bpy, "Glow", "emission", **{"Color": (1.0, 1.0, 1.0), "Strength": 3.0})
    for op, name, kw in (("cube", "SmallLamp", {"size": 0.2}), ("uv_sphere", "BigLamp", {"radius": 0.1})):
        getattr(bpy.ops.mesh, f"primitive_{op}_add")(location=(1.0, 1.0, 1.0), **kw)
        bpy.context.active_object.name = name
        bpy.context.active_object.data.materials.append(glow)
    blend = tmp_path / "lamps.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    res = convert_scene(blend, tmp_path / "s.usda")
    assert [w for w in res.warnings if "BigLamp" in w and "light-samples" in w]
    assert not [w for w in res.warnings if "SmallLamp" in w]


def test_ray_visibility_holdout_and_shadow_catcher_are_warned(tmp_path):
    """Cycles' per-object ray visibility, holdout and shadow catcher have no USD counterpart: each is named in a
    warning (the object is written as an ordinary surface). Before, they were dropped silently."""
    from nasset_converters.blender.fidelity import _floor, _new_scene
    from nasset_converters.blender.usd_export import convert_scene

    _new_scene(bpy, 8, (0.0, -2.8, 1.2), (0.0, 0.0, 0.3))
    floor = _floor(bpy)
    floor.visible_camera = False
    floor.is_shadow_catcher = True
    blend = tmp_path / "s.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    res = convert_scene(blend, tmp_path / "s.usda", check_usd=False)
    said = [w for w in res.warnings if "Floor" in w]
    assert said and "invisible to camera rays" in said[0] and "is_shadow_catcher" in said[0], res.warnings


def test_geometry_is_evaluated_as_cycles_renders_it(tmp_path):
    """Python reaches only the viewport depsgraph, which evaluated the fidelity suite's render_evaluation scene with
    the viewport's settings: the Subdivision Surface at level 0 (12 triangles), the render-only Bevel left out, the
    viewport-only Array's three boxes, the curve at resolution 1, the instances of an empty disabled in viewports
    dropped, and the vertex instancer's grid and original stud written (Cycles renders neither). The render settings
    are now copied onto the viewport ones (noise ratio 92 before, 1.1 after, 64 x 64, 64 spp)."""
    from pxr import Usd, UsdGeom

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("render_evaluation", tmp_path, 8), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    children = stage.GetPrimAtPath("/World/Geometry").GetChildren()
    faces = {p.GetName(): len(UsdGeom.Mesh(p).GetFaceVertexCountsAttr().Get()) for p in children if p.IsA(UsdGeom.Mesh)}
    assert faces["Rounded"] == 12 * 4 ** 3, faces  # render level 3
    assert faces["Bevelled"] > 12 and faces["Row"] == 12, faces  # Bevel in renders only, Array in the viewport only
    assert faces["Ring"] >= 4 * 16 * 4, faces  # render resolution 16 per segment
    assert "HiddenInViewport" in faces and "Studs" not in faces and "Stud" not in faces, faces
    placed = sorted(p.GetName() for p in children if p.IsInstance())
    assert placed == ["PebblePlacer_Pebble"] + [f"Studs_Stud{s}" for s in ("", "_2", "_3", "_4")], placed
    assert not res.warnings, res.warnings


def test_particle_instances_and_viewport_only_node_branches(tmp_path):
    """A hair particle system rendered as Object instances, displayed as nothing in the viewport at 20 %: Cycles
    renders all its instances (they were dropped, with a warning about particle hair). A Geometry Nodes group that
    reads Is Viewport is written as its viewport branch, warned by the modifier's name."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import _add, _new_scene

    _new_scene(bpy, 8, (0.0, -6.0, 2.0), (0.0, 0.0, 0.0))
    pebble = _add(bpy, "uv_sphere", "Pebble", None, radius=0.08, location=(5.0, 5.0, 5.0), segments=8, ring_count=4)
    emitter = _add(bpy, "plane", "Emitter", None, size=1.0)
    settings = emitter.modifiers.new("Particles", "PARTICLE_SYSTEM").particle_system.settings
    settings.type, settings.count, settings.render_type, settings.instance_object = "HAIR", 10, "OBJECT", pebble
    settings.display_method, settings.display_percentage = "NONE", 20
    tree = bpy.data.node_groups.new("Switcher", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gin, gout = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    switch, viewport = tree.nodes.new("GeometryNodeSwitch"), tree.nodes.new("GeometryNodeIsViewport")
    tree.links.new(viewport.outputs[0], switch.inputs["Switch"])
    tree.links.new(gin.outputs[0], switch.inputs["False"])
    tree.links.new(switch.outputs[0], gout.inputs[0])
    box = _add(bpy, "cube", "Proxy", None, size=0.5, location=(0.0, 1.0, 0.5))
    box.modifiers.new("ViewportProxy", "NODES").node_group = tree
    blend = tmp_path / "particles.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    res = convert_scene(blend, tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    placed = [p for p in stage.GetPrimAtPath("/World/Geometry").GetChildren() if p.IsInstance()]
    assert len(placed) == 10, [p.GetName() for p in placed]
    assert not [w for w in res.warnings if "particle hair" in w], res.warnings
    assert [w for w in res.warnings if "ViewportProxy" in w and "Is Viewport" in w], res.warnings


def _linked_scene(tmp_path):
    """main.blend: two red cubes sharing a local mesh "Cube" and material "Paint"; linked from lib.blend, two green
    balls sharing the library's mesh also named "Cube" and its material also named "Paint"."""
    from nasset_converters.blender.fidelity import _add, _material, _new_scene

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    paint = _material(bpy, "Paint", **{"Color": (0.1, 0.9, 0.1)})
    ball = _add(bpy, "uv_sphere", "LibBall", paint, radius=0.3)
    ball.data.name = "Cube"
    twin = bpy.data.objects.new("LibBallTwin", ball.data)
    bpy.context.scene.collection.objects.link(twin)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "lib.blend"))
    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    cube = _add(bpy, "cube", "LocalCube", _material(bpy, "Paint", **{"Color": (0.9, 0.1, 0.1)}), size=0.3)
    cube.data.name = "Cube"
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("LocalCubeTwin", cube.data))
    with bpy.data.libraries.load(str(tmp_path / "lib.blend"), link=True, relative=True) as (_, linked):
        linked.objects = ["LibBall", "LibBallTwin"]
    for ob in linked.objects:
        bpy.context.scene.collection.objects.link(ob)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "main.blend"))
    return tmp_path / "main.blend"


def test_linked_data_named_like_local_data_keeps_its_own_mesh_and_material(tmp_path):
    """Blender names are unique per library only: a linked mesh and material named like local ones were taken for
    them (the linked balls were written as instances of the local red cube). They are told apart by full name."""
    from pxr import Usd, UsdGeom, UsdShade

    res = convert_scene(_linked_scene(tmp_path), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    for name, triangles, rgb in (("LocalCube", 12, (0.9, 0.1, 0.1)), ("LibBall", 960, (0.1, 0.9, 0.1))):
        placed = stage.GetPrimAtPath(f"/World/Geometry/{name}")
        assert placed.IsInstance(), name
        mesh = next(p for p in Usd.PrimRange(placed.GetPrototype()) if p.IsA(UsdGeom.Mesh))
        assert len(UsdGeom.Mesh(mesh).GetFaceVertexCountsAttr().Get()) == triangles, name
        material = UsdShade.MaterialBindingAPI(mesh).ComputeBoundMaterial()[0]
        shader = stage.GetPrimAtPath(material.GetPath().AppendChild("PreviewSurface"))
        assert np.allclose(shader.GetAttribute("inputs:diffuseColor").Get(), rgb, atol=1e-6), name


def test_a_missing_library_is_warned_by_name(tmp_path):
    """A library that is not where the file says: its objects are empty placeholders, which Cycles renders as nothing;
    they were dropped without a word. The converter names the library and its objects; the bake refuses them."""
    import shutil

    from nasset_converters.blender.scene import open_blend, pick_objects

    blend = _linked_scene(tmp_path)
    moved = tmp_path / "moved"
    moved.mkdir()
    shutil.copy(blend, moved / "main.blend")
    res = convert_scene(moved / "main.blend", moved / "s.usda")
    assert [w for w in res.warnings if "library lib.blend" in w and "missing" in w and "LibBall, LibBallTwin" in w], \
        res.warnings
    open_blend(moved / "main.blend")
    with pytest.raises(NassetError) as e:
        pick_objects(["LibBall"])
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "lib.blend" in str(e.value)


def test_links_are_read_as_cycles_reads_them(tmp_path):
    """The fidelity suite's node_links scene (MSE 588x its noise before, 64 x 64, 64 spp): a texture through Reroutes
    or a muted node reached the BSDF as "dropped" (the socket's default), a muted link was followed (Cycles ignores
    it), RGB and Value nodes were dropped, and a material without a Surface link or with a muted shader was grey
    (Cycles: black)."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.mitsuba.usd_export import TextureMap

    build("node_links", tmp_path, 8)
    mats = {name: map_material(bpy.data.materials[name]) for name in ("Rerouted", "MutedInvert", "MutedLink",
                                                                        "Constants", "NoSurface", "MutedShader")}
    assert isinstance(mats["Rerouted"][0]["diffuseColor"], TextureMap), mats["Rerouted"]
    assert isinstance(mats["MutedInvert"][0]["diffuseColor"], TextureMap), mats["MutedInvert"]
    assert np.allclose(mats["MutedLink"][0]["diffuseColor"], (0.8, 0.15, 0.1)), mats["MutedLink"]
    inputs, notes = mats["Constants"]
    scale = principled_diffuse_scale(0.9, 1.5)
    assert np.allclose(inputs["diffuseColor"], np.multiply((0.1, 0.6, 0.2), scale), atol=1e-4)
    assert np.isclose(inputs["roughness"], 0.9)
    for name in ("NoSurface", "MutedShader"):
        inputs, notes = mats[name]
        assert inputs["diffuseColor"] == (0.0, 0.0, 0.0) and inputs["specularColor"] == (0.0, 0.0, 0.0), (name, inputs)
        assert not notes, notes
    assert "Rerouted" in bpy.data.materials and len(bpy.data.materials) == len(set(bpy.data.materials.keys()))


def test_a_world_colour_through_a_reroute_from_an_rgb_node_is_the_dome(tmp_path):
    """An RGB node through a Reroute on the Background colour: the world was dropped ("background colour from
    NodeReroute"), a black sky where Cycles lights the scene."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import _new_scene, _world

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    nt = _world(bpy, strength=2.0).node_tree
    rgb, reroute = nt.nodes.new("ShaderNodeRGB"), nt.nodes.new("NodeReroute")
    rgb.outputs[0].default_value = (0.2, 0.4, 0.6, 1.0)
    nt.links.new(rgb.outputs[0], reroute.inputs[0])
    nt.links.new(reroute.outputs[0], next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBackground").inputs["Color"])
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "w.blend"))
    res = convert_scene(tmp_path / "w.blend", tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    dome = stage.GetPrimAtPath("/World/Lights/World")
    rgb = np.array(dome.GetAttribute("inputs:color").Get()) * dome.GetAttribute("inputs:intensity").Get()
    assert np.allclose(rgb, (0.4, 0.8, 1.2), rtol=1e-5), (rgb, res.warnings)
    assert len(bpy.data.worlds) == 1  # the resolved copy is gone


def test_node_groups_are_read_through(tmp_path):
    """An Image Texture into a node group whose nested group holds a Principled BSDF (Base Color from the outer
    group's input, Roughness from a value set on the inner group node): the group node was "not convertible" (grey).
    The groups are ungrouped in a temporary copy, so the texture and the roughness reach the mapping."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.mitsuba.usd_export import TextureMap

    build("node_links", tmp_path, 8)
    inputs, notes = map_material(bpy.data.materials["Grouped"])
    assert isinstance(inputs["diffuseColor"], TextureMap) and np.isclose(inputs["roughness"], 0.8), (inputs, notes)
    assert not [n for n in notes if "not convertible" in n], notes
    assert sorted(bpy.data.node_groups.keys()) == ["InnerPaint", "OuterPaint"]  # the file's groups untouched


def test_light_node_trees_scale_and_tint_the_lights(tmp_path):
    """The fidelity suite's light_nodes scene: a light's node tree (Emission Strength, Color, a Blackbody node) was
    ignored without a warning (MSE 294x its noise, 64 x 64, 64 spp); Cycles multiplies the light by it."""
    from pxr import Usd, UsdLux

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("light_nodes", tmp_path, 8), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))

    def rgb(name):
        prim = stage.GetPrimAtPath(f"/World/Lights/{name}")
        return np.array(prim.GetAttribute("inputs:color").Get()) * prim.GetAttribute("inputs:intensity").Get()

    assert np.allclose(rgb("Bulb"), 30.0 / (4.0 * math.pi), rtol=1e-5)
    body = np.array(UsdLux.BlackbodyTemperatureAsRgb(3500.0))
    assert np.allclose(rgb("Sun"), 1.5 * body, rtol=1e-5)
    assert np.allclose(rgb("Panel"), 15.0 * np.array([0.3, 0.6, 1.0]) / (math.pi * 0.25), rtol=1e-5)
    assert not res.warnings and len(bpy.data.lights) == 3, res.warnings


def test_geometry_nodes_instances_and_evaluated_materials(tmp_path):
    """The fidelity suite's gn_instances scene (MSE 171x its noise before, 64 x 64, 64 spp): instances a Geometry Nodes
    tree makes (of its own geometry or of an object through Object Info) were dropped, the instancer called an object
    "without faces"; realized geometry without materials took the object's material where Cycles shows its default
    surface; and no material was a grey surface with a specular lobe where Cycles' default is a Diffuse BSDF of 0.8."""
    from pxr import Usd, UsdGeom, UsdShade

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("gn_instances", tmp_path, 8), tmp_path / "s.usda")
    assert not res.warnings, res.warnings
    stage = Usd.Stage.Open(str(res.output))
    children = stage.GetPrimAtPath("/World/Geometry").GetChildren()
    placed = sorted(p.GetName().rstrip("_234") for p in children if p.IsInstance())
    assert placed == ["Cubes_Cube"] * 4 + ["Spheres_Mesh"] * 4 + ["WithBase_Mesh"] * 4, placed

    def surface(prim):
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        shader = stage.GetPrimAtPath(material.GetPath().AppendChild("PreviewSurface"))
        return {a.GetBaseName(): a.Get() for a in shader.GetPrim().GetAttributes() if a.GetNamespace() == "inputs"}

    cube = next(p for p in Usd.PrimRange(stage.GetPrimAtPath("/World/Geometry/Cubes_Cube").GetPrototype())
                if p.IsA(UsdGeom.Mesh))
    assert np.allclose(surface(cube)["diffuseColor"], (0.8, 0.2, 0.15)), surface(cube)  # the object's own material
    realized = surface(stage.GetPrimAtPath("/World/Geometry/Realized"))
    assert np.allclose(realized["diffuseColor"], 0.8) and np.allclose(realized["specularColor"], 0.0), realized
    assert realized["useSpecularWorkflow"] == 1


@pytest.mark.parametrize("setting", ["world camera ray visibility", "transparent film"])
def test_a_world_hidden_from_the_camera_is_a_dome_hidden_from_camera_rays(tmp_path, setting):
    """Cycles' transparent film and a world whose camera ray visibility is off render a black background while the
    world still lights the scene (the fidelity scene hidden_world read an MSE 3102x its noise: the sky was shown)."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import _new_scene, _world

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    world = _world(bpy)
    if setting == "transparent film":
        bpy.context.scene.render.film_transparent = True
    else:
        world.cycles_visibility.camera = False
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "w.blend"))
    res = convert_scene(tmp_path / "w.blend", tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    assert stage.GetPrimAtPath("/World/Lights/World").GetAttribute("nasset:cameraVisibility").Get() is False


def test_render_settings_and_image_sources_the_stage_cannot_carry_are_named(tmp_path):
    """Cycles' biased shortcuts (Blender's defaults clamp indirect light at 10 and filter glossy at 1), motion blur, a
    render border and non-square pixels change Cycles' image and were dropped without a word; so were the tiles of a
    UDIM image past the first."""
    from nasset_converters.blender.fidelity import _add, _material, _new_scene

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    sc = bpy.context.scene
    sc.cycles.sample_clamp_indirect, sc.cycles.blur_glossy, sc.cycles.caustics_refractive = 10.0, 1.0, False
    sc.render.use_motion_blur, sc.render.use_border, sc.render.pixel_aspect_x = True, True, 2.0
    mat = _material(bpy, "Tiles")
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = bpy.data.images.new("Udim", 8, 8, tiled=True)
    tex.image.tiles.new(1002)
    mat.node_tree.links.new(tex.outputs["Color"], mat.node_tree.nodes["Diffuse BSDF"].inputs["Color"])
    _add(bpy, "plane", "Tiled", mat)
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "r.blend"))
    res = convert_scene(tmp_path / "r.blend", tmp_path / "s.usda")
    text = "\n".join(res.warnings)
    for part in ("indirect clamp 10", "Filter Glossy 1", "refractive caustics off", "motion blur", "render border",
                 "pixel aspect 2:1", "image Udim is UDIM tiles"):
        assert part in text, (part, res.warnings)


@pytest.mark.parametrize("name, value", [("Diffuse Roughness", 0.8), ("Specular Tint", (1.0, 0.2, 0.2, 1.0)),
                                         ("Coat Weight", 0.5)])
def test_principled_inputs_without_a_counterpart_are_named(name, value):
    """Principled BSDF v4 inputs UsdPreviewSurface cannot carry are warned by name: Diffuse Roughness and a coloured
    Specular Tint were dropped without a word (only the float inputs were compared with their off values)."""
    from nasset_converters.blender.fidelity import _material

    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = _material(bpy, "P", "principled", **{name: value})
    inputs, notes = map_material(mat)
    assert [n for n in notes if f"Principled {name} dropped" in n], notes
    inputs, notes = map_material(_material(bpy, "Plain", "principled"))
    assert not [n for n in notes if "dropped" in n], notes


def test_portals_are_not_lights_and_light_settings_are_named(tmp_path):
    """An area light marked as a portal emits nothing in Cycles (measured: a 100 W portal under a grey world adds
    nothing) and was written as a 100 W RectLight; a light's shadows off, ray visibility off or own bounce limit were
    dropped without a word."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import _light, _new_scene, _world

    _new_scene(bpy, 8, (0.0, 0.0, 4.0), (0.0, 0.0, 0.0))
    _world(bpy)
    _light(bpy, "Window", "AREA", (0.0, 0.0, 2.0), energy=100.0, size=1.0).data.cycles.is_portal = True
    lamp = _light(bpy, "Lamp", "POINT", (1.0, 0.0, 2.0), energy=10.0)
    lamp.data.use_shadow, lamp.visible_glossy, lamp.data.cycles.max_bounces = False, False, 1
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "p.blend"))
    res = convert_scene(tmp_path / "p.blend", tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    assert not stage.GetPrimAtPath("/World/Lights/Window").IsValid()
    assert [w for w in res.warnings if "Lamp" in w and "no shadows" in w and "glossy" in w and "max bounces 1" in w], \
        res.warnings


def test_a_file_with_several_scenes_names_the_one_converted(tmp_path):
    """A .blend holding several scenes converts its active one (as a command-line render does); which one was taken
    went unsaid."""
    from nasset_converters.blender.fidelity import _new_scene

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    bpy.data.scenes.new("Alternate")
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "two.blend"))
    res = convert_scene(tmp_path / "two.blend", tmp_path / "s.usda")
    assert [w for w in res.warnings if "['Alternate', 'Scene']" in w and "'Scene' (the active one)" in w], res.warnings


def test_nodes_between_a_texture_and_a_shader_are_folded_into_the_texels(tmp_path):
    """The fidelity suite's texture_ops scene (MSE 591x its noise before, 64 x 64, 64 spp): a Mix, Color Ramp,
    Separate Color, Math, Map Range, Invert or Brightness/Contrast node between an Image Texture and a shader input
    dropped the texture (the socket's default used). They are applied to the texels, with Cycles' formulas."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.mitsuba.usd_export import TextureMap
    from nasset_reference_renderer.textures import srgb_to_linear

    build("texture_ops", tmp_path, 8)
    floor, notes = map_material(bpy.data.materials["TintedFloor"])
    tint = 0.1 + 0.9 * np.array([0.5, 0.8, 1.0])  # Multiply at factor 0.9
    tex = floor["diffuseColor"]
    assert isinstance(tex, TextureMap) and "Mix multiply" in tex.what, (floor, notes)
    image = bpy.data.images.load(str(tmp_path / "checker.png"))
    plain = srgb_to_linear(np.array(image.pixels[:]).reshape(-1, 4)[:, :3]).max(0)  # the checker's brightest texels
    assert np.allclose(tex.image.reshape(-1, 3).max(0), plain * tint, rtol=3e-3), (tex.image.max((0, 1)), plain * tint)
    packed, notes = map_material(bpy.data.materials["Packed"])
    rough, alpha = packed["roughness"], packed["opacity"]
    assert np.allclose([rough.image.min(), rough.image.max()], np.array([110, 240]) / 255 * 0.8, atol=1e-6)
    assert np.allclose(np.unique(alpha.image.round(6)), [0.6, 1.0]), np.unique(alpha.image)
    ramped, _ = map_material(bpy.data.materials["Ramped"])
    colours = ramped["diffuseColor"].image.reshape(-1, 3)
    assert colours[:, 0].max() > 0.5 and colours[:, 2].max() > 0.5  # red at one end, blue at the other


def test_rough_principled_metals_get_cycles_multiple_scattering_energy():
    """Cycles' Principled metal is a multiple-scattering GGX: at roughness 0.6 and 0.8 it reflects 7-34 % more than
    the renderer's single-scattering lobe (the fidelity scene rough_metal read an MSE 13.9x its noise at 64 x 64,
    64 spp; 0.96 at 32 x 32 now). With F0 = 1 the compensated lobe conserves energy: the factor is 1 / E_avg."""
    from nasset_converters.blender.fidelity import _material
    from nasset_converters.blender.usd_export import multiscatter_scale

    assert np.allclose(multiscatter_scale(0.05, (0.8, 0.5, 0.3)), 1.0, atol=2e-3)
    k = [multiscatter_scale(r, (0.8, 0.8, 0.8))[0] for r in (0.3, 0.5, 0.7, 0.9)]
    assert all(a < b for a, b in zip(k, k[1:], strict=False)) and 1.5 < k[-1] < 2.0, k
    bpy.ops.wm.read_factory_settings(use_empty=True)
    mat = _material(bpy, "Copper", "principled", **{"Base Color": (0.8, 0.5, 0.3), "Roughness": 0.6, "Metallic": 1.0})
    inputs, notes = map_material(mat)
    assert np.allclose(inputs["diffuseColor"], np.multiply((0.8, 0.5, 0.3), multiscatter_scale(0.6, (0.8, 0.5, 0.3))))
    assert [n for n in notes if "multiple-scattering" in n], notes


def test_a_multiscatter_glossy_bsdf_gets_the_energy_of_its_lobe():
    """A Glossy BSDF of distribution Multiscatter GGX (Blender's default) reflects more than one GGX scattering: its
    colour takes the view-averaged factor (a gold ball at roughness 0.7: MSE 6.0x its noise without, 3.1 with, the
    rest being the Schlick Fresnel from Color); a plain GGX one keeps its colour."""
    from nasset_converters.blender.fidelity import _mixed
    from nasset_converters.blender.usd_export import multiscatter_scale

    bpy.ops.wm.read_factory_settings(use_empty=True)
    for distribution, k in (("MULTI_GGX", multiscatter_scale(0.7, (0.9, 0.7, 0.3))), ("GGX", np.ones(3))):
        mat = _mixed(bpy, distribution, "mix", [("ShaderNodeBsdfAnisotropic", {"Color": (0.9, 0.7, 0.3), "Roughness": 0.7})],
                     0.0)
        next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfAnisotropic").distribution = distribution
        inputs, _ = map_material(mat)
        assert np.allclose(inputs["specularColor"], np.multiply((0.9, 0.7, 0.3), k), rtol=1e-6), (distribution, inputs)


def test_a_beckmann_glossy_bsdf_is_written_as_a_beckmann_lobe():
    """A Glossy BSDF of distribution Beckmann keeps its roughness (Cycles' alpha = roughness^2, the renderer's) and says
    nasset:microfacet = beckmann (renderer.md#materials); a GGX of alpha x 0.82-0.93 stood in for it before, which read
    1.12-1.28 of Cycles' mean on a random scene (a rough glossy cylinder's caps mirroring an area light)."""
    from nasset_converters.blender.fidelity import _mixed

    bpy.ops.wm.read_factory_settings(use_empty=True)
    for distribution in ("BECKMANN", "GGX"):
        mat = _mixed(bpy, distribution, "mix", [("ShaderNodeBsdfAnisotropic", {"Color": (0.9, 0.7, 0.3), "Roughness": 0.6})],
                     0.0)
        next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeBsdfAnisotropic").distribution = distribution
        inputs, notes = map_material(mat)
        assert inputs["roughness"] == pytest.approx(0.6, rel=1e-6), (distribution, inputs)
        assert inputs.get("microfacet") == ("beckmann" if distribution == "BECKMANN" else None), inputs


def test_lights_in_instanced_collections_are_placed_lights(tmp_path):
    """The fidelity suite's instanced_lights scene (MSE 2127x its noise before, 64 x 64, 64 spp): lights inside a
    collection placed by collection instances were skipped with a warning. Each placement is a light with the
    instance's world matrix."""
    from pxr import Usd, UsdGeom

    from nasset_converters.blender.fidelity import build

    res = convert_scene(build("instanced_lights", tmp_path, 8), tmp_path / "s.usda")
    assert not res.warnings, res.warnings
    stage = Usd.Stage.Open(str(res.output))
    names = sorted(p.GetName() for p in stage.GetPrimAtPath("/World/Lights").GetChildren())
    assert names == ["LampPlacer0_Bulb", "LampPlacer0_Cone", "LampPlacer1_Bulb", "LampPlacer1_Cone", "World"], names
    bulb = UsdGeom.Xformable(stage.GetPrimAtPath("/World/Lights/LampPlacer1_Bulb"))
    where = np.array(bulb.ComputeLocalToWorldTransform(Usd.TimeCode.Default()))[3, :3]
    assert np.allclose(where, (0.8, 1.0, -0.2), atol=1e-5), where  # Blender (0.8, 0.2, 0.2 + 0.8) in +Y-up


@pytest.mark.parametrize("vector_type, degrees", [("POINT", 70.0), ("TEXTURE", -70.0)])
def test_a_mapping_node_turning_the_environment_turns_the_dome(tmp_path, vector_type, degrees):
    """An HDRI turned about Z by a Mapping node on the Generated direction (the fidelity scene hdri_turned: MSE 162x
    its noise before, 64 x 64, 64 spp; 0.99 at 32 x 32 now): the mapping was dropped with a warning. The dome turns
    by the opposite angle about USD +Y (a Texture mapping is the inverse of a Point one)."""
    from pxr import Usd, UsdGeom

    from nasset_converters.blender.fidelity import build

    build("hdri_turned", tmp_path, 8)
    mapping = next(n for n in bpy.context.scene.world.node_tree.nodes if n.bl_idname == "ShaderNodeMapping")
    mapping.vector_type, mapping.inputs["Rotation"].default_value = vector_type, (0.0, 0.0, math.radians(degrees))
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "turned.blend"))
    res = convert_scene(tmp_path / "turned.blend", tmp_path / "s.usda")
    assert not [w for w in res.warnings if "world" in w], res.warnings
    stage = Usd.Stage.Open(str(res.output))
    m = np.array(UsdGeom.Xformable(stage.GetPrimAtPath("/World/Lights/World")).ComputeLocalToWorldTransform(0))[:3, :3]
    c, s = math.cos(math.radians(-70.0)), math.sin(math.radians(-70.0))
    spin = np.array([[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]])
    assert np.allclose(m, DOME_ROWS[:3, :3] @ spin, atol=1e-6), m


def test_volumes_displacement_and_light_linking_are_named(tmp_path):
    """A world volume (fog), a material's volume next to its surface, its displacement, and light linking (an object
    receiving only some lights, a light lighting only some objects) change Cycles' image and were dropped without a
    word. A bump-only displacement (Cycles' default method) is now baked into a normal map; one that moves the
    geometry stays dropped, named."""
    from nasset_converters.blender.fidelity import _add, _light, _material, _new_scene, _world

    _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
    nt = _world(bpy).node_tree
    fog = nt.nodes.new("ShaderNodeVolumePrincipled")
    nt.links.new(fog.outputs[0], next(n for n in nt.nodes if n.bl_idname == "ShaderNodeOutputWorld").inputs["Volume"])
    mat = _material(bpy, "Jelly")
    out = next(n for n in mat.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    mat.node_tree.links.new(mat.node_tree.nodes.new("ShaderNodeVolumeAbsorption").outputs[0], out.inputs["Volume"])
    mat.node_tree.links.new(mat.node_tree.nodes.new("ShaderNodeDisplacement").outputs[0], out.inputs["Displacement"])
    cube = _add(bpy, "cube", "Jelly", mat)
    moved = _material(bpy, "Moved")  # true displacement moves the geometry: dropped (a bump-only one is baked)
    moved.displacement_method = "DISPLACEMENT"
    out = next(n for n in moved.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    moved.node_tree.links.new(moved.node_tree.nodes.new("ShaderNodeDisplacement").outputs[0], out.inputs["Displacement"])
    _add(bpy, "cube", "Moved", moved, location=(3.0, 0.0, 0.0))
    lamp = _light(bpy, "Lamp", "POINT", (1.0, -1.0, 2.0), energy=10.0)
    only = bpy.data.collections.new("OnlyThese")
    lamp.light_linking.receiver_collection = only
    cube.light_linking.blocker_collection = only
    bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "v.blend"))
    text = "\n".join(convert_scene(tmp_path / "v.blend", tmp_path / "s.usda").warnings)
    for part in ("world World: its volume", "material Jelly: volume shader dropped",
                 "material Jelly: Displacement from ShaderNodeDisplacement baked by Cycles",
                 "material Moved: displacement (displacement) dropped", "light Lamp: light linking",
                 "object Jelly: light linking"):
        assert part in text, (part, text)


def test_a_world_of_other_nodes_is_rendered_into_the_dome(tmp_path):
    """The fidelity suite's sky_world scene: a Sky Texture world, the only light, was dropped with a warning (a black
    image: MSE 2809x its noise at 64 x 64, 64 spp); Cycles now renders the world into a lat-long map for the dome.
    The render's layout is an Environment Texture's: a world holding an Environment Texture renders to its image."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import build
    from nasset_converters.blender.world_bake import render_world

    res = convert_scene(build("sky_world", tmp_path, 8), tmp_path / "s.usda")
    assert [w for w in res.warnings if "ShaderNodeTexSky: rendered by Cycles" in w], res.warnings
    stage = Usd.Stage.Open(str(res.output))
    dome = stage.GetPrimAtPath("/World/Lights/World")
    assert dome.GetTypeName() == "DomeLight" and dome.GetAttribute("inputs:texture:file").Get() is not None
    build("hdri", tmp_path / "hdri", 8)
    world = bpy.context.scene.world
    image = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeTexEnvironment").image
    src = np.array(image.pixels[:]).reshape(8, 16, 4)[::-1, :, :3].repeat(4, 0).repeat(4, 1)
    rendered = render_world(bpy, world, width=64, spp=4)
    assert rendered.shape == (32, 64, 3)
    err = {name: float(np.abs(img - src).mean()) for name, img in (("same", rendered), ("mirrored", rendered[:, ::-1]),
                                                                  ("half turn", np.roll(rendered, 32, 1)),
                                                                  ("upside down", rendered[::-1]))}
    assert err["same"] < 0.5 * min(v for k, v in err.items() if k != "same"), err  # measured 0.08 against 0.23-0.62
    assert len(bpy.data.scenes) == 1 and "nasset_world_bake" not in bpy.data.cameras


def test_closest_interpolation_keeps_texels_sharp(tmp_path):
    """Image Textures with Closest interpolation (the fidelity scene pixel_art: MSE 298x its noise before, 64 x 64,
    64 spp) were looked up bilinearly, blurring pixel art. Each texel is now repeated (64x within the texel budget),
    so the renderer's bilinear lookup blends only a thin band at texel edges."""
    from nasset_converters.blender.fidelity import build

    build("pixel_art", tmp_path, 8)
    inputs, notes = map_material(bpy.data.materials["PixelBox"])
    tex = inputs["diffuseColor"]
    assert tex.image.shape[:2] == (4 * 64, 4 * 64) and not notes, (tex.image.shape, notes)
    assert len(np.unique(tex.image.reshape(-1, 3), axis=0)) == 16  # the 4 x 4 texels, nothing in between


def test_an_srgb_environment_image_is_decoded(tmp_path):
    """An 8-bit sRGB panorama (PNG, JPEG) on the world: its stored values were written as linear radiance (the
    fidelity scene hdri_srgb: ratio 1.7-2.1, MSE 280x its noise at 64 x 64, 64 spp, without a warning). They are
    decoded as Cycles decodes them."""
    from pxr import Usd

    from nasset_converters.blender.fidelity import build
    from nasset_reference_renderer.film import read_exr
    from nasset_reference_renderer.textures import srgb_to_linear

    res = convert_scene(build("hdri_srgb", tmp_path, 8), tmp_path / "s.usda")
    stage = Usd.Stage.Open(str(res.output))
    texture = stage.GetPrimAtPath("/World/Lights/World").GetAttribute("inputs:texture:file").Get().resolvedPath
    dome = read_exr(texture)
    image = bpy.data.images.load(str(tmp_path / "sky.png"))
    stored = np.array(image.pixels[:]).reshape(-1, 4)[:, :3]
    assert np.isclose(dome.max(), srgb_to_linear(stored).max(), rtol=1e-3), (dome.max(), stored.max())


def test_soft_falloff_of_a_sphere_light_is_named(tmp_path):
    """Cycles lights each point from a disk facing it when a point light of radius r has Soft Falloff (Blender's
    default), dimmer near the light than the sphere the stage gets (measured: converted 17 % brighter, MSE 29x its
    noise, with r = 0.3 at 0.5 m; exact with Soft Falloff off). It went without a word."""
    from nasset_converters.blender.fidelity import _light, _new_scene

    for soft in (True, False):
        _new_scene(bpy, 8, (0.0, -3.0, 1.0), (0.0, 0.0, 0.0))
        _light(bpy, "Bulb", "POINT", (0.0, 0.0, 1.0), energy=10.0, shadow_soft_size=0.3).data.use_soft_falloff = soft
        bpy.ops.wm.save_as_mainfile(filepath=str(tmp_path / "b.blend"))
        warned = [w for w in convert_scene(tmp_path / "b.blend", tmp_path / "s.usda").warnings if "Soft Falloff" in w]
        assert bool(warned) == soft, warned


def test_a_holdout_material_is_black(tmp_path):
    """A Holdout shader (black to the camera in Cycles, alpha 0) was grey, "not convertible" (the fidelity scene
    holdout: MSE 512x its noise at 64 x 64, 64 spp); it is a black surface now, its alpha named in a warning."""
    from nasset_converters.blender.fidelity import build

    build("holdout", tmp_path, 8)
    inputs, notes = map_material(bpy.data.materials["Hold"])
    assert inputs["diffuseColor"] == (0.0, 0.0, 0.0) and inputs["specularColor"] == (0.0, 0.0, 0.0), inputs
    assert [n for n in notes if "Holdout" in n and "alpha" in n], notes


def test_the_converted_stage_is_written_atomically(tmp_path, monkeypatch):
    # the output was deleted first and written in place: a conversion failing half way lost the earlier stage, and an
    # output folder that could not be created was a raw FileExistsError traceback
    from nasset_converters.blender import usd_export

    out = tmp_path / "out" / "s.usda"
    convert_scene(None, out, example="blender-surface", check_usd=False)
    before = out.read_bytes()

    def fail(self):
        raise NassetError("CONVERT_SHAPE_UNSUPPORTED", "a shape the converter cannot write")

    monkeypatch.setattr(usd_export._BlenderConverter, "shapes", fail)
    with pytest.raises(NassetError) as e:
        convert_scene(None, out, example="blender-surface", check_usd=False)
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED"
    assert out.read_bytes() == before and [p.name for p in out.parent.iterdir() if p.suffix == ".usda"] == ["s.usda"]
    monkeypatch.undo()
    (tmp_path / "file").write_text("")
    with pytest.raises(NassetError) as e:
        convert_scene(None, tmp_path / "file" / "s.usda", example="blender-surface", check_usd=False)
    assert e.value.code == "WRITE_FAILED"


def test_procedural_textures_are_baked_by_cycles_per_object(tmp_path):
    """The fidelity suite's procedural_textures scene (ratio 1.13 / 1.15 / 1.13 and MSE 197x its noise before,
    64 x 64, 128 spp): a Noise, Checker or Voronoi (through a Color Ramp) texture on a Principled input was dropped
    with a warning and the input's own value used. Cycles now bakes each such input over the object's UV map into a
    texture of its own per object (Generated coordinates follow each object's bounds); an object without a UV map
    keeps the warning, naming it."""
    from pxr import Usd, UsdShade

    from nasset_converters.blender.fidelity import build
    from nasset_sdk.images import read_exr

    blend = build("procedural_textures", tmp_path, 8)
    bare = bpy.data.objects["NoiseBall2"].copy()  # the shared Noise material on a mesh without a UV map
    bare.name, bare.data = "Bare", bare.data.copy()
    bare.location.x -= 1.2
    bare.data.uv_layers.remove(bare.data.uv_layers[0])
    bpy.context.scene.collection.objects.link(bare)
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    res = convert_scene(blend, tmp_path / "out.usda", check_usd=False)
    baked = [w for w in res.warnings if "baked by Cycles" in w]
    assert len(baked) == 4 and not [w for w in res.warnings if "dropped" in w and "Bare" not in w], res.warnings
    assert [w for w in res.warnings if w.startswith("object Bare:") and "no UV map to bake into" in w], res.warnings
    stage = Usd.Stage.Open(str(tmp_path / "out.usda"))

    def texels(material, name):
        surface = UsdShade.Shader.Get(stage, f"/World/Looks/{material}/PreviewSurface")
        source = surface.GetInput(name).GetConnectedSources()[0][0].source
        file = UsdShade.Shader(source.GetPrim()).GetInput("file").Get().resolvedPath
        return read_exr(file)

    one, two = texels("Noisy_NoiseBall", "diffuseColor"), texels("Noisy_NoiseBall2", "diffuseColor")
    assert one.std(axis=(0, 1)).min() > 0.02 and two.std(axis=(0, 1)).min() > 0.02  # a texture, not a flat colour
    assert not stage.GetPrimAtPath("/World/Looks/Noisy_Bare/PreviewSurface").GetAttribute("inputs:diffuseColor") \
        .HasAuthoredConnections()
    rough = texels("CheckerRough_Floor", "roughness")[..., 0]
    assert np.allclose(np.percentile(rough, [2, 98]), [0.4, 0.9], atol=2e-3), np.percentile(rough, [2, 98])
    assert 0.3 < (rough < 0.65).mean() < 0.7  # half the squares of each
    cells = texels("Cells_CellBox", "diffuseColor").reshape(-1, 3)
    cells = cells[cells.max(1) > 0.02]  # the cube's UV islands (the rest of the image is unused)
    assert cells[:, 0].max() > 0.5 and cells[:, 2].max() > 0.5  # the ramp's red and blue ends


def test_a_textured_roughness_scales_a_principled_base_colour_per_texel(tmp_path):
    """Cycles layers a dielectric Principled BSDF's diffuse under its specular lobe, whose albedo depends on the
    roughness. With a roughness texture the factor was taken at the texture's mean (a checker of 0.15 / 0.85 then
    rendered its smooth squares 3 % too bright, its rough ones 3 % too dark); it is now applied per texel."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.mitsuba.usd_export import TextureMap

    build("pbr_textures", tmp_path, 8)
    floor, notes = map_material(bpy.data.materials["RoughFloor"])
    base, rough = floor["diffuseColor"], floor["roughness"]
    assert isinstance(base, TextureMap) and base.image.shape == rough.image.shape, (floor, notes)
    r = rough.image[..., 0].ravel()
    for value in (r.min(), r.max()):
        k = principled_diffuse_scale(float(value), 1.5)
        texel = base.image.reshape(-1, 3)[np.argmin(np.abs(r - value))]
        assert np.allclose(texel, np.array([0.5, 0.45, 0.4]) * k, rtol=2e-3), (value, texel, k)


def test_a_procedural_on_a_collection_instance_is_baked_on_its_object(tmp_path):
    """An object placed only by collection instances (its collection excluded from the view layer) is not in the view
    layer, where Cycles bakes: its procedural was dropped ("cannot be selected"). It is now linked into the scene for
    the bake, and the prototype's material reads the image."""
    from pxr import Usd, UsdShade

    from nasset_converters.blender.fidelity import build

    blend = build("instances", tmp_path, 8)
    nt = bpy.data.materials["Orange"].node_tree
    noise = nt.nodes.new("ShaderNodeTexNoise")
    nt.links.new(noise.outputs["Color"], next(n for n in nt.nodes if n.bl_idname == "ShaderNodeBsdfDiffuse").inputs["Color"])
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    res = convert_scene(blend, tmp_path / "out.usda", check_usd=False)
    assert [w for w in res.warnings if w.startswith("object Head:") and "baked by Cycles" in w], res.warnings
    stage = Usd.Stage.Open(str(tmp_path / "out.usda"))
    surfaces = [UsdShade.Shader(p) for p in stage.TraverseAll() if "Orange" in str(p.GetPath()) and p.GetName() == "PreviewSurface"]
    assert len(surfaces) == 1 and surfaces[0].GetInput("diffuseColor").HasConnectedSource(), surfaces
    assert "Head" not in [o.name for o in bpy.data.scenes[0].collection.objects]  # put back


def test_a_baked_uv_map_that_overlaps_itself_is_named(tmp_path):
    """A bake fills texels that several faces share (mirrored halves, stacked islands) with one face's values, where
    Cycles shades each face by its own coordinates; before, nothing said so. The share of such texels is measured
    (exactly 0 for a square split along a diagonal through texel centres, 1 for two stacked copies) and warned."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.blender.procedural_bake import OVERLAP_GRID, uv_overlap

    square = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], np.float64)
    assert uv_overlap(square) == 0.0
    assert uv_overlap(square * (OVERLAP_GRID - 1) / OVERLAP_GRID + 0.5 / OVERLAP_GRID) == 0.0  # edges on centres
    assert uv_overlap(np.concatenate([square, square * 0.5])) == pytest.approx(0.25 / 1.0, abs=0.02)
    assert uv_overlap(np.concatenate([square, square])) == 1.0
    blend = build("procedural_textures", tmp_path, 8)
    bpy.data.objects["CellBox"].modifiers.new("Mirror", "MIRROR")  # mirrored halves on the same UVs
    bpy.ops.wm.save_as_mainfile(filepath=str(blend), check_existing=False)
    res = convert_scene(blend, tmp_path / "out.usda", check_usd=False)
    shared = [w for w in res.warnings if "overlaps itself" in w]
    assert len(shared) == 1 and shared[0].startswith("object CellBox:"), res.warnings


def test_the_bake_size_follows_the_object_on_screen(tmp_path):
    """Twice the object's extent on screen, a power of two within 64-1024; 256 for an object wholly behind the
    camera (before: 1024, a 16x larger bake for an object seen only in reflections and lighting); 1024 without a
    camera."""
    from nasset_converters.blender.fidelity import build
    from nasset_converters.blender.procedural_bake import BAKE_BEHIND, BAKE_MAX, BAKE_MIN, bake_size

    build("procedural_textures", tmp_path, 64)
    ball, scene = bpy.data.objects["NoiseBall"], bpy.context.scene
    assert bake_size(bpy, ball) == BAKE_MIN  # about 20 pixels wide at 64 x 64
    scene.render.resolution_x = scene.render.resolution_y = 1024
    assert bake_size(bpy, ball) == 1024  # about 330 pixels wide
    ball.location = (0.0, -4.0, 2.0)  # behind the camera at (0, -2, 2.2)
    bpy.context.view_layer.update()
    assert bake_size(bpy, ball) == BAKE_BEHIND
    scene.camera = None
    assert bake_size(bpy, ball) == BAKE_MAX


def test_shaders_without_a_counterpart_keep_their_colour():
    """Subsurface Scattering, Translucent, Toon, Glass, Refraction and Sheen BSDFs were grey 0.8 whatever their colour
    (a Subsurface ball of colour (0.9, 0.5, 0.3) read MSE 36x its noise against Cycles at 48², 64 spp; 1.4 now): each
    is now the closest opaque surface, named in a note (converters/blender/usd_export.APPROXIMATED_SHADERS)."""
    from nasset_converters.blender.examples import shader_material
    from nasset_converters.blender.usd_export import map_material

    bpy.ops.wm.read_factory_settings(use_empty=True)
    colour = (0.9, 0.5, 0.3)
    want = {"ShaderNodeSubsurfaceScattering": colour, "ShaderNodeBsdfToon": colour,
            "ShaderNodeBsdfTranslucent": tuple(0.5 * c for c in colour), "ShaderNodeBsdfGlass": (0.0, 0.0, 0.0),
            "ShaderNodeBsdfRefraction": (0.0, 0.0, 0.0), "ShaderNodeBsdfSheen": (0.0, 0.0, 0.0)}
    for kind, diffuse in want.items():
        mat, node = shader_material(bpy, kind, kind)
        node.inputs["Color"].default_value = (*colour, 1.0)
        if kind == "ShaderNodeBsdfGlass":
            node.inputs["IOR"].default_value = 1.6
        inputs, notes = map_material(mat)
        np.testing.assert_allclose(inputs["diffuseColor"], diffuse, atol=1e-6, err_msg=kind)
        f0 = ((1.6 - 1.0) / 2.6) ** 2 * np.array(colour) if kind == "ShaderNodeBsdfGlass" else np.zeros(3)
        np.testing.assert_allclose(inputs["specularColor"], f0, atol=1e-6, err_msg=kind)
        if kind in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction"):  # beside the opaque fallback, a MaterialX
            g = inputs["glass"]  # glass (spec/renderer.md#transmission); Refraction reflects nothing
            assert (g.weight, g.thin) == (1.0, False)
            assert g.ior == pytest.approx(1.6 if kind == "ShaderNodeBsdfGlass" else 1.45)  # the node's default IOR
            reflect = colour if kind == "ShaderNodeBsdfGlass" else (0.0, 0.0, 0.0)
            np.testing.assert_allclose([g.color, g.specular], [colour, reflect], atol=1e-6)
            assert any("MaterialX glass" in n for n in notes), notes
        else:
            assert any("has no counterpart" in n and "neural asset" in n for n in notes), (kind, notes)


def test_principled_transmission_takes_its_share_of_the_diffuse_base():
    """A Principled BSDF with Transmission Weight t was written with its whole base colour diffuse (a Principled glass
    ball: an opaque white ball, 1.22 of Cycles' mean at 48², 64 spp; 0.91 now, the light it lets through being lost);
    the diffuse base is now x (1 - t), the specular layer kept, and the transmitted part a MaterialX glass of weight t
    whose colour is the base colour's square root (Cycles tints a pass through, two refractions, once)."""
    from nasset_converters.blender.fidelity import _material
    from nasset_converters.blender.usd_export import map_material

    bpy.ops.wm.read_factory_settings(use_empty=True)
    base = {}
    for t in (0.0, 0.5, 1.0):
        mat = _material(bpy, f"T{t}", "principled", **{"Base Color": (0.8, 0.4, 0.2), "Transmission Weight": t})
        inputs, notes = map_material(mat)
        base[t] = np.asarray(inputs["diffuseColor"], np.float64)
        assert inputs["ior"] == pytest.approx(1.5, abs=1e-3)  # the specular layer stays
        assert (t > 0) == any("Transmission Weight" in n and "MaterialX glass" in n for n in notes), notes
        assert ("glass" in inputs) == (t > 0)
        if t > 0:
            assert inputs["glass"].weight == pytest.approx(t)
            np.testing.assert_allclose(inputs["glass"].color, np.sqrt([0.8, 0.4, 0.2]), rtol=1e-6)
    np.testing.assert_allclose(base[0.5], 0.5 * base[0.0], rtol=1e-6)
    np.testing.assert_allclose(base[1.0], 0.0, atol=1e-9)
