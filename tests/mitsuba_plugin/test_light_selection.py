"""The plugin's choice of an emitter per light sample (mitsuba_plugin/lights.py: light_power, selection_weights): half by
power, half uniform over the emitters. Mitsuba picked uniformly, so in a scene with one light that matters and several
that hardly do most light samples were wasted (docs/bench-mitsuba-jit.md#light-selection)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

pytest.importorskip("mitsuba")

import nasset_mitsuba_plugin.lights as lights_jit  # noqa: E402
from nasset_mitsuba_plugin.render import render  # noqa: E402
from nasset_mitsuba_renderer.lights import build_lights  # noqa: E402
from nasset_mitsuba_renderer.usdscene import read_scene  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402


def _scene(tmp_path):
    """A floor lit by a rect light, and three faint point lights (a thousandth of its power) off to the side."""
    b = SceneBuilder()
    b.camera((0, 3, 3), (0, 0, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.6, 0.6, 0.6))
    b.rect_light("Panel", (0, 2, 0), 1.0, 1.0, (0, -1, 0), 4.0)
    for i in range(3):
        b.sphere_light(f"Faint{i}", (-2.0 + 2.0 * i, 1.5, -2.0), 0.0, 0.001)
    return b.write(tmp_path / "lights.usda")


def test_light_power_formulas(tmp_path):
    """Each light's power from its description, against closed forms: a rect light pi L A (here L = 4, A = 1), a point
    light 4 pi I; a sun E pi r^2 and a dome 4 pi^2 r^2 L for a scene of bounding radius r."""
    from nasset_mitsuba_plugin.variant import jit_mitsuba

    jit_mitsuba()  # the light surfaces' Mitsuba transforms need a variant
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = read_scene(_scene(tmp_path))
    lights, _ = build_lights(desc.lights, "s.usda")
    by = {lt.desc.prim.rsplit("/", 1)[-1]: lt for lt in lights}
    assert lights_jit.light_power(by["Panel"], 2.0) == pytest.approx(math.pi * 4.0 * 1.0, rel=1e-6)
    assert lights_jit.light_power(by["Faint0"], 2.0) == pytest.approx(4.0 * math.pi * 0.001, rel=1e-6)
    sun = type("L", (), {"desc": type("D", (), {"type": "DistantLight", "radiance": np.array([2.0, 2.0, 2.0])})()})()
    dome = type("L", (), {"desc": type("D", (), {"type": "DomeLight", "radiance": np.array([0.5, 0.5, 0.5])})(), "tex": None})()
    assert lights_jit.light_power(sun, 3.0) == pytest.approx(2.0 * math.pi * 9.0, rel=1e-6)
    assert lights_jit.light_power(dome, 3.0) == pytest.approx(0.5 * 4.0 * math.pi ** 2 * 9.0, rel=1e-6)


def test_selection_weights_mix_power_and_uniform():
    w = lights_jit.selection_weights({"a": 3.0, "b": 1.0, "c": 0.0}, share=0.5)
    assert w == pytest.approx({"a": 0.5 / 3 + 0.375, "b": 0.5 / 3 + 0.125, "c": 0.5 / 3})
    assert sum(w.values()) == pytest.approx(1.0)
    assert lights_jit.selection_weights({"a": 0.0, "b": float("nan")}) == {"a": 1.0, "b": 1.0}  # nothing to go by: uniform


def test_emitters_carry_the_weights_and_the_image_keeps_its_mean_with_less_variance(tmp_path):
    """The rect light is picked with probability 1/8 + 1/2 x its share of the power (about 0.62, against 1/4 uniformly):
    the floor's noise falls by more than 1.5x at the same spp, and the two choices' image means agree within 4 standard
    errors of their difference (both unbiased)."""
    scene = _scene(tmp_path)

    def two(share):
        lights_jit.POWER_SHARE = share
        a, b = (render(scene, 32, seed=s, width=32, height=32) for s in (1, 2))
        return float(np.mean((a - b) ** 2) / 2), float(0.5 * (a + b).mean()), a.size

    try:
        var_u, mean_u, n = two(0.0)
        var_d, mean_d, _ = two(0.5)
    finally:
        lights_jit.POWER_SHARE = 0.5
    assert var_u / var_d > 1.5, (var_u, var_d)
    standard_error = math.sqrt((var_u + var_d) / (2 * n))  # of the difference of two means over two renders of n values
    assert abs(mean_d - mean_u) < 4 * standard_error, (mean_d, mean_u, standard_error)
