"""The time a scene renders at (spec/renderer.md#traversal): an animation cache without default values renders."""

from __future__ import annotations

import pytest
from pxr import Gf, Sdf, Usd, UsdGeom

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.scene import render_time
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError


def _animated(tmp_path, *, time_range: bool) -> str:
    """A lit floor whose points and a translate op exist only as time samples (frames 1 and 5): at frame 1 the floor
    is under the camera, at frame 5 it has moved 100 m aside."""
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=200)
    quad = b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5))
    pts = quad.GetPointsAttr().Get()
    quad.GetPointsAttr().Clear()
    quad.GetPointsAttr().Set(pts, 1.0)
    quad.GetPointsAttr().Set(pts, 5.0)
    op = UsdGeom.Xformable(quad).AddTranslateOp()
    op.Set(Gf.Vec3d(0, 0, 0), 1.0)
    op.Set(Gf.Vec3d(100, 0, 0), 5.0)
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    if time_range:
        b.stage.SetStartTimeCode(5.0)
        b.stage.SetEndTimeCode(5.0)
    return b.write(tmp_path / f"s_{time_range}.usda")


def _mean(path, **kw) -> float:
    return float(render(load_scene(path, **kw), RenderSettings(spp=1, width=4, height=4, max_depth=1)).image.mean())


def test_an_animation_cache_renders_at_its_first_sample_or_the_stage_start(tmp_path):
    """Before, the scene rendered at the default time: points without a default value made the floor 'a mesh
    without points' (skipped) and the translate op resolved to nothing, a black image."""
    path = _animated(tmp_path, time_range=False)
    assert _mean(path) > 0.1  # the first sample: frame 1, the floor under the camera
    assert _mean(path, time=5.0) == 0.0  # moved aside
    ranged = _animated(tmp_path, time_range=True)
    assert _mean(ranged) == 0.0  # the stage's startTimeCode, frame 5
    assert _mean(ranged, time=1.0) > 0.1


def test_render_time_of_a_static_stage_keeps_default_values():
    stage = Usd.Stage.CreateInMemory()
    attr = stage.DefinePrim("/p").CreateAttribute("x", Sdf.ValueTypeNames.Float)
    attr.Set(2.0)
    assert attr.Get(render_time(stage)) == 2.0
    assert render_time(stage, 3).GetValue() == 3.0
    with pytest.raises(SceneError):
        render_time(stage, float("nan"))


def test_render_cli_refuses_a_time_that_is_not_a_finite_number(tmp_path):
    from nasset_sdk.cli import main

    path = _animated(tmp_path, time_range=False)
    for bad in ("soon", "nan", "inf"):
        with pytest.raises(SystemExit) as exc:
            main(["render", path, "-o", str(tmp_path / "o.exr"), "--time", bad])
        assert exc.value.code == 2
