"""UsdLux.DiskLight (spec/renderer.md#lights): a disk (an ellipse under non-uniform scale) emitting along local -Z.
Before, a scene with a DiskLight was SCENE_UNSUPPORTED."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.lights import DiskLight, RectLight
from nasset_reference_renderer.testscenes import SceneBuilder
from tests.stats import stat_seed


@pytest.mark.parametrize("sx, sy", [(1.0, 1.0), (2.0, 0.5)])
def test_disk_light_samples_integrate_the_irradiance_and_match_its_pdf(sx, sy):
    """Irradiance at a point 1 below the centre of a unit-radiance disk of radius 0.5 (an ellipse of semi-axes
    0.5 sx, 0.5 sy), by light sampling, against a midpoint quadrature over the ellipse."""
    light = DiskLight([0.0, 1.0, 0.0], [0.5 * sx, 0.0, 0.0], [0.0, 0.0, -0.5 * sy], [1.0, 1.0, 1.0])  # emits along -Y
    np.testing.assert_allclose(light.n, [0.0, -1.0, 0.0])
    assert light.A == pytest.approx(np.pi * 0.25 * sx * sy)
    rng = np.random.default_rng(stat_seed(31))
    p = np.zeros((200_000, 3))
    wi, _, li, pdf = light.sample(p, rng.random((len(p), 2)))
    np.testing.assert_allclose(light.pdf(p, wi), pdf, rtol=1e-9)
    e_mc = np.mean(li[:, 0] * wi[:, 1] / pdf)
    g = (np.arange(1200) + 0.5) / 1200 * 2 - 1
    a, b = np.meshgrid(g, g)
    inside = a * a + b * b <= 1
    x, z = 0.5 * sx * a[inside], 0.5 * sy * b[inside]
    e_q = np.sum(1.0 / (x * x + 1.0 + z * z) ** 2) * (0.5 * sx * 2 / 1200) * (0.5 * sy * 2 / 1200)
    assert abs(e_mc / e_q - 1) < 0.01
    _, _, li_b, pdf_b = light.sample(np.tile([0.0, 2.0, 0.0], (100, 1)), rng.random((100, 2)))
    assert not li_b.any() and not pdf_b.any()  # nothing above it


def test_sheared_rect_light_is_hit_where_it_is_sampled():
    """A RectLight under a shear (edges not orthogonal) is the parallelogram its samples cover: every sampled direction
    hits it with the sample's own pdf (rays tested the two slabs across the edges before: the parallelogram's sharp
    corners were never hit, a sample there had pdf 0 as a hit, and rays beyond its obtuse corners hit a light that was
    not there)."""
    light = RectLight([0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.8, 0.0, -0.6], [1.0, 1.0, 1.0])  # 37 degrees apart, emits down
    rng = np.random.default_rng(stat_seed(32))
    p = rng.uniform(-1.0, 1.0, (20_000, 3)) * [1.0, 0.0, 1.0]
    wi, _, li, pdf = light.sample(p, rng.random((len(p), 2)))
    assert (pdf > 0).all()
    np.testing.assert_allclose(light.pdf(p, wi), pdf, rtol=1e-9)
    # a point just beyond an obtuse corner is not on the light
    corner = light.c + 0.5 * light.ex - 0.5 * light.ey
    beyond = corner + 0.05 * (light.ex - light.ey) / np.linalg.norm(light.ex - light.ey)
    t, _ = light.intersect(beyond[None] - [0.0, 1.0, 0.0], np.array([[0.0, 1.0, 0.0]]))
    assert np.isinf(t).all()


def test_floor_under_a_disk_light_matches_the_closed_form(tmp_path):
    """kd / pi * E with E = pi L R^2 / (h^2 + R^2) under the centre of a disk (radius R = 0.5, height h = 1)."""
    from pxr import Gf, UsdGeom, UsdLux

    b = SceneBuilder()
    b.camera((0, 0.5, 0.001), (0, 0, 0), focal=400)
    b.quad("Floor", (0, 0, 0), 10.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    disk = UsdLux.DiskLight.Define(b.stage, "/World/Disk")
    disk.CreateRadiusAttr(0.5)
    disk.CreateIntensityAttr(2.0)
    UsdGeom.Xformable(disk).AddTransformOp().Set(Gf.Matrix4d(1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 1, 0, 1))  # -Z down
    scene = load_scene(b.write(tmp_path / "s.usda"))
    r = render(scene, RenderSettings(spp=64, width=4, height=4, max_depth=2, seed=stat_seed(6)))
    expect = 0.5 / np.pi * np.pi * 2.0 * 0.25 / (1.0 + 0.25)
    se = np.sqrt(r.variance.mean() / 16)
    assert abs(r.image.mean() - expect) < 5 * se + 0.005 * expect, (r.image.mean(), expect, se)
