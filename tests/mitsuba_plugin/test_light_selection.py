"""The plugin's choice of an emitter per light sample (mitsuba_plugin/lights.py: light_power, selection_weights): half by
power, half uniform over the emitters. Mitsuba picked uniformly, so in a scene with one light that matters and several
that hardly do most light samples were wasted (docs/bench-mitsuba-jit.md#light-selection)."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

pytest.importorskip("mitsuba")

import nasset_mitsuba_plugin.lights as lights_jit  # noqa: E402
from nasset_mitsuba_plugin.render import render  # noqa: E402
from nasset_mitsuba_renderer.lights import build_lights  # noqa: E402
from nasset_mitsuba_renderer.usdscene import read_scene  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402
from tests.stage_scenes import asset_among_many_lights, cone_lights_scene, glossy_floor_many_lights  # noqa: E402


def _scene(tmp_path):
    """A floor lit by a rect light, and three faint point lights (a thousandth of its power) off to the side."""
    b = SceneBuilder()
    b.camera((0, 3, 3), (0, 0, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.6, 0.6, 0.6))
    b.rect_light("Panel", (0, 2, 0), 1.0, 1.0, (0, -1, 0), 4.0)
    for i in range(3):
        b.sphere_light(f"Faint{i}", (-2.0 + 2.0 * i, 1.5, -2.0), 0.0, 0.001)
    return b.write(tmp_path / "lights.usda")


def test_light_power_formulas(tmp_path):
    """Each light's power from its description, against closed forms: a rect light pi L A (here L = 4, A = 1), a point
    light 4 pi I; a sun E pi r^2 and a dome 4 pi^2 r^2 L for a scene of bounding radius r."""
    from nasset_mitsuba_plugin.variant import jit_mitsuba

    jit_mitsuba()  # the light surfaces' Mitsuba transforms need a variant
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        desc = read_scene(_scene(tmp_path))
    lights, _ = build_lights(desc.lights, "s.usda")
    by = {lt.desc.prim.rsplit("/", 1)[-1]: lt for lt in lights}
    assert lights_jit.light_power(by["Panel"], 2.0) == pytest.approx(math.pi * 4.0 * 1.0, rel=1e-6)
    assert lights_jit.light_power(by["Faint0"], 2.0) == pytest.approx(4.0 * math.pi * 0.001, rel=1e-6)
    sun = type("L", (), {"desc": type("D", (), {"type": "DistantLight", "radiance": np.array([2.0, 2.0, 2.0])})()})()
    dome = type("L", (), {"desc": type("D", (), {"type": "DomeLight", "radiance": np.array([0.5, 0.5, 0.5])})(), "tex": None})()
    assert lights_jit.light_power(sun, 3.0) == pytest.approx(2.0 * math.pi * 9.0, rel=1e-6)
    assert lights_jit.light_power(dome, 3.0) == pytest.approx(0.5 * 4.0 * math.pi ** 2 * 9.0, rel=1e-6)


def test_selection_weights_mix_power_and_uniform():
    w = lights_jit.selection_weights({"a": 3.0, "b": 1.0, "c": 0.0}, share=0.5)
    assert w == pytest.approx({"a": 0.5 / 3 + 0.375, "b": 0.5 / 3 + 0.125, "c": 0.5 / 3})
    assert sum(w.values()) == pytest.approx(1.0)
    assert lights_jit.selection_weights({"a": 0.0, "b": float("nan")}) == {"a": 1.0, "b": 1.0}  # nothing to go by: uniform


def test_emitters_carry_the_weights_and_the_image_keeps_its_mean_with_less_variance(tmp_path):
    """The rect light is picked with probability 1/8 + 1/2 x its share of the power (about 0.62, against 1/4 uniformly):
    the floor's noise falls by more than 1.5x at the same spp, and the two choices' image means agree within 4 standard
    errors of their difference (both unbiased)."""
    scene = _scene(tmp_path)

    def two(share):
        lights_jit.POWER_SHARE = share
        a, b = (render(scene, 32, seed=s, width=32, height=32) for s in (1, 2))
        return float(np.mean((a - b) ** 2) / 2), float(0.5 * (a + b).mean()), a.size

    try:
        var_u, mean_u, n = two(0.0)
        var_d, mean_d, _ = two(0.5)
    finally:
        lights_jit.POWER_SHARE = 0.5
    assert var_u / var_d > 1.5, (var_u, var_d)
    standard_error = math.sqrt((var_u + var_d) / (2 * n))  # of the difference of two means over two renders of n values
    assert abs(mean_d - mean_u) < 4 * standard_error, (mean_d, mean_u, standard_error)


# -- the choice by where the vertex is (mitsuba_plugin/light_choice.py), with many emitters -------------------------
def test_spatial_choice_probabilities_and_draws(tmp_path):
    """At a point, the choice's probabilities sum to 1, follow the importance of the module docstring (checked in
    numpy from the emitters' terms), and the emitters drawn follow them (chi-squared over 40 000 draws)."""
    import drjit as dr

    from nasset_mitsuba_plugin.light_choice import UNIFORM_SHARE, EmitterChoice, emitter_terms
    from nasset_mitsuba_plugin.scene import usd_scene
    from nasset_mitsuba_plugin.variant import jit_mitsuba
    from tests.stats import chi2_test

    mi = jit_mitsuba()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = mi.load_dict(usd_scene(glossy_floor_many_lights(tmp_path / "many.usda"), 8, 8, mi=mi))
    choice = EmitterChoice(mi, scene)
    m = choice.m
    assert m == 76
    x = np.array([0.3, 0.1, -0.7])
    centre, b, factor, const = emitter_terms(mi, scene)
    imp = factor / np.maximum(((x - centre) ** 2).sum(1), b) + const
    want = UNIFORM_SHARE / m + (1 - UNIFORM_SHARE) * imp / imp.sum()
    p = mi.Point3f(*x.tolist())
    total = choice._total(p, True)
    got = np.array([choice._probability(p, mi.UInt32(j), total, True)[0] for j in range(m)])
    np.testing.assert_allclose(got, want, rtol=1e-4)
    assert got.sum() == pytest.approx(1.0, rel=1e-5)
    n = 40_000
    u = mi.Float(np.random.default_rng(3).random(n).tolist())
    j, prob, ux = choice.choose(dr.zeros(mi.Point3f, n) + p, u, mi.Bool(True))
    j, prob, ux = np.asarray(j), np.asarray(prob), np.asarray(ux)
    np.testing.assert_allclose(prob, want[j], rtol=1e-4)
    assert ((ux >= 0) & (ux < 1)).all()
    assert chi2_test(np.bincount(j, minlength=m), want)[2] > 1e-4


@pytest.mark.parametrize("what", ["glossy floor", "8dna"])
def test_spatial_choice_keeps_the_image(tmp_path, monkeypatch, what):
    """Many emitters, the choice by the vertex against Mitsuba's choice by weight alone: the same image within the noise
    (per-channel means within 4.5 standard errors). The glossy floor reflects the sphere lights through both techniques,
    so the MIS weight of a BSDF sample that meets a light must use the same probability as the light samples; the 8dna
    asset takes light samples at x_o and at u_i."""
    import nasset_mitsuba_plugin.light_choice as choice
    from tests.renderer.render_stats import assert_renders_agree

    if what == "8dna":
        from nasset_sdk.examples import example_builder

        asset = example_builder("8dna", size="tiny", seed=2).write(tmp_path / "a.usdc")
        scene, spp = asset_among_many_lights(tmp_path / "many.usda", asset, seed=1), 32
    else:
        scene, spp = glossy_floor_many_lights(tmp_path / "many.usda"), 64

    def renders(seeds):
        imgs = [render(scene, spp, seed=s, width=32, height=32, max_depth=2) for s in seeds]
        img = np.mean(imgs, 0)
        var = np.var(imgs, 0, ddof=1) / len(imgs)  # of the mean of independent renders
        return type("R", (), {"image": img, "variance": var})()

    spatial = renders(range(1, 5))
    monkeypatch.setattr(choice, "SPATIAL_MIN", 10_000)  # Mitsuba's own choice
    mitsuba = renders(range(11, 15))
    assert spatial.image.mean() > 0.01
    assert_renders_agree(spatial, mitsuba, z_mean=4.5, z_pixel=6.0, pixel_fraction=0.02)
    assert spatial.variance.mean() < mitsuba.variance.mean(), (spatial.variance.mean(), mitsuba.variance.mean())


# -- emitters that light a cone only: a spread, a spot (mitsuba_plugin/light_choice.py, emitter_cone) ----------------
def test_cone_lights_give_nothing_outside_their_cones(tmp_path):
    """Where emitter_cone says a point is outside an emitter's cone, the emitter's own light samples from that point
    (Mitsuba's sample_direction, 64 per point) carry no light; inside, some do. Checked for the four cone lights of the
    scene, at points on the floor and in the air; the dome has no cone."""
    import drjit as dr

    from nasset_mitsuba_plugin.light_choice import emitter_cone
    from nasset_mitsuba_plugin.scene import usd_scene
    from nasset_mitsuba_plugin.variant import jit_mitsuba

    mi = jit_mitsuba()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = mi.load_dict(usd_scene(cone_lights_scene(tmp_path / "cones.usda"), 8, 8, mi=mi))
    rng = np.random.default_rng(7)
    pts = np.concatenate([rng.uniform([-4, 0, -4], [4, 0, 4], (300, 3)), rng.uniform([-4, 0, -4], [4, 2.5, 4], (100, 3))])
    k = 64
    cones = 0
    for e in scene.emitters():
        cone = emitter_cone(mi, e)
        if cone is None:
            continue
        cones += 1
        apex, axis, cos_t = cone
        v = pts - apex
        inside = v @ axis >= cos_t * np.linalg.norm(v, axis=1)
        assert 0.02 < inside.mean() < 0.8, (e.to_string(), inside.mean())
        x = np.repeat(pts, k, 0)
        it = dr.zeros(mi.Interaction3f, len(x))
        it.p = mi.Point3f(*(x[:, i].tolist() for i in range(3)))
        u = rng.random((len(x), 2))
        _, spec = e.sample_direction(it, mi.Point2f(u[:, 0].tolist(), u[:, 1].tolist()), True)
        lit = (np.asarray(spec, np.float64).reshape(3, -1).max(0) > 0).reshape(len(pts), k).any(1)
        assert not (lit & ~inside).any(), (e.to_string(), np.nonzero(lit & ~inside)[0][:5])
        assert lit[inside].mean() > 0.5, e.to_string()
    assert cones == 4


def test_cone_lights_choice_keeps_the_image_with_less_noise(tmp_path, monkeypatch):
    """The scene of the cone lights, the choice by the vertex (its cones) against Mitsuba's choice by weight alone: the
    same image within its noise, at less than half the variance (docs/bench-mitsuba-jit.md#cone-lights)."""
    import nasset_mitsuba_plugin.light_choice as choice
    from tests.renderer.render_stats import assert_renders_agree

    scene = cone_lights_scene(tmp_path / "cones.usda")

    def renders(seeds):
        imgs = [render(scene, 16, seed=s, width=32, height=32, max_depth=2) for s in seeds]
        return type("R", (), {"image": np.mean(imgs, 0), "variance": np.var(imgs, 0, ddof=1) / len(imgs)})()

    by_vertex = renders(range(1, 5))
    monkeypatch.setattr(choice, "emitter_cone", lambda mi, e: None)  # no cones, 5 emitters: Mitsuba's own choice
    mitsuba = renders(range(11, 15))
    assert by_vertex.image.mean() > 0.01
    assert_renders_agree(by_vertex, mitsuba, z_mean=4.5, z_pixel=6.0, pixel_fraction=0.02)
    assert 2 * by_vertex.variance.mean() < mitsuba.variance.mean(), (by_vertex.variance.mean(), mitsuba.variance.mean())


def test_choice_unrolled_and_looped_agree_with_numpy(tmp_path):
    """Under the cone lights (5 emitters), the straight-line choice and the Dr.Jit loop give the probabilities of the
    module docstring at 300 points (checked in numpy from the emitters' terms and cones: 0 importance outside a cone),
    summing to 1, and choose the same emitter with the same rescaled u for the same uniform numbers."""
    import drjit as dr

    from nasset_mitsuba_plugin.light_choice import UNIFORM_SHARE, EmitterChoice, emitter_cone, emitter_terms
    from nasset_mitsuba_plugin.scene import usd_scene
    from nasset_mitsuba_plugin.variant import jit_mitsuba

    mi = jit_mitsuba()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = mi.load_dict(usd_scene(cone_lights_scene(tmp_path / "cones.usda"), 8, 8, mi=mi))
    rng = np.random.default_rng(8)
    x = rng.uniform([-4, 0, -4], [4, 2.5, 4], (300, 3))
    centre, b, factor, const = emitter_terms(mi, scene)
    imp = factor / np.maximum(((x[:, None] - centre[None]) ** 2).sum(2), b) + const  # [300, m]
    for j, e in enumerate(scene.emitters()):
        cone = emitter_cone(mi, e)
        if cone is not None:
            v = x - cone[0]
            imp[:, j] *= v @ cone[1] >= cone[2] * np.linalg.norm(v, axis=1)
    m = imp.shape[1]
    total = imp.sum(1, keepdims=True)
    want = UNIFORM_SHARE / m + (1 - UNIFORM_SHARE) * np.where(total > 0, imp / np.where(total > 0, total, 1), 1 / m)
    assert (imp == 0).any() and (imp > 0).any()
    p = mi.Point3f(*(x[:, i].tolist() for i in range(3)))
    u = mi.Float(rng.random(len(x)).tolist())
    picks = []
    for unrolled in (True, False):
        choice = EmitterChoice(mi, scene, unrolled=unrolled)
        got = np.stack([np.asarray(choice.probability(p, dr.full(mi.UInt32, j, len(x)))) for j in range(m)], 1)
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-7)
        j, prob, ux = choice.choose(p, u, mi.Bool(True))
        np.testing.assert_allclose(np.asarray(prob), want[np.arange(len(x)), np.asarray(j)], rtol=1e-4)
        picks.append((np.asarray(j), np.asarray(ux)))
    assert np.array_equal(picks[0][0], picks[1][0])
    np.testing.assert_allclose(picks[0][1], picks[1][1], atol=1e-5)
