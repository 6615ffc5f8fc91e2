"""The plugin's ``nasset_spot`` (spec/renderer.md#spot-lights): a USD point light with ``UsdLux.ShapingAPI``. The plugin
loaded it as Mitsuba's unshaped point light before (``rna_spot_lights`` 25x its tolerance, the image 2.7x too bright)."""

from __future__ import annotations

import drjit as dr
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import lights as lights_jit  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_mitsuba_renderer.lights import spot_falloff  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _run_case, _vec  # noqa: E402


@pytest.mark.parametrize("profile, cone, softness", [("linear", 30.0, 0.4), ("linear", 60.0, 0.0), ("smoothstep", 20.0, 0.3),
                                                     ("smoothstep", 45.0, 0.0)])
def test_spot_sample_is_intensity_times_falloff_over_distance_squared(rng, profile, cone, softness):
    """The light sample's weight at random points is I falloff(theta) / d^2, the falloff the second implementation's
    (numpy, float64); the direction points at the light, delta, pdf 1."""
    mi = jit_mitsuba()
    lights_jit.register(mi)
    pos, axis = np.array([0.3, 2.0, -0.4]), np.array([0.2, -1.0, 0.1])
    spot = mi.load_dict({"type": lights_jit.SPOT, "position": mi.ScalarPoint3f(*pos), "intensity": mi.ScalarColor3f(3.0, 2.0, 1.0),
                         "axis": mi.ScalarVector3f(*axis), "cone": cone, "softness": softness, "profile": profile})
    p = rng.uniform(-2.0, 2.0, (20000, 3)) * [1.0, 0.5, 1.0]
    it = dr.zeros(mi.Interaction3f, len(p))
    it.p = _vec(mi, p)
    ds, w = spot.sample_direction(it, mi.Point2f(0.5, 0.5))
    v = pos - p
    dist = np.linalg.norm(v, axis=1)
    cos_t = -(v / dist[:, None]) @ (axis / np.linalg.norm(axis))
    want = np.array([3.0, 2.0, 1.0]) * (spot_falloff(cos_t, cone, softness, profile) / dist**2)[:, None]
    got = np.asarray(w.numpy()).T
    assert np.allclose(got, want, rtol=2e-4, atol=1e-6 * want.max()), np.abs(got - want).max()
    assert 0.05 < (got[:, 0] > 0).mean() < 0.95  # both inside and outside the cone
    assert np.allclose(np.asarray(ds.d.numpy()).T, v / dist[:, None], atol=1e-5) and bool(ds.delta[0])


def test_spot_bad_profile():
    mi = jit_mitsuba()
    lights_jit.register(mi)
    with pytest.raises(RuntimeError) as exc:  # Mitsuba wraps the plugin's typed error
        mi.load_dict({"type": lights_jit.SPOT, "profile": "cosine"})
    assert "SCENE_INVALID" in str(exc.value)


def test_spot_lights_conformance_case(tmp_path):
    """At twice the case's spp: the plugin picks one of the two lights per vertex, the reference renderer samples both."""
    row = _run_case("rna_spot_lights", tmp_path, spp_scale=2)
    assert row["passed"], row


@pytest.mark.parametrize("x", [0.0, 0.7])
def test_floor_under_a_sphere_spot_matches_the_quadrature(tmp_path, x):
    """A spot with a radius (spec/renderer.md#spot-lights; the plugin's nasset_profiled emitter on the sphere): the
    floor under its centre and near its cone's edge reads kd / pi times the quadrature of the shaped sphere, as in the
    reference renderer's test. Two seeds bound the noise."""
    from nasset_mitsuba_plugin.render import render
    from tests.renderer.test_sphere_spot import sphere_spot_stage

    path, expect = sphere_spot_stage(tmp_path / "s.usda", x)
    a, b = (render(path, 256, width=4, height=4, max_depth=2, seed=s).mean() for s in (1, 2))
    assert abs(0.5 * (a + b) - expect) < 3 * abs(a - b) + 0.02 * expect, (a, b, expect)
