"""Both Mitsuba-based implementations' near-field fetch of rna and neupress assets (the second implementation and the
JIT plugin, each test run on both) (spec/kinds/rna.md#near-field-fetch, spec/kinds/neupress.md#near-field-fetch): f = 0 authored
renders as no attribute; light samples are drawn and tested for occlusion at the fetch point p while the branch is
chosen from x; continuations find their radiance from p. Scenes and closed forms: tests/near_field_scenes.py."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytest.importorskip("onnxruntime")

from nasset_converters.mitsuba import is_jit, load_mitsuba  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder, random_rna_asset  # noqa: E402
from tests import near_field_scenes as nf  # noqa: E402


class _Renderer:
    """``render(scene, spp, **options)`` of one implementation on one thread (its own name in test ids)."""

    def __init__(self, name: str) -> None:
        self.name = name
        mi = load_mitsuba()
        assert is_jit(mi), f"Mitsuba loaded the {mi.variant()} variant: the implementations need llvm_ad_rgb"
        if name == "second":
            from nasset_mitsuba_renderer import render as second

            self._render, self._extra = second.render, {"threads": 1}
        else:
            from nasset_mitsuba_plugin.render import render as plugin

            self._render, self._extra = plugin, {}

    def render(self, scene, spp, **options):
        return self._render(scene, spp, **options, **self._extra)

    def assert_same(self, a, b):
        """The same image: bit for bit from the second implementation; from the plugin to float32 rounding, whose
        deferred light rows of one lane are added atomically in either order (docs/bench-mitsuba-jit.md)."""
        if self.name == "second":
            np.testing.assert_array_equal(a, b)
        else:
            np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-12)


@pytest.fixture(scope="module", params=["second", "plugin"])
def nr(request):
    return _Renderer(request.param)


def _random_scene(tmp_path, asset):
    b = SceneBuilder()
    b.camera((0, 1, 3), (0, 0, 0))
    b.distant("Sun", (0.3, 1.0, 0.5), 2.0)
    b.sphere_light("Bulb", (1.0, 1.2, 1.0), 0.2, 5.0)
    b.asset("A", asset)
    b.quad("Floor", (0, -0.6, 0), 4, diffuse=(0.6, 0.5, 0.4))
    return b.write(tmp_path / f"scene_{Path(asset).stem}.usda")


def test_zero_fetch_authored_renders_as_unauthored(nr, tmp_path):
    """``nasset:nearFieldFetch = 0`` authored (a 0.3 file) gives the image of the same asset without it, bit for bit
    (same seed): f = 0 is the rule of format 0.2 exactly."""
    plain = random_rna_asset(tmp_path / "rand.usda", seed=2, size="tiny")
    zero = nf.with_fetch_authored(plain, tmp_path / "rand_f0.usda", 0.0)
    a = nr.render(_random_scene(tmp_path, plain), 4, width=16, height=16, seed=5)
    b = nr.render(_random_scene(tmp_path, zero), 4, width=16, height=16, seed=5)
    assert a.max() > 0
    nr.assert_same(a, b)


def test_point_light_is_fetched_at_the_fetch_point(nr, tmp_path):
    """Constant asset under a point light of intensity I, direct lighting: with f = 1 every whole pixel is
    T I / |l - c|^2, T the unshadowed transport on the asset's upper half and the shadowed one on its lower half
    (the branch is still the ray from x); with f = 0 the unshadowed pixels fall off as 1 / |l - x|^2 (brighter
    toward the top, nearer the light)."""
    e_c = nf.INTENSITY / float(np.sum(nf.LIGHT ** 2))  # c is the origin
    unsh, sh = np.asarray(nf.UNSHADOWED), np.asarray(nf.SHADOWED)
    img1 = nr.render(nf.point_light_scene(tmp_path, nf.constant_asset(tmp_path, 1.0)), 4, width=16, height=16, seed=3,
                     max_depth=1)
    whole_un = np.all(np.isclose(img1, unsh * e_c, rtol=1e-4), -1)
    whole_sh = np.all(np.isclose(img1, sh * e_c, rtol=1e-4), -1)
    assert whole_un.sum() >= 20 and whole_sh.sum() >= 10, (whole_un.sum(), whole_sh.sum())
    rows = np.arange(16)[:, None] * np.ones((1, 16))
    assert rows[whole_un].max() < rows[whole_sh].min()  # lit from above: the branch is chosen at x
    cover = img1 / (unsh * e_c)
    assert cover[..., 0].max() <= 1.0 + 1e-4  # nothing brighter than a whole pixel

    img0 = nr.render(nf.point_light_scene(tmp_path, nf.constant_asset(tmp_path, 0.0)), 4, width=16, height=16, seed=3,
                     max_depth=1)
    lit = img0[whole_un][:, 0] / unsh[0]  # E = I / |l - x|^2 at the same pixels
    assert lit.max() / lit.min() > 1.15  # the falloff over the asset (|l - x| from about 2.6 to 3.1)
    upper, lower = lit[rows[whole_un] <= np.median(rows[whole_un])], lit[rows[whole_un] > np.median(rows[whole_un])]
    assert upper.mean() > lower.mean()



def test_fetch_point_follows_the_instance_transform(nr, tmp_path):
    """The same closed form under an instance that rotates, scales non-uniformly and translates an asset whose encoding
    box is off its object origin: every whole pixel is T I / |l - c_w|^2 with c_w = c M (c in object space would
    put it 24 % off)."""
    asset, m, c_w = nf.moved_constant_asset(tmp_path, 1.0)
    e_c = nf.INTENSITY / float(np.sum((nf.LIGHT - c_w) ** 2))
    img = nr.render(nf.point_light_scene(tmp_path, asset, matrix=m), 4, width=16, height=16, seed=3, max_depth=1)
    whole_un = np.all(np.isclose(img, np.asarray(nf.UNSHADOWED) * e_c, rtol=1e-4), -1)
    whole_sh = np.all(np.isclose(img, np.asarray(nf.SHADOWED) * e_c, rtol=1e-4), -1)
    assert whole_un.sum() >= 20 and whole_sh.sum() >= 10, (whole_un.sum(), whole_sh.sum())
    assert img[..., 0].max() <= nf.UNSHADOWED[0] * e_c * (1 + 1e-4)

@pytest.mark.parametrize("kind", ["rna", "neupress"])
@pytest.mark.parametrize("occluder", ["centre", "side", "inside"])
def test_occlusion_is_tested_from_the_fetch_point(nr, tmp_path, occluder, kind):
    """A black occluder on the line c -> light that no line x -> light of the hits in view meets turns the f = 1
    asset off and leaves f = 0 lit; one that shadows part of the asset seen from x (not c) darkens f = 0 there and
    leaves f = 1 as without it; one inside the asset (hidden from the camera) between hits of its lower half and the
    asset's upper half leaves f = 1 as without it too (the branch from x counts only the asset's own triangles).
    The same for the constant neupress asset with a GGX boundary (S^ and f_r alike; V_self from x)."""
    constant = nf.constant_asset if kind == "rna" else nf.constant_neupress_asset
    imgs = {}
    for f in (0.0, 1.0):
        asset = constant(tmp_path, f)
        for occ in (None, occluder):
            imgs[f, occ] = nr.render(nf.point_light_scene(tmp_path, asset, occ), 4, width=16, height=16, seed=3, max_depth=1)
    lit0, lit1 = imgs[0.0, None][..., 0] > 0, imgs[1.0, None][..., 0] > 0
    assert lit0.sum() > 40 and lit1.sum() > 40
    if occluder == "centre":
        assert np.all(imgs[1.0, "centre"] == 0.0)
        kept = imgs[0.0, "centre"][lit0][:, 0] == imgs[0.0, None][lit0][:, 0]
        assert kept.mean() > 0.8
    elif occluder == "side":
        nr.assert_same(imgs[1.0, "side"], imgs[1.0, None])
        dark = (imgs[0.0, "side"][..., 0] == 0.0) & lit0
        assert dark.sum() >= 4
    else:
        nr.assert_same(imgs[1.0, "inside"], imgs[1.0, None])


@pytest.mark.parametrize("f", [0.0, 0.5, 1.0])
def test_continuations_start_at_the_fetch_point(nr, tmp_path, f):
    """Constant asset (T 1 unshadowed, 0 shadowed) inside an emissive shell (the plugin light-samples it: its light
    samples and continuations see it from p; the second implementation reaches it by continuations only), a black
    square just below it: a pixel's expectation is the solid
    angle of the directions that leave the asset at x and along which a ray from p misses the square
    (tests/near_field_scenes.py). Moving p toward the centre darkens the front (the square's near half comes into
    view) and brightens the bottom (the square shrinks); over each of these two regions the image agrees with the
    expectation within 4 standard errors (from the pixels' residuals) plus 1 % (the closed form's quadrature), and the
    expectations at f = 0 and f = 1 are more than 5 standard errors apart."""
    size = 48
    asset = nf.constant_asset(tmp_path, f, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0))
    img = nr.render(nf.dome_square_scene(tmp_path, asset), 64, width=size, height=size, seed=11, max_depth=2)
    rows, cols, expected = nf.dome_square_expected(asset, f, size, size)
    e0, e1 = (nf.dome_square_expected(asset, g, size, size)[2] for g in (0.0, 1.0))
    got = img[rows, cols, 0].astype(np.float64)
    for region in (e1 < e0 - 0.05, e1 > e0 + 0.05):
        res = got[region] - expected[region]
        se = res.std() / np.sqrt(region.sum())
        assert abs(res.mean()) < 4.0 * se + 0.01 * expected[region].mean(), (f, res.mean(), se)
        assert abs(e1[region].mean() - e0[region].mean()) > 5.0 * se  # the test tells f = 0 from f = 1


def test_fiber_light_is_fetched_at_the_fetch_point(nr, tmp_path):
    """A straight constant fiber (one curve, its own segments exempt: always the unshadowed branch) under the point
    light, direct lighting: with f = 1 no pixel exceeds T I / |l - c|^2 and the whole ones equal it; with f = 0 the
    top of the fiber, nearer the light, is brighter than that."""
    from nasset_reference_renderer.testscenes import constant_rna_fiber_asset

    curve = np.stack([np.linspace(-0.6, 0.6, 4), np.zeros(4), np.zeros(4)], 1)
    base = constant_rna_fiber_asset(tmp_path / "fiber.usda", [curve], 0.3, unshadowed=nf.UNSHADOWED, shadowed=nf.SHADOWED)
    e_c = nf.INTENSITY / float(np.sum(nf.LIGHT ** 2))
    unsh = np.asarray(nf.UNSHADOWED)
    for f in (1.0, 0.0):
        asset = nf.with_fetch(base, tmp_path / f"fiber_f{f}.usda", f)
        img = nr.render(nf.point_light_scene(tmp_path, asset), 4, width=16, height=16, seed=3, max_depth=1)
        cover = img / (unsh * e_c)
        assert np.allclose(cover, cover[..., :1], atol=1e-4)  # unshadowed everywhere
        if f == 1.0:
            assert cover.max() <= 1.0 + 1e-4 and (cover[..., 0] > 1.0 - 1e-4).sum() >= 10
        else:
            assert cover.max() > 1.03  # |l - x| down to about 2.88


@pytest.mark.parametrize("value", [1.5, -0.25, float("nan")])
def test_fetch_outside_the_unit_interval_is_a_typed_error(nr, tmp_path, value):
    """``nasset:nearFieldFetch`` outside [0, 1] (or NaN): NEAR_FIELD_INVALID naming the asset file and the attribute,
    before anything is rendered."""
    from nasset_sdk.errors import NassetError

    base = nf.constant_asset(tmp_path, 0.0)
    bad = nf.with_fetch_authored(base, tmp_path / "bad.usda", value)
    with pytest.raises(NassetError) as err:
        nr.render(nf.point_light_scene(tmp_path, bad), 1, width=8, height=8)
    assert err.value.code == "NEAR_FIELD_INVALID", err.value
    assert "bad.usda" in str(err.value) and "nasset:nearFieldFetch" in str(err.value)


@pytest.mark.parametrize("kind", ["8dna"])
def test_fetch_on_another_kind_is_a_typed_error(nr, tmp_path, kind):
    """A non-zero ``nasset:nearFieldFetch`` on an 8dna asset (the attribute is rna's and neupress's: 8dna carries its
    near-field transport itself): NEAR_FIELD_INVALID naming the asset file and the attribute, as the reference renderer
    reports it, not an asset rendered as if it were absent."""
    from nasset_sdk.errors import NassetError
    from nasset_sdk.examples import example_builder

    src = example_builder(kind, size="tiny", seed=1).write(tmp_path / f"{kind}.usda")
    bad = nf.with_fetch_authored(src, tmp_path / "bad.usda", 0.5)
    with pytest.raises(NassetError) as err:
        nr.render(nf.point_light_scene(tmp_path, bad), 1, width=8, height=8)
    assert err.value.code == "NEAR_FIELD_INVALID", err.value
    assert "bad.usda" in str(err.value) and "nasset:nearFieldFetch" in str(err.value)


# kind neupress (spec/kinds/neupress.md#near-field-fetch): the light of S^ and f_r at p, S^, f_r, the lobe and V_self at x


def test_neupress_zero_fetch_authored_renders_as_unauthored(nr, tmp_path):
    """A random neupress asset (with ``sampling``: MIS of the light samples and the lobe) with ``nasset:nearFieldFetch = 0``
    authored gives the image without it, bit for bit; f = 0.5 changes it (the bulb is near)."""
    from nasset_sdk.examples import example_builder

    plain = example_builder("neupress", size="tiny", seed=2).write(tmp_path / "np.usda")
    zero = nf.with_fetch_authored(plain, tmp_path / "np_f0.usda", 0.0)
    half = nf.with_fetch_authored(plain, tmp_path / "np_f05.usda", 0.5)
    a, b, c = (nr.render(_random_scene(tmp_path, x), 4, width=16, height=16, seed=5) for x in (plain, zero, half))
    assert a.max() > 0
    nr.assert_same(a, b)
    assert not np.array_equal(a, c)


def test_neupress_point_light_is_fetched_at_the_fetch_point(nr, tmp_path):
    """Constant-S^ neupress asset with a GGX boundary under the point light, direct lighting, f = 1: every whole pixel
    is (S^ + f_r V_self) I / |l - c|^2 with the light's direction seen from c (f_r from the SDK's evaluator, at x):
    exactly S^ I / |l - c|^2 on the lower half (V_self = 0, the branch from x), within 8 % per pixel and 1 % on
    average where f_r lights the upper half (f_r varies from face to face inside a pixel: 64 film samples against 64
    quadrature points); the surface reflection is a fifth of the light there at least. With f = 0 the lower half falls
    off as 1 / |l - x|^2 instead."""
    size = 16
    rows, cols, expected = nf.point_light_neupress_expected(nf.constant_neupress_asset(tmp_path, 1.0), size, size)
    s_e = np.asarray(nf.NEUPRESS_S) * nf.INTENSITY / float(np.sum(nf.LIGHT ** 2))
    lower = np.all(np.isclose(expected, s_e, rtol=1e-6), 1)
    upper = expected[:, 0] > 1.2 * s_e[0]
    assert lower.sum() >= 20 and upper.sum() >= 20, (lower.sum(), upper.sum())
    for f in (1.0, 0.0):
        img = nr.render(nf.point_light_scene(tmp_path, nf.constant_neupress_asset(tmp_path, f)), 64, width=size,
                        height=size, seed=3, max_depth=1)
        got = img[rows, cols].astype(np.float64)
        if f == 1.0:
            np.testing.assert_allclose(got[lower], np.broadcast_to(s_e, got[lower].shape), rtol=1e-4)
            np.testing.assert_allclose(got[upper], expected[upper], rtol=0.08)
            assert abs(got[upper].sum() / expected[upper].sum() - 1.0) < 0.01, got[upper].sum() / expected[upper].sum()
        else:
            ratio = got[lower][:, 0] / s_e[0]
            assert ratio.max() / ratio.min() > 1.1  # |l - x| varies over the lower half


@pytest.mark.parametrize("f", [0.0, 1.0])
def test_neupress_continuations_start_at_the_fetch_point(nr, tmp_path, f):
    """The dome-and-square scene of :func:`test_continuations_start_at_the_fetch_point` with a neupress asset of
    constant S^ = 1 and no surface reflection (eta = 1): a pixel's expectation is the solid angle of all directions
    along which a ray from p misses the square (the A sample, uniform on the sphere, leaves p); same tolerance and
    separation of f = 0 from f = 1."""
    size = 48
    asset = nf.constant_neupress_asset(tmp_path, f, (1.0, 1.0, 1.0), (1.0, 0.5))
    img = nr.render(nf.dome_square_scene(tmp_path, asset), 64, width=size, height=size, seed=11, max_depth=2)
    rows, cols, expected = nf.dome_square_expected(asset, f, size, size, leaving=False)
    e0, e1 = (nf.dome_square_expected(asset, g, size, size, leaving=False)[2] for g in (0.0, 1.0))
    got = img[rows, cols, 0].astype(np.float64)
    for region in (e1 < e0 - 0.05, e1 > e0 + 0.05):
        assert region.sum() >= 10
        res = got[region] - expected[region]
        se = res.std() / np.sqrt(region.sum())
        assert abs(res.mean()) < 4.0 * se + 0.01 * expected[region].mean(), (f, res.mean(), se)
        assert abs(e1[region].mean() - e0[region].mean()) > 5.0 * se


def test_neupress_sampling_modes_agree_with_the_fetch(tmp_path, monkeypatch):
    """The second implementation's --neupress-sampling modes under a fetch (f = 1, a random asset with ``sampling``, a
    large SphereLight close beside it, no other object): ``dome`` reaches the light by light samples drawn at p alone,
    ``lobe`` by A samples whose rays leave p alone, ``mis`` by both with the light's pdf seen from p; the three are
    one expectation (paired pixel differences within 4 standard errors), and that expectation is not the f = 0 one
    (more than 6 standard errors of the difference of two seeds' renders apart)."""
    from nasset_mitsuba_renderer import neupress as np_mod
    from nasset_mitsuba_renderer.render import render
    from nasset_sdk.examples import example_builder

    base = example_builder("neupress", size="tiny", seed=3).write(tmp_path / "np.usda")
    imgs = {}
    for f in (1.0, 0.0):
        asset = nf.with_fetch_authored(base, tmp_path / f"np_f{f}.usda", f)
        b = SceneBuilder()
        b.camera((0, 0.3, 2.5), (0, 0, 0))
        b.sphere_light("Bulb", (0.75, 0.45, 0.3), 0.3, 20.0)
        b.asset("A", asset)
        scene = b.write(tmp_path / f"modes_f{f}.usda")
        for mode in ("dome", "lobe", "mis") if f == 1.0 else ("mis",):
            monkeypatch.setattr(np_mod, "SAMPLING", [mode])
            imgs[f, mode] = render(scene, 32, width=16, height=16, seed=7, max_depth=2, threads=1).astype(np.float64)
        if f == 1.0:
            imgs[f, "mis", 8] = render(scene, 32, width=16, height=16, seed=8, max_depth=2, threads=1).astype(np.float64)
    cover = imgs[1.0, "mis"].sum(-1) > 0
    assert cover.sum() > 40

    def z(a, b):
        d = (a - b)[cover].sum(-1)
        return d.mean() / (d.std() / np.sqrt(len(d)))

    for m1, m2 in (("dome", "mis"), ("lobe", "mis"), ("dome", "lobe")):
        assert abs(z(imgs[1.0, m1], imgs[1.0, m2])) < 4.0, (m1, m2, z(imgs[1.0, m1], imgs[1.0, m2]))
    # f = 1 against f = 0: the mean difference against the noise of a difference of two renders (two seeds)
    noise = (imgs[1.0, "mis"] - imgs[1.0, "mis", 8])[cover].sum(-1)
    gap = (imgs[1.0, "mis"] - imgs[0.0, "mis"])[cover].sum(-1).mean()
    assert abs(gap) > 6.0 * noise.std() / np.sqrt(len(noise)), (gap, noise.std() / np.sqrt(len(noise)))


def test_neupress_prt_mode_ignores_the_fetch(tmp_path):
    """The plugin's PRT mode (spec/kinds/neupress.md#near-field-fetch: a dome is the same from every point): a neupress
    asset with f = 0.5 renders bit for bit as without the attribute, the floor's paths included."""
    from nasset_mitsuba_plugin.render import render
    from nasset_sdk.examples import example_builder

    plain = example_builder("neupress", size="tiny", seed=2).write(tmp_path / "np.usda")
    imgs = []
    for asset in (plain, nf.with_fetch_authored(plain, tmp_path / "np_f05.usda", 0.5)):
        b = SceneBuilder()
        b.camera((0, 1, 3), (0, 0, 0))
        b.dome("Sky", color=(1.0, 0.9, 0.8))
        b.asset("A", asset)
        b.quad("Floor", (0, -0.6, 0), 4, diffuse=(0.6, 0.5, 0.4))
        imgs.append(render(b.write(tmp_path / f"prt_{Path(asset).stem}.usda"), 4, width=16, height=16, seed=1, prt=True))
    assert imgs[0].max() > 0
    np.testing.assert_array_equal(imgs[0], imgs[1])
