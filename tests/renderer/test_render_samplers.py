"""chi² tests for every direction sampler of the reference renderer, and sample pdf == pdf()."""

import numpy as np
import pytest

from nasset_reference_renderer import bsdf, lights, sampling
from tests.stats import SIGNIFICANCE, sphere_chi2

P_MIN = SIGNIFICANCE  # reject the sampler when the fit is this unlikely


def _report(name, p, dof):
    print(f"chi2 {name}: p={p:.3g} dof={dof}")


def test_cosine_hemisphere():
    p, dof, integral = sphere_chi2(sampling.square_to_cosine_hemisphere, sampling.cosine_hemisphere_pdf, pdf_total=1.0)
    _report("cosine", p, dof)
    assert p > P_MIN and abs(integral - 1) < 1e-2


def test_uniform_sphere_and_cone():
    p, dof, _ = sphere_chi2(sampling.square_to_uniform_sphere, sampling.uniform_sphere_pdf, pdf_total=1.0)
    assert p > P_MIN
    cm = np.cos(0.6)
    p, dof, integral = sphere_chi2(lambda u: sampling.square_to_uniform_cone(u, cm), lambda v: sampling.uniform_cone_pdf(v, cm),
                                   pdf_total=1.0)
    _report("cone", p, dof)
    assert p > P_MIN and abs(integral - 1) < 2e-2


@pytest.mark.parametrize("kappa", [0.3, 6.0, 60.0])
def test_von_mises_fisher(kappa):
    p, dof, integral = sphere_chi2(lambda u: sampling.square_to_vmf(u, kappa), lambda v: sampling.vmf_pdf(v[:, 2], kappa),
                                   n_theta=30, n_phi=40, pdf_total=1.0)
    _report(f"vmf kappa={kappa}", p, dof)
    assert p > P_MIN and abs(integral - 1) < 2e-2


@pytest.mark.parametrize("wo,t", [
    ((0.3, 0.5, 0.81), (0.0, 1.0, 0.0)),  # general
    ((0.0, 0.0, 1.0), (1.0, 0.0, 0.0)),  # wo perpendicular to the fiber: the band is the great circle
    ((0.0, 0.96, 0.28), (0.0, 1.0, 0.0)),  # grazing: the band is clipped at the pole
    ((0.0, 1.0, 0.0), (0.0, 1.0, 0.0)),  # wo along the fiber
    ((0.6, 0.0, 0.8), (0.0, 0.0, 0.0)),  # no tangent (degenerate segment): a fixed axis, still a density
])
def test_fiber_continuation_mixture(wo, t):
    from nasset_reference_renderer.shaders.rna_fiber import FiberContinuation

    wo = sampling.normalize(np.array([wo], float))
    fc = FiberContinuation(wo, np.array([t], float))
    pick = np.random.default_rng(7)

    def sample(u):
        u3 = np.concatenate([u, pick.random((len(u), 1))], 1)
        return fc.sample(np.zeros(len(u), np.int64), u3)

    p, dof, integral = sphere_chi2(sample, lambda v: fc.pdf(np.zeros(len(v), np.int64), v), n_theta=30, n_phi=40,
                                   pdf_total=1.0)
    _report(f"fiber continuation wo={wo[0]}", p, dof)
    assert p > P_MIN and abs(integral - 1) < 2e-2
    v = fc.sample(np.zeros(1000, np.int64), pick.random((1000, 3)))
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0) and (fc.pdf(np.zeros(1000, np.int64), v) >= 0.4 / (4 * np.pi)).all()


@pytest.mark.parametrize("wo,n", [
    ((0.3, 0.5, 0.81), (0.0, 0.0, 1.0)),  # general
    ((0.0, 0.6, -0.8), (0.0, 0.0, 1.0)),  # wo below the normal: the lobes flip to wo's side
    ((1.0, 0.0, 0.0), (0.0, 0.0, 1.0)),  # grazing: the mirror direction is wo's opposite along the surface
    ((0.0, 0.0, 1.0), (0.0, 0.0, 1.0)),  # head-on: the mirror lobe and the cosine lobe share the axis
    ((0.3, 0.5, 0.81), (0.0, 0.0, 0.0)),  # no normal: the lobes turn about wo, still a density
])
def test_surface_continuation_mixture(wo, n):
    from nasset_reference_renderer.shaders.rna_surface import SurfaceContinuation

    sc = SurfaceContinuation(sampling.normalize(np.array([wo], float)), np.array([n], float))
    pick = np.random.default_rng(8)
    rows = lambda k: np.zeros(k, np.int64)  # noqa: E731

    def sample(u):
        return sc.sample(rows(len(u)), np.concatenate([u, pick.random((len(u), 1))], 1))

    p, dof, integral = sphere_chi2(sample, lambda v: sc.pdf(rows(len(v)), v), n_theta=30, n_phi=40, pdf_total=1.0)
    _report(f"surface continuation wo={wo}", p, dof)
    assert p > P_MIN and abs(integral - 1) < 2e-2
    v = sc.sample(rows(1000), pick.random((1000, 3)))
    assert np.allclose(np.linalg.norm(v, axis=1), 1.0) and (sc.pdf(rows(1000), v) >= 0.4 / (4 * np.pi)).all()


def _check_reflection_lobe(label, theta, half_vectors, reflect_pdf):
    """Chi-squared of directions reflected about ``half_vectors(wo [n,3], u [n,2])`` at the view angle ``theta``
    (those below the surface dropped) against ``reflect_pdf(wo [n,3], wi [n,3])``."""
    wo = np.array([[np.sin(theta), 0.0, np.cos(theta)]])

    def sample(u):
        w = np.repeat(wo, len(u), 0)
        wi = bsdf.reflect(w, half_vectors(w, u))
        wi[wi[:, 2] <= 0] = np.nan
        return wi

    p, dof, _ = sphere_chi2(sample, lambda v: reflect_pdf(np.repeat(wo, len(v), 0), v), n_theta=30, n_phi=60, sub=8)
    _report(label, p, dof)
    assert p > P_MIN


@pytest.mark.parametrize("alpha,theta", [(0.3, 0.4), (0.7, 1.1), (0.15, 0.9)])
def test_ggx_visible_normals(alpha, theta):
    _check_reflection_lobe(f"ggx a={alpha}", theta, lambda w, u: bsdf.ggx_sample_vndf(w, np.full(len(u), alpha), u),
                           lambda w, v: bsdf.ggx_reflect_pdf(w, v, np.full(len(v), alpha)))


@pytest.mark.parametrize("alpha, wo_theta", [(0.3, 0.4), (0.6, 1.35), (0.08, 1.0)])
def test_beckmann_sampling_matches_pdf(alpha, wo_theta):
    """nasset:microfacet = beckmann: half vectors of density D cos_h, reflected, against beckmann_reflect_pdf."""
    _check_reflection_lobe(f"beckmann a={alpha}", wo_theta, lambda w, u: bsdf.beckmann_sample(np.full(len(u), alpha), u),
                           lambda w, v: bsdf.beckmann_reflect_pdf(w, v, np.full(len(v), alpha)))


@pytest.mark.parametrize("alpha", [0.05, 0.3, 0.9])
def test_beckmann_distribution_terms(alpha):
    """D is normalised (its projected area integrates to 1, quadrature over the hemisphere) and the rational Lambda
    is within 0.4 % of the exact (erf(a) - 1) / 2 + exp(-a^2) / (2 a sqrt(pi)) wherever G1 differs from 1 by 1e-3."""
    from math import erf

    n = 4000
    mu = (np.arange(n) + 0.5) / n  # cos theta_h, midpoint rule
    h = np.stack([np.sqrt(1 - mu * mu), np.zeros(n), mu], 1)
    assert abs(2 * np.pi * np.sum(bsdf.beckmann_d(h, np.full(n, alpha)) * mu) / n - 1) < 2e-3
    theta = np.linspace(0.05, 1.55, 200)
    w = np.stack([np.sin(theta), np.zeros_like(theta), np.cos(theta)], 1)
    a = np.cos(theta) / (alpha * np.sin(theta))
    exact = np.array([(erf(x) - 1) / 2 + np.exp(-x * x) / (2 * x * np.sqrt(np.pi)) for x in a])
    approx = bsdf.beckmann_lambda(w, np.full(len(theta), alpha))
    g_exact, g_approx = 1 / (1 + exact), 1 / (1 + approx)
    keep = g_exact < 0.999
    assert keep.any()
    np.testing.assert_allclose(g_approx[keep], g_exact[keep], rtol=4e-3)


def _material_table(kd, f0, alpha):
    return bsdf.MaterialTable(np.array([kd]), np.array([f0]), np.array([alpha]), np.zeros((1, 3)), ["m"])


def _check_mixture(mt, wo, rng, name):
    """bsdf_sample of material 0 seen from wo [1,3] against bsdf_eval's pdf (chi-squared), and the pdf and value a
    sample reports equal eval's at its direction; returns (wi [1000,3], f [1000,3]) of those samples."""
    def sample(u):
        n = len(u)
        wi, f, pdf = bsdf.bsdf_sample(mt, np.zeros(n, int), np.repeat(wo, n, 0), rng.random(n), u)
        wi[pdf <= 0] = np.nan
        return wi

    def pdf(v):
        return bsdf.bsdf_eval(mt, np.zeros(len(v), int), np.repeat(wo, len(v), 0), v)[1]

    p, dof, _ = sphere_chi2(sample, pdf, n_theta=30, n_phi=60)
    _report(name, p, dof)
    assert p > P_MIN
    n = 1000
    wi, f, pdf_s = bsdf.bsdf_sample(mt, np.zeros(n, int), np.repeat(wo, n, 0), rng.random(n), rng.random((n, 2)))
    f_e, pdf_e = bsdf.bsdf_eval(mt, np.zeros(n, int), np.repeat(wo, n, 0), wi)
    np.testing.assert_allclose(pdf_s, pdf_e, rtol=1e-9)
    np.testing.assert_allclose(f, f_e, rtol=1e-9)
    return wi, f_e


def test_beckmann_material_in_the_mixture():
    """A Beckmann material through bsdf_sample / bsdf_eval: chi-squared, the pdf a sample reports equals eval's,
    and its lobe differs from the GGX one of the same alpha (the flag is read)."""
    mt = _material_table([0.2, 0.2, 0.2], [0.6, 0.6, 0.6], 0.25)
    mt.beckmann = np.array([True])
    wo = np.array([[0.6, 0.1, np.sqrt(1 - 0.37)]])
    wi, f_e = _check_mixture(mt, wo, np.random.default_rng(3), "bsdf mixture beckmann")
    mt.beckmann = None
    f_ggx, _ = bsdf.bsdf_eval(mt, np.zeros(len(wi), int), np.repeat(wo, len(wi), 0), wi)
    assert np.abs(f_ggx - f_e).max() > 0.05 * np.abs(f_e).max()


def test_bsdf_mixture_sampling_and_pdf():
    mt = _material_table([0.5, 0.4, 0.3], [0.3, 0.3, 0.3], 0.2)
    _check_mixture(mt, np.array([[0.5, 0.2, np.sqrt(1 - 0.29)]]), np.random.default_rng(1), "bsdf mixture")


P0 = np.array([[0.3, -0.2, 0.1]])


def _light_chi2(light, name, **kw):
    def sample(u):
        wi, dist, li, pdf = light.sample(np.repeat(P0, len(u), 0), u)
        wi = wi.copy()
        wi[pdf <= 0] = np.nan
        return wi

    def pdf(v):
        return light.pdf(np.repeat(P0, len(v), 0), v)

    p, dof, integral = sphere_chi2(sample, pdf, pdf_total=1.0, **kw)  # a light sample never fails
    _report(name, p, dof)
    assert p > P_MIN
    assert abs(integral - 1) < 3e-2
    # the pdf a sample reports equals pdf() at that direction
    rng = np.random.default_rng(5)
    wi, _, _, pdf_s = light.sample(np.repeat(P0, 2000, 0), rng.random((2000, 2)))
    ok = pdf_s > 0
    np.testing.assert_allclose(pdf_s[ok], light.pdf(np.repeat(P0, ok.sum(), 0), wi[ok]), rtol=1e-6)


def test_sphere_light_sampling():
    _light_chi2(lights.SphereLight([1.5, 1.0, 2.0], 0.9, [1, 1, 1]), "sphere light", n_theta=40, n_phi=80)


def test_rect_light_sampling():
    _light_chi2(lights.RectLight([0.5, 1.2, 0.3], [0.0, 0.0, 1.5], [2.0, 0.0, 0.0], [1, 1, 1]), "rect light",
                n_theta=30, n_phi=60, sub=48, n=60_000)


def test_distant_light_cone_sampling():
    _light_chi2(lights.DistantLight([0.2, 1.0, 0.3], [1, 1, 1], 40.0), "distant cone", n_theta=30, n_phi=60, sub=48,
                n=60_000)


def test_dome_importance_sampling():
    rng = np.random.default_rng(3)
    h, w = 16, 32
    yy, xx = np.mgrid[0:h, 0:w]
    img = 0.05 + np.exp(-((yy - 5) ** 2 + (xx - 20) ** 2) / 8.0)[..., None] * np.array([4.0, 3.0, 2.0])
    img = img * rng.uniform(0.5, 1.5, (h, w, 1))
    rot = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # 90 degrees about Y
    dome = lights.DomeLight([1.0, 1.0, 1.0], img, rot)
    _light_chi2(dome, "dome", n_theta=32, n_phi=64, sub=12)
    # radiance returned with a sample equals the radiance seen along that direction
    wi, _, li, _ = dome.sample(np.repeat(P0, 500, 0), rng.random((500, 2)))
    np.testing.assert_allclose(li, dome.le_escaped(wi), rtol=1e-6)


@pytest.mark.parametrize("value", ["phong", "GGX", 3])
def test_an_unknown_microfacet_is_scene_invalid_in_both_numpy_renderers(tmp_path, value):
    """nasset:microfacet other than ggx / beckmann (spec/renderer.md#materials): SCENE_INVALID naming the attribute and
    the shader, in the reference renderer and in the second implementation."""
    from pxr import Sdf

    from nasset_reference_renderer.scene import load_scene
    from nasset_reference_renderer.testscenes import SceneBuilder
    from nasset_sdk.errors import SceneError

    b = SceneBuilder()
    b.camera((0, 1.0, 2.0), (0, 0, 0))
    b.distant("Sun", (0.3, 1.0, 0.2), 2.0)
    b.quad("Floor", (0, 0, 0), 2.0, diffuse=(0.5, 0.5, 0.5))
    shader = next(p for p in b.stage.Traverse() if p.GetName() == "PreviewSurface")
    kind = Sdf.ValueTypeNames.Int if isinstance(value, int) else Sdf.ValueTypeNames.Token
    shader.CreateAttribute("nasset:microfacet", kind, custom=True).Set(value)
    path = b.write(tmp_path / "s.usda")
    loaders = [load_scene]
    try:
        from nasset_mitsuba_renderer.usdscene import read_scene

        loaders.append(read_scene)
    except ImportError:  # the second implementation needs mitsuba
        pass
    for load in loaders:
        with pytest.raises(SceneError) as exc:
            load(str(path))
        assert exc.value.code == "SCENE_INVALID" and exc.value.attribute == "nasset:microfacet", load
        assert str(shader.GetPath()) in str(exc.value)
