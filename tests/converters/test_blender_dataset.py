"""Cycles ground truth: units, camera alignment, fiber inputs and visibility (converters/blender/dataset.py).

Needs Blender's Python module (``pip install bpy``, installed in CI); skipped without it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")

from nasset_converters.blender import dataset as bds  # noqa: E402
from nasset_converters.blender import scene as bsc  # noqa: E402
from nasset_converters.blender.examples import build_example, shader_material  # noqa: E402
from nasset_converters.caster import Caster  # noqa: E402


def _diffuse_quad(albedo: float):
    """A 2 x 2 m Lambertian quad in Blender's XY plane (normal +Z Blender = +Y asset space)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    me = bpy.data.meshes.new("Quad")
    me.from_pydata([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)], [], [(0, 1, 2, 3)])
    ob = bpy.data.objects.new("Quad", me)
    bpy.context.scene.collection.objects.link(ob)
    mat, d = shader_material(bpy, "White", "ShaderNodeBsdfDiffuse")
    d.inputs["Color"].default_value = (albedo, albedo, albedo, 1.0)
    d.inputs["Roughness"].default_value = 0.0
    me.materials.append(mat)
    bpy.context.view_layer.update()
    return ob


def test_sun_units_and_camera_alignment(tmp_path):
    """A Lambertian quad of albedo a under a unit-irradiance sun at incidence theta has radiance
    a cos(theta) / pi (transport units of spec/kinds/rna.md); our rays and Cycles' pixels agree."""
    albedo, theta = 0.6, math.radians(30.0)
    ob = _diffuse_quad(albedo)
    variant, geo, _ = bsc.asset_geometry([ob])
    bsc.isolate([ob])
    s = bds.DataSettings(res=24, spp=64, light_angle_deg=0.0, distance=1.5)
    rig = bds.CyclesRig(s, tmp_path)
    caster = Caster(variant, geo)
    eye = np.array([0.3, 1.5, 0.2])  # above the quad (asset space, +Y up)
    o, d = bds.camera_rays(eye, np.zeros(3), math.radians(25.0), 24)
    hit = caster.hits(o, d)
    rig.place_camera(eye, np.zeros(3), math.radians(25.0), 24)
    wi = np.array([math.sin(theta), math.cos(theta), 0.0])
    rig.place_suns([wi])
    rgba, suns = rig.render(64, seed=1)
    rgba = rgba.reshape(-1, 4)
    rig.close()
    assert suns.shape == (1, 24, 24, 3) and np.allclose(suns[0].reshape(-1, 3), rgba[:, :3], rtol=1e-5, atol=1e-7)
    covered = rgba[:, 3] > 0.5
    ours = np.zeros(len(o), bool)
    ours[hit["pix"]] = True
    assert ours.sum() > 100 and np.count_nonzero(ours != covered) <= 2  # the same pixels, up to grazing edge pixels
    L = rgba[hit["pix"], :3]
    expect = albedo * math.cos(theta) / math.pi
    # per-pixel noise of a diffuse surface under a delta sun is only the BSDF sampling of indirect
    # light (none here): the mean over >100 pixels is within 2 % of the analytic value
    assert abs(float(L.mean()) - expect) < 0.02 * expect, (float(L.mean()), expect)
    assert np.allclose(hit["frame"], [0.0, 1.0, 0.0], atol=1e-5)
    assert caster.visibility(hit, wi).all()  # nothing of the asset above the quad


def test_fiber_view_inputs(tmp_path):
    """Hair views: h spans [-1, 1] and is close to uniform across fibers (a cylinder seen by
    parallel-ish rays has a uniform offset); tangents are unit; self-shadowing is partial."""
    names = build_example("blender-hair")
    objs = bsc.pick_objects(names)
    variant, geo, _ = bsc.asset_geometry(objs)
    center, radius = bsc.bounding_sphere(geo)
    bsc.isolate(objs)
    s = bds.DataSettings(res=48, spp=4, val_spp=4)
    rig = bds.CyclesRig(s, tmp_path)
    caster = Caster(variant, geo)
    views = [bds.render_view(rig, caster, center, radius, i, validation=False) for i in range(3)]
    rig.close()
    h = np.concatenate([v["h"] for v in views])
    t = np.concatenate([v["n"] for v in views])
    vis = np.concatenate([v["vis"] for v in views])
    assert len(h) > 500
    assert np.allclose(np.linalg.norm(t, axis=1), 1.0, atol=1e-4)
    assert h.min() >= -1.0 and h.max() <= 1.0
    # uniform on [-1, 1]: mean 0 and mean |h| = 0.5, each within 4 standard errors
    se = 1.0 / math.sqrt(3.0 * len(h))
    assert abs(float(h.mean())) < 4 * se and abs(float(np.abs(h).mean()) - 0.5) < 4 * (1 / math.sqrt(12 * len(h)))
    assert 0.05 < float(vis.mean()) < 0.98
    disagree = sum(int(v["disagree"]) for v in views) / max(1, sum(int(v["covered"]) for v in views))
    assert disagree < 0.1  # curved Cycles tubes vs our 8-sided prisms differ only at silhouettes
    rgb = np.concatenate([v["rgb"] for v in views])
    assert np.isfinite(rgb).all() and (rgb >= 0).all() and rgb.mean() > 0


def test_light_groups_give_each_sun_its_own_radiance(tmp_path):
    """k suns in one render, each in its own light group: every group carries its own sun's light, the analytic
    a cos(theta_i) / pi of a Lambertian quad, though each path's light sample picks one of the k suns."""
    albedo = 0.6
    thetas = np.radians([0.0, 35.0, 65.0])
    ob = _diffuse_quad(albedo)
    variant, geo, _ = bsc.asset_geometry([ob])
    bsc.isolate([ob])
    rig = bds.CyclesRig(bds.DataSettings(res=24, spp=64, light_angle_deg=0.0), tmp_path)
    hit = Caster(variant, geo).hits(*bds.camera_rays(np.array([0.3, 1.5, 0.2]), np.zeros(3), math.radians(25.0), 24))
    rig.place_camera(np.array([0.3, 1.5, 0.2]), np.zeros(3), math.radians(25.0), 24)
    rig.place_suns(np.stack([np.sin(thetas), np.cos(thetas), np.zeros(3)], 1))
    rgba, suns = rig.render(256, seed=3)
    rig.close()
    assert suns.shape == (3, 24, 24, 3)
    L = suns.reshape(3, -1, 3)[:, hit["pix"]].mean(axis=(1, 2))
    expect = albedo * np.cos(thetas) / math.pi
    assert np.all(np.abs(L - expect) < 0.03 * expect[0]), (L, expect)  # within 3 % of the brightest sun's radiance
    assert np.allclose(suns.sum(0), rgba[..., :3], rtol=1e-4, atol=1e-6)  # the groups add up to every light


def test_lights_per_view_samples(tmp_path):
    """k suns per training view: every kept pixel gives k samples, one per sun (its own light direction, visibility
    cast toward it, and the same geometry); held-out views keep one sun."""
    names = build_example("blender-surface")
    objs = bsc.pick_objects(names)
    variant, geo, _ = bsc.asset_geometry(objs)
    center, radius = bsc.bounding_sphere(geo)
    bsc.isolate(objs)
    s = bds.DataSettings(res=24, spp=6, lights_per_view=3)
    assert s.spp_per_target == 2.0
    rig = bds.CyclesRig(s, tmp_path)
    caster = Caster(variant, geo)
    v = bds.render_view(rig, caster, center, radius, 0, validation=False)
    val = bds.render_view(rig, caster, center, radius, 0, validation=True)
    rig.close()
    assert len(np.unique(v["wi"], axis=0)) == 3 and len(np.unique(val["wi"], axis=0)) == 1
    kept = len(v["pix"]) // 3
    assert kept > 50 and len(v["pix"]) == 3 * kept and len(v["rgb"]) == 3 * kept
    for i in range(1, 3):  # sun i's rows repeat sun 0's pixels and geometry
        rows = slice(i * kept, (i + 1) * kept)
        assert np.array_equal(v["pix"][rows], v["pix"][:kept]) and np.array_equal(v["x"][rows], v["x"][:kept])
        assert not np.array_equal(v["wi"][rows], v["wi"][:kept])
    _, eye, half_fov, res = bds.view_camera(s, center, radius, 0, False)
    hit = caster.hits(*bds.camera_rays(eye, np.asarray(center), half_fov, res))
    keep = np.isin(hit["pix"], v["pix"])
    sel = {k: (a[keep] if isinstance(a, np.ndarray) and len(a) == len(hit["pix"]) else a) for k, a in hit.items()}
    for i in range(3):
        rows = slice(i * kept, (i + 1) * kept)
        assert np.array_equal(caster.visibility(sel, v["wi"][rows]).astype(np.uint8), v["vis"][rows])
    assert np.isfinite(v["rgb"]).all() and (v["rgb"] >= 0).all()
    lit = [float(v["rgb"][i * kept:(i + 1) * kept].mean()) for i in range(3)]
    assert len(set(lit)) == 3 and min(lit) >= 0  # three suns, three different images


def test_isolate_renders_an_asset_object_of_a_hidden_or_excluded_collection():
    """The asset's own object is rendered whatever its collection says (Cycles skips objects of collections disabled
    in renders or excluded from the view layer: the views would be black); the other objects stay hidden."""
    ob = _diffuse_quad(0.5)
    other = bpy.data.objects.new("Other", ob.data)
    bpy.context.scene.collection.objects.link(other)
    for hide in ("render", "exclude"):
        coll = bpy.data.collections.new(f"C_{hide}")
        bpy.context.scene.collection.children.link(coll)
        for c in list(ob.users_collection):
            c.objects.unlink(ob)
        coll.objects.link(ob)
        if hide == "render":
            coll.hide_render = True
        else:
            bpy.context.view_layer.layer_collection.children[coll.name].exclude = True
        renders = bsc.render_visible(bpy.context.view_layer)
        assert not renders(ob) and renders(other)
        bsc.isolate([ob])
        renders = bsc.render_visible(bpy.context.view_layer)
        assert renders(ob) and not renders(other), hide
        other.hide_render = False
