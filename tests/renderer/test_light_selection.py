"""Light selection (spec/renderer.md#light-selection): a kind of light with more than ``light_draws`` lights is sampled
by that many stratified draws per vertex, by importance. The importance terms and probabilities against closed forms,
the draws against their probabilities, scenes of many lights against the same scenes with every light sampled (meshes
and the three neural kinds), and the light samples per vertex bounded whatever the number of lights."""

import argparse

import numpy as np
import pytest

import nasset_reference_renderer.light_selection as selection
from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.cli import add_args
from nasset_reference_renderer.light_selection import LightSelection, emission_cone, importance_terms
from nasset_reference_renderer.lights import (
    CylinderLight,
    DiskLight,
    DistantLight,
    DomeLight,
    PointLight,
    RectLight,
    SphereLight,
    rays_near_shapes,
)
from nasset_reference_renderer.sampling import luminance
from nasset_reference_renderer.testscenes import SceneBuilder, random_rna_asset
from nasset_sdk.errors import UsageError
from nasset_sdk.examples import example_builder
from tests.renderer.render_stats import assert_renders_agree, render_finite
from tests.stage_scenes import add_many_lights, asset_among_many_lights, glossy_floor_many_lights, spot_stage_scene
from tests.stats import chi2_test

GREY = np.array([2.0, 2.0, 2.0])


def _importance(light, x):
    c, a, b = importance_terms(light)
    return a if c is None else a / max(float(np.sum((np.asarray(x) - c) ** 2)), b)


def test_importance_is_the_irradiance_bound():
    """Far from a light its importance is the irradiance it gives at normal incidence; near it, capped."""
    x = np.array([0.0, 0.0, 4.0])  # 4 m from lights at the origin
    assert _importance(PointLight((0, 0, 0), GREY), x) == pytest.approx(2.0 / 16)
    spot = PointLight((0, 0, 0), GREY, axis=(0, 0, 1), cone_deg=20.0)  # as a point light: it aims at the scene
    assert _importance(spot, x) == pytest.approx(2.0 / 16)
    assert _importance(SphereLight((0, 0, 0), 0.5, GREY), x) == pytest.approx(np.pi * 2.0 * 0.25 / 16)
    assert _importance(SphereLight((0, 0, 0), 0.5, GREY), (0, 0, 0.1)) == pytest.approx(np.pi * 2.0)  # inside: pi L
    rect = RectLight((0, 0, 0), (1.0, 0, 0), (0, 0.5, 0), GREY)  # edge vectors: a 1 x 0.5 rectangle
    assert _importance(rect, x) == pytest.approx(2.0 * 0.5 / 16)
    disk = DiskLight((0, 0, 0), (0.5, 0, 0), (0, 0.5, 0), GREY)
    assert _importance(disk, x) == pytest.approx(2.0 * np.pi * 0.25 / 16)
    assert _importance(DistantLight((0, 1, 0), GREY, 0.0), x) == pytest.approx(2.0)
    assert _importance(DomeLight(GREY), x) == pytest.approx(np.pi * 2.0)
    img = np.zeros((64, 8, 3))  # a lat-long image: rows weighted by their solid angle (the lower half holds half)
    img[32:] = 4.0
    assert _importance(DomeLight((1, 1, 1), img), x) == pytest.approx(np.pi * 2.0, rel=1e-3)
    red = np.array([1.0, 0.0, 0.0])
    assert _importance(PointLight((0, 0, 0), red), x) == pytest.approx(luminance(red) / 16)
    # zero, negative and non-finite lights have no importance; a light on the point is finite
    assert importance_terms(PointLight((0, 0, 0), np.zeros(3)))[1] == 0.0
    assert importance_terms(PointLight((0, 0, 0), np.array([np.inf, 0, 0])))[1] == 0.0
    assert importance_terms(PointLight((np.nan, 0, 0), GREY))[1] == 0.0
    assert np.isfinite(_importance(PointLight((0, 0, 0), GREY), (0, 0, 0)))


@pytest.mark.parametrize("light", [
    PointLight((0.2, 2.0, -0.3), GREY, axis=(0.1, -1.0, 0.3), cone_deg=25.0),
    SphereLight((0.2, 2.0, -0.3), 0.3, GREY, axis=(-0.2, -1.0, 0.1), cone_deg=30.0),
    RectLight((0.2, 1.5, -0.3), (0.8, 0.0, 0.0), (0.0, 0.2, 0.5), GREY, spread=0.9),
    DiskLight((0.2, 1.5, -0.3), (0.4, 0.1, 0.0), (0.0, 0.1, -0.3), GREY, spread=1.6),
], ids=["spot", "sphere spot", "rect spread", "disk spread"])
def test_emission_cone_holds_every_lit_point(light):
    """Where emission_cone puts a point outside the cone, the light's own samples from it (64 each) carry nothing; inside,
    most points get some light. 600 points around the light and below it."""
    rng = np.random.default_rng(12)
    apex, axis, cos_t = emission_cone(light)
    x = rng.uniform([-3, -1, -3], [3, 3.5, 3], (600, 3))
    v = x - apex
    inside = v @ axis >= cos_t * np.linalg.norm(v, axis=1)
    assert 0.03 < inside.mean() < 0.7
    k = 64
    _, _, li, _ = light.sample(np.repeat(x, k, 0), rng.random((len(x) * k, 2)))
    lit = (li.max(1) > 0).reshape(len(x), k).any(1)
    assert not (lit & ~inside).any(), np.nonzero(lit & ~inside)[0][:5]
    assert lit[inside].mean() > 0.5
    # lights that may light any point in front of them: no cone
    assert emission_cone(PointLight((0, 0, 0), GREY)) is None
    assert emission_cone(RectLight((0, 0, 0), (1.0, 0, 0), (0, 1.0, 0), GREY)) is None
    assert emission_cone(SphereLight((0, 0, 0), 0.3, GREY, axis=(0, 0, 1), cone_deg=120.0)) is None


def test_spots_are_drawn_where_they_reach(tmp_path, monkeypatch):
    """A stage of 12 spots over a floor, 2 draws per vertex: the importance with the spots' cones gives the same image as
    without them (both unbiased) at less than a fifth of the variance (measured: 16x less)."""
    scene = load_scene(spot_stage_scene(tmp_path / "stage.usda"))

    def renders(seeds):
        imgs = [render(scene, RenderSettings(spp=16, width=32, height=32, seed=s, light_draws=2, max_depth=2)).image
                for s in seeds]
        return type("R", (), {"image": np.mean(imgs, 0), "variance": np.var(imgs, 0, ddof=1) / len(imgs)})()

    coned = renders(range(1, 5))
    monkeypatch.setattr(selection, "emission_cone", lambda light: None)
    plain = renders(range(11, 15))
    assert coned.image.mean() > 0.05
    assert_renders_agree(coned, plain, z_mean=4.5, z_pixel=6.0, pixel_fraction=0.02)
    assert coned.variance.mean() < 0.2 * plain.variance.mean(), (coned.variance.mean(), plain.variance.mean())


def _kind(lights):
    sel = LightSelection(lights, list(range(len(lights))), draws=2)
    assert sel.any_drawn
    return sel, sel.kinds[0]


def test_probabilities_follow_importance_with_a_uniform_share():
    lights = [PointLight((0, 0, 0), GREY), PointLight((10, 0, 0), GREY), PointLight((0, 10, 0), np.zeros(3))]
    sel, kind = _kind(lights)
    x = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 1.0], [5.0, 5.0, 1.0]])
    prob = kind.probabilities(x)
    np.testing.assert_allclose(prob.sum(1), 1.0)
    a = selection.UNIFORM_SHARE / 3
    imp = np.array([[_importance(light, xi) for light in lights] for xi in x])
    np.testing.assert_allclose(prob, a + (1 - selection.UNIFORM_SHARE) * imp / imp.sum(1, keepdims=True))
    assert prob[0, 0] > 0.9 and prob[1, 1] > 0.9  # the near light
    assert (prob >= a * (1 - 1e-12)).all()  # every light keeps its share: none is never drawn
    # every importance zero (or the points not finite): uniform
    zero = [PointLight((i, 0, 0), np.zeros(3)) for i in range(3)]
    np.testing.assert_allclose(_kind(zero)[1].probabilities(x), 1 / 3)
    np.testing.assert_allclose(kind.probabilities(np.array([[np.nan, 0.0, 0.0]])), 1 / 3)
    # count: draws x P at each point, 1 for lights sampled every time, 0 for lights not sampled at vertices
    np.testing.assert_allclose(sel.count(1, x), 2 * prob[:, 1])
    few = LightSelection(lights[:2], [0], draws=2)
    assert (few.count(0, x) == 1).all() and (few.count(1, x) == 0).all()
    both = sel.counts([(0, np.array([2, 0])), (1, np.array([1]))], x)
    np.testing.assert_allclose(both[0], 2 * prob[[2, 0], 0])
    np.testing.assert_allclose(both[1], 2 * prob[[1], 1])


def test_few_lights_are_each_sampled_once_in_order():
    """At most ``draws`` lights of a kind: every light, in the scene's order, with the random numbers the integrator
    always drew for it (so images of such scenes do not change)."""
    lights = [PointLight((0, 1, 0), np.full(3, v)) for v in (1.0, 2.0, 3.0)] + [SphereLight((0, 3, 0), 0.5, GREY)]
    sel = LightSelection(lights, [0, 1, 2, 3])
    assert not sel.any_drawn
    p = np.zeros((6, 3))
    got = list(sel.samples(p, np.random.default_rng(4)))
    rng = np.random.default_rng(4)
    want = [(light.delta, *light.sample(p, rng.random((6, 2)))) for light in lights]
    assert len(got) == 4
    for g, w in zip(got, want, strict=True):
        assert g[0] == w[0]
        for a, b in zip(g[1:], w[1:], strict=True):
            np.testing.assert_array_equal(a, b)
    assert len(list(sel.samples(p, np.random.default_rng(4), delta_only=True))) == 3


def test_draws_are_stratified_by_probability():
    """20 point lights around a point, 8 draws per vertex: at every vertex each light is drawn floor(8 P_k) or
    ceil(8 P_k) times (the strata), the counts over vertices follow 8 P_k (chi-squared), and a draw of light k
    carries pdf 8 P_k. Lights are told apart by their direction from the vertex."""
    rng = np.random.default_rng(0)
    centres = rng.normal(size=(20, 3)) * np.linspace(0.3, 3.0, 20)[:, None]
    lights = [PointLight(c, GREY * (1 + i % 3)) for i, c in enumerate(centres)]
    sel = LightSelection(lights, list(range(20)))
    n, d = 3000, selection.DRAWS
    x = np.zeros((n, 3))
    p_k = sel.kinds[0].probabilities(x[:1])[0]
    draws = list(sel.samples(x, np.random.default_rng(1)))
    assert len(draws) == d and all(g[0] for g in draws)  # delta lights
    dirs = centres / np.linalg.norm(centres, axis=1, keepdims=True)
    k = np.stack([np.argmax(g[1] @ dirs.T, 1) for g in draws], 1)  # [n, d] light of each draw
    for t, g in enumerate(draws):
        np.testing.assert_allclose(g[1], dirs[k[:, t]], atol=1e-12)
        np.testing.assert_allclose(g[4], d * p_k[k[:, t]])
    per_vertex = np.stack([(k == j).sum(1) for j in range(20)], 1)  # [n, 20]
    assert (per_vertex >= np.floor(d * p_k - 1e-9)).all() and (per_vertex <= np.ceil(d * p_k + 1e-9)).all()
    assert chi2_test(per_vertex.sum(0), p_k)[2] > 1e-4


def test_delta_and_other_lights_are_drawn_apart():
    lights = [PointLight((i, 1.0, 0.0), GREY) for i in range(10)] + [SphereLight((i, 3.0, 0.0), 0.2, GREY) for i in range(3)]
    sel = LightSelection(lights, list(range(13)))
    got = list(sel.samples(np.zeros((5, 3)), np.random.default_rng(1)))
    # the three spheres each once, then the draws among the ten point lights
    assert [g[0] for g in got] == [False] * 3 + [True] * selection.DRAWS
    assert (sel.count(10, np.zeros((5, 3))) == 1).all()
    assert [g[0] for g in sel.samples(np.zeros((5, 3)), np.random.default_rng(1), delta_only=True)] == \
        [True] * selection.DRAWS


def _every_light_and_drawn(path, **kw):
    """(render with every light sampled, render with the default draws): independent seeds."""
    return render_finite(path, seed=1, light_draws=0, **kw), render_finite(path, seed=2, **kw)


def test_many_lights_over_a_glossy_floor(tmp_path):
    """64 sphere lights and 12 point lights over a glossy floor beside a ball: the drawn lights give the image of
    every light sampled, and a vertex traces DRAWS shadow rays per kind, not one per light. The floor reflects the
    sphere lights through both techniques, so the MIS weight at a BSDF sample that meets a light must count that
    light's draws: with the light's own pdf instead (the count left out) the image means are 15-17 standard errors
    apart."""
    path = glossy_floor_many_lights(tmp_path / "s.usda")
    every, drawn = _every_light_and_drawn(path, width=32, height=32, spp=64, max_depth=2)
    assert drawn.image.mean() > 0.1
    assert_renders_agree(every, drawn, z_mean=4.5, z_pixel=4.5, pixel_fraction=0.01)
    rays = [r.stats.rays / r.stats.camera_samples for r in (every, drawn)]
    assert rays[1] < 0.3 * rays[0], rays


@pytest.mark.parametrize("kind", ["rna", "neupress", "8dna"])
def test_many_lights_on_neural_assets(tmp_path, kind):
    """Each neural kind's light samples (rna rows, the neupress lobe's MIS, 8dna's at x_o and at u_i) under 12 sphere
    lights and 10 point lights near the asset, with a floor for continuations: drawn lights give the image of every
    light sampled."""
    if kind == "rna":
        asset = random_rna_asset(tmp_path / "a.usdc", seed=3)
    else:
        asset = example_builder(kind, size="tiny", seed=2).write(tmp_path / "a.usdc")
    path = asset_among_many_lights(tmp_path / "s.usda", asset)
    every, drawn = _every_light_and_drawn(path, width=20, height=20, spp=32, max_depth=3)
    assert drawn.image.mean() > 0.01
    assert_renders_agree(every, drawn, z_mean=4.5, z_pixel=4.5, pixel_fraction=0.02)


def test_explain_says_how_lights_are_chosen(tmp_path, capsys):
    from nasset_sdk.cli import main as nasset

    b = SceneBuilder()
    b.camera((0, 2, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 4.0)
    add_many_lights(b, np.random.default_rng(0), 10, 3)
    path = b.write(tmp_path / "s.usda")
    args = [path, "-o", str(tmp_path / "o.exr"), "--width", "4", "--height", "4", "--spp", "1", "--explain", "--quiet"]
    assert nasset(["render", *args]) == 0
    out = capsys.readouterr().out
    assert "10 lights with a surface or solid angle: 8 stratified draws per vertex" in out and "3 others" in out
    assert nasset(["render", *args, "--light-draws", "0"]) == 0
    assert "every light sampled at every vertex (13 with shadow rays)" in capsys.readouterr().out


def test_light_draws_setting(tmp_path):
    """``light_draws`` is checked like the other settings; the CLI's default is the renderer's."""
    b = SceneBuilder()
    b.camera((0, 2, 3), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 4.0)
    add_many_lights(b, np.random.default_rng(0), 10, 0)
    scene = load_scene(b.write(tmp_path / "s.usda"))
    for bad in (-1, selection.MAX_DRAWS + 1, 2.0, True):
        with pytest.raises(UsageError, match="light_draws"):
            render(scene, RenderSettings(width=4, height=4, spp=1, light_draws=bad))
    p = argparse.ArgumentParser()
    add_args(p)
    assert p.parse_args(["s.usda", "-o", "x.exr"]).light_draws == selection.DRAWS == RenderSettings().light_draws


@pytest.mark.parametrize("offset, size", [(0.0, 1.0), (1e4, 1e-2), (-3e3, 30.0)])
def test_rays_near_shapes_keep_every_hit(offset, size):
    """The culling of light shapes by bounding spheres (many light surfaces) keeps every ray that meets a shape before
    t_end, far from the origin and at small and large scales too, and culls most rays of a scattered batch."""
    rng = np.random.default_rng(int(abs(offset)) + 1)
    c = lambda: offset + size * rng.uniform(-2, 2, 3)  # noqa: E731
    lights = []
    for _ in range(12):
        r = size * rng.uniform(0.05, 0.4)
        ax = rng.normal(size=3)
        lights += [SphereLight(c(), r, GREY), RectLight(c(), size * rng.normal(size=3), size * rng.normal(size=3), GREY),
                   DiskLight(c(), size * rng.normal(size=3), size * rng.normal(size=3), GREY),
                   CylinderLight(c(), ax, r, size * rng.uniform(0.2, 2.0), GREY)]
    n = 4000
    o = offset + size * rng.uniform(-3, 3, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)  # unit directions, as the renderer's rays
    t_end = np.where(rng.random(n) < 0.3, np.inf, rng.uniform(0.0, 3.0, n))
    near = rays_near_shapes([light.bounding_sphere() for light in lights], o, d, t_end)
    kept = hits = 0
    for light, rows in zip(lights, near, strict=True):
        t, _ = light.intersect(o, d)
        hit = np.nonzero(t < t_end)[0]
        assert set(hit) <= set(rows.tolist()), type(light).__name__
        kept, hits = kept + len(rows), hits + len(hit)
    assert hits > 50 and kept < 0.5 * n * len(lights)
    # a shape without bounds is tested on every ray
    assert (rays_near_shapes([None, lights[0].bounding_sphere()], o, d, t_end)[0] == np.arange(n)).all()
