"""Rational-quadratic splines and the bounding-box parameterisation (spec/kinds/8dna.md#spline, #bbox)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_sdk.errors import UsageError
from nasset_sdk.kinds.spline import S_PER_T, BoxFlow, BoxParam, RQSpline, surface_pdf
from tests.stats import midpoints


def _splines(rng, n=2000, k=8, scale=2.0):
    return RQSpline.from_raw(rng.normal(0, scale, (n, 3 * k + 1)))


def test_inverse_of_forward_is_identity(rng):
    spl = _splines(rng)
    z = rng.random(len(spl.xk))
    y, ld = spl.forward(z)
    z2, ld2 = spl.inverse(y)
    np.testing.assert_allclose(z2, z, atol=1e-9)
    np.testing.assert_allclose(ld2, -ld, atol=1e-7)
    y2, _ = spl.forward(spl.inverse(y)[0])
    np.testing.assert_allclose(y2, y, atol=1e-9)


def test_logdet_matches_finite_differences(rng):
    spl = _splines(rng, n=500)
    z = rng.uniform(0.01, 0.99, 500)
    # keep away from knots, where the derivative is continuous but the second derivative jumps
    near = np.abs(z[:, None] - spl.xk).min(1) < 1e-4
    z = np.where(near, z + 2e-4, z)
    h = 1e-6
    fd = (spl.forward(z + h)[0] - spl.forward(z - h)[0]) / (2 * h)
    _, ld = spl.forward(z)
    np.testing.assert_allclose(np.exp(ld), fd, rtol=1e-5)
    # the inverse's log-det is minus the forward's at the same point (test above), so it is covered too


def test_knots_edges_and_extreme_parameters_are_finite(rng):
    raw = rng.normal(0, 2, (6, 25))
    raw[1] = 1e4
    raw[2] = -1e4
    raw[3, :8] = np.linspace(-800, 800, 8)  # near-degenerate bins
    raw[4] = np.nan
    raw[5, 16:] = -50  # derivatives at the minimum
    spl = RQSpline.from_raw(raw)
    for k in range(spl.bins + 1):
        y, ld = spl.forward(spl.xk[:, k])
        np.testing.assert_allclose(y, spl.yk[:, k], atol=1e-12)
        assert np.isfinite(ld).all()
        z, ldi = spl.inverse(spl.yk[:, k])
        np.testing.assert_allclose(z, spl.xk[:, k], atol=1e-9)
        assert np.isfinite(ldi).all()
    for v in (0.0, 1.0, -3.0, 7.0, np.nan):
        for fn in (spl.forward, spl.inverse):
            out, ld = fn(np.full(6, v))
            assert np.isfinite(out).all() and np.isfinite(ld).all() and (out >= 0).all() and (out <= 1).all()


def test_monotone_and_onto(rng):
    spl = _splines(rng, n=50)
    z = np.linspace(0, 1, 2001)
    ys = np.stack([spl.forward(np.full(50, v))[0] for v in z], 1)
    assert (np.diff(ys, axis=1) >= 0).all()
    np.testing.assert_allclose(ys[:, 0], 0, atol=1e-15)
    np.testing.assert_allclose(ys[:, -1], 1, atol=1e-12)


def test_bad_parameters_raise():
    with pytest.raises(UsageError):
        RQSpline.from_raw(np.zeros((2, 24)))
    with pytest.raises(UsageError):
        RQSpline.from_raw(np.zeros((2, 25)), min_bin_width=0.2)  # 8 * 0.2 > 1


def _box_face_grid(box: BoxParam, m: int):
    """Midpoint nodes (object space) and areas on the six faces of the box."""
    pts, areas = [], []
    for ax in range(3):
        a, b = (ax + 1) % 3, (ax + 2) % 3
        ua = midpoints(-box.half[a], box.half[a], m)
        ub = midpoints(-box.half[b], box.half[b], m)
        A, B = np.meshgrid(ua, ub, indexing="ij")
        for sg in (-1, 1):
            p = np.zeros((m * m, 3))
            p[:, ax] = sg * box.half[ax]
            p[:, a] = A.ravel()
            p[:, b] = B.ravel()
            pts.append(p + box.center)
            areas.append(np.full(m * m, 4 * box.half[a] * box.half[b] / (m * m)))
    return np.concatenate(pts), np.concatenate(areas)


def test_box_jacobian_integrates_to_full_sphere():
    box = BoxParam([-0.3, -1.0, 0.1], [0.5, 0.2, 0.4])
    u, area = _box_face_grid(box, 200)
    _, jac = box.from_rays(u, np.tile([0, 0, 1.0], (len(u), 1)))
    np.testing.assert_allclose((jac * area).sum(), 4 * np.pi, rtol=1e-4)


def test_box_round_trip_and_poles(rng):
    box = BoxParam([-0.3, -1.0, 0.1], [0.5, 0.2, 0.4])
    s = box.s_from_t(rng.random((1000, 4)))
    u, w, jac = box.to_rays(s)
    rel = np.abs(u - box.center) / box.half
    np.testing.assert_allclose(rel.max(1), 1, atol=1e-12)  # on the box
    s2, jac2 = box.from_rays(u, w)
    np.testing.assert_allclose(s2, s, atol=1e-9)
    np.testing.assert_allclose(jac2, jac, rtol=1e-9)
    edge = box.s_from_t(np.array([[0, 0, 0, 0], [1, 1, 1, 1], [0.5, 0.5, 0.5, 0.5], [1, 0, 0, 1.0]]))
    u, w, jac = box.to_rays(edge)
    assert np.isfinite(u).all() and np.isfinite(w).all() and np.isfinite(jac).all() and (jac > 0).all()
    corners = box.center + box.half * np.array([[1, 1, 1], [-1, 1, -1], [1, 0, 1], [0, 0, 0.0]])
    s3, jac3 = box.from_rays(corners, np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, 0, 0.0]]))
    assert np.isfinite(s3).all() and np.isfinite(jac3).all()


def test_surface_pdf_guards_parallel_rays():
    out = surface_pdf(np.ones(3), np.array([[0, 0, 1.0]] * 3), np.array([[1, 0, 0.0]] * 3),
                      np.array([[0, 0, 1.0], [0, 1, 0.0], [0, 0, 0.0]]))
    assert np.isfinite(out).all()


def _linear_flow(rng, k=5):
    """A BoxFlow whose conditioner is a random linear map of (x, wo, s_prev) (no ONNX needed)."""
    mats = [rng.normal(0, 0.4, (6 + j - 1 + 1, 3 * (3 * k + 1))) for j in range(1, 5)]

    def cond(j, ctx, s_prev):
        x, wo = ctx
        feats = np.concatenate([x, wo, s_prev, np.ones((len(x), 1))], 1)
        return feats @ mats[j - 1]

    return BoxFlow(BoxParam([-0.5, -0.4, -0.6], [0.5, 0.4, 0.6]), cond)


def test_flow_sample_matches_pdf_and_integrates(rng):
    flow = _linear_flow(rng)
    n = 4000
    x = np.tile(rng.normal(0, 0.2, (1, 3)), (n, 1))
    wo = np.tile([[0.0, 0.6, 0.8]], (n, 1))
    for ch in range(3):
        ui, wi, pdf = flow.sample(x, wo, ch, rng)
        np.testing.assert_allclose(flow.pdf(x, wo, ui, wi, ch), pdf, rtol=1e-6)
        np.testing.assert_allclose(flow.pdf_position(x, wo, ui, ch) * flow.pdf_direction(x, wo, ui, wi, ch), pdf, rtol=1e-6)
    # importance-sampled estimate of the integral of the density itself, with uniform proposals
    box = flow.box
    m = 20000
    s = box.s_from_t(rng.random((m, 4)))
    ui, wi, jac = box.to_rays(s)
    xx, ww = np.tile(x[:1], (m, 1)), np.tile(wo[:1], (m, 1))
    p = flow.pdf(xx, ww, ui, wi, 1)
    est = p / jac * S_PER_T  # p(u, w) / q(u, w) with q = jac / S_PER_T
    assert abs(est.mean() - 1) < 5 * est.std() / np.sqrt(m)


def test_flow_rejects_bad_channel(rng):
    flow = _linear_flow(rng)
    with pytest.raises(UsageError):
        flow.sample(np.zeros((2, 3)), np.ones((2, 3)), 3, rng)
    with pytest.raises(UsageError):
        flow.pdf(np.zeros((2, 3)), np.ones((2, 3)), np.ones((2, 3)), np.ones((2, 3)), np.array([0.5, 1]))
    with pytest.raises(UsageError):
        flow.sample(np.zeros((2, 3)), np.ones((2, 3)), 0)


def test_float32_knots(rng):
    """dtype=float32 stores the knots in float32 (the bins' arithmetic stays float64): knots within float32 rounding
    of the float64 ones, still a bijection of [0, 1] with matching log-determinants; other dtypes are refused."""
    raw = rng.normal(0, 2, (3000, 3 * 8 + 1))
    s64, s32 = RQSpline.from_raw(raw), RQSpline.from_raw(raw, dtype=np.float32)
    assert s32.xk.dtype == np.float32 and s64.xk.dtype == np.float64
    np.testing.assert_allclose(s32.xk, s64.xk, atol=1e-6)
    np.testing.assert_allclose(s32.yk, s64.yk, atol=1e-6)
    z = rng.random(3000)
    y, ld = s32.forward(z)
    z2, ld2 = s32.inverse(y)
    np.testing.assert_allclose(z2, z, atol=1e-9)
    np.testing.assert_allclose(ld2, -ld, atol=1e-7)
    assert np.median(np.abs(ld - s64.forward(z)[1])) < 1e-5
    with pytest.raises(UsageError, match="dtype"):
        RQSpline.from_raw(raw, dtype=np.float16)


def test_from_raw_leaves_its_input_alone(rng):
    """The knots are built in place in a bin-major copy: never in the caller's array, whatever its layout (one row,
    Fortran order, float32)."""
    for raw in (rng.normal(0, 2, (1, 25)), np.asfortranarray(rng.normal(0, 2, (7, 25))), rng.normal(0, 2, (5, 25)).astype(np.float32)):
        keep = raw.copy()
        a = RQSpline.from_raw(raw)
        b = RQSpline.from_raw(raw)
        np.testing.assert_array_equal(raw, keep)
        np.testing.assert_array_equal(a.xk, b.xk)


def test_clamps_equal_nan_to_num_then_clip():
    """The spline's clamp of latents / values (clamp01) and cylindrical_to_direction's inputs equal numpy's
    nan_to_num followed by clip, bit for bit, on NaN, +-inf, signed zeros, the ends and values outside."""
    from nasset_sdk.kinds.spline import clamp01, cylindrical_to_direction

    v = np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 1.0, np.nextafter(1.0, 2.0), -1e-300, 0.3, 7.0, -2.0, 1e308])
    np.testing.assert_array_equal(clamp01(v), np.clip(np.nan_to_num(v, nan=0.0), 0.0, 1.0))
    phi = v[::-1].copy()
    z = np.clip(np.nan_to_num(v), -1.0, 1.0)
    with np.errstate(invalid="ignore"):
        p = np.nan_to_num(phi)
        r = np.sqrt(np.maximum(1.0 - z * z, 0.0))
        want = np.stack([r * np.cos(p), r * np.sin(p), z], axis=-1)
    with np.errstate(invalid="ignore"):
        np.testing.assert_array_equal(cylindrical_to_direction(v, phi), want)
        finite = np.isfinite(v) & np.isfinite(phi)  # the one-pass branch: all inputs finite
        np.testing.assert_array_equal(cylindrical_to_direction(v[finite], phi[finite]), want[finite])
