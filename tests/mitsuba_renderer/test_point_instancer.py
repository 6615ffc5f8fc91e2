"""PointInstancer in the Mitsuba implementations' scene reader (spec/renderer.md#geometry; mitsuba_renderer/usdscene.py):
both refused it (SCENE_UNSUPPORTED) while the reference renderer rendered it. The reader's placements are checked
against the reference renderer's instances, the image against its render (tests/stage_scenes.py)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from pxr import Gf, UsdGeom

pytest.importorskip("mitsuba")

from nasset_mitsuba_renderer import usdscene  # noqa: E402
from nasset_reference_renderer import load_scene  # noqa: E402
from nasset_sdk.errors import SceneError  # noqa: E402
from tests.stage_scenes import check_point_instancer, instancer_with_prototype, point_instancer_scene  # noqa: E402


def _read(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return usdscene.read_scene(str(path))


def test_instances_are_the_reference_renderers_triangles(tmp_path):
    """Every instance's triangles, as world points, are the reference renderer's (same prims, same placement
    M_prim · M_root⁻¹ · X_i · M_instancer; the mask leaves one out), to float rounding; the mirrored instance is a mesh
    of its own with the front sign flipped."""
    path = point_instancer_scene(tmp_path)
    desc = _read(path)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = load_scene(path)
    for part in ("/Pyramid", "/Ball", "/Dots"):
        got = np.concatenate([m.points[m.faces].reshape(-1, 9) for m in desc.meshes if m.prim.endswith(part)])
        want = np.concatenate([ref.triangles[i.first_tri:i.first_tri + i.n_tri].reshape(-1, 9)
                               for i in ref.instances if i.prim.endswith(part)])
        assert len(got) == len(want) and (part != "/Pyramid" or len(got) == 3 * 4)  # three rocks: one is masked
        for tris in (got, want):  # each triangle's corners in a fixed order (a mirrored instance may wind them the other way)
            c = tris.reshape(-1, 3, 3)
            tris[:] = np.take_along_axis(c, np.lexsort(c.transpose(2, 0, 1)[::-1])[..., None], 1).reshape(-1, 9)
        np.testing.assert_allclose(got[np.lexsort(got.T[::-1])], want[np.lexsort(want.T[::-1])], atol=1e-7)
    pyramids = [m for m in desc.meshes if m.prim.endswith("/Pyramid")]
    assert sorted((len(m.faces), m.front_sign) for m in pyramids) == [(4, -1.0), (8, 1.0)]  # two rocks, one mirrored
    dots = [m for m in desc.meshes if m.prim.endswith("/Dots")]
    assert len(dots) == 1 and len(dots[0].faces) == 2 * 5 * 80  # two instances of five 80-triangle spheres


def test_corner_normals_follow_each_instance(tmp_path):
    """The authored normals of the pyramid, moved by each placement's inverse transpose: each stays on the outer side of
    its world triangle (mirrored instance included, where the front sign says which side is the front)."""
    desc = _read(point_instancer_scene(tmp_path))
    for m in (m for m in desc.meshes if m.prim.endswith("/Pyramid")):
        tri = m.points[m.faces]
        ng = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]) * m.front_sign
        assert (np.einsum("fk,fck->fc", ng, m.corner_normals) > 0).all()
        np.testing.assert_allclose(np.linalg.norm(m.corner_normals, axis=-1), 1.0, atol=1e-12)


def _instancer(tmp_path, define=None, n=2, proto_indices=None, position=None):
    return instancer_with_prototype(tmp_path, define, n=n, proto_indices=proto_indices, position=position)


@pytest.mark.parametrize("what, define, code", [
    ("NURBS patch", lambda stage, p: UsdGeom.NurbsPatch.Define(stage, p), "SCENE_UNSUPPORTED"),
    ("nested instancer", lambda stage, p: UsdGeom.PointInstancer.Define(stage, p), "SCENE_UNSUPPORTED"),
])
def test_unsupported_prototype_contents_name_the_prim(tmp_path, what, define, code):
    with pytest.raises(SceneError) as info:
        _read(_instancer(tmp_path, define))
    assert info.value.code == code and "/World/Scatter/Prototypes/Lamp/Part" in str(info.value), what


def test_bad_instances_are_scene_invalid(tmp_path, monkeypatch):
    with pytest.raises(SceneError) as info:
        _read(_instancer(tmp_path, proto_indices=[0, 3]))
    assert info.value.code == "SCENE_INVALID" and info.value.attribute == "protoIndices"
    with pytest.raises(SceneError) as info:
        _read(_instancer(tmp_path, position=(float("nan"), 0.0, 0.0)))
    assert info.value.code == "SCENE_INVALID" and info.value.attribute == "positions"
    monkeypatch.setattr(usdscene, "MAX_INSTANCES", 3)
    with pytest.raises(SceneError) as info:
        _read(_instancer(tmp_path, n=4))
    assert "more than 3" in str(info.value)
    monkeypatch.setattr(usdscene, "MAX_INSTANCED_TRIANGLES", 20)  # a cube is 12 triangles
    with pytest.raises(SceneError) as info:
        _read(_instancer(tmp_path, n=2))
    assert "more than 20 triangles" in str(info.value)


def test_light_in_a_prototype_is_warned_by_name(tmp_path):
    from pxr import UsdLux

    path = _instancer(tmp_path, lambda stage, p: UsdLux.SphereLight.Define(stage, p))
    with pytest.warns(UserWarning, match="/World/Scatter/Prototypes/Lamp/Part.*not instanced"):
        desc = usdscene.read_scene(str(path))
    assert not any(lt.prim.startswith("/World/Scatter") for lt in desc.lights)


def test_instances_render_as_in_the_reference_renderer(tmp_path):
    from nasset_mitsuba_renderer import render as mitsuba

    check_point_instancer(mitsuba.render, tmp_path, spp=64)


def test_material_groups_carry_only_the_points_they_use(tmp_path):
    """A prototype mesh of 20 000 points, 3 of them used, split in two materialBind GeomSubsets, instanced 50 times: each
    group's Mesh holds the points its faces use (3 per copy), not all 20 000 per group and per instance (160 MB here,
    unbounded for a hostile file: the triangle bound does not bound points)."""
    from pxr import UsdShade

    def define(stage, p):
        mesh = UsdGeom.Mesh.Define(stage, p)
        pts = [Gf.Vec3f(0, 0, 0), Gf.Vec3f(0.2, 0, 0), Gf.Vec3f(0, 0.2, 0)] + [Gf.Vec3f(9, 9, 9)] * 19997
        mesh.CreatePointsAttr(pts)
        mesh.CreateFaceVertexCountsAttr([3, 3])
        mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 0, 2, 1])
        binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
        for name, face in (("front", 0), ("back", 1)):
            subset = binding.CreateMaterialBindSubset(name, [face], UsdGeom.Tokens.face)
            mat = UsdShade.Material.Define(stage, f"/World/Looks/{name}")
            shader = UsdShade.Shader.Define(stage, f"/World/Looks/{name}/S")
            shader.CreateIdAttr("UsdPreviewSurface")
            mat.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
            UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(mat)

    desc = _read(_instancer(tmp_path, define, n=50, position=(0.0, 2.0, 0.0)))
    parts = [m for m in desc.meshes if m.prim.startswith("/World/Scatter")]
    assert len(parts) == 2 and all(len(m.faces) == 50 and len(m.points) == 150 for m in parts)
    for m in parts:  # the renumbered faces still draw the triangle (0, 0.2) x (0, 0.2) moved to y = 2
        np.testing.assert_allclose(m.points[m.faces].reshape(-1, 3).max(0), [0.2, 2.2, 0.0], atol=1e-6)
