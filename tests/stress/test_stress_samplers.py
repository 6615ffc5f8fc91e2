"""Numerical stress tests of the reference renderer's warps, BSDF sampling and light sampling.

Uniform numbers exactly at 0, 1 - ulp and subnormal; grazing and normal-incidence directions;
lights at 1e-4 and 1e4 scales, shading points on / inside / far from emitters; a dome with one
1e6 pixel. Outputs must be finite, pdfs >= 0, and a sample's pdf must equal pdf() at the sample.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from nasset_reference_renderer import bsdf as RB
from nasset_reference_renderer import lights as RL
from nasset_reference_renderer import sampling as RS
from tests.stress.stress_inputs import TINY, finite_all, unit_interval

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")

FAST = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

uniforms = st.integers(1, 24).flatmap(lambda n: arrays(np.float64, (n, 2), elements=unit_interval))
half_open = st.integers(1, 24).flatmap(lambda n: arrays(np.float64, (n, 2), elements=unit_interval.map(lambda v: min(v, 1 - 2 ** -53))))
# upper-hemisphere local directions: normal incidence, grazing (z = 0, subnormal), and general
_up_special = [(0, 0, 1), (1, 0, 0), (0, 1, 0), (1, 0, 1e-300), (1, 0, TINY), (1, 1, 1e-8), (1e-9, 0, 1), (1, 1, 1)]
up_dirs = st.lists(st.one_of(st.sampled_from(_up_special),
                             st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(0, 1))), min_size=1, max_size=24).map(
    lambda v: RS.normalize(np.array(v, np.float64) + np.array([0.0, 0.0, 0.0])))
alphas = st.one_of(st.sampled_from([RB.MIN_ALPHA, 0.01, 0.5, 1.0]), st.floats(RB.MIN_ALPHA, 1.0))


def _unit(v):
    return np.abs(np.linalg.norm(v, axis=1) - 1.0) < 1e-9


@FAST
@given(u=uniforms)
def test_cosine_hemisphere(counts, u):
    w = RS.square_to_cosine_hemisphere(u)
    p = RS.cosine_hemisphere_pdf(w)
    counts.add("sampling.square_to_cosine_hemisphere", len(u))
    assert finite_all(w, p) and _unit(w).all() and (w[:, 2] >= 0).all() and (p >= 0).all()
    np.testing.assert_allclose(p, w[:, 2] / np.pi, atol=1e-15)


@FAST
@given(u=uniforms, cos_max=st.one_of(st.sampled_from([-1.0, 0.0, 1.0 - 1e-16, float(np.nextafter(1.0, 0.0)), 1.0]), st.floats(-1, 1)))
def test_uniform_sphere_and_cone(counts, u, cos_max):
    w = RS.square_to_uniform_sphere(u)
    counts.add("sampling.square_to_uniform_sphere", len(u))
    assert finite_all(w) and _unit(w).all()
    c = RS.square_to_uniform_cone(u, cos_max)
    p = RS.uniform_cone_pdf(c, cos_max)
    counts.add("sampling.square_to_uniform_cone", len(u))
    assert finite_all(c, p) and _unit(c).all() and (p >= 0).all()
    assert (c[:, 2] >= cos_max - 1e-12).all()


@FAST
@given(wo=up_dirs, u=uniforms, alpha=alphas)
def test_ggx_vndf_sample_and_pdf(counts, wo, u, alpha):
    m = min(len(wo), len(u))
    wo, u = wo[:m], u[:m]
    a = np.full(m, alpha)
    h = RB.ggx_sample_vndf(wo, a, u)
    counts.add("bsdf.ggx_sample_vndf", m)
    assert finite_all(h) and _unit(h).all() and (h[:, 2] > 0).all()
    wi = RB.reflect(wo, h)
    p = RB.ggx_reflect_pdf(wo, wi, a)
    counts.add("bsdf.ggx_reflect_pdf", m)
    assert finite_all(wi, p) and (p >= 0).all()


@FAST
@given(wo=up_dirs, u=uniforms, ul=st.floats(0, 1), alpha=alphas, kd=st.sampled_from([0.0, 0.5, 1.0]),
       f0=st.sampled_from([0.0, 0.04, 1.0]))
def test_bsdf_sample_matches_eval(counts, wo, u, ul, alpha, kd, f0):
    m = min(len(wo), len(u))
    wo, u = wo[:m], u[:m]
    mt = RB.MaterialTable(kd=np.full((1, 3), kd), f0=np.full((1, 3), f0), alpha=np.array([alpha]), emission=np.zeros((1, 3)), names=["m"])
    mat = np.zeros(m, np.int64)
    wi, f, pdf = RB.bsdf_sample(mt, mat, wo, np.full(m, ul), u)
    counts.add("bsdf.bsdf_sample", m)
    assert finite_all(wi, f, pdf) and (f >= 0).all() and (pdf >= 0).all()
    f2, pdf2 = RB.bsdf_eval(mt, mat, wo, wi)
    counts.add("bsdf.bsdf_eval", m)
    np.testing.assert_array_equal(pdf2, pdf)
    ok = pdf > 0
    weight = f[ok] * (wi[ok, 2] / pdf[ok])[:, None]  # the path throughput factor the integrator uses
    assert np.isfinite(weight).all()


# ----------------------------------------------------------------------------------------
# lights

scales = st.sampled_from([1e-4, 1.0, 1e4])
# shading points relative to the light, in units of its size
rel_points = st.lists(st.one_of(
    st.sampled_from([(0, 0, 0), (1, 0, 0), (0, 0, 1 + 1e-12), (0, 0, 1 - 1e-12), (3, 0, 0), (0, 1e4, 0), (1e6, 1e6, 1e6),
                     (0.5, 0.5, 0), (0.5, 0.5, 1e-12), (0.5, 0.5, -1), (0.2, 0.1, 2)]),
    st.tuples(st.floats(-5, 5), st.floats(-5, 5), st.floats(-5, 5))), min_size=1, max_size=16).map(lambda v: np.array(v, np.float64))


def _check_light_sample(light, p, u, name, counts, *, inner):
    wi, dist, li, pdf = light.sample(p, u)
    counts.add(f"lights.{name}.sample", len(p))
    assert finite_all(wi, li, pdf) and (pdf >= 0).all() and (li >= 0).all()
    assert not np.isnan(dist).any() and (dist > 0).all()
    live = pdf > 0
    assert _unit(wi[live]).all()
    p2 = light.pdf(p, wi)
    counts.add(f"lights.{name}.pdf", len(p))
    assert np.isfinite(p2).all() and (p2 >= 0).all()
    # away from the edge of the sampled domain (u strictly inside), pdf() at the sample is the sample's pdf
    sel = live & inner
    np.testing.assert_allclose(p2[sel], pdf[sel], rtol=1e-6)
    if live.any():
        assert np.isfinite(li[live] / pdf[live, None]).all()
    return wi, pdf


def _inner(u, margin=1e-6):
    return ((u > margin) & (u < 1 - margin)).all(1)


@FAST
@given(rel=rel_points, u=half_open, scale=scales, radius=st.sampled_from([1.0, 1e-3]))
def test_sphere_light(counts, rel, u, scale, radius):
    m = min(len(rel), len(u))
    r = radius * scale
    c = np.array([1.0, -2.0, 0.5]) * scale
    light = RL.SphereLight(c, r, [1e6, 1.0, 1e-6])
    p = c + rel[:m] * r
    _check_light_sample(light, p, u[:m], "SphereLight", counts, inner=_inner(u[:m]))


@FAST
@given(rel=rel_points, u=half_open, scale=scales)
def test_point_light(counts, rel, u, scale):
    m = min(len(rel), len(u))
    light = RL.PointLight(np.zeros(3), [1e6, 1.0, 1e-6])
    wi, dist, li, pdf = light.sample(rel[:m] * scale, u[:m])
    counts.add("lights.PointLight.sample", m)
    assert finite_all(wi, dist, li, pdf) and (li >= 0).all() and (pdf == 1).all()


@FAST
@given(rel=rel_points, u=half_open, scale=scales, aspect=st.sampled_from([1.0, 1e-3]))
def test_rect_light(counts, rel, u, scale, aspect):
    m = min(len(rel), len(u))
    ex, ey = np.array([2.0, 0, 0]) * scale, np.array([0, 2.0 * aspect, 0]) * scale
    c = np.array([0.3, 0.0, -1.0]) * scale
    light = RL.RectLight(c, ex, ey, [1e6, 1.0, 1e-6])  # emits toward -Z (local -Z = -(ex x ey))
    p = c + rel[:m] * np.array([1.0, aspect, -1.0]) * scale
    _check_light_sample(light, p, u[:m], "RectLight", counts, inner=_inner(u[:m], 1e-4))


@FAST
@given(u=half_open, angle=st.one_of(st.sampled_from([0.0, 1e-9, 1e-6, 0.53, 90.0, 180.0, 359.9, 360.0, 720.0]), st.floats(0, 360)),
       d=st.sampled_from([(0, 0, 1), (0, 1, 0), (1, 1, 1), (0, 0, -1)]))
def test_distant_light(counts, u, angle, d):
    light = RL.DistantLight(d, [1e6, 1.0, 1e-6], angle)
    p = np.zeros((len(u), 3))
    wi, pdf = _check_light_sample(light, p, u, "DistantLight", counts, inner=_inner(u) & (not light.delta) & (0 < angle < 360))
    le = light.le_escaped(wi)
    assert np.isfinite(le).all() and (le >= 0).all()
    if not light.delta:
        # sum of L cos / pdf over the cone's axis recovers E (the cone is uniform): E within rounding at any angle
        axis_u = np.array([[0.0, 0.3]])
        w0, _, l0, p0 = light.sample(np.zeros((1, 3)), axis_u)
        e_est = l0 / p0[:, None] * (w0 @ light.w)[:, None]
        tiny = angle < 1.0  # a narrow cone: every sample is within 1e-2 of the axis, so L cos / pdf ~ E
        if tiny:
            np.testing.assert_allclose(e_est[0], light.E, rtol=1e-2)


def _hot_dome(h, w, hot, rot=None):
    img = np.zeros((h, w, 3))
    img[hot] = 1e6
    return RL.DomeLight([1.0, 1.0, 1.0], img, rotation=rot)


@FAST
@given(u=half_open, hot=st.sampled_from([(0, 0), (0, 7), (3, 4), (7, 15), (7, 0)]),
       shape=st.sampled_from([(8, 16), (1, 1), (2, 1)]), dark=st.sampled_from([0.0, TINY, 1e-300]))
def test_dome_hot_pixel(counts, u, hot, shape, dark):
    h, w = shape
    hot = (min(hot[0], h - 1), min(hot[1], w - 1))
    light = _hot_dome(h, w, hot)
    light.image[light.image == 0] = dark
    p = np.zeros((len(u), 3))
    wi, pdf = _check_light_sample(light, p, u, "DomeLight", counts, inner=_inner(u))
    le = light.le_escaped(wi)
    assert np.isfinite(le).all() and (le >= 0).all()
    # directions at the poles and seams of the lat-long map
    poles = np.array([[0, 1.0, 0], [0, -1.0, 0], [0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0], [-1.0, 0, 0]])
    pp = light.pdf(np.zeros((6, 3)), poles)
    counts.add("lights.DomeLight.pdf", 6)
    assert np.isfinite(pp).all() and (pp >= 0).all() and np.isfinite(light.le_escaped(poles)).all()


def test_dome_all_dark_image(counts):
    light = RL.DomeLight([1.0, 1.0, 1.0], np.zeros((4, 8, 3)))
    u = np.random.default_rng(0).random((64, 2))
    wi, dist, li, pdf = light.sample(np.zeros((64, 3)), u)
    counts.add("lights.DomeLight.sample", 64)
    assert light.power_is_zero() and finite_all(wi, li, pdf) and (li == 0).all()


@FAST
@given(u=uniforms, kappa=st.one_of(st.sampled_from([1e-8, 1e-3, 6.0, 700.0, 1e4]), st.floats(1e-6, 1e3)))
def test_von_mises_fisher(counts, u, kappa):
    w = RS.square_to_vmf(u, kappa)
    p = RS.vmf_pdf(w[:, 2], kappa)
    counts.add("sampling.square_to_vmf", len(u))
    assert finite_all(w, p) and _unit(w).all() and (p >= 0).all()


_axes = [(0, 0, 1), (1, 0, 0), (0, 0, -1), (0, 0, 0), (1e-300, 0, 1), (1, 1, TINY)]


@FAST
@given(wo=up_dirs, u=uniforms, pick=st.floats(0, 1), fiber=st.booleans(), axis=st.sampled_from(_axes))
@example(wo=np.zeros((1, 3)), u=np.zeros((1, 2)), pick=1.0, fiber=False, axis=(0, 0, 1))  # a zero wo (up_dirs draws it)
@example(wo=np.zeros((1, 3)), u=np.zeros((1, 2)), pick=1.0, fiber=False, axis=(0, 0, 0))
@example(wo=np.zeros((1, 3)), u=np.zeros((1, 2)), pick=0.5, fiber=False, axis=(0, 0, 0))
@example(wo=np.zeros((1, 3)), u=np.zeros((1, 2)), pick=0.6, fiber=True, axis=(0, 0, 0))
@example(wo=np.zeros((1, 3)), u=np.zeros((1, 2)), pick=1.0, fiber=True, axis=(0, 0, 0))
def test_rna_continuation_mixtures(counts, wo, u, pick, fiber, axis):
    """The continuation mixtures at normal incidence, grazing, wo along the fiber, a missing normal or
    tangent, and a zero wo: unit directions, finite densities, never below the uniform part's 0.4 / 4 pi."""
    from nasset_reference_renderer.shaders.rna_fiber import FiberContinuation
    from nasset_reference_renderer.shaders.rna_surface import SurfaceContinuation

    m = min(len(wo), len(u))
    wo, u = wo[:m], u[:m]
    frame = RS.normalize(np.repeat(np.array([axis], np.float64), m, 0))  # a zero axis stays zero
    cont = (FiberContinuation if fiber else SurfaceContinuation)(wo, frame)
    rows = np.arange(m)
    w = cont.sample(rows, np.concatenate([u, np.full((m, 1), pick)], 1))
    p = cont.pdf(rows, w)
    counts.add("rna_fiber.FiberContinuation" if fiber else "rna_surface.SurfaceContinuation", m)
    assert finite_all(w, p) and _unit(w).all() and (p >= 0.4 / (4 * np.pi) - 1e-12).all()
