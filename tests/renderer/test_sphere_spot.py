"""A spot with a radius (spec/renderer.md#spot-lights): UsdLux.ShapingAPI on a SphereLight of radius > 0 shapes the
radiance leaving each point of the sphere by the direction it leaves along (Cycles' spot light with Soft Falloff off).
Before, ShapingAPI was ignored there, and the Blender converter wrote such a spot as a point spot with hard shadows
(MSE 36-39x the noise in random scenes)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.lights import SphereLight
from nasset_reference_renderer.testscenes import SceneBuilder
from tests.renderer.test_light_spread import sampled_irradiance
from tests.stats import stat_seed

KD = 0.5
HEIGHT, RADIUS, CONE, SOFTNESS = 1.2, 0.25, 30.0, 0.3


def _smoothstep_falloff(cos_t):
    """Cycles' spot edge written out here: smoothstep((cos t - cos c) / ((1 - cos c) s)), c = CONE, s = SOFTNESS."""
    cc = np.cos(np.radians(CONE))
    x = np.clip((cos_t - cc) / ((1 - cc) * SOFTNESS), 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _irradiance(p, radiance=1.0, n=800):
    """Irradiance at floor point p [3] (normal +Y) from the downward spot sphere at (0, HEIGHT, 0): midpoint quadrature
    over the sphere's surface of L falloff(emitted direction) cos_p cos_l / d^2, over the points that face p."""
    th = (np.arange(n) + 0.5) / n * np.pi
    ph = (np.arange(2 * n) + 0.5) / (2 * n) * 2 * np.pi
    t, f = np.meshgrid(th, ph, indexing="ij")
    nrm = np.stack([np.sin(t) * np.cos(f), np.cos(t), np.sin(t) * np.sin(f)], -1).reshape(-1, 3)
    q = np.array([0.0, HEIGHT, 0.0]) + RADIUS * nrm
    v = p - q
    d2 = (v * v).sum(1)
    w = v / np.sqrt(d2)[:, None]  # emitted direction, toward p
    cos_l, cos_p = (w * nrm).sum(1), -w[:, 1]
    ok = (cos_l > 0) & (cos_p > 0)
    da = RADIUS**2 * np.sin(t).ravel() * (np.pi / n) * (np.pi / n)
    return radiance * np.sum((_smoothstep_falloff(-w[:, 1]) * cos_l * cos_p / d2 * da)[ok])


def sphere_spot_stage(path, x: float):
    """A grey floor (kd 0.5, no specular) under a spot sphere (radius 0.25, 1.2 up, pointing down, cone 30 deg,
    softness 0.3, smoothstep, radiance 3); a narrow camera looking down at the floor point (x, 0, 0). Returns (stage
    path, the pixel value expected: kd / pi times the irradiance by quadrature)."""
    from pxr import Gf, Sdf, UsdGeom, UsdLux

    b = SceneBuilder()
    b.camera((x, 0.5, 0.001), (x, 0, 0), focal=400)
    b.quad("Floor", (0, 0, 0), 10.0, diffuse=(KD, KD, KD), specular=(0, 0, 0), roughness=1.0)
    lt = UsdLux.SphereLight.Define(b.stage, "/World/Spot")
    lt.CreateRadiusAttr(RADIUS)
    lt.CreateIntensityAttr(3.0)
    shaping = UsdLux.ShapingAPI.Apply(lt.GetPrim())
    shaping.CreateShapingConeAngleAttr(CONE)
    shaping.CreateShapingConeSoftnessAttr(SOFTNESS)
    lt.GetPrim().CreateAttribute("nasset:shaping:falloff", Sdf.ValueTypeNames.Token, custom=True).Set("smoothstep")
    UsdGeom.Xformable(lt).AddTransformOp().Set(Gf.Matrix4d(1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, HEIGHT, 0, 1))  # -Z down
    return b.write(path), KD / np.pi * _irradiance(np.array([x, 0.0, 0.0]), 3.0)


def test_sphere_spot_samples_and_hits_agree_and_shape_each_emitted_direction():
    """A sampled direction's radiance is what a ray along it meets, and it is the falloff of the direction it leaves the
    sphere along, not of the direction from the centre: at a floor point on the cone's edge the two differ."""
    light = SphereLight([0.0, HEIGHT, 0.0], RADIUS, [1.0, 1.0, 1.0], axis=[0.0, -1.0, 0.0], cone_deg=CONE,
                        softness=SOFTNESS, falloff="smoothstep")
    rng = np.random.default_rng(stat_seed(43))
    edge = HEIGHT * np.tan(np.radians(CONE))  # the centre's cone meets the floor here
    for x in (0.0, 0.6 * edge, edge):
        e_mc, wi, li = sampled_irradiance(light, x, 200_000, rng)
        np.testing.assert_allclose(li[:, 0], _smoothstep_falloff(wi[:, 1]), rtol=1e-9, atol=1e-12)  # emitted: -wi
        assert abs(e_mc / _irradiance(np.array([x, 0.0, 0.0])) - 1) < 0.01, x
    assert _irradiance(np.array([edge, 0.0, 0.0])) > 0.02 * _irradiance(np.zeros(3))  # the soft edge: a point spot's is 0


@pytest.mark.parametrize("x", [0.0, 0.7])
def test_floor_under_a_sphere_spot_matches_the_quadrature(tmp_path, x):
    path, expect = sphere_spot_stage(tmp_path / "s.usda", x)
    r = render(load_scene(path), RenderSettings(spp=256, width=4, height=4, max_depth=2, seed=stat_seed(44)))
    se = np.sqrt(r.variance.mean() / 16)
    assert abs(r.image.mean() - expect) < 5 * se + 0.005 * expect, (r.image.mean(), expect, se)
