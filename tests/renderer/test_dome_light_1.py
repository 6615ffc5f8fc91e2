"""UsdLux.DomeLight_1 (spec/renderer.md#lights): a DomeLight whose poleAxis sets where the texture's top pole
points before the prim's own orientation. Before, a DomeLight_1 was SCENE_UNSUPPORTED."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Sdf, UsdGeom, UsdLux

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError

Y_TO_Z = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # rows: images of x, y, z


@pytest.mark.parametrize("pole, up, rotation", [("Y", "Z", np.eye(3)), ("Z", "Y", Y_TO_Z), ("scene", "Z", Y_TO_Z),
                                                ("scene", "Y", np.eye(3))])
def test_pole_axis_turns_the_texture_frame(tmp_path, pole, up, rotation):
    b = SceneBuilder()
    UsdGeom.SetStageUpAxis(b.stage, up)
    b.camera((0, 0, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 1.0, normal=(0, 0, 1))
    dome = UsdLux.DomeLight_1.Define(b.stage, "/World/Sky")
    dome.CreatePoleAxisAttr(pole)
    scene = load_scene(b.write(tmp_path / "s.usda"))
    np.testing.assert_allclose(scene.lights[0].R, rotation, atol=1e-12)
    img = render(scene, RenderSettings(spp=1, width=4, height=4, max_depth=1)).image
    assert np.isfinite(img).all() and img.mean() > 0


def test_an_unknown_pole_axis_is_a_scene_error(tmp_path):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    UsdLux.DomeLight_1.Define(b.stage, "/World/Sky").GetPrim().CreateAttribute("poleAxis", Sdf.ValueTypeNames.Token).Set("X")
    with pytest.raises(SceneError) as exc:
        load_scene(b.write(tmp_path / "s.usda"))
    assert "poleAxis" in str(exc.value)


def test_a_portal_light_is_ignored_with_a_warning(tmp_path):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 1.0, normal=(0, 0, 1))
    UsdLux.DomeLight.Define(b.stage, "/World/Sky")
    UsdLux.PortalLight.Define(b.stage, "/World/Window")
    with pytest.warns(UserWarning, match="PortalLight ignored"):
        scene = load_scene(b.write(tmp_path / "s.usda"))
    assert [type(light).__name__ for light in scene.lights] == ["DomeLight"]


def test_light_linking_that_leaves_objects_out_is_warned(tmp_path):
    from pxr import Usd

    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 1.0, normal=(0, 0, 1))
    dome = UsdLux.DomeLight.Define(b.stage, "/World/Sky")
    Usd.CollectionAPI(dome.GetPrim(), "lightLink").CreateExcludesRel().SetTargets(["/World/Floor"])
    with pytest.warns(UserWarning, match="lightLink collection ignored"):
        load_scene(b.write(tmp_path / "s.usda"))
