"""The plugin's ``nasset_sky`` emitter: several lights at infinity (a dome, suns with an angle) as Mitsuba's one
environment emitter. Its radiance is the parts' sum, its sampler agrees with its pdf and integrates the sum, and a
USD scene with such lights renders (Mitsuba refused it before; ``rna_suns_and_dome``: test_light_surfaces.py)."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import lights as lights_jit  # noqa: E402
from nasset_mitsuba_plugin.render import load_scene  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402
from tests.mitsuba_plugin.test_dome import _image  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _vec  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    lights_jit.register(mi)
    return mi


def _parts(mi, rng):
    cones = [{"type": lights_jit.NAME, "direction": mi.ScalarVector3f(0.3, 1.0, 0.2), "angle": 6.0,
              "irradiance": mi.ScalarColor3f(3.0, 2.0, 1.0)},
             {"type": lights_jit.NAME, "direction": mi.ScalarVector3f(-1.0, 0.2, 0.1), "angle": 30.0,
              "irradiance": mi.ScalarColor3f(0.5, 0.5, 0.8)}]
    bitmap = mi.Bitmap(np.ascontiguousarray(_image(rng), np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    dome = {"type": lights_jit.DOME, "radiance": mi.ScalarColor3f(0.2, 0.3, 0.4), "bitmap": bitmap}
    return [mi.load_dict(e) for e in (*cones, dome)]


def _directions(rng, n):
    d = rng.normal(size=(n, 3))
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def test_sky_radiance_is_the_sum_of_its_parts(mi, rng):
    parts = _parts(mi, rng)
    sky = mi.load_dict({"type": lights_jit.SKY, **{f"part_{i}": p for i, p in enumerate(parts)}})
    d = _directions(rng, 20000)
    d[:200] = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])  # inside the narrow cone too
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = -_vec(mi, d)
    got = np.asarray(sky.eval(si).numpy()).T
    want = sum(np.asarray(p.eval(si).numpy()).T for p in parts)
    assert np.allclose(got, want, rtol=1e-6)
    assert (np.asarray(parts[0].eval(si).numpy()).T[:200] > 0).all()  # the narrow cone is seen through the sky


def test_sky_sampler_pdf_and_integral(mi, rng):
    """Each sample's pdf is pdf_direction at its direction; E[L / pdf] is the sum of the parts' integrals over the sphere
    (each part's own estimator, 2 M samples); the pdf integrates to 1. Tolerances: 5 standard errors."""
    parts = _parts(mi, rng)
    sky = mi.load_dict({"type": lights_jit.SKY, **{f"part_{i}": p for i, p in enumerate(parts)}})
    n = 400000
    it = dr.zeros(mi.Interaction3f, n)
    u = rng.random((n, 2)).astype(np.float32)
    ds, w = sky.sample_direction(it, mi.Point2f(u[:, 0], u[:, 1]))
    pdf_s = np.asarray(ds.pdf.numpy())
    assert (pdf_s > 0).mean() > 0.999
    pdf_e = np.asarray(sky.pdf_direction(it, ds).numpy())
    assert np.allclose(pdf_e, pdf_s, rtol=1e-5)
    est = np.asarray(w.numpy()).T
    exact, var = np.zeros(3), np.zeros(3)
    m = 2_000_000
    itm = dr.zeros(mi.Interaction3f, m)
    for p in parts:  # each part alone integrates its own radiance (the dome's closed form is in test_dome)
        v = rng.random((m, 2)).astype(np.float32)
        _, wp = p.sample_direction(itm, mi.Point2f(v[:, 0], v[:, 1]))
        wp = np.asarray(wp.numpy()).T
        exact += wp.mean(0)
        var += wp.var(0) / m
    se = np.sqrt(est.var(0) / n + var)
    assert np.all(np.abs(est.mean(0) - exact) < 5 * se), (est.mean(0), exact, se)
    d = _directions(rng, n)
    dsu = dr.zeros(mi.DirectionSample3f, n)
    dsu.d = _vec(mi, d)
    p = np.asarray(sky.pdf_direction(it, dsu).numpy()) * 4 * np.pi
    assert abs(p.mean() - 1.0) < 5 * p.std() / math.sqrt(n)


def test_usd_scene_with_a_dome_and_angular_suns_renders(mi, tmp_path):
    """A dome with two suns of non-zero angle: one ``nasset_sky`` emitter holds the three (Mitsuba keeps one
    environment emitter and refused the scene before); a delta sun stays its own emitter."""
    b = SceneBuilder()
    b.camera((0, 1.0, 4.0), (0, 0, 0))
    b.quad("Floor", (0, -0.5, 0), 6.0)
    b.distant("Sun", (0.3, 1.0, 0.4), 3.0, angle=4.0)
    b.distant("Sun2", (-0.5, 1.0, 0.1), 2.0, angle=8.0)
    b.distant("Delta", (0.0, 1.0, -0.3), 1.0)
    b.dome("Sky", 0.3)
    scene = load_scene(b.write(tmp_path / "s.usda"), 16, 16, mi=mi)
    kinds = sorted(type(e).__name__ for e in scene.emitters())
    assert "SkyLight" in kinds and "ConeLight" not in kinds and "DomeLight" not in kinds, kinds
    (sky,) = [e for e in scene.emitters() if type(e).__name__ == "SkyLight"]
    assert sorted(type(p).__name__ for p in sky.parts) == ["ConeLight", "ConeLight", "DomeLight"]


def test_sky_part_that_is_not_a_light_at_infinity(mi):
    with pytest.raises(RuntimeError) as exc:  # Mitsuba wraps the plugin's typed error
        mi.load_dict({"type": lights_jit.SKY, "part_0": {"type": "point", "position": [0, 1, 0]}})
    assert "SCENE_INVALID" in str(exc.value)
