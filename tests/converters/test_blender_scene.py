"""Blender scene access: examples, geometry export (meshes, hair curves, particle hair), typed errors.

Needs Blender's Python module (``pip install bpy``, installed in CI); skipped without it.
"""

from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")

from nasset_converters.blender import Z_UP_TO_Y_UP, to_y_up, to_z_up  # noqa: E402
from nasset_converters.blender import scene as bsc  # noqa: E402
from nasset_converters.blender.examples import build_example, hair_strands, write_example_blend  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402
from nasset_sdk.geometry import CurvesGeometry, MeshGeometry  # noqa: E402


def test_axis_conversion_is_a_rotation():
    assert np.allclose(Z_UP_TO_Y_UP @ Z_UP_TO_Y_UP.T, np.eye(3)) and np.isclose(np.linalg.det(Z_UP_TO_Y_UP), 1.0)
    assert np.allclose(to_y_up([[0.0, 0.0, 1.0]]), [[0.0, 1.0, 0.0]])  # Blender up -> USD up
    v = np.random.default_rng(0).normal(size=(5, 3))
    assert np.allclose(to_z_up(to_y_up(v)), v)


def test_hair_example_exports_basis_curves_with_widths():
    names = build_example("blender-hair")
    objs = bsc.pick_objects(names)
    variant, geo, notes = bsc.asset_geometry(objs)
    assert variant == "fiber" and isinstance(geo, CurvesGeometry) and notes == []
    pts, radius = hair_strands()  # the generator's own strands, Blender space
    assert len(geo.counts) == 1000 and (geo.counts == 12).all()
    assert np.allclose(geo.points, to_y_up(pts), atol=1e-5)
    assert np.allclose(geo.widths, 2.0 * radius, rtol=1e-5)
    lo, hi = geo.bounds()
    assert lo[1] >= 0.0 - 1e-3 and hi[1] > 0.5  # +Y up: the tuft stands on the ground


def test_surface_example_exports_smooth_triangles():
    names = build_example("blender-surface")
    variant, geo, _ = bsc.asset_geometry(bsc.pick_objects(names))
    assert variant == "surface" and isinstance(geo, MeshGeometry)
    geo.validate()
    assert len(geo.faces) > 1000  # Suzanne with one subdivision level
    assert np.allclose(np.linalg.norm(geo.normals, axis=1), 1.0, atol=1e-4)
    # outward normals: the mean of n . (p - centroid) over vertices is clearly positive
    c = geo.points.mean(0)
    assert float(np.mean(np.sum(geo.normals * (geo.points - c), 1))) > 0.05


def test_particle_hair_becomes_curves():
    build_example("blender-surface")
    bpy.ops.mesh.primitive_plane_add(size=1.0, location=(0.0, 3.0, 0.0))
    ob = bpy.context.active_object
    ob.name = "Fur"
    ob.modifiers.new("hair", type="PARTICLE_SYSTEM")
    st = ob.particle_systems[0].settings
    st.type = "HAIR"
    st.count = 40
    st.hair_length = 0.2
    st.root_radius, st.tip_radius, st.radius_scale = 1.0, 0.5, 0.004
    bpy.context.view_layer.update()
    variant, geo, _ = bsc.asset_geometry([ob])
    assert variant == "fiber" and len(geo.counts) == 40 and (geo.counts >= 2).all()
    first = np.concatenate([[0], np.cumsum(geo.counts)[:-1]])
    length = [np.linalg.norm(np.diff(geo.points[a:a + n], axis=0), axis=1).sum() for a, n in zip(first, geo.counts, strict=True)]
    assert np.allclose(length, 0.2, rtol=0.05)  # strands of the requested length
    assert np.isclose(geo.widths[first].mean(), 0.004, rtol=1e-3)  # root width = root radius x scale
    assert geo.widths[first + geo.counts - 1].mean() < geo.widths[first].mean()


def test_mixed_mesh_and_hair_is_rejected():
    build_example("blender-hair")
    with pytest.raises(NassetError) as e:
        bsc.asset_geometry(bsc.pick_objects(["Hair", "Scalp"]))
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED"


def test_missing_blend_and_unknown_object(tmp_path):
    with pytest.raises(NassetError) as e:
        bsc.open_blend(tmp_path / "nope.blend")
    assert e.value.code == "CONVERT_SCENE_MISSING" and "nope.blend" in str(e.value)
    bad = tmp_path / "bad.blend"
    bad.write_bytes(b"not a blend file")
    with pytest.raises(NassetError) as e:
        bsc.open_blend(bad)
    assert e.value.code == "CONVERT_SCENE_LOAD"
    path = write_example_blend("blender-surface", tmp_path)
    bsc.open_blend(path)
    with pytest.raises(NassetError) as e:
        bsc.pick_objects(["Nobody"], file=str(path))
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN" and "Monkey" in str(e.value)
    with pytest.raises(NassetError) as e:
        bsc.pick_objects(["Camera"], file=str(path))
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED"


def _material(name: str, *, emission_node: bool = False, strength: float = 0.0, linked: bool = True):
    mat = bpy.data.materials.new(name)
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    out = next(n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    if emission_node:
        em = nodes.new("ShaderNodeEmission")
        em.inputs["Strength"].default_value = strength
        if linked:
            links.new(em.outputs[0], out.inputs["Surface"])
    else:
        bsdf = next(n for n in nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
        bsdf.inputs["Emission Color"].default_value = (1.0, 0.8, 0.5, 1.0)
        bsdf.inputs["Emission Strength"].default_value = strength
    return mat


@pytest.mark.parametrize("case, emits", [
    ("principled, emission strength 0", False),
    ("principled, emission strength 3", True),
    ("emission node, linked", True),
    ("emission node, strength 0", False),
    ("emission node, not linked to the output", False),
])
def test_an_emitting_object_cannot_be_baked_or_replaced(tmp_path, case, emits):
    """A neural asset carries light transport, not emission: bakes (pick_objects) and convert --replace refuse an
    object whose material emits, with CONVERT_SHAPE_UNSUPPORTED naming object, material and node."""
    from nasset_converters.blender.usd_export import _check_replace
    from nasset_sdk.examples import example_builder

    names = build_example("blender-surface")
    ob = bpy.context.scene.objects[names[0]]
    mat = {"principled, emission strength 0": lambda: _material("m", strength=0.0),
           "principled, emission strength 3": lambda: _material("m", strength=3.0),
           "emission node, linked": lambda: _material("m", emission_node=True, strength=5.0),
           "emission node, strength 0": lambda: _material("m", emission_node=True, strength=0.0),
           "emission node, not linked to the output": lambda: _material("m", emission_node=True, strength=5.0,
                                                                        linked=False)}[case]()
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    asset = example_builder("rna", size="tiny").write(tmp_path / "a.usdc")
    if not emits:
        assert bsc.pick_objects(names) == [ob]
        _check_replace(bpy, {names[0]: asset}, "scene.blend")
        return
    for call in (lambda: bsc.pick_objects(names, file="scene.blend"),
                 lambda: _check_replace(bpy, {names[0]: asset}, "scene.blend")):
        with pytest.raises(NassetError) as ei:
            call()
        assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED" and repr(names[0]) in str(ei.value), ei.value
        assert f"material {mat.name!r}" in str(ei.value)


def test_an_object_given_twice_is_a_usage_error():
    from nasset_sdk.errors import UsageError

    names = build_example("blender-surface")
    with pytest.raises(UsageError, match="given more than once"):
        bsc.pick_objects([names[0], names[0]])


def test_a_mirrored_object_keeps_its_faces_wound_about_its_normals():
    """A negative scale mirrors the points; the faces must be reversed with them (and their UV corners), or the
    triangles wind clockwise about the (correctly mirrored) normals: an inside-out asset and scene mesh."""
    names = build_example("blender-surface")
    ob = bpy.context.scene.objects[names[0]]

    def geometry():
        uvs = []
        geo = bsc.mesh_geometry([ob], uv_out=uvs)
        tri = geo.points[geo.faces]
        face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        agree = np.mean(np.sum(face_n * geo.normals[geo.faces].mean(1), 1) > 0)
        return geo, uvs[0], agree

    geo, uv, agree = geometry()
    ob.scale = (-1.0, 1.0, 1.0)
    bpy.context.view_layer.update()
    geo_m, uv_m, agree_m = geometry()
    assert agree > 0.99 and agree_m > 0.99, (agree, agree_m)
    np.testing.assert_allclose(geo_m.points[:, 0], -geo.points[:, 0], atol=1e-6)  # +X (Blender and USD) mirrored
    np.testing.assert_array_equal(geo_m.faces, geo.faces[:, ::-1])
    if uv is not None:
        np.testing.assert_array_equal(uv_m, uv[:, ::-1])


@pytest.mark.parametrize("shading", ["smooth by angle", "sharp edges", "flat"])
def test_hard_edges_keep_cycles_normals(shading):
    """Cycles shades with Blender's corner normals: a cube under Smooth by Angle (the modifier Blender's "Shade Auto
    Smooth" adds), with its edges marked sharp, or with flat faces shades flat. The export used to average the
    vertex normals across a hard edge, so a smooth-shaded cube with hard edges came out shaded like a sphere."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    ob = bpy.context.active_object
    if shading == "smooth by angle":
        bpy.ops.object.shade_auto_smooth(angle=np.radians(30.0))
    elif shading == "sharp edges":
        bpy.ops.object.shade_smooth()
        ob.data.attributes.new("sharp_edge", "BOOLEAN", "EDGE").data.foreach_set("value", [True] * len(ob.data.edges))
    else:
        bpy.ops.object.shade_flat()
    bpy.context.view_layer.update()
    geo = bsc.mesh_geometry([ob], local=True)
    tri = geo.points[geo.faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    face_n /= np.linalg.norm(face_n, axis=1, keepdims=True)
    for corner in range(3):  # every corner's normal is its face's
        np.testing.assert_allclose(geo.normals[geo.faces[:, corner]], face_n, atol=1e-6)
    assert len(geo.points) == 24


def test_a_smooth_mesh_keeps_one_vertex_per_blender_vertex():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0)
    ob = bpy.context.active_object
    bpy.ops.object.shade_smooth()
    bpy.context.view_layer.update()
    geo = bsc.mesh_geometry([ob], local=True)
    assert len(geo.points) == len(ob.data.vertices)
    np.testing.assert_allclose(np.sum(geo.normals * geo.points, axis=1), 1.0, atol=1e-4)  # radial normals


def _ball_with(name, build):
    """A sphere of radius 0.5 m whose node material ``build(node_tree, output, principled)`` sets up."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5)
    ob = bpy.context.active_object
    ob.name = name
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nt = mat.node_tree
    build(nt, nt.nodes.get("Material Output"), nt.nodes.get("Principled BSDF"))
    ob.data.materials.append(mat)
    return ob


def _glass(roughness, density=None):
    def build(nt, out, principled):
        glass = nt.nodes.new("ShaderNodeBsdfGlass")
        glass.inputs["Roughness"].default_value = roughness
        nt.links.new(glass.outputs[0], out.inputs["Surface"])
        if density is not None:
            volume = nt.nodes.new("ShaderNodeVolumeScatter")
            volume.inputs["Density"].default_value = density
            nt.links.new(volume.outputs[0], out.inputs["Volume"])
    return build


def _principled(**inputs):
    def build(nt, out, principled):
        for key, value in inputs.items():
            principled.inputs[key].default_value = value
    return build


def test_see_through_materials():
    """Blender's side of spec/bake.md#see-through: sharp glass, Principled transmission or alpha over at most a thin
    volume lets light through unscattered, which rna cannot store. A 0.5 m ball has mean chord 2/3 m: density 1 / m
    lets ~51 % through, 50 / m ~3e-15."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    cases = {  # name: (material, flagged)
        "clear": (_glass(0.0), True), "frosted": (_glass(0.3), False), "milky": (_glass(0.0, 1.0), True),
        "dense": (_glass(0.0, 50.0), False), "cutout": (_principled(Alpha=0.0), True),
        "half": (_principled(Alpha=0.5), True), "plain": (_principled(), False),
        "pglass": (_principled(**{"Transmission Weight": 1.0, "Roughness": 0.0}), True),
        "pfrosted": (_principled(**{"Transmission Weight": 1.0, "Roughness": 0.2}), False),
    }
    objects = [_ball_with(name, build) for name, (build, _) in cases.items()]
    bpy.context.view_layer.update()
    found = [s.split(" (")[0] for s in bsc.see_through(objects)]
    assert found == [name for name, (_, flagged) in cases.items() if flagged], found


def test_rna_bake_warns_about_a_see_through_object(tmp_path, capsys):
    pytest.importorskip("torch", reason="bakes need torch")
    from nasset_bakers.blender.rna import bake

    bpy.ops.wm.read_factory_settings(use_empty=True)
    _ball_with("Lens", _glass(0.0))
    blend = tmp_path / "lens.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bake(blend, ["Lens"], tmp_path / "lens.usdc", size="tiny", views=2, epochs=1, res=16)
    assert "warning: object(s) ['Lens (Glass BSDF of roughness 0)'] let light through" in capsys.readouterr().err


def test_a_degenerate_transform_is_a_typed_error(tmp_path):
    """An object scaled to 0 along one axis: the normals' inverse transform is singular. The bake stopped with
    numpy's LinAlgError and the converter called the object empty ("no faces")."""
    from nasset_converters.blender.usd_export import convert_scene

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    box = bpy.context.active_object
    box.name = "Squashed"
    box.scale = (1.0, 1.0, 0.0)
    bpy.context.view_layer.update()
    with pytest.raises(NassetError) as e:
        bsc.mesh_geometry([box])
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "degenerate transform" in str(e.value)
    blend = tmp_path / "squashed.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    res = convert_scene(blend, tmp_path / "s.usda", check_usd=False)
    assert any("Squashed" in w and "degenerate transform" in w for w in res.warnings), res.warnings


def _fuzzy_ball(name="Fuzz"):
    """A ball with particle hair whose viewport settings differ from the render ones Cycles uses: 2 display steps
    against 3 render steps, 2 interpolated children per parent in the viewport against 10 in renders, 40 % of the
    parents displayed."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.3)
    ob = bpy.context.active_object
    ob.name = name
    st = ob.modifiers.new("hair", "PARTICLE_SYSTEM").particle_system.settings
    st.type, st.count, st.hair_length = "HAIR", 60, 0.25
    st.root_radius, st.tip_radius, st.radius_scale = 1.0, 0.5, 0.01
    st.display_step, st.render_step = 2, 3
    st.child_type, st.child_percent, st.rendered_child_count, st.display_percentage = "INTERPOLATED", 2, 10, 40
    bpy.context.view_layer.update()
    return ob, st


def test_particle_hair_exports_the_strands_cycles_renders():
    """Parents and their render children, at the render step count (2^3 + 1 points), and the viewport settings put
    back. Before: the viewport's strands (parents only, here a share of them, at 2^2 + 1 points)."""
    ob, st = _fuzzy_ball()
    hair = bsc.hair_strands([ob])
    assert len(hair.counts) == 60 * (1 + 10) and set(hair.counts.tolist()) == {9}
    assert (st.display_step, st.child_percent, st.display_percentage) == (2, 2, 40)


def test_particle_hair_with_children_matches_cycles_in_the_bake(tmp_path):
    """Independent check by Cycles itself: the bake keeps pixels where our caster (on the exported strands) and
    Cycles' alpha agree. With the parents only, 90 % of the pixels disagreed (135 samples were left); now the
    silhouettes of thin fibres at 32^2 pixels, 9 %."""
    pytest.importorskip("torch", reason="bakes need torch")
    from nasset_bakers.blender.rna import bake

    _fuzzy_ball()
    blend = tmp_path / "fuzz.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    summary = bake(blend, ["Fuzz"], tmp_path / "fuzz.usdc", size="tiny", views=4, epochs=1, quiet=True)
    assert summary["mask_disagreement"] < 0.2, summary["mask_disagreement"]


def test_a_baked_object_has_the_geometry_cycles_renders(tmp_path):
    """The bake reads asset geometry through the viewport depsgraph; a cube under a Subdivision Surface of viewport
    level 0 and render level 2 was exported as its 12 triangles while Cycles rendered (and the bake's ground truth
    showed) the 192 of level 2. An opened file now evaluates with its render settings."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    box = bpy.context.active_object
    box.name = "Rounded"
    sub = box.modifiers.new("Subdivision", "SUBSURF")
    sub.levels, sub.render_levels = 0, 2
    blend = tmp_path / "rounded.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    bsc.open_blend(blend)
    geo = bsc.mesh_geometry(bsc.pick_objects(["Rounded"]))
    assert len(geo.faces) == 12 * 4 ** 2
    assert np.abs(geo.points).max() < 0.5  # the subdivided surface lies inside the cube's corners


@pytest.mark.parametrize("muted", [False, True])
def test_emission_inside_a_node_group_is_found(muted):
    """An Emission shader inside a node group was not seen (the object was baked as if it did not emit); a muted one
    emits nothing in Cycles and is not refused."""
    from nasset_converters.blender.fidelity import _group

    names = build_example("blender-surface")
    ob = bpy.context.scene.objects[names[0]]

    def glow(tree, gin, gout):
        em = tree.nodes.new("ShaderNodeEmission")
        em.inputs["Strength"].default_value = 4.0
        em.mute = muted
        tree.links.new(em.outputs[0], gout.inputs[0])

    mat = bpy.data.materials.new("Glow")
    mat.use_nodes = True
    nt = mat.node_tree
    for node in [n for n in nt.nodes if n.bl_idname != "ShaderNodeOutputMaterial"]:
        nt.nodes.remove(node)
    group = nt.nodes.new("ShaderNodeGroup")
    group.node_tree = _group(bpy, "GlowGroup", [], glow)
    nt.links.new(group.outputs[0], nt.nodes["Material Output"].inputs["Surface"])
    ob.data.materials.clear()
    ob.data.materials.append(mat)
    if muted:
        assert bsc.pick_objects([ob.name]) == [ob]
    else:
        with pytest.raises(NassetError) as e:
            bsc.pick_objects([ob.name])
        assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "emits light" in str(e.value)
    assert sorted(m.name for m in bpy.data.materials if m.name.startswith("Glow")) == ["Glow"]


def test_non_finite_and_huge_vertices_drop_their_triangles(tmp_path):
    """A vertex at NaN, or at inf (which Blender stores as 3.4e38): the converter wrote them, and the renderer refused
    the whole stage (SCENE_INVALID: "mesh topology invalid", or world coordinates beyond its bound). Their triangles
    are left out with a warning naming the object; the rest renders, as in Cycles."""
    from nasset_converters.blender.usd_export import convert_scene
    from nasset_reference_renderer import RenderSettings, load_scene, render

    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    box = bpy.context.active_object
    box.name = "Broken"
    box.data.vertices[0].co = (float("nan"), 0.0, 0.0)
    box.data.vertices[1].co = (float("inf"), 0.0, 0.0)
    bpy.ops.object.camera_add(location=(0.0, -4.0, 0.0), rotation=(1.5708, 0.0, 0.0))
    bpy.context.scene.camera = bpy.context.active_object
    blend = tmp_path / "broken.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    res = convert_scene(blend, tmp_path / "s.usda", check_usd=False)
    assert [w for w in res.warnings if "Broken" in w and "6 triangles" in w], res.warnings
    render(load_scene(str(res.output)), RenderSettings(spp=1, width=4, height=4))
    geo = bsc.mesh_geometry(bsc.pick_objects(["Broken"]))
    assert len(geo.faces) == 6 and np.isfinite(geo.points).all()
