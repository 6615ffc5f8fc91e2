"""Neural-asset integration (rna) and bad-input handling of the reference renderer."""

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, make_plan, render
from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_asset, random_rna_asset
from nasset_sdk.errors import SceneError

TU, TS, E = 1.0, 0.25, 2.0


def _rot_y(deg, t=(0, 0, 0)):
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    m = np.eye(4)
    m[0, :3], m[2, :3], m[3, :3] = (c, 0, -s), (s, 0, c), t
    return m


def test_instanced_twice_matches_single_instances(tmp_path):
    asset = random_rna_asset(tmp_path / "a.usdc", seed=3)
    mats = {"A": _rot_y(30, (-0.8, 0, 0)), "B": _rot_y(-75, (0.8, 0.1, 0))}

    def scene(names, fname):
        b = SceneBuilder()
        b.camera((0, 0.5, 4), (0, 0, 0), focal=35)
        b.distant("Sun", (0.3, 1.0, 0.5), E)
        for n in names:
            b.asset(n, asset, mats[n], typed=(n == "A"))  # typed NeuralAsset and untyped def + reference
        return load_scene(b.write(tmp_path / fname))

    kw = dict(width=32, height=24, spp=1, max_depth=1)  # direct light only: deterministic given the seed
    both = render(scene(["A", "B"], "ab.usda"), RenderSettings(**kw)).image
    a = render(scene(["A"], "a.usda"), RenderSettings(**kw)).image
    b = render(scene(["B"], "b.usda"), RenderSettings(**kw)).image
    assert a.max() > 0 and b.max() > 0
    np.testing.assert_allclose(both, a + b, atol=1e-5)


def test_rigid_transform_invariance(tmp_path):
    """Moving asset, light and camera together leaves the image unchanged (object-space evaluation)."""
    asset = random_rna_asset(tmp_path / "a.usdc", seed=4)
    g = _rot_y(50, (2.0, -1.0, 0.5))
    from nasset_reference_renderer.testscenes import look_at

    imgs = []
    for k, m in enumerate((np.eye(4), g)):
        b = SceneBuilder()
        b.camera(None, None, matrix=look_at((0, 0.4, 3), (0, 0, 0)) @ m)
        b.distant("Sun", np.array([0.4, 1.0, 0.2]) @ m[:3, :3], E)
        b.asset("Obj", asset, _rot_y(20) @ m)
        imgs.append(render(load_scene(b.write(tmp_path / f"s{k}.usda")), RenderSettings(width=24, height=24, spp=1)).image)
    assert imgs[0].max() > 0
    np.testing.assert_allclose(imgs[0], imgs[1], atol=2e-4 * imgs[0].max())


def _constant_scene(tmp_path, occluder=False):
    asset = constant_rna_asset(tmp_path / "c.usdc", unshadowed=(TU,) * 3, shadowed=(TS,) * 3)
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0), focal=60)
    b.distant("Sun", (0, 1, 0), E)
    b.asset("Obj", asset)
    if occluder:
        b.quad("Blocker", (0.35, 3.0, 0.3), 0.5, normal=(0, -1, 0), diffuse=(0, 0, 0))
    return load_scene(b.write(tmp_path / ("occ.usda" if occluder else "c.usda")))


def test_self_shadowing_picks_shadowed_output(tmp_path):
    scene = _constant_scene(tmp_path)
    img = render(scene, RenderSettings(width=40, height=40, spp=4)).image[..., 0]
    # upper half of the sphere faces the light: T_unshadowed * E; lower half: the asset blocks it
    assert np.allclose(img[12, 18:22], TU * E)
    assert np.allclose(img[28, 18:22], TS * E)
    vals = set(np.round(img[img > 0], 6))
    assert {round(TU * E, 6), round(TS * E, 6)} <= vals


def test_other_object_shadow_respected(tmp_path):
    scene = _constant_scene(tmp_path, occluder=True)
    plan = make_plan(scene, width=40, height=40, spp=4, max_depth=5, tile=64, batch=65536)
    assert plan.instance_indirect.all()
    img = render(scene, RenderSettings(width=40, height=40, spp=4)).image[..., 0]
    assert np.allclose(img[12, 26:29], 0.0)  # upper right of the sphere, in the blocker's shadow
    assert np.allclose(img[12, 12:15], TU * E)  # upper left, lit (blocker is black: no indirect light)
    assert np.allclose(img[28, 18:22], TS * E)


def test_plan_lone_asset(tmp_path):
    scene = _constant_scene(tmp_path)
    plan = make_plan(scene, width=8, height=8, spp=1, max_depth=5, tile=64, batch=65536)
    assert not plan.instance_indirect.any()
    text = plan.explain()
    assert "indirect off" in text and "load ['core']" in text


# -- bad input ---------------------------------------------------------------------------------
def test_no_camera(tmp_path):
    b = SceneBuilder()
    b.quad("Floor", (0, 0, 0), 1.0)
    with pytest.raises(SceneError) as e:
        load_scene(b.write(tmp_path / "s.usda"))
    assert e.value.code == "SCENE_INVALID" and "camera" in str(e.value)


def test_unsupported_light(tmp_path):
    from pxr import UsdLux

    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    UsdLux.GeometryLight.Define(b.stage, "/World/Tube")
    with pytest.raises(SceneError) as e:
        load_scene(b.write(tmp_path / "s.usda"))
    assert e.value.code == "SCENE_UNSUPPORTED" and e.value.prim == "/World/Tube"


def test_unsupported_material(tmp_path):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 1.0)
    b.stage.GetPrimAtPath("/World/Looks/FloorMat/PreviewSurface").GetAttribute("info:id").Set("arnold:standard_surface")
    with pytest.raises(SceneError) as e:
        load_scene(b.write(tmp_path / "s.usda"))
    assert e.value.code == "SCENE_UNSUPPORTED" and "/World/Looks/FloorMat" in str(e.value)


def test_missing_asset(tmp_path):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.asset("Obj", tmp_path / "nope.usdc")
    with pytest.raises(SceneError) as e:
        load_scene(b.write(tmp_path / "s.usda"))
    assert e.value.prim == "/World/Obj" and "not found" in str(e.value)


def test_invalid_asset(tmp_path):
    from pxr import Sdf, Usd

    asset = random_rna_asset(tmp_path / "a.usdc")
    st = Usd.Stage.Open(str(asset))
    st.GetPrimAtPath("/Asset").GetAttribute("nasset:specVersion").Set("99.0")
    st.Save()
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.asset("Obj", asset)
    with pytest.raises(SceneError) as e:
        load_scene(b.write(tmp_path / "s.usda"))
    assert e.value.code == "SCENE_INVALID" and e.value.prim == "/World/Obj" and "SPEC_VERSION" in str(e.value)
    del Sdf


def test_unknown_attribute_is_a_warning(tmp_path):
    from pxr import Sdf

    from nasset_reference_renderer import SceneWarning

    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    lt = b.distant("Sun", (0, 1, 0))
    lt.GetPrim().CreateAttribute("inputs:shaping:cone:angle", Sdf.ValueTypeNames.Float).Set(30.0)
    with pytest.warns(SceneWarning, match="shaping"):
        scene = load_scene(b.write(tmp_path / "s.usda"))
    assert any("shaping" in w for w in scene.warnings)


def test_cli_render_asset_file(tmp_path):
    from nasset_sdk.cli import main

    asset = random_rna_asset(tmp_path / "a.usdc")
    out = tmp_path / "o.exr"
    rc = main(["render", str(asset), "-o", str(out), "--spp", "1", "--width", "16", "--quiet", "--explain",
               "--png", str(tmp_path / "o.png"), "--variance", str(tmp_path / "v.exr")])
    assert rc == 0 and out.stat().st_size > 0 and (tmp_path / "o.png").read_bytes()[:4] == b"\x89PNG"
    from nasset_reference_renderer import read_exr

    assert read_exr(out).shape == (16, 16, 3)


def test_scene_stage_loads_scene_payloads_but_no_asset_components(tmp_path):
    """spec/renderer.md#traversal: a prim placed with a payload is composed; asset components stay for the plan."""
    from pxr import Sdf, Usd

    from nasset_reference_renderer.scene import open_stage

    asset = tmp_path / "a.usdc"
    random_rna_asset(asset, seed=3)
    scene = tmp_path / "s.usda"
    stage = Usd.Stage.CreateNew(str(scene))
    stage.DefinePrim("/World/Direct").GetReferences().AddReference("./a.usdc")
    placed = stage.DefinePrim("/World/Placed")
    placed.GetPayloads().AddPayload(Sdf.Payload("./a.usdc"))
    stage.GetRootLayer().Save()
    opened = open_stage(str(scene))
    assert opened.GetPrimAtPath("/World/Placed").GetTypeName() == "NeuralAsset"  # the scene's payload was loaded
    for root in ("/World/Direct", "/World/Placed"):
        comp = opened.GetPrimAtPath(root + "/Components/core")
        assert comp and not comp.IsLoaded()  # the asset's component payloads were not


def test_mesh_rows_and_boxes_with_neural_instances_between_meshes(tmp_path):
    """Corner normals are stored for mesh triangles only (Scene.corner_rows): a mesh loaded after a neural
    instance keeps the rows it has in a scene without the asset; face normals and the scene's bounds cover every
    triangle, and the neural instance's box and shared-vertex mesh describe its own triangles."""
    from pxr import Sdf, UsdGeom

    from nasset_reference_renderer.sampling import face_normals

    asset = random_rna_asset(tmp_path / "a.usdc", seed=3)

    def scene(with_asset, fname):
        b = SceneBuilder()
        b.camera((0, 0.5, 4), (0, 0, 0), focal=35)
        b.distant("Sun", (0.3, 1.0, 0.5), E)
        b.quad("Floor", (0, -1, 0), 4.0)
        if with_asset:
            b.asset("A", asset, _rot_y(30, (-0.8, 0, 0)))
        ball = b.sphere_mesh("Ball", (0.8, 0, 0), 0.4, subdivisions=1)
        n = np.asarray(ball.GetPointsAttr().Get(), np.float64) - [0.8, 0, 0]  # smooth normals, unlike the faces'
        UsdGeom.PrimvarsAPI(ball).CreatePrimvar("normals", Sdf.ValueTypeNames.Normal3fArray,
                                                UsdGeom.Tokens.vertex).Set(n.astype(np.float32))
        return load_scene(b.write(tmp_path / fname))

    mixed, plain = scene(True, "mixed.usda"), scene(False, "plain.usda")
    kinds = [i.kind for i in mixed.instances]
    assert kinds == ["mesh", "neural", "mesh"]
    floor, neural, ball = mixed.instances
    assert len(mixed.tri_normals) == len(mixed.tri_st) == floor.n_tri + ball.n_tri
    for inst, ref in zip((floor, ball), plain.instances, strict=True):
        prim = inst.first_tri + np.arange(inst.n_tri)
        rows = mixed.corner_rows(prim, np.full(len(prim), mixed.instances.index(inst)))
        got = mixed.tri_normals[rows]
        want = plain.tri_normals[ref.first_tri + np.arange(ref.n_tri)]
        np.testing.assert_array_equal(got, want)
    ball_rows = mixed.corner_rows(ball.first_tri + np.arange(ball.n_tri), np.full(ball.n_tri, 2))
    assert np.abs(mixed.tri_normals[ball_rows] - np.repeat(mixed.tri_ng[ball.first_tri:][:, None], 3, 1)).max() > 0.05
    np.testing.assert_array_equal(mixed.tri_ng, face_normals(mixed.triangles))
    p = mixed.triangles.reshape(-1, 3)
    np.testing.assert_array_equal(np.stack(mixed.bounds), np.stack([p.min(0), p.max(0)]))
    own = mixed.triangles[neural.first_tri:neural.first_tri + neural.n_tri]
    np.testing.assert_array_equal(np.stack(neural.box), np.stack([own.reshape(-1, 3).min(0), own.reshape(-1, 3).max(0)]))
    pts, faces, _ = mixed.world_mesh(1)
    assert mixed.world_mesh(0) is None and mixed.world_mesh(2) is None
    np.testing.assert_array_equal(pts[faces], own)


def continuation_against_light_sampling(tmp_path, asset, matrix, continuation, spp, size, le=0.5):
    """Renders of ``asset`` (instance ``matrix``) alone under a constant sky of radiance ``le``, with a tiny black
    quad far away (solid angle < 1e-6 sr) that turns continuations on: (full render with ``continuation`` at
    max_depth 3, the same scene at max_depth 1: light samples alone, weight 1, no continuation). Both estimate
    the same image; asserts that their sums agree within 4 standard errors and that the errors are small enough
    (< 1 %) to see a few percent of bias."""
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.dome("Sky", le)
    b.quad("Speck", (0, 0, -40), 0.01, normal=(0, 0, 1), diffuse=(0.0, 0.0, 0.0))
    b.asset("A", asset, matrix)
    scene = b.write(tmp_path / "scene.usda")
    full = render(load_scene(scene), RenderSettings(spp=spp, width=size, height=size, seed=5, max_depth=3,
                                                    rna_continuation=continuation))
    direct = render(load_scene(scene), RenderSettings(spp=spp, width=size, height=size, seed=6, max_depth=1))
    assert np.isfinite(full.image).all()
    total = direct.image.sum((0, 1))
    diff = full.image.sum((0, 1)) - total
    se = np.sqrt(full.variance.sum((0, 1)) + direct.variance.sum((0, 1)))
    assert np.all(np.abs(diff) < 4 * se), (diff / total, se / total)
    assert np.all(se < 0.01 * total)
    return full, direct


@pytest.mark.parametrize("transformed,continuation", [(False, "lobes"), (True, "lobes"), (True, "uniform")])
def test_continuation_is_unbiased_under_a_constant_sky(tmp_path, transformed, continuation):
    """A convex asset of constant transport (T_u, T_s) under a constant sky Le: a pixel's expectation is
    2 pi Le (T_u + T_s) times its coverage (directions into the asset take the shadowed branch), whatever density
    the continuation samples, as long as the sky's light samples are MIS-weighted with that same density
    (:func:`continuation_against_light_sampling`). The transformed instance is rotated and scaled unevenly, so
    the normal that places the lobes must be mapped by the inverse transpose to stay a world density."""
    asset = constant_rna_asset(tmp_path / "c.usdc", unshadowed=(TU,) * 3, shadowed=(TS,) * 3, subdivisions=2)
    M = _rot_y(40) @ np.diag([1.3, 0.7, 1.0, 1.0]) if transformed else None
    _, direct = continuation_against_light_sampling(tmp_path, asset, M, continuation, spp=64, size=20)
    centre = direct.image[8:12, 8:12, 0]  # fully covered pixels
    expected = 2 * np.pi * 0.5 * (TU + TS)
    assert centre.mean() == pytest.approx(expected, abs=4 * np.sqrt(direct.variance[8:12, 8:12, 0].sum()) / 16)
