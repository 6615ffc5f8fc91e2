"""UsdLux.CylinderLight (spec/renderer.md#lights): the side of a cylinder along local X emitting outward.
Before, a scene with a CylinderLight was SCENE_UNSUPPORTED."""

from __future__ import annotations

import numpy as np

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.lights import CylinderLight
from nasset_reference_renderer.testscenes import SceneBuilder
from tests.stats import stat_seed


def _quadrature(p, radius, length, n=800):
    """Irradiance at p on a surface facing +Y from a unit-radiance cylinder along X through (0, 1, 0)."""
    x = ((np.arange(n) + 0.5) / n - 0.5) * length
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi
    X, P = np.meshgrid(x, phi)
    q = np.stack([X, 1 + radius * np.cos(P), radius * np.sin(P)], -1).reshape(-1, 3)
    nq = np.stack([np.zeros_like(P), np.cos(P), np.sin(P)], -1).reshape(-1, 3)
    v = q - p
    d2 = (v * v).sum(1)
    w = v / np.sqrt(d2)[:, None]
    cos_p, cos_l = np.maximum(w[:, 1], 0), np.maximum(-(w * nq).sum(1), 0)
    return float((cos_p * cos_l / d2).sum() * (length / n) * (2 * np.pi * radius / n))


def test_cylinder_light_samples_integrate_the_irradiance_and_match_its_pdf():
    light = CylinderLight([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], 0.2, 1.5, [1.0, 1.0, 1.0])
    rng = np.random.default_rng(stat_seed(41))
    p = np.tile([0.3, 0.0, 0.1], (200_000, 1))
    wi, _, li, pdf = light.sample(p, rng.random((len(p), 2)))
    ok = pdf > 0
    np.testing.assert_allclose(light.pdf(p[ok], wi[ok]), pdf[ok], rtol=1e-3)  # grazing rays: the quadratic's precision
    e_mc = np.mean(np.where(ok, li[:, 0] * np.maximum(wi[:, 1], 0) / np.where(ok, pdf, 1.0), 0.0))
    assert abs(e_mc / _quadrature(p[0], 0.2, 1.5) - 1) < 0.01
    t, _ = light.intersect(np.array([[0.0, 1.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))  # from inside: not hit
    assert not np.isfinite(t).any()


def test_floor_under_a_cylinder_light(tmp_path):
    from pxr import Gf, UsdGeom, UsdLux

    b = SceneBuilder()
    b.camera((0.3, 0.5, 0.1001), (0.3, 0.0, 0.1), focal=400)
    b.quad("Floor", (0, 0, 0), 10.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    tube = UsdLux.CylinderLight.Define(b.stage, "/World/Tube")
    tube.CreateRadiusAttr(0.2)
    tube.CreateLengthAttr(1.5)
    UsdGeom.Xformable(tube).AddTranslateOp().Set(Gf.Vec3d(0.0, 1.0, 0.0))
    scene = load_scene(b.write(tmp_path / "s.usda"))
    r = render(scene, RenderSettings(spp=64, width=4, height=4, max_depth=2, seed=stat_seed(7)))
    expect = 0.5 / np.pi * _quadrature(np.array([0.3, 0.0, 0.1]), 0.2, 1.5)
    se = np.sqrt(r.variance.mean() / 16)
    assert abs(r.image.mean() - expect) < 5 * se + 0.01 * expect, (r.image.mean(), expect, se)


def test_a_cylinder_light_of_infinite_length_is_a_scene_error(tmp_path):
    import pytest
    from pxr import UsdLux

    from nasset_sdk.errors import SceneError

    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    UsdLux.CylinderLight.Define(b.stage, "/World/Tube").CreateLengthAttr(float("inf"))
    with pytest.raises(SceneError) as exc:
        load_scene(b.write(tmp_path / "s.usda"))
    assert "length" in str(exc.value)
