"""PointInstancer (spec/renderer.md#geometry): each instance renders its prototype, placed as USD computes it.
Before, a PointInstancer was SCENE_UNSUPPORTED."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pxr import Gf, UsdGeom, Vt

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError


def _scene(tmp_path, *, positions, proto_indices, invisible=(), with_root_xform=False):
    """Two prototypes under the instancer (a red unit quad facing +Y, a green cube of edge 0.5), a camera above."""
    b = SceneBuilder()
    b.camera((0, 6, 0.001), (0, 0, 0), focal=20)
    pi = UsdGeom.PointInstancer.Define(b.stage, "/World/Scatter")
    protos = b.stage.DefinePrim("/World/Scatter/Prototypes", "Scope")
    quad = b.mesh("Scatter/Prototypes/Tile", [(-0.5, 0, -0.5), (-0.5, 0, 0.5), (0.5, 0, 0.5), (0.5, 0, -0.5)],
                  [[0, 1, 2, 3]], diffuse=(0.8, 0.1, 0.1), specular=(0, 0, 0), roughness=1.0)
    if with_root_xform:  # the prototype root's own transform is part of each instance
        UsdGeom.Xformable(quad).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.0, 1.0))
    cube = UsdGeom.Cube.Define(b.stage, "/World/Scatter/Prototypes/Box")
    cube.CreateSizeAttr(0.5)
    assert protos
    pi.CreatePrototypesRel().SetTargets([quad.GetPath(), cube.GetPath()])
    pi.CreateProtoIndicesAttr(Vt.IntArray(list(proto_indices)))
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(*p) for p in positions]))
    if invisible:
        pi.CreateInvisibleIdsAttr(Vt.Int64Array(list(invisible)))
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(b.write(tmp_path / "s.usda"))


def _centroid_x(scene, channel):
    img = render(scene, RenderSettings(spp=2, width=64, height=64, max_depth=1)).image[..., channel]
    ys, xs = np.mgrid[0:64, 0:64]
    return float((img * xs).sum() / img.sum()), float(img.sum())


def test_instances_render_their_prototypes_where_the_instancer_places_them(tmp_path):
    scene = _scene(tmp_path, positions=[(-1.5, 0, 0), (1.5, 0, 0), (0, 0, 0)], proto_indices=[0, 0, 1])
    assert len([i for i in scene.instances if i.prim.endswith("/Tile")]) == 2
    assert len([i for i in scene.instances if i.prim.endswith("/Box")]) == 1
    tiles = [i.box for i in scene.instances if i.prim.endswith("/Tile")]
    np.testing.assert_allclose(sorted(0.5 * (lo[0] + hi[0]) for lo, hi in tiles), [-1.5, 1.5], atol=1e-9)
    x, red = _centroid_x(scene, 0)
    assert red > 0 and abs(x - 31.5) < 1.0  # two tiles placed symmetrically about the image centre


def test_masked_instances_and_the_prototype_root_transform(tmp_path):
    scene = _scene(tmp_path, positions=[(-1.5, 0, 0), (1.5, 0, 0)], proto_indices=[0, 0], invisible=[0],
                   with_root_xform=True)
    (lo, hi), = [i.box for i in scene.instances]
    np.testing.assert_allclose(0.5 * (lo + hi), [1.5, 0.0, 1.0], atol=1e-6)


def test_bad_proto_indices_are_scene_errors(tmp_path):
    with pytest.raises(SceneError) as exc:
        _scene(tmp_path, positions=[(0, 0, 0)], proto_indices=[5])
    assert "protoIndices" in str(exc.value)


def test_instances_past_the_triangle_bound_are_refused(tmp_path, monkeypatch):
    from nasset_reference_renderer import scene as scene_module

    monkeypatch.setattr(scene_module, "MAX_INSTANCED_TRIANGLES", 20)
    with pytest.raises(SceneError) as exc:
        _scene(tmp_path, positions=[(x, 0, 0) for x in range(20)], proto_indices=[0] * 20)
    assert "more than 20 triangles" in str(exc.value)


def test_more_instances_than_the_bound_are_refused_before_their_transforms(tmp_path, monkeypatch):
    from nasset_reference_renderer import scene as scene_module

    monkeypatch.setattr(scene_module, "MAX_INSTANCES", 3)
    with pytest.raises(SceneError) as exc:
        _scene(tmp_path, positions=[(x, 0, 0) for x in range(4)], proto_indices=[0] * 4)
    assert "more than 3" in str(exc.value)


def test_points_and_curves_prototypes_are_placed_like_meshes(tmp_path):
    """A Points prototype (one sphere of width 0.4 at the prototype's origin) instanced at x = -1 and 2: its spheres'
    triangles are centred there. Before, curves and points prototypes were left out."""
    b = SceneBuilder()
    b.camera((0, 6, 0.001), (0, 0, 0), focal=20)
    pi = UsdGeom.PointInstancer.Define(b.stage, "/World/Scatter")
    dot = UsdGeom.Points.Define(b.stage, "/World/Scatter/Prototypes/Dot")
    dot.CreatePointsAttr([(0.0, 0.0, 0.0)])
    dot.CreateWidthsAttr([0.4])
    pi.CreatePrototypesRel().SetTargets([dot.GetPath()])
    pi.CreateProtoIndicesAttr(Vt.IntArray([0, 0]))
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(-1, 0, 0), Gf.Vec3f(2, 0, 0)]))
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(b.write(tmp_path / "dots.usda"))
    centres = sorted(float(scene.triangles[i.first_tri:i.first_tri + i.n_tri].reshape(-1, 3)[:, 0].mean())
                     for i in scene.instances)
    np.testing.assert_allclose(centres, [-1.0, 2.0], atol=1e-9)
    assert {round(float(np.ptp(scene.triangles[i.first_tri:i.first_tri + i.n_tri].reshape(-1, 3)[:, 1])), 6)
            for i in scene.instances} == {0.4}


def _instancer_with_prototype(tmp_path, define):
    """A PointInstancer of one prototype Xform under which ``define(stage, path)`` puts a child, over a lit floor."""
    from tests.stage_scenes import instancer_with_prototype

    return instancer_with_prototype(tmp_path, define)


def test_light_in_a_prototype_is_warned_by_name(tmp_path):
    """A lamp prototype (an Xform holding a SphereLight) lit nothing, and nothing said so."""
    from pxr import UsdLux

    path = _instancer_with_prototype(tmp_path, lambda stage, p: UsdLux.SphereLight.Define(stage, p))
    with pytest.warns(UserWarning):
        said = load_scene(path).warnings
    assert any("/World/Scatter/Prototypes/Lamp/Part" in m and "not instanced" in m for m in said), said


def test_unsupported_geometry_in_a_prototype_is_scene_unsupported(tmp_path):
    """A NURBS patch (any Gprim the renderer does not draw) inside a prototype rendered nothing without a word."""
    path = _instancer_with_prototype(tmp_path, lambda stage, p: UsdGeom.NurbsPatch.Define(stage, p))
    with pytest.raises(SceneError) as info:
        load_scene(path)
    assert info.value.code == "SCENE_UNSUPPORTED" and "/World/Scatter/Prototypes/Lamp/Part" in str(info.value)
