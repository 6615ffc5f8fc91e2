"""Numerical stress tests of the kinds' encodings, splines, boundary lobe and evaluators.

Property-based (hypothesis, derandomised): adversarial inputs (poles, cube edges and corners, knots,
zero / subnormal / huge / NaN / Inf vectors, points far outside the domain, fp16 extremes) must give
finite outputs, non-negative transports and consistent pdfs.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from nasset_sdk.asset import Asset
from nasset_sdk.kinds import boundary as B
from nasset_sdk.kinds import encodings as E
from nasset_sdk.kinds import get_kind
from nasset_sdk.kinds import neupress as NP
from nasset_sdk.kinds import spline as S
from tests.stress.stress_inputs import (
    EDGE_DIRS,
    F16_MAX,
    F16_SUB,
    TINY,
    component,
    edge_dir_rows,
    finite_all,
    rows,
    unit_interval,
)

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # overflow warnings of adversarial inputs are expected

FAST = settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
SLOW = settings(max_examples=40, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def _fp16_tensor(shape, rng):
    """float16-representable values: +-65504, subnormals, zeros and ordinary numbers."""
    pool = np.array([F16_MAX, -F16_MAX, F16_SUB, -F16_SUB, 0.0, -0.0, 1.0, -0.5, 6.1e-5, 60000.0], np.float16)
    t = rng.choice(pool, size=shape).astype(np.float32)
    t.flat[0], t.flat[-1] = F16_MAX, -F16_MAX
    return t


# ----------------------------------------------------------------------------------------
# encodings


@FAST
@given(pts=rows(elements=st.one_of(st.sampled_from([-1.0, 1.0, 0.0, -1e6, 1e6, 1 + 1e-9, -1 - 1e-9, TINY]),
                                   st.floats(-1e6, 1e6))),
       scale=st.sampled_from([1e-4, 1.0, 1e4]), centre=st.sampled_from([0.0, 1e-3, -7.0, 3e4]))
def test_to_unit_box_scales(counts, pts, scale, centre):
    """Domains at 1e-4 and 1e4 scene scales: inside points land in [-1, 1], far points stay finite and affine."""
    half = scale * np.array([1.0, 2.0, 0.5])
    lo, hi = centre - half, centre + half
    x = centre + pts * half
    xn = E.to_unit_box(x, lo, hi)
    counts.add("encodings.to_unit_box", len(x))
    assert xn.dtype == np.float32 and np.isfinite(xn).all()
    inside = (np.abs(pts) <= 1.0).all(1)
    assert (np.abs(xn[inside]) <= 1.0 + 1e-5).all()
    np.testing.assert_allclose(xn, pts, rtol=1e-5, atol=1e-5 * (1.0 + abs(centre) / scale))


@FAST
@given(x=rows(elements=component))
def test_to_unit_box_nonfinite_stays_in_its_component(counts, x):
    """The map is affine per component (spec: not clamped): a NaN/Inf coordinate never leaks into another."""
    xn = E.to_unit_box(x, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0])
    counts.add("encodings.to_unit_box", len(x))
    ok = np.isfinite(x) & (np.abs(x) < 1e38)
    assert np.isfinite(xn[ok]).all()


@FAST
@given(uv=rows(width=2), seed=st.integers(0, 3), shape=st.sampled_from([(1, 1), (1, 5), (4, 4), (3, 8)]))
def test_grid_sample_2d(counts, uv, seed, shape):
    plane = _fp16_tensor((*shape, 2), np.random.default_rng(seed))
    out = E.grid_sample_2d(plane, uv[:, 0], uv[:, 1])
    counts.add("encodings.grid_sample_2d", len(uv))
    assert out.shape == (len(uv), 2) and np.isfinite(out).all()
    # a convex combination of texels: within the channel's range (float32 rounding of the weights)
    lo, hi = plane.min((0, 1)), plane.max((0, 1))
    tol = 1e-6 * F16_MAX
    assert (out >= lo - tol).all() and (out <= hi + tol).all()
    # NaN reads texel 0 (the same as the lower edge -1)
    u0 = np.where(np.isnan(uv[:, 0]), -1.0, uv[:, 0])
    v0 = np.where(np.isnan(uv[:, 1]), -1.0, uv[:, 1])
    np.testing.assert_array_equal(out, E.grid_sample_2d(plane, u0, v0))


@FAST
@given(xn=rows(), seed=st.integers(0, 3))
def test_triplane(counts, xn, seed):
    planes = _fp16_tensor((3, 4, 4, 3), np.random.default_rng(seed))
    out = E.triplane(planes, xn)
    counts.add("encodings.triplane", len(xn))
    assert np.isfinite(out).all()
    lo, hi = planes.min((1, 2)).sum(0), planes.max((1, 2)).sum(0)
    tol = 1e-5 * F16_MAX
    assert (out >= lo - tol).all() and (out <= hi + tol).all()


@FAST
@given(d=edge_dir_rows(), seed=st.integers(0, 3), r=st.sampled_from([1, 2, 4]))
def test_cubemap(counts, d, seed, r):
    grid = _fp16_tensor((6, r, r, 2), np.random.default_rng(seed))
    out = E.cubemap(grid, d)
    face, s, t = E.cube_face_uv(d)
    counts.add("encodings.cubemap", len(d))
    assert np.isfinite(out).all()
    assert ((face >= 0) & (face < 6)).all() and ((s >= 0) & (s <= 1) & (t >= 0) & (t <= 1)).all()
    tol = 1e-5 * F16_MAX
    assert (out >= grid.min((0, 1, 2)) - tol).all() and (out <= grid.max((0, 1, 2)) + tol).all()


@FAST
@given(d=st.sampled_from(EDGE_DIRS), eps=st.sampled_from([1e-12, 1e-9]), seed=st.integers(0, 7))
def test_cubemap_continuous_at_edges_and_corners(counts, d, eps, seed):
    """Directions exactly on a face edge / corner and nudged off it to every side read (almost) the same value."""
    grid = np.random.default_rng(seed).normal(size=(6, 4, 4, 3)).astype(np.float32)
    d = np.array(d, np.float64)
    nudges = np.array([[a, b, c] for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)], np.float64) * eps
    dirs = d[None] + nudges
    out = E.cubemap(grid, dirs)
    counts.add("encodings.cubemap", len(dirs))
    assert np.isfinite(out).all()
    # the lookup is Lipschitz in the direction; 1e-9 moves change values by far less than 1e-4
    assert np.abs(out - out[13]).max() <= 1e-4 * (1 + np.abs(grid).max())


@FAST
@given(t=st.lists(component, min_size=1, max_size=24).map(np.array), seed=st.integers(0, 3), k=st.sampled_from([1, 2, 8]))
def test_grid_1d(counts, t, seed, k):
    grid = _fp16_tensor((k, 3), np.random.default_rng(seed))
    out = E.grid_1d(grid, t)
    counts.add("encodings.grid_1d", len(t))
    assert np.isfinite(out).all()
    tol = 1e-6 * F16_MAX
    assert (out >= grid.min(0) - tol).all() and (out <= grid.max(0) + tol).all()


@FAST
@given(v=rows(width=5), seed=st.integers(0, 3))
def test_fourier_features(counts, v, seed):
    G = np.random.default_rng(seed).normal(NP.FOURIER_MEAN, NP.FOURIER_STD, (6, 5))
    out = E.fourier_features(G, v)
    counts.add("encodings.fourier_features", len(v))
    assert out.shape == (len(v), 12) and np.isfinite(out).all()
    assert (np.abs(out) <= 1.0).all()


@FAST
@given(n=edge_dir_rows())
def test_local_frame(counts, n):
    t, b, nn = E.local_frame(n)
    counts.add("encodings.local_frame", len(n))
    assert finite_all(t, b, nn)
    for a in (t, b, nn):
        np.testing.assert_allclose(np.linalg.norm(a, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose((t * b).sum(1), 0.0, atol=1e-12)
    np.testing.assert_allclose((t * nn).sum(1), 0.0, atol=1e-12)
    np.testing.assert_allclose(np.cross(t, b), nn, atol=1e-12)


@FAST
@given(w=edge_dir_rows(), n=edge_dir_rows())
def test_azimuthal_equidistant_round_trip(counts, w, n):
    m = min(len(w), len(n))
    w, n = w[:m], n[:m]
    p = E.azimuthal_equidistant(w, n)
    counts.add("encodings.azimuthal_equidistant", m)
    assert np.isfinite(p).all() and (np.hypot(p[:, 0], p[:, 1]) <= np.pi + 1e-12).all()
    back = E.azimuthal_equidistant_inverse(p, n)
    counts.add("encodings.azimuthal_equidistant_inverse", m)
    assert np.isfinite(back).all()
    np.testing.assert_allclose(np.linalg.norm(back, axis=1), 1.0, atol=1e-12)
    wu = E.unit64(w)
    far = np.hypot(p[:, 0], p[:, 1]) < np.pi - 1e-6  # away from the antipode circle (phi undefined there)
    np.testing.assert_allclose(back[far], wu[far], atol=1e-6)


@FAST
@given(p=rows(width=2), n=edge_dir_rows())
def test_azimuthal_equidistant_inverse_any_point(counts, p, n):
    m = min(len(p), len(n))
    w = E.azimuthal_equidistant_inverse(p[:m], n[:m])
    counts.add("encodings.azimuthal_equidistant_inverse", m)
    assert np.isfinite(w).all()
    np.testing.assert_allclose(np.linalg.norm(w, axis=1), 1.0, atol=1e-12)


@FAST
@given(w=edge_dir_rows())
def test_sh9(counts, w):
    y = E.sh9(w)
    counts.add("encodings.sh9", len(w))
    assert np.isfinite(y).all()
    # addition theorem: sum_m Y_lm^2 = (2l + 1) / (4 pi) for every unit direction
    for band, sl in ((0, slice(0, 1)), (1, slice(1, 4)), (2, slice(4, 9))):
        np.testing.assert_allclose((y[:, sl] ** 2).sum(1), (2 * band + 1) / (4 * np.pi), rtol=1e-9)


@FAST
@given(v=edge_dir_rows())
def test_safe_normalize(counts, v):
    out = E.safe_normalize(v)
    counts.add("encodings.safe_normalize", len(v))
    assert out.dtype == np.float32 and np.isfinite(out).all()
    np.testing.assert_allclose(np.linalg.norm(out.astype(np.float64), axis=1), 1.0, atol=1e-6)
    vf = np.where(np.isfinite(v), v, 0.0)
    mag = np.abs(vf).max(1)
    big = mag > 1e-10  # clearly above the 1e-20 fallback threshold: the result is parallel to v
    direction = vf[big] / mag[big, None]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    np.testing.assert_allclose(out[big], direction, atol=1e-6)


@FAST
@given(w=edge_dir_rows())
def test_spherical_coords(counts, w):
    c = E.spherical_coords(w)
    counts.add("encodings.spherical_coords", len(w))
    assert np.isfinite(c).all()
    assert ((c[:, 0] >= 0) & (c[:, 0] <= 1) & (c[:, 1] >= -0.5) & (c[:, 1] <= 0.5)).all()


# ----------------------------------------------------------------------------------------
# splines

K = 4


def _spline_rows(raw, n):
    s = S.RQSpline.from_raw(raw)
    return S.RQSpline(np.repeat(s.xk, n, 0), np.repeat(s.yk, n, 0), np.repeat(s.dk, n, 0))


raw_params = arrays(np.float64, (1, 3 * K + 1), elements=st.one_of(
    st.sampled_from([0.0, 30.0, -30.0, 700.0, -700.0, 1e30, -1e30, 1e300, np.nan, np.inf, -np.inf]), st.floats(-20, 20)))
bounded_raw = arrays(np.float64, (1, 3 * K + 1), elements=st.floats(-12, 12))
spline_points = st.lists(st.one_of(unit_interval, component), min_size=1, max_size=16)


@FAST
@given(raw=raw_params, pts=spline_points)
def test_rqspline_finite_on_knots_and_edges(counts, raw, pts):
    s1 = S.RQSpline.from_raw(raw)
    z = np.concatenate([s1.xk[0], s1.yk[0], np.nextafter(s1.xk[0], 2.0), np.nextafter(s1.xk[0], -1.0), np.array(pts)])
    spl = _spline_rows(raw, len(z))
    y, ld = spl.forward(z)
    zi, ldi = spl.inverse(z)
    counts.add("spline.RQSpline.forward", len(z))
    counts.add("spline.RQSpline.inverse", len(z))
    assert finite_all(y, ld, zi, ldi)
    assert ((y >= 0) & (y <= 1) & (zi >= 0) & (zi <= 1)).all()
    assert (np.diff(s1.xk[0]) >= 0).all() and (np.diff(s1.yk[0]) >= 0).all() and (s1.dk > 0).all()
    # monotone: sorting the (clamped) inputs sorts the outputs
    zc = np.clip(np.nan_to_num(z, nan=0.0), 0.0, 1.0)
    order = np.argsort(zc, kind="stable")
    assert (np.diff(y[order]) >= -1e-15).all()
    # the knots map onto each other
    nk = K + 1
    np.testing.assert_allclose(y[:nk], s1.yk[0], atol=1e-12)


@FAST
@given(raw=bounded_raw, pts=spline_points)
def test_rqspline_round_trip(counts, raw, pts):
    s1 = S.RQSpline.from_raw(raw)
    z = np.clip(np.nan_to_num(np.concatenate([s1.xk[0], np.array(pts)]), nan=0.0), 0.0, 1.0)
    spl = _spline_rows(raw, len(z))
    y, ld = spl.forward(z)
    z2, ld2 = spl.inverse(y)
    counts.add("spline.RQSpline.forward", len(z))
    counts.add("spline.RQSpline.inverse", len(z))
    np.testing.assert_allclose(z2, z, atol=1e-9)
    # at a knot the two neighbouring bins give the same derivative only up to their (large, for
    # minimum-width bins) curvature times the rounding of xi: log-dets agree to 1e-3, not to 1e-7
    np.testing.assert_allclose(ld + ld2, 0.0, atol=1e-3)


box_scale = st.sampled_from([1e-4, 1.0, 1e4])
box_aspect = st.sampled_from([(1.0, 1.0, 1.0), (1.0, 2.0, 0.5), (1.0, 1e-3, 1.0)])


def _box(scale, aspect, centre=0.0):
    half = scale * np.array(aspect)
    return S.BoxParam(centre - half, centre + half)


@FAST
@given(d=edge_dir_rows(), w=edge_dir_rows(), scale=box_scale, aspect=box_aspect)
def test_boxparam_rays(counts, d, w, scale, aspect):
    """u on box faces / edges / corners, w parallel to a face, zero and NaN vectors."""
    box = _box(scale, aspect, centre=3.0 * scale)
    m = min(len(d), len(w))
    u = box.center + np.where(np.isfinite(d[:m]), d[:m], 0.0) * box.half / np.maximum(np.abs(np.nan_to_num(d[:m])).max(1), 1e-300)[:, None]
    u = np.where(np.isfinite(u), u, box.center)
    s, jac = box.from_rays(u, w[:m])
    counts.add("spline.BoxParam.from_rays", m)
    assert finite_all(s, jac) and (jac > 0).all()
    assert (np.abs(s[:, [0, 2]]) <= 1).all() and (np.abs(s[:, [1, 3]]) <= np.pi).all()
    u2, w2, jac2 = box.to_rays(s)
    counts.add("spline.BoxParam.to_rays", m)
    assert finite_all(u2, w2, jac2) and (jac2 > 0).all()
    np.testing.assert_allclose(np.linalg.norm(w2, axis=1), 1.0, atol=1e-12)
    rel = np.abs(u2 - box.center) / box.half
    np.testing.assert_allclose(rel.max(1), 1.0, rtol=1e-9)  # on the box surface
    u_box = box.project(E.unit64(u - box.center))[0] + box.center  # u itself, or the +Z face point for u = centre
    np.testing.assert_allclose(u2, u_box, atol=1e-9 * box.half.max())
    # the Jacobian |n_u . u| / |u|^3 jumps across box edges (n_u changes there): compare off the edges
    ratio = np.sort(box.half / np.maximum(np.abs(E.unit64(u - box.center)), 1e-300), axis=1)
    off_edge = ratio[:, 1] > ratio[:, 0] * (1 + 1e-6)
    np.testing.assert_allclose(jac2[off_edge], jac[off_edge], rtol=1e-9)


def _conditioner(kind):
    """Deterministic stand-in for the flow networks: smooth bounded functions of s_prev, or adversarial outputs."""

    def cond(j, ctx, s_prev):
        x, wo = ctx
        n = len(x)
        base = np.sin(np.arange(3 * (3 * K + 1))[None, :] * 0.7 + j + np.nan_to_num(s_prev).sum(1, keepdims=True))
        if kind == "bounded":
            return 3.0 * base + np.zeros((n, 1))
        bad = np.array([np.nan, np.inf, -np.inf, 1e30, -1e30, 1e300])
        out = base * 50.0
        out[:, ::4] = bad[(np.arange(out[:, ::4].size) + j) % len(bad)].reshape(n, -1)
        return out

    return cond


flow_latents = st.integers(1, 12).flatmap(lambda n: arrays(np.float64, (n, 4), elements=st.one_of(unit_interval, component)))


@SLOW
@given(u=flow_latents, scale=box_scale, aspect=box_aspect, channel=st.integers(0, 2))
def test_boxflow_sample_matches_pdf(counts, u, scale, aspect, channel):
    box = _box(scale, aspect, centre=-2.0 * scale)
    flow = S.BoxFlow(box, _conditioner("bounded"))
    n = len(u)
    x = np.tile(box.center, (n, 1))
    wo = np.tile([0.0, 0.0, 1.0], (n, 1))
    ui, wi, pdf = flow.sample(x, wo, channel, u=u)
    counts.add("spline.BoxFlow.sample", n)
    assert finite_all(ui, wi, pdf) and (pdf > 0).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose((np.abs(ui - box.center) / box.half).max(1), 1.0, rtol=1e-9)
    p2 = flow.pdf(x, wo, ui, wi, channel)
    counts.add("spline.BoxFlow.pdf", n)
    assert np.isfinite(p2).all() and (p2 > 0).all()
    # latents 0 / 1 land on a pole (s1, s3 = +-1) or the phi = +-pi seam, where the recovered angle is
    # ambiguous and the density has two valid values; everywhere else sample and pdf() must agree
    inner = ((u > 1e-6) & (u < 1 - 1e-6)).all(1)
    np.testing.assert_allclose(p2[inner], pdf[inner], rtol=1e-6)
    wd, pd = flow.sample_direction(x, wo, ui, channel, u=u[:, 2:])
    counts.add("spline.BoxFlow.sample_direction", n)
    pd2 = flow.pdf_direction(x, wo, ui, wd, channel)
    counts.add("spline.BoxFlow.pdf_direction", n)
    assert finite_all(wd, pd, pd2) and (pd > 0).all() and (pd2 > 0).all()
    np.testing.assert_allclose(pd2[inner], pd[inner], rtol=1e-6)
    pp = flow.pdf_position(x, wo, ui, channel)
    counts.add("spline.BoxFlow.pdf_position", n)
    assert np.isfinite(pp).all() and (pp > 0).all()
    # the reused-conditioner path: same sample, same densities
    fs = flow.sample_state(x, wo, channel, u=u)
    counts.add("spline.BoxFlow.sample_state", n)
    prgb = flow.pdf_rgb_at(fs, np.arange(n), wd)
    counts.add("spline.BoxFlow.pdf_rgb_at", n)
    assert finite_all(fs.ui, fs.wi, fs.pdf, fs.pdf_position_rgb(), prgb) and (prgb > 0).all()
    np.testing.assert_array_equal(fs.ui, ui)
    np.testing.assert_allclose(fs.pdf, pdf, rtol=1e-12)
    np.testing.assert_allclose(fs.pdf_position_rgb()[inner, channel], pp[inner], rtol=1e-6)
    np.testing.assert_allclose(prgb[inner, channel], (pp * pd2)[inner], rtol=1e-6)
    # w_i drawn for every other row only; the densities at the sample's own (u_i, w_i) reuse its conditioners
    drawn = np.arange(n) % 2 == 0
    fd = flow.sample_state(x, wo, channel, u=u, directions=drawn)
    counts.add("spline.BoxFlow.sample_state", n)
    own = flow.pdf_rgb_sampled(fd, np.nonzero(drawn)[0])
    counts.add("spline.BoxFlow.pdf_rgb_sampled", int(drawn.sum()))
    assert finite_all(fd.ui, fd.wi, fd.pdf, own) and (own > 0).all()
    np.testing.assert_allclose(fd.pdf[drawn], pdf[drawn], rtol=1e-12)
    np.testing.assert_allclose(own[inner[drawn], channel], pdf[drawn & inner], rtol=1e-6)


@SLOW
@given(u=flow_latents, wi=edge_dir_rows(12), scale=box_scale)
def test_boxflow_adversarial_parameters(counts, u, wi, scale):
    """Conditioners returning NaN / Inf / 1e300 parameters still give finite samples and pdfs."""
    box = _box(scale, (1.0, 2.0, 0.5))
    flow = S.BoxFlow(box, _conditioner("adversarial"))
    n = len(u)
    x = np.tile(box.center, (n, 1))
    wo = np.tile([1.0, 0.0, 0.0], (n, 1))
    ui, w, pdf = flow.sample(x, wo, np.arange(n) % 3, u=u)
    counts.add("spline.BoxFlow.sample", n)
    assert finite_all(ui, w, pdf) and (pdf >= 0).all()
    m = min(n, len(wi))
    p2 = flow.pdf(x[:m], wo[:m], ui[:m], wi[:m], 0)
    counts.add("spline.BoxFlow.pdf", m)
    assert np.isfinite(p2).all() and (p2 >= 0).all()
    fs = flow.sample_state(x, wo, np.arange(n) % 3, u=u)
    counts.add("spline.BoxFlow.sample_state", n)
    prgb = flow.pdf_rgb_at(fs, np.arange(m), wi[:m])
    counts.add("spline.BoxFlow.pdf_rgb_at", m)
    assert finite_all(fs.ui, fs.wi, fs.pdf, fs.pdf_position_rgb(), prgb) and (prgb >= 0).all()
    own = flow.pdf_rgb_sampled(fs, np.arange(n))
    counts.add("spline.BoxFlow.pdf_rgb_sampled", n)
    assert finite_all(own) and (own >= 0).all()


# ----------------------------------------------------------------------------------------
# boundary (GGX rough dielectric) and the neupress Gaussian lobe

alphas = st.one_of(st.sampled_from([B.ALPHA_MIN, 1e-3, 0.5, 1.0]), st.floats(B.ALPHA_MIN, 1.0))
etas = st.one_of(st.sampled_from([1e-3, 0.5, 1.0, 1.0 + 1e-12, 1.5, 1e3]), st.floats(1e-3, 1e3))


@FAST
@given(c=st.lists(component, min_size=1, max_size=24).map(np.array), eta=etas)
def test_fresnel(counts, c, eta):
    f = B.fresnel_dielectric(c, eta)
    counts.add("boundary.fresnel_dielectric", len(c))
    assert np.isfinite(f).all() and ((f >= 0) & (f <= 1)).all()


@FAST
@given(p=arrays(np.float64, (2,), elements=component))
def test_boundary_params(counts, p):
    eta, alpha = B.boundary_params(p)
    counts.add("boundary.boundary_params", 1)
    assert 1e-3 <= eta <= 1e3 and B.ALPHA_MIN <= alpha <= 1.0


@FAST
@given(n=edge_dir_rows(), wo=edge_dir_rows(), wi=edge_dir_rows(), alpha=alphas, eta=etas)
def test_ggx_eval_and_pdf(counts, n, wo, wi, alpha, eta):
    m = min(len(n), len(wo), len(wi))
    n, wo, wi = n[:m], wo[:m], wi[:m]
    f = B.ggx_reflection(n, wo, wi, eta, alpha)
    p = B.ggx_pdf(n, wo, wi, alpha)
    counts.add("boundary.ggx_reflection", m)
    counts.add("boundary.ggx_pdf", m)
    assert finite_all(f, p) and (f >= 0).all() and (p >= 0).all()


@FAST
@given(n=edge_dir_rows(), wo=edge_dir_rows(), u=rows(width=2, elements=st.one_of(unit_interval, component)), alpha=alphas)
@example(n=np.full((1, 3), -1e-300), wo=np.array([[0.0, 1.0000000000000002, 1e-6]]), u=np.zeros((1, 2)), alpha=1e-4)
def test_ggx_sample_matches_pdf(counts, n, wo, u, alpha):
    m = min(len(n), len(wo), len(u))
    n, wo, u = n[:m], wo[:m], u[:m]
    wi, pdf = B.ggx_sample(n, wo, u, alpha)
    counts.add("boundary.ggx_sample", m)
    assert finite_all(wi, pdf) and (pdf >= 0).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    p2 = B.ggx_pdf(n, wo, wi, alpha)
    counts.add("boundary.ggx_pdf", m)
    assert np.isfinite(p2).all() and (p2 >= 0).all()
    # pdf() recovers h = normalize(wo + wi), which cancels catastrophically in two places: u1 -> 1 puts h
    # within 1e-8 of the tangent plane, and a grazing wo.h puts wi near -wo (an ulp of wo moves wo.h by
    # eps / (2 wo.h), the pdf by eps / (2 (wo.h)^2) relative: 1e-4 at wo.h = 1e-6). Elsewhere pdf() at the
    # sample is the sample's pdf.
    inner_h = np.clip(np.nan_to_num(u[:, 0]), 0, 1) < 1 - 1e-6
    cos_oh2 = 0.5 * (1.0 + E.dot3(E.unit64(wo), wi))  # (wo.h)^2, accurate to an ulp absolute
    conditioned = inner_h & (cos_oh2 > 1e-8)
    np.testing.assert_allclose(p2[conditioned], pdf[conditioned], rtol=1e-6)
    f = B.ggx_reflection(n, wo, wi, 1.5, alpha)
    assert np.isfinite(f).all() and (f >= 0).all()


sigmas = st.one_of(st.sampled_from([0.0, NP.SIGMA_MIN, 1e-6, 1.0, NP.SIGMA_MAX, 1e30, np.nan, np.inf, -np.inf]),
                   st.floats(1e-3, 1e3))


@FAST
@given(n=edge_dir_rows(), u=rows(width=2, elements=st.one_of(unit_interval, component)), sigma=sigmas)
def test_gaussian_lobe_sample_matches_pdf(counts, n, u, sigma):
    m = min(len(n), len(u))
    wi, pdf = NP.gaussian_lobe_sample(n[:m], sigma, u[:m])
    counts.add("neupress.gaussian_lobe_sample", m)
    assert finite_all(wi, pdf) and (pdf > 0).all()
    np.testing.assert_allclose(np.linalg.norm(wi, axis=1), 1.0, atol=1e-12)
    p2 = NP.gaussian_lobe_pdf(n[:m], sigma, wi)
    counts.add("neupress.gaussian_lobe_pdf", m)
    np.testing.assert_allclose(p2, pdf, rtol=1e-9)


# ----------------------------------------------------------------------------------------
# evaluators of tiny random assets, opened from a written .usdc


def _write(kind, path, *, seed=5, scale=None, fp16_extreme=False):
    rng = np.random.default_rng(seed)
    geometry = None
    if scale is not None:
        from nasset_sdk.geometry import MeshGeometry
        from nasset_sdk.kinds.rna import example_mesh

        g = example_mesh()
        geometry = MeshGeometry((np.asarray(g.points, np.float64) * scale).astype(np.float32), g.faces, g.normals)
    b = get_kind(kind).build_random(rng, size="tiny", geometry=geometry)
    if fp16_extreme:
        core = b.components["core"][""]
        trng = np.random.default_rng(seed + 100)
        for name, (arr, dtype, layout) in list(core.tensors.items()):
            if dtype == "float16":
                core.add_tensor(name, _fp16_tensor(arr.shape, trng), dtype="float16", layout=layout)
    b.write(path)
    return Asset.open(path, load="all")


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    d = tmp_path_factory.mktemp("stress_assets")
    out = {}
    for kind in ("rna", "neupress", "8dna"):
        out[kind] = _write(kind, d / f"{kind}.usdc").evaluator()
        out[kind + "_fp16"] = _write(kind, d / f"{kind}_fp16.usdc", fp16_extreme=True).evaluator()
    return out


def _points(ev, k):
    """Domain-relative points: inside, on the domain corners/faces, 1e4 domains away, and non-finite."""
    lo, hi = np.asarray(ev.lo, np.float64), np.asarray(ev.hi, np.float64)
    c, h = 0.5 * (lo + hi), 0.5 * (hi - lo)
    return c + np.where(np.isfinite(k), k, 0.0) * h + np.where(np.isfinite(k), 0.0, k)


point_coeffs = rows(n_max=12, elements=st.one_of(st.sampled_from([0.0, 1.0, -1.0, 1e4, -1e4, 1e-4, np.nan, np.inf, -np.inf]),
                                                 st.floats(-1.5, 1.5)))


@SLOW
@given(k=point_coeffs, frame=edge_dir_rows(12), wo=edge_dir_rows(12), wi=edge_dir_rows(12), fp16=st.booleans())
def test_rna_evaluate(counts, assets, k, frame, wo, wi, fp16):
    ev = (assets["rna_fp16" if fp16 else "rna"])
    m = min(len(k), len(frame), len(wo), len(wi))
    x = _points(ev, k[:m])
    tu, ts = ev.evaluate(x, frame[:m], wo[:m], wi[:m])
    counts.add("rna.evaluate", m)
    assert finite_all(tu, ts) and (tu >= 0).all() and (ts >= 0).all()


@SLOW
@given(k=point_coeffs, n=edge_dir_rows(12), wo=edge_dir_rows(12), wi=edge_dir_rows(12), u=rows(12, 2, st.one_of(unit_interval, component)),
       fp16=st.booleans())
def test_neupress_evaluator(counts, assets, k, n, wo, wi, u, fp16):
    ev = (assets["neupress_fp16" if fp16 else "neupress"])
    m = min(len(k), len(n), len(wo), len(wi), len(u))
    x, n, wo, wi, u = _points(ev, k[:m]), n[:m], wo[:m], wi[:m], u[:m]
    s = ev.evaluate(x, n, wo, wi)
    r = ev.surface_reflection(n, wo, wi)
    sig = ev.sigma(x, wo)
    counts.add("neupress.evaluate", m)
    counts.add("neupress.surface_reflection", m)
    counts.add("neupress.sigma", m)
    assert finite_all(s, r, sig) and (s >= 0).all() and (r >= 0).all()
    assert ((sig >= NP.SIGMA_MIN) & (sig <= NP.SIGMA_MAX)).all()
    w, p = ev.sample_lobe(x, n, wo, u)
    counts.add("neupress.sample_lobe", m)
    assert finite_all(w, p) and (p > 0).all()
    np.testing.assert_allclose(ev.lobe_pdf(x, n, wo, w), p, rtol=1e-6)  # r / sin r near the antipode costs digits
    v = np.arange(m) % ev.prt_coefficients().shape[0]
    light = np.nan_to_num(np.resize(k.ravel(), 27).reshape(9, 3), nan=0.0, posinf=1e30, neginf=-1e30)
    rad = ev.prt_radiance(light, v, n, wo)
    counts.add("neupress.prt_radiance", m)
    assert np.isfinite(rad).all()


@SLOW
@given(k=point_coeffs, wo=edge_dir_rows(12), wi=edge_dir_rows(12), u=rows(12, 4, st.one_of(unit_interval, component)),
       fp16=st.booleans())
def test_8dna_evaluator(counts, assets, k, wo, wi, u, fp16):
    ev = (assets["8dna_fp16" if fp16 else "8dna"])
    m = min(len(k), len(wo), len(wi), len(u))
    x, wo, wi, u = _points(ev, k[:m]), wo[:m], wi[:m], u[:m]
    a = ev.albedo(x, wo)
    counts.add("8dna.albedo", m)
    assert np.isfinite(a).all() and (a >= 0).all()
    ch = np.arange(m) % 3
    ui, w, pdf = ev.sample(x, wo, ch, u=u)
    counts.add("8dna.sample", m)
    assert finite_all(ui, w, pdf) and (pdf >= 0).all()
    p2 = ev.pdf(x, wo, ui, w, ch)
    counts.add("8dna.pdf", m)
    assert np.isfinite(p2).all()
    # where the inputs are finite and the latents are off the poles / phi seam (see test_boxflow_sample_matches_pdf)
    # the flow's sample density equals pdf() at the sample
    ok = np.isfinite(x).all(1) & np.isfinite(wo).all(1) & ((u > 1e-6) & (u < 1 - 1e-6)).all(1)
    # (extreme random flows reach densities ~1e23; the spline log-det conditioning then costs ~4 digits)
    np.testing.assert_allclose(p2[ok], pdf[ok], rtol=1e-3)
    t = ev.transport(x, wo, ui, wi)
    counts.add("8dna.transport", m)
    assert np.isfinite(t).all() and (t >= 0).all()
    n = wi
    de = ev.direct_eval(n, wo, wi)
    dw, dp = ev.direct_sample(n, wo, u[:, :2])
    counts.add("8dna.direct_eval", m)
    counts.add("8dna.direct_sample", m)
    assert finite_all(de, dw, dp) and (de >= 0).all() and (dp >= 0).all()
    # u1 -> 1 puts h within 1e-8 of the tangent plane, where recovering h = normalize(wo + wi) cancels
    # catastrophically; elsewhere pdf() at the sample is the sample's pdf
    inner_h = np.clip(np.nan_to_num(u[:, 0]), 0, 1) < 1 - 1e-6
    np.testing.assert_allclose(ev.direct_pdf(n, wo, dw)[inner_h], dp[inner_h], rtol=1e-6)


@pytest.mark.parametrize("kind", ["rna", "neupress"])
def test_scene_scale_invariance(counts, tmp_path, kind):
    """The same networks on geometry scaled by 1e-4 and 1e4 (matching domains) give the same transport at scaled points."""
    rng = np.random.default_rng(11)
    n = 256
    k = np.concatenate([rng.uniform(-1, 1, (n - 8, 3)), np.array(EDGE_DIRS[:8])])  # domain-relative, corners included
    dirs = rng.normal(size=(3, n, 3))
    vals = {}
    for scale in (1e-4, 1.0, 1e4):
        ev = (_write(kind, tmp_path / f"{kind}_{scale:g}.usdc", seed=3, scale=scale).evaluator())
        x = _points(ev, k)
        vals[scale] = np.concatenate(ev.evaluate(x, dirs[0], dirs[1], dirs[2]), axis=1) if kind == "rna" else ev.evaluate(x, *dirs)
        counts.add(f"{kind}.evaluate", n)
        assert np.isfinite(vals[scale]).all()
    ref = vals[1.0]
    for scale in (1e-4, 1e4):
        np.testing.assert_allclose(vals[scale], ref, rtol=1e-3, atol=1e-3 * np.abs(ref).max())
