"""Textured emission (spec/renderer.md#textures): ``emissiveColor`` from a texture is read at each hit and at each
mesh-light sample. Before, the emitter took the input's own value (warned)."""

from __future__ import annotations

import numpy as np

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.film import write_exr
from nasset_reference_renderer.testscenes import SceneBuilder
from tests.stats import stat_seed

RED, BLUE = (4.0, 0.2, 0.2), (0.2, 0.2, 4.0)


def _panel_over_floor(tmp_path, textured: bool):
    """A 1 x 1 panel 0.5 above a floor, emitting downward: one panel whose emissiveColor is a 64 x 1 texture (left half
    RED, right half BLUE; clamp), or two half panels of those constant colours."""
    b = SceneBuilder()
    b.camera((0, 3.0, 0.001), (0, 0, 0), focal=30.0)
    b.quad("Floor", (0, 0, 0), 3.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    if not textured:
        for name, x, col in (("Left", -0.25, RED), ("Right", 0.25, BLUE)):
            pts = np.array([[x - 0.25, 0.5, -0.5], [x + 0.25, 0.5, -0.5], [x + 0.25, 0.5, 0.5], [x - 0.25, 0.5, 0.5]])
            b.mesh(name, pts, [[0, 1, 2, 3]], diffuse=(0, 0, 0), specular=(0, 0, 0), emission=col)
        return load_scene(b.write(tmp_path / "halves.usda"))
    img = np.zeros((1, 64, 3), np.float32)
    img[0, :32], img[0, 32:] = RED, BLUE
    write_exr(tmp_path / "e.exr", img)
    pts = np.array([[-0.5, 0.5, -0.5], [0.5, 0.5, -0.5], [0.5, 0.5, 0.5], [-0.5, 0.5, 0.5]])
    panel = b.mesh("Panel", pts, [[0, 1, 2, 3]], diffuse=(0, 0, 0), specular=(0, 0, 0), emission=(0.0, 0.0, 0.0))
    b.texture("PanelMat", {"emissiveColor": "rgb"}, "e.exr", st=[[0, 0], [1, 0], [1, 1], [0, 1]], mesh=panel)
    return load_scene(b.write(tmp_path / "textured.usda"))


def test_textured_emitter_lights_and_shows_like_its_halves(tmp_path):
    """The floor lit by (and the camera's view of) the textured panel equals the two constant half panels' within noise:
    light samples read the texture at the sampled point (the one-texel blend at the middle is 1.6 % of the panel)."""
    s_ = RenderSettings(spp=128, width=16, height=16, max_depth=2, seed=stat_seed(41))
    a = render(_panel_over_floor(tmp_path, True), s_)
    b = render(_panel_over_floor(tmp_path, False), s_)
    assert len([lt for lt in _panel_over_floor(tmp_path, True).lights]) == 1  # the panel is a sampled mesh light
    left, right = a.image[:, :6].mean((0, 1)), a.image[:, 10:].mean((0, 1))
    assert left[0] > 2 * left[2] and right[2] > 2 * right[0]  # red light falls left, blue right
    se = np.sqrt((a.variance + b.variance).mean((0, 1)) / 256)
    diff = a.image.mean((0, 1)) - b.image.mean((0, 1))
    assert np.all(np.abs(diff) < 5 * se + 0.02 * b.image.mean((0, 1))), (diff, se)
