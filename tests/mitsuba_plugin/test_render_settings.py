"""The render settings of a USD scene in the plugin (spec/renderer.md#render-settings): ``nasset:maxDepth`` is the
bounce limit when the caller gives none, ``nasset:pixelFilter = "gaussian"`` filters the film. The plugin used 5
bounces and a box filter whatever the scene said (Blender's converted scenes author both)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from tests.stage_scenes import floor_scene, render_settings  # noqa: E402


def _edge_scene(tmp_path, **attrs):
    """An emissive (radiance 1) half plane x < 0 at z = -1 in front of a camera at the origin: its edge projects onto
    the vertical line through the image centre."""
    from nasset_reference_renderer.testscenes import SceneBuilder

    b = SceneBuilder()
    b.camera((0, 0, 0), (0, 0, -1))
    b.mesh("Half", [(-50, -50, -1), (0, -50, -1), (0, 50, -1), (-50, 50, -1)], [(0, 1, 2, 3)], diffuse=(0, 0, 0),
           specular=(0, 0, 0), emission=(1, 1, 1))
    s = render_settings(b, "/Render/Settings", resolution=(8, 4))
    for name, (kind, value) in attrs.items():
        s.GetPrim().CreateAttribute(name, kind).Set(value)
    return b.write(tmp_path / "edge.usda")


def test_gaussian_pixel_filter_of_the_settings_is_applied(tmp_path):
    """Mitsuba's gaussian filter (the spec's, radius 4 s) splats the edge over the columns beside it: each column's value
    is the filter mass left of the edge, the truncated Gaussian's CDF at the column's distance (the samples'
    Bernoulli noise, within 5 sigma); the box filter gives 0 / 1 there."""
    from pxr import Sdf

    s, spp = 0.5, 256
    img = render(_edge_scene(tmp_path, **{"nasset:pixelFilter": (Sdf.ValueTypeNames.Token, "gaussian"),
                                         "nasset:pixelFilterStddev": (Sdf.ValueTypeNames.Float, s)}), spp, seed=5)
    assert img.shape == (4, 8, 3)
    x = np.linspace(-4 * s, 4 * s, 200001)
    density = np.exp(-x * x / (2 * s * s)) - np.exp(-8.0)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(x))])
    cdf /= cdf[-1]
    expect = np.interp(4.0 - (np.arange(8) + 0.5), x, cdf)
    got = img[..., 0].mean(0)
    sigma = np.maximum(np.sqrt(expect * (1 - expect) / (4 * spp)), 1.0 / (4 * spp))
    assert np.all(np.abs(got - expect) <= 5 * sigma), (got, expect)
    assert 0.05 < got[4] < 0.3 and 0.7 < got[3] < 0.95  # neither the box's 0 / 1 step
    box = render(_edge_scene(tmp_path), spp, seed=5)[..., 0].mean(0)
    np.testing.assert_allclose(box, [1, 1, 1, 1, 0, 0, 0, 0], atol=1e-6)


def test_max_depth_of_the_settings_is_the_default(tmp_path):
    """``nasset:maxDepth`` is the bounce limit when the caller gives none; a caller's limit wins."""
    from pxr import Sdf

    def scene(name, depth=None):
        b, _ = floor_scene()
        b.quad("Ceiling", (0, 5, 0), 10.0, normal=(0, -1, 0), diffuse=(0.8, 0.8, 0.8))
        b.sphere_light("Bulb", (2, 1.5, 0), 0.2, 20.0)  # outside the view
        b.stage.RemovePrim("/World/Sun")
        s = render_settings(b, "/Render/Settings", resolution=(8, 8))
        if depth is not None:
            s.GetPrim().CreateAttribute("nasset:maxDepth", Sdf.ValueTypeNames.Int).Set(depth)
        return b.write(tmp_path / name)

    plain, one = scene("plain.usda"), scene("one.usda", 1)
    direct = render(plain, 16, seed=2, max_depth=1)
    np.testing.assert_array_equal(render(one, 16, seed=2), direct)
    assert render(plain, 16, seed=2).mean() > 1.01 * direct.mean()  # the ceiling's bounce
    np.testing.assert_array_equal(render(one, 16, seed=2, max_depth=5), render(plain, 16, seed=2))
