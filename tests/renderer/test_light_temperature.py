"""Light colour temperature (spec/renderer.md#lights): ``enableColorTemperature`` tints a light by a blackbody's RGB."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder


@pytest.mark.parametrize("kelvin", [2700.0, 9000.0])
def test_light_color_temperature_tints_the_light_by_the_blackbody_rgb(tmp_path, kelvin):
    """enableColorTemperature multiplies the light's colour by a blackbody's RGB. Checked against Planck's law
    integrated with the CIE 1931 colour matching functions (Wyman et al.'s fit), taken to linear Rec. 709 and
    normalised to luminance 1: a floor under the tinted sun over the same floor under the white one gives those
    channel ratios (2 % bound: the fit and USD's table). Before, colorTemperature was ignored (warned)."""
    def floor(temperature):
        b = SceneBuilder()
        b.camera((0, 1.0, 0.001), (0, 0, 0), focal=200.0)
        b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
        sun = b.distant("Sun", (0.0, 1.0, 0.0), 2.0)
        if temperature:
            sun.CreateEnableColorTemperatureAttr(True)
            sun.CreateColorTemperatureAttr(kelvin)
        return load_scene(b.write(tmp_path / f"t{temperature}.usda"))

    s_ = RenderSettings(spp=2, width=4, height=4, max_depth=1)
    ratio = render(floor(True), s_).image.mean((0, 1)) / render(floor(False), s_).image.mean((0, 1))

    lam = np.arange(380.0, 781.0, 1.0)

    def g(x, mu, s1, s2):
        return np.exp(-0.5 * ((x - mu) / np.where(x < mu, s1, s2)) ** 2)

    xyz = np.stack([1.056 * g(lam, 599.8, 37.9, 31.0) + 0.362 * g(lam, 442.0, 16.0, 26.7) - 0.065 * g(lam, 501.1, 20.4, 26.2),
                    0.821 * g(lam, 568.8, 46.9, 40.5) + 0.286 * g(lam, 530.9, 16.3, 31.1),
                    1.217 * g(lam, 437.0, 11.8, 36.0) + 0.681 * g(lam, 459.0, 26.0, 13.8)])
    planck = 1.0 / (lam ** 5 * (np.exp(1.4387769e7 / (lam * kelvin)) - 1.0))
    X, Y, Z = xyz @ planck
    rgb = np.array([[3.2404542, -1.5371385, -0.4985314], [-0.9692660, 1.8760108, 0.0415560],
                    [0.0556434, -0.2040259, 1.0572252]]) @ np.array([X, Y, Z]) / Y
    np.testing.assert_allclose(ratio, rgb, rtol=0.02, atol=0.01)
