"""Transmission (spec/renderer.md#transmission): the glass lobe of a MaterialX surface with ``transmission`` > 0.

The lobe's sampling density is its pdf (checked by integrating the pdf over the sphere against the share of valid
samples), smooth glass keeps the analytic Fresnel energy, and a glass pane or ball inside a uniform dome shows the
dome (a white furnace: nothing absorbs, so every path ends in the dome's radiance). Before, transmission was dropped
with a warning and the glass rendered as an opaque reflector."""

from __future__ import annotations

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdShade

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.bsdf import glass_eval, glass_sample
from nasset_reference_renderer.testscenes import SceneBuilder

CASES = [(1.5, False, 0.3, 0.6), (1 / 1.5, False, 0.3, 0.6), (1 / 1.5, False, 0.3, 1.2), (1.5, True, 0.5, 1.0)]


def _lobe(n, eta, thin, alpha, theta):
    wo = np.tile([np.sin(theta), 0.0, np.cos(theta)], (n, 1))
    return wo, np.full(n, eta), np.full(n, thin), np.full(n, alpha), np.ones((n, 3))


def _uniform_sphere(rng, n):
    """n directions [n, 3] uniform over the sphere (density 1 / 4 pi)."""
    z = rng.uniform(-1.0, 1.0, n)
    phi = rng.uniform(0.0, 2.0 * np.pi, n)
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], 1)


@pytest.mark.parametrize("eta, thin, alpha, theta", CASES)
def test_the_pdf_integrates_to_the_share_of_valid_samples(eta, thin, alpha, theta):
    rng = np.random.default_rng(3)
    n = 400_000
    wo, e, t, a, tint = _lobe(n, eta, thin, alpha, theta)
    _, valid = glass_sample(wo, a, e, t, rng.random(n), rng.random((n, 2)))
    _, pdf = glass_eval(wo, _uniform_sphere(rng, n), a, e, t, tint)
    integral = 4.0 * np.pi * pdf.mean()
    se = 4.0 * np.pi * pdf.std() / np.sqrt(n)
    assert abs(integral - valid.mean()) < 5 * se + 2e-3, (integral, se, valid.mean())


@pytest.mark.parametrize("eta, thin, alpha, theta", CASES)
def test_sampled_weights_match_the_lobe_integrated_uniformly(eta, thin, alpha, theta):
    """E[f |cos| / pdf] over the lobe's samples equals the integral of f |cos| over the sphere."""
    rng = np.random.default_rng(4)
    n = 400_000
    wo, e, t, a, tint = _lobe(n, eta, thin, alpha, theta)
    wi, valid = glass_sample(wo, a, e, t, rng.random(n), rng.random((n, 2)))
    f, pdf = glass_eval(wo, wi, a, e, t, tint)
    w = np.where(valid & (pdf > 0), f[:, 0] * np.abs(wi[:, 2]) / np.maximum(pdf, 1e-300), 0.0)
    uniform = _uniform_sphere(rng, n)
    fu, _ = glass_eval(wo, uniform, a, e, t, tint)
    u = 4.0 * np.pi * fu[:, 0] * np.abs(uniform[:, 2])
    se = np.hypot(w.std(), u.std()) / np.sqrt(n)
    assert np.isfinite(w).all() and abs(w.mean() - u.mean()) < 5 * se, (w.mean(), u.mean(), se)


@pytest.mark.parametrize("eta, thin, expect", [
    (1.5, False, 0.04 + 0.96 / 1.5 ** 2),  # entering: R + T / eta^2 (radiance)
    (1 / 1.5, False, 0.04 + 0.96 * 1.5 ** 2),  # leaving
    (1.5, True, 1.0)])  # a thin wall passes what it does not reflect
def test_smooth_glass_at_normal_incidence_has_the_fresnel_energy(eta, thin, expect):
    rng = np.random.default_rng(5)
    n = 100_000
    wo, e, t, a, tint = _lobe(n, eta, thin, 1e-3, 0.0)
    wi, valid = glass_sample(wo, a, e, t, rng.random(n), rng.random((n, 2)))
    f, pdf = glass_eval(wo, wi, a, e, t, tint)
    w = np.where(valid, f[:, 0] * np.abs(wi[:, 2]) / np.maximum(pdf, 1e-300), 0.0)
    assert w.mean() == pytest.approx(expect, rel=2e-3)


def _glass_material(stage, path, *, thin, roughness=0.0, ior=1.5, color=(1.0, 1.0, 1.0), universal=False):
    mat = UsdShade.Material.Define(stage, path)
    sh = UsdShade.Shader.Define(stage, f"{path}/Surface")
    sh.CreateIdAttr("ND_standard_surface_surfaceshader")
    sh.CreateInput("base", Sdf.ValueTypeNames.Float).Set(0.0)
    sh.CreateInput("transmission", Sdf.ValueTypeNames.Float).Set(1.0)
    sh.CreateInput("transmission_color", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    sh.CreateInput("specular_IOR", Sdf.ValueTypeNames.Float).Set(ior)
    sh.CreateInput("specular_roughness", Sdf.ValueTypeNames.Float).Set(roughness)
    sh.CreateInput("thin_walled", Sdf.ValueTypeNames.Bool).Set(thin)
    mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")
    if universal:  # an opaque black UsdPreviewSurface beside it, as convert-scene writes it
        ps = UsdShade.Shader.Define(stage, f"{path}/Preview")
        ps.CreateIdAttr("UsdPreviewSurface")
        ps.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.0, 0.0, 0.0))
        mat.CreateSurfaceOutput().ConnectToSource(ps.ConnectableAPI(), "surface")
    return mat


@pytest.mark.parametrize("shape, thin, roughness", [("pane", True, 0.0), ("ball", False, 0.0), ("ball", False, 0.3)])
def test_glass_in_a_uniform_dome_shows_the_dome(tmp_path, shape, thin, roughness):
    """White furnace: a smooth pane or ball (and a rough ball, which loses only GGX's single-scattering energy, a few
    per cent) in a dome of radiance 1 renders 1 wherever the camera looks; an opaque black reflector (the glass before
    transmission was read) renders its Fresnel reflection, about 0.1 in the middle."""
    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0), focal=50)
    prim = b.quad("Pane", (0, 0, 0), 1.5, normal=(0, 0, 1)) if shape == "pane" else \
        b.sphere_mesh("Ball", (0, 0, 0), 0.8, subdivisions=4)
    mat = _glass_material(b.stage, "/World/Looks/Glass", thin=thin, roughness=roughness, universal=True)
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(mat)
    b.dome("Sky", 1.0)
    path = b.write(tmp_path / "furnace.usda")
    img = render(load_scene(path), RenderSettings(spp=64, width=16, height=16, max_depth=24, seed=2)).image
    centre = img[5:11, 5:11].mean()
    assert np.isfinite(img).all()
    assert centre == pytest.approx(1.0, abs=0.06 if roughness else 0.02), centre


def test_a_thin_pane_tints_what_it_lets_through(tmp_path):
    """A thin pane of transmission colour c over a white dome: the light through it is (1 - R) c, its reflection R."""
    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0), focal=50)
    prim = b.quad("Pane", (0, 0, 0), 1.5, normal=(0, 0, 1))
    c = (0.2, 0.6, 1.0)
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(_glass_material(b.stage, "/World/Looks/G", thin=True, color=c))
    b.dome("Sky", 1.0)
    img = render(load_scene(b.write(tmp_path / "tint.usda")), RenderSettings(spp=32, width=16, height=16,
                                                                           max_depth=8, seed=3)).image
    f = 0.04  # normal incidence, eta 1.5: the slab reflects 2 F / (1 + F)
    r = 2 * f / (1 + f)
    np.testing.assert_allclose(img[6:10, 6:10].mean((0, 1)), r + (1 - r) * np.asarray(c), atol=0.02)


@pytest.mark.parametrize("shape, thin, roughness", [("pane", True, 0.0), ("ball", False, 0.0), ("ball", False, 0.3)])
def test_the_second_implementation_shows_the_dome_through_glass(tmp_path, shape, thin, roughness):
    """The second implementation (nasset_mitsuba_renderer: its own numpy glass, h sampled by D(h) (n.h), its own
    Fresnel) passes the same white furnace."""
    from nasset_mitsuba_renderer.render import render as second

    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0), focal=50)
    prim = b.quad("Pane", (0, 0, 0), 1.5, normal=(0, 0, 1)) if shape == "pane" else \
        b.sphere_mesh("Ball", (0, 0, 0), 0.8, subdivisions=4)
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(
        _glass_material(b.stage, "/World/Looks/Glass", thin=thin, roughness=roughness))
    b.dome("Sky", 1.0)
    img = np.asarray(second(str(b.write(tmp_path / "furnace.usda")), 64, width=16, height=16, seed=2, max_depth=24))
    assert np.isfinite(img).all()
    assert img[5:11, 5:11].mean() == pytest.approx(1.0, abs=0.06 if roughness else 0.02)


@pytest.mark.parametrize("outside, thin, t", [(True, False, 1.0), (False, False, 1.0), (True, True, 1.0),
                                              (True, False, 0.5)])
def test_the_second_implementations_glass_samples_by_its_pdf(outside, thin, t):
    """chi-squared: the second implementation's BSDF sampler (opaque lobes and glass, u_lobe split) against its pdf; the
    half-glass with a Beckmann opaque lobe beside its GGX glass lobe (spec/renderer.md#materials)."""
    from nasset_mitsuba_renderer.integrator import PathTracer
    from tests.stats import SIGNIFICANCE, sphere_chi2

    pt = PathTracer.__new__(PathTracer)  # the BSDF methods read no tracer state

    def mat(n):
        eta = 1.5 if outside or thin else 1 / 1.5
        return {"kd": np.tile([0.5, 0.3, 0.2], (n, 1)), "f0": np.full((n, 3), 0.04), "alpha": np.full(n, 0.35),
                "ps": np.full(n, 0.5), "spec": np.ones(n, bool), "t": np.full(n, t), "tint": np.ones((n, 3)),
                "reflect": np.ones((n, 3)), "thin": np.full(n, thin), "eta": np.full(n, eta),
                "beckmann": np.full(n, t < 1.0)}  # a half-glass: its opaque lobe Beckmann's, its glass lobe GGX's

    def frame(n):
        return np.tile([0.0, 0.0, 1.0], (n, 1)), np.tile([0.6, 0.0, 0.8], (n, 1))

    def sample(u):
        n, wo = frame(len(u))
        wi, _, pdf = pt.bsdf_sample(mat(len(u)), n, wo, u, np.random.default_rng(8).random(len(u)))
        return np.where((pdf > 0)[:, None], wi, np.nan)

    def pdf(v):
        n, wo = frame(len(v))
        return pt.bsdf_eval(mat(len(v)), n, wo, v)[1]

    p, dof, integral = sphere_chi2(sample, pdf)
    assert p > SIGNIFICANCE, (p, dof, integral)


def test_mtlx_output_is_read_before_the_universal_one():
    """A material with both outputs is read through MaterialX's (the render context a MaterialX renderer asks for), and
    through the universal one when the MaterialX shader is not one the renderers read."""
    from nasset_sdk import stage_rules

    b = SceneBuilder()
    mat = _glass_material(b.stage, "/World/Looks/Glass", thin=False, universal=True)
    assert stage_rules.surface_shader(mat).GetPath() == Sdf.Path("/World/Looks/Glass/Surface")
    UsdShade.Shader(b.stage.GetPrimAtPath("/World/Looks/Glass/Surface")).SetShaderId("ND_gltf_pbr_surfaceshader")
    assert stage_rules.surface_shader(mat).GetPath() == Sdf.Path("/World/Looks/Glass/Preview")


@pytest.mark.parametrize("roughness, continues", [(0.0, True), (0.25, True), (0.6, False)])
def test_a_lone_mirror_floor_keeps_its_continuation_and_shows_the_dome(tmp_path, roughness, continues):
    """The plan gives a lone planar mesh NEE only, unless its lobe is sharp (alpha < SHARP_ALPHA) or it transmits:
    light samples almost never fall in a mirror's lobe, so NEE alone showed next to nothing of the dome a lone mirror
    floor reflects (unbiased, but nearly every sample 0). A metal mirror under a dome of radiance 1 reflects about 1."""
    from nasset_reference_renderer.plan import make_plan

    b = SceneBuilder()
    b.camera((0, 2, 2), (0, 0, 0), focal=50)
    b.quad("Mirror", (0, 0, 0), 8.0, diffuse=(1.0, 1.0, 1.0), metallic=1.0, roughness=roughness)
    b.dome("Sky", 1.0)
    scene = load_scene(b.write(tmp_path / "mirror.usda"))
    plan = make_plan(scene, width=8, height=8, spp=1, max_depth=4, tile=64, batch=65536)
    assert bool(plan.instance_indirect[0]) == continues
    if roughness == 0.0:
        img = render(scene, RenderSettings(spp=16, width=8, height=8, max_depth=4, seed=1)).image
        assert img.mean() == pytest.approx(1.0, abs=0.03) and img.std() < 0.05, (img.mean(), img.std())


@pytest.mark.parametrize("eta, thin, alpha, theta", [(1.5, False, 0.3, 0.5), (1 / 1.5, False, 0.4, 0.9),
                                                     (1.5, True, 0.5, 1.0), (1.33, False, 0.6, 1.3)])
def test_glass_sampling_matches_its_pdf(eta, thin, alpha, theta):
    """chi-squared over the sphere: the lobe's samples (reflected or transmitted; invalid ones are failed samples)
    against its pdf."""
    from tests.stats import SIGNIFICANCE, sphere_chi2

    def sample(u):
        n = len(u)
        wo, e, t, a, _ = _lobe(n, eta, thin, alpha, theta)
        wi, valid = glass_sample(wo, a, e, t, np.random.default_rng(11).random(n), u)
        return np.where(valid[:, None], wi, np.nan)

    def pdf(v):
        wo, e, t, a, tint = _lobe(len(v), eta, thin, alpha, theta)
        return glass_eval(wo, v, a, e, t, tint)[1]

    p, dof, integral = sphere_chi2(sample, pdf)
    assert p > SIGNIFICANCE, (p, dof, integral)


@pytest.mark.parametrize("outside", [True, False])
def test_a_half_glass_material_samples_by_its_pdf(outside):
    """t = 0.5: the opaque UsdPreviewSurface lobes and the glass lobe drawn by one u_lobe (bsdf_sample) against the
    mixture's pdf (bsdf_eval), chi-squared; an opaque sample below the surface is a failed sample."""
    from nasset_reference_renderer.bsdf import MaterialTable, bsdf_eval, bsdf_sample
    from tests.stats import SIGNIFICANCE, sphere_chi2

    mt = MaterialTable(np.array([[0.5, 0.3, 0.2]]), np.array([[0.04] * 3]), np.array([0.2]), np.zeros((1, 3)), ["m"],
                       transmission=np.array([0.5]), transmission_color=np.array([[0.9, 0.8, 0.7]]),
                       eta=np.array([1.5]), thin=np.array([False]), reflection_color=np.ones((1, 3)))

    def rows(n):
        wo = np.tile([0.6, 0.0, 0.8], (n, 1))
        return np.zeros(n, np.int64), wo, mt.glass(np.zeros(n, np.int64), np.full(n, outside))

    def sample(u):
        m, wo, glass = rows(len(u))
        wi, f, pdf = bsdf_sample(mt, m, wo, np.random.default_rng(9).random(len(u)), u, glass=glass)
        return np.where((pdf > 0)[:, None], wi, np.nan)

    def pdf(v):
        m, wo, glass = rows(len(v))
        return bsdf_eval(mt, m, wo, v, glass=glass)[1]

    p, dof, integral = sphere_chi2(sample, pdf)
    assert p > SIGNIFICANCE, (p, dof, integral)


@pytest.mark.parametrize("ior", [1.0, 1e-6, 1e6])
def test_extreme_and_index_matched_iors_stay_finite_and_keep_the_dome(tmp_path, ior):
    """A rough ball of IOR 1 (index-matched: read as a thin wall, since refraction at IOR 1 sends every microfacet's
    light straight on, which no GGX density holds; it read 0.42 of the dome before), and of IORs far from any glass
    (total internal reflection nearly everywhere), in a dome of radiance 1: finite, and about 1 (GGX's
    single-scattering loss at alpha 0.09 aside)."""
    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0), focal=50)
    prim = b.sphere_mesh("Ball", (0, 0, 0), 0.8, subdivisions=3)
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(
        _glass_material(b.stage, "/World/Looks/G", thin=False, ior=ior, roughness=0.3))
    b.dome("Sky", 1.0)
    img = render(load_scene(b.write(tmp_path / "ior.usda")), RenderSettings(spp=16, width=8, height=8, max_depth=8,
                                                                          seed=3)).image
    assert np.isfinite(img).all()
    assert 0.9 < img[2:6, 2:6].mean() < 1.05, img[2:6, 2:6].mean()
