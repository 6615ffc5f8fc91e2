"""The plugin's ``nasset_preview`` BSDF (UsdPreviewSurface of spec/renderer.md#materials in Dr.Jit):
its sampler against its pdf (chi-squared), and its value against the formula evaluated in numpy."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import preview  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from tests.stats import SIGNIFICANCE, sphere_chi2  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    preview.register(mi)
    return mi


def _bsdf_and_si(mi, alpha, wi, n, beckmann=False):
    import drjit as dr

    b = mi.load_dict({"type": preview.NAME, "alpha": alpha, "kd": mi.ScalarColor3f(0.5, 0.3, 0.2), "f0": mi.ScalarColor3f(0.04),
                      "beckmann": beckmann})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*(np.asarray(wi, np.float64) / np.linalg.norm(wi)).tolist())
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)  # the geometric normal (a flat hit): directions below it count for nothing
    return b, si


@pytest.mark.parametrize("alpha,wi,beckmann", [(0.05, (0.3, 0.2, 0.93), False), (0.3, (0.9, 0.0, 0.2), False),
                                               (1.0, (0.2, 0.1, -0.9), False), (0.08, (0.3, 0.2, 0.93), True),
                                               (0.4, (0.9, 0.0, 0.2), True)])
def test_sampling_matches_pdf(mi, alpha, wi, beckmann):
    """Lobe choice from u0 (split and rescaled, so the 2D sampler is exact for the mixture); samples with
    zero weight (below the horizon) are failed samples."""
    import drjit as dr

    def sample(u):
        n = len(u)
        b, si = _bsdf_and_si(mi, alpha, wi, n, beckmann)
        spec = u[:, 0] < preview.P_SPECULAR
        u0 = np.where(spec, u[:, 0] / preview.P_SPECULAR, (u[:, 0] - preview.P_SPECULAR) / (1 - preview.P_SPECULAR))
        lobe = np.where(spec, 0.25, 0.75).astype(np.float32)
        bs, w = b.sample(mi.BSDFContext(), si, mi.Float(lobe), mi.Point2f(mi.Float(u0.astype(np.float32)), mi.Float(u[:, 1].astype(np.float32))))
        v = np.asarray(bs.wo.numpy(), np.float64).reshape(3, -1).T.copy()
        v[~np.asarray(dr.any(w != 0).numpy(), bool)] = np.nan
        return v

    def pdf(v):
        b, si = _bsdf_and_si(mi, alpha, wi, len(v), beckmann)
        return np.asarray(b.pdf(mi.BSDFContext(), si, mi.Vector3f(*[mi.Float(v[:, k].astype(np.float32)) for k in range(3)])).numpy(),
                          np.float64)

    p, dof, integral = sphere_chi2(sample, pdf)
    assert p > SIGNIFICANCE, (p, dof, integral)


def test_value_is_the_spec_formula(mi, rng):
    """f cos_o = (kd / pi + D G2 F / (4 cos_i cos_o)) cos_o with GGX D, height-correlated G2, Schlick F;
    the back side is shaded like the front (double-sided)."""
    alpha, kd, f0 = 0.3, np.array([0.5, 0.3, 0.2]), 0.04
    n = 2000
    wi = rng.normal(size=(n, 3))
    wo = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    wo[:, 2] = np.abs(wo[:, 2]) * np.sign(wi[:, 2])  # same side
    b, si = _bsdf_and_si(mi, alpha, (0, 0, 1), n)
    si.wi = mi.Vector3f(*[mi.Float(wi[:, k].astype(np.float32)) for k in range(3)])
    got = np.asarray(b.eval(mi.BSDFContext(), si, mi.Vector3f(*[mi.Float(wo[:, k].astype(np.float32)) for k in range(3)])).numpy()).reshape(3, -1).T
    s = np.sign(wi[:, 2:3])
    a, o = wi * [1, 1, 1] * np.hstack([np.ones((n, 2)), s]), wo * np.hstack([np.ones((n, 2)), s])
    h = (a + o) / np.linalg.norm(a + o, axis=1, keepdims=True)
    d = alpha**2 / (np.pi * (h[:, 2] ** 2 * (alpha**2 - 1) + 1) ** 2)

    def lam(w):
        t2 = (1 - w[:, 2] ** 2) / w[:, 2] ** 2
        return 0.5 * (np.sqrt(1 + alpha**2 * t2) - 1)

    g2 = 1 / (1 + lam(a) + lam(o))
    f = f0 + (1 - f0) * (1 - (a * h).sum(1)) ** 5
    want = (kd[None] / np.pi + (d * g2 * f / (4 * a[:, 2] * o[:, 2]))[:, None]) * o[:, 2:3]
    np.testing.assert_allclose(got, want, rtol=2e-4, atol=1e-6)


@pytest.mark.parametrize("alpha", [0.1, 0.45])
def test_beckmann_value_is_the_reference_renderers(mi, rng, alpha):
    """nasset:microfacet = beckmann: the plugin's f cos_o against the reference renderer's numpy lobe (an independent
    implementation of the same formula), and unlike the GGX lobe of the same alpha."""
    from nasset_reference_renderer import bsdf as ref

    n = 3000
    wi = rng.normal(size=(n, 3))
    wo = rng.normal(size=(n, 3))
    wi[:, 2], wo[:, 2] = np.abs(wi[:, 2]) + 0.05, np.abs(wo[:, 2]) + 0.05
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    got = {}
    for beckmann in (True, False):
        b, si = _bsdf_and_si(mi, alpha, (0, 0, 1), n, beckmann)
        si.wi = mi.Vector3f(*[mi.Float(wi[:, k].astype(np.float32)) for k in range(3)])
        got[beckmann] = np.asarray(b.eval(mi.BSDFContext(), si, mi.Vector3f(*[mi.Float(wo[:, k].astype(np.float32))
                                                                               for k in range(3)])).numpy()).reshape(3, -1).T
    table = ref.MaterialTable(np.array([[0.5, 0.3, 0.2]]), np.full((1, 3), 0.04), np.array([alpha]), np.zeros((1, 3)), ["m"],
                              beckmann=np.array([True]))
    f, _ = ref.bsdf_eval(table, np.zeros(n, int), wi, wo)
    want = f * wo[:, 2:3]
    np.testing.assert_allclose(got[True], want, rtol=2e-3, atol=2e-5)
    assert np.abs(got[False] - want).max() > 0.05 * np.abs(want).max()


def _glass_bsdf_and_si(mi, glass, thin, wi, n, alpha=0.3, ior=1.5):
    import drjit as dr

    b = mi.load_dict({"type": preview.NAME, "alpha": alpha, "kd": mi.ScalarColor3f(0.5, 0.3, 0.2),
                      "f0": mi.ScalarColor3f(0.04), "glass": glass, "glass_ior": ior, "glass_thin": thin,
                      "glass_tint": mi.ScalarColor3f(0.9, 0.7, 0.5), "glass_reflect": mi.ScalarColor3f(0.8, 1.0, 0.6)})
    si = dr.zeros(mi.SurfaceInteraction3f, n)
    si.wi = mi.Vector3f(*(np.asarray(wi, np.float64) / np.linalg.norm(wi)).tolist())
    si.sh_frame = mi.Frame3f(mi.Vector3f(0, 0, 1))
    si.n = mi.Normal3f(0, 0, 1)
    return b, si


@pytest.mark.parametrize("glass, thin, wi", [(1.0, False, (0.3, 0.2, 0.93)), (1.0, False, (0.6, 0.0, -0.5)),
                                             (1.0, True, (0.8, 0.1, 0.5)), (0.5, False, (0.2, -0.3, 0.8))])
def test_glass_sampling_matches_pdf(mi, glass, thin, wi):
    """spec/renderer.md#transmission: with a glass weight the sampler draws reflections and transmissions (the viewer
    inside a solid glass too: eta inverted) by the pdf eval_pdf gives (chi-squared; zero-weight samples failed)."""
    import drjit as dr

    def sample(u):
        n = len(u)
        b, si = _glass_bsdf_and_si(mi, glass, thin, wi, n)
        u1 = np.random.default_rng(5).random(n).astype(np.float32)
        bs, w = b.sample(mi.BSDFContext(), si, mi.Float(u1), mi.Point2f(mi.Float(u[:, 0].astype(np.float32)),
                                                                          mi.Float(u[:, 1].astype(np.float32))))
        v = np.asarray(bs.wo.numpy(), np.float64).reshape(3, -1).T.copy()
        v[~np.asarray(dr.any(w != 0).numpy(), bool)] = np.nan
        return v

    def pdf(v):
        b, si = _glass_bsdf_and_si(mi, glass, thin, wi, len(v))
        return np.asarray(b.pdf(mi.BSDFContext(), si, mi.Vector3f(*[mi.Float(v[:, k].astype(np.float32)) for k in range(3)])).numpy(),
                          np.float64)

    p, dof, integral = sphere_chi2(sample, pdf)
    assert p > SIGNIFICANCE, (p, dof, integral)


@pytest.mark.parametrize("thin", [False, True])
def test_glass_value_is_the_reference_renderers(mi, rng, thin):
    """The plugin's glass lobe (weight 1) equals the reference renderer's (nasset_reference_renderer.bsdf.glass_eval,
    written separately in numpy) times |cos|, the viewer outside and inside, the light on either side."""
    from nasset_reference_renderer.bsdf import glass_eval

    n = 4000
    wi = rng.normal(size=(n, 3))
    wo = rng.normal(size=(n, 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    b, si = _glass_bsdf_and_si(mi, 1.0, thin, (0, 0, 1), n)
    si.wi = mi.Vector3f(*[mi.Float(wi[:, k].astype(np.float32)) for k in range(3)])
    got = np.asarray(b.eval(mi.BSDFContext(), si, mi.Vector3f(*[mi.Float(wo[:, k].astype(np.float32)) for k in range(3)])).numpy()).reshape(3, -1).T
    s = np.sign(wi[:, 2:3])  # the frame is flipped toward the viewer; eta inverted from the back
    a, o = wi * np.hstack([np.ones((n, 2)), s]), wo * np.hstack([np.ones((n, 2)), s])
    eta = np.where((s[:, 0] > 0) | thin, 1.5, 1 / 1.5)
    f, _ = glass_eval(a, o, np.full(n, 0.3), eta, np.full(n, thin), np.tile([0.9, 0.7, 0.5], (n, 1)),
                      np.tile([0.8, 1.0, 0.6], (n, 1)))
    want = f * np.abs(o[:, 2:3])
    np.testing.assert_allclose(got, want, rtol=2e-3, atol=1e-5)


def test_glass_conformance_case(tmp_path):
    """``rna_behind_glass`` (spec/renderer.md#transmission) passes through the plugin at the case's own spp."""
    from tests.mitsuba_plugin.test_plugin import _run_case

    row = _run_case("rna_behind_glass", tmp_path)
    assert row["passed"], row
