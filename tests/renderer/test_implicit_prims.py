"""Implicit prims (spec/renderer.md#implicit-prims): Cylinder, Cone, Capsule and Plane are tessellated like Sphere and
Cube, with their schema's fallbacks, axis and outward normals. Before, each was SCENE_UNSUPPORTED."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError
from nasset_sdk.implicit import IMPLICIT_PRIMS, implicit_mesh


def _volume(pts, faces) -> float:
    t = pts[faces]
    return float(np.einsum("ij,ij->i", t[:, 0], np.cross(t[:, 1], t[:, 2])).sum() / 6.0)


@pytest.mark.parametrize("axis", ["X", "Y", "Z"])
def test_solids_have_their_schema_volume_extent_and_outward_normals(axis):
    k = {"X": 0, "Y": 1, "Z": 2}[axis]
    for tname, expect, half_extent in (("Cylinder", np.pi * 0.5 ** 2 * 3.0, 1.5), ("Cone", np.pi * 0.5 ** 2 * 3.0 / 3, 1.5),
                                       ("Capsule", np.pi * 0.5 ** 2 * 3.0 + 4 / 3 * np.pi * 0.5 ** 3, 2.0)):
        pts, faces, nrm = implicit_mesh(tname, {"radius": 0.5, "height": 3.0}, axis)
        assert _volume(pts, faces) == pytest.approx(expect, rel=0.01), tname  # positive: wound about the outside
        assert np.abs(pts[:, k]).max() == pytest.approx(half_extent), tname  # extent along the axis
        centre = pts[faces].mean(1)
        assert ((nrm.mean(1) * centre).sum(1) > 0).mean() > 0.99, tname  # normals point away from the centre
        np.testing.assert_allclose(np.linalg.norm(nrm, axis=-1), 1.0, atol=1e-9)
    pts, faces, _ = implicit_mesh("Cone", {"radius": 0.5, "height": 3.0}, axis)
    assert pts[np.argmax(pts[:, k])][[j for j in range(3) if j != k]] == pytest.approx([0, 0])  # the apex on +axis


@pytest.mark.parametrize("axis, width_axis, length_axis", [("X", 2, 1), ("Y", 0, 2), ("Z", 0, 1)])
def test_plane_spans_width_and_length_along_usds_axes_and_faces_its_axis(axis, width_axis, length_axis):
    pts, faces, nrm = implicit_mesh("Plane", {"width": 4.0, "length": 1.0}, axis)
    assert np.ptp(pts[:, width_axis]) == 4.0 and np.ptp(pts[:, length_axis]) == 1.0
    t = pts[faces]
    normal = np.eye(3)[{"X": 0, "Y": 1, "Z": 2}[axis]]
    assert (np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]) @ normal > 0).all()
    np.testing.assert_allclose(nrm, np.broadcast_to(normal, nrm.shape))


def test_lit_implicit_prims_render_and_bad_sizes_are_scene_errors(tmp_path):
    from pxr import Sdf, Usd, UsdGeom

    b = SceneBuilder()
    b.camera((0, 2, 6), (0, 0.5, 0), focal=20)
    for k, tname in enumerate(IMPLICIT_PRIMS):
        prim = b.stage.DefinePrim(f"/World/{tname}", tname)
        UsdGeom.Xformable(prim).AddTranslateOp().Set((-2.5 + k, 0.6, 0.0))
        if tname in ("Cylinder", "Cone", "Capsule", "Plane"):
            prim.CreateAttribute("axis", Sdf.ValueTypeNames.Token).Set("Y")  # upright; the plane faces the sun
    b.distant("Sun", (0.3, 1.0, 0.6), 2.0)
    path = b.write(tmp_path / "s.usda")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # each prim is tessellated (warned)
        scene = load_scene(path)
    img = render(scene, RenderSettings(spp=2, width=48, height=24, max_depth=1)).image
    assert np.isfinite(img).all() and img.mean() > 0.02
    assert {i.prim.rsplit("/", 1)[-1] for i in scene.instances} == set(IMPLICIT_PRIMS)
    stage = Usd.Stage.Open(path)
    stage.GetPrimAtPath("/World/Cone").GetAttribute("radius").Set(-1.0)
    stage.GetRootLayer().Save()
    with pytest.raises(SceneError) as exc, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_scene(path)
    assert "radius" in str(exc.value)
