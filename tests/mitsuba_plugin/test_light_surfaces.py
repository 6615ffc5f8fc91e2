"""Light surfaces of a USD scene in the plugin (spec/renderer.md#light-surfaces): ``nasset:cameraVisibility`` false
lets camera rays through a SphereLight's sphere and hides a dome from escaping camera rays; no light surface blocks a
shadow ray. Mitsuba's own emitters do neither, so the plugin rendered Blender's converted scenes (lights hidden from
the camera) with the lights in view, and light spheres casting shadows."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _run_case  # noqa: E402


def _hide(light):
    from pxr import Sdf

    light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool, custom=True).Set(False)


def _bulb_in_front(tmp_path, name, hidden_bulb, hidden_dome):
    """The camera looks at a sphere light (radiance 5) that fills the image's centre; behind it a constant dome (0.5)."""
    b = SceneBuilder()
    b.camera((0, 0, 3.0), (0, 0, 0), focal=50)
    bulb = b.sphere_light("Bulb", (0, 0, 0), 0.5, 5.0)
    dome = b.dome("Sky", 0.5)
    if hidden_bulb:
        _hide(bulb)
    if hidden_dome:
        _hide(dome)
    return b.write(tmp_path / f"{name}.usda")


@pytest.mark.parametrize("hidden_bulb, hidden_dome, centre, corner", [
    (False, False, 5.5, 0.5), (True, False, 0.5, 0.5), (False, True, 5.0, 0.0), (True, True, 0.0, 0.0)])
def test_camera_visibility(tmp_path, hidden_bulb, hidden_dome, centre, corner):
    """What a camera ray sees is exact here (direct lighting only, no surface in the scene): the sphere's radiance plus
    the dome's behind it (light surfaces occlude nothing), or through a hidden sphere the dome's, or black."""
    img = render(_bulb_in_front(tmp_path, "s", hidden_bulb, hidden_dome), 4, width=16, height=16, max_depth=1)
    assert np.allclose(img[8, 8], centre, rtol=1e-5) and np.allclose(img[0, 0], corner, rtol=1e-5), (img[8, 8], img[0, 0])


def _as_bright_as_without(scene, spp, centre):
    """The centre of ``scene(with_light=True)`` over that of ``scene(with_light=False)`` (direct light only): the
    faint light there must not darken the floor (within 10 %). Returns the light-free render's centre pixels."""
    with_light = render(scene(True), spp, width=16, height=16, max_depth=1)
    without = render(scene(False), spp, width=16, height=16, max_depth=1)
    assert abs(with_light[centre].mean() / without[centre].mean() - 1.0) < 0.1, with_light[centre].mean()
    return without[centre]


def _floor_under(tmp_path, bulb):
    b = SceneBuilder()
    b.camera((2.5, 1.0, 0.0), (0, 0, 0), focal=80)  # low: the sphere is out of view, the floor under it in view
    b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5))
    b.distant("Sun", (0, 1, 0), 2.0)
    if bulb:  # a faint light sphere between the sun and the floor's centre
        b.sphere_light("Bulb", (0, 0.8, 0), 0.4, 1e-6)
    return b.write(tmp_path / f"bulb_{bulb}.usda")


def test_a_light_surface_casts_no_shadow(tmp_path):
    """The floor's centre, under a faint light sphere that covers the sun's direction, is as bright as without the
    sphere: rho E / pi = 0.318 (the light picked is the sun half the time, then weighted 2x). Before: 0, in shadow."""
    without = _as_bright_as_without(lambda bulb: _floor_under(tmp_path, bulb), 256, (slice(6, 10), slice(6, 10)))
    assert np.allclose(without, 0.5 * 2.0 / np.pi, rtol=1e-3)


def test_rays_pass_a_rect_light_from_behind(tmp_path):
    """The camera sees the back of a faint RectLight (it emits away from the camera) and, through it, the floor as bright
    as without the light (rho E cos / pi under a delta sun, within 10 %). Before: black, Mitsuba's rectangle stops it."""
    def scene(panel):
        b = SceneBuilder()
        b.camera((0, 1.0, 3.0), (0, 0, 0))
        b.quad("Floor", (0, -0.5, 0), 6.0, diffuse=(0.5, 0.5, 0.5))
        b.distant("Sun", (0, 1, 0), 2.0)
        if panel:
            b.rect_light("Panel", (0, 0.3, 0.5), 1.5, 1.0, (0, 0.3, -1.0), 1e-6)
        return b.write(tmp_path / f"panel_{panel}.usda")

    assert _as_bright_as_without(scene, 64, (slice(7, 9), slice(7, 9))).mean() > 0.1


def test_light_surfaces_occlude_nothing(tmp_path):
    """A ray goes on past every light surface it meets (spec/renderer.md#light-surfaces); the plugin's rays ended on the
    first one, so a faint area light between a dome and a floor darkened the floor under it to 48 %."""
    from tests.stage_scenes import check_light_surfaces_occlude_nothing

    check_light_surfaces_occlude_nothing(render, tmp_path)


@pytest.mark.parametrize("case", ["rna_hidden_lights", "rna_suns_and_dome", "rna_rect_light_back", "rna_disk_cylinder_lights",
                                  "rna_lights_in_the_way"])
def test_light_conformance_cases(tmp_path, case):
    """At twice the case's spp (spec/conformance.md: a noisier renderer passes ``--spp-scale``): the plugin picks one light
    per vertex where the reference renderer samples each, about 4x the variance with four lights."""
    row = _run_case(case, tmp_path, spp_scale=2)
    assert row["passed"], row


def test_many_lights_conformance_case(tmp_path):
    """``rna_many_lights`` (40 lights) at twice the case's spp: one emitter sample per vertex, picked where the vertex is
    (light_choice.py). Measured 0.044 and 0.031 against the tolerance 0.050 at 1x and 2x; with the choice by power alone
    0.136, 0.060, 0.047 and 0.032 at 1, 2, 4 and 8x."""
    row = _run_case("rna_many_lights", tmp_path, spp_scale=2)
    assert row["passed"], row


@pytest.mark.parametrize("light", ["rect", "disk"])
def test_floor_beside_a_spread_light_matches_the_quadrature(tmp_path, light):
    """nasset:spread (spec/renderer.md#lights) in the plugin (its nasset_profiled emitter): the floor 0.3 beside the
    centre of a light of spread 70 deg reads kd / pi times the quadrature of Cycles' profile (4x what a Lambertian
    light gives there), as in the reference renderer's test. Two seeds bound the noise."""
    import math

    from tests.renderer.test_light_spread import spread_stage

    path, expect = spread_stage(tmp_path / "s.usda", math.radians(70), light)
    a, b = (render(path, 256, width=4, height=4, max_depth=2, seed=s).mean() for s in (1, 2))
    assert abs(0.5 * (a + b) - expect) < 3 * abs(a - b) + 0.02 * expect, (a, b, expect)
