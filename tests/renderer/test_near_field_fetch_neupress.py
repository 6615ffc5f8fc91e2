"""The neupress near-field fetch in the reference renderer (spec/kinds/neupress.md#near-field-fetch): the light of the
whole integrand (S^ and the surface reflection f_r) of an asset with f > 0 is fetched at p = x + f (c_w - x), while
S^, f_r, the lobe and V_self are evaluated at x; f = 0 written explicitly renders the same bits as no attribute."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("embreex")

from nasset_reference_renderer import RenderSettings, load_scene, make_plan, render  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder, constant_neupress_asset  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from tests.renderer.test_near_field_fetch import _point_light, _with_fetch  # noqa: E402

S_HAT = 0.2  # the constant subsurface transport (1/sr)
LIGHT = np.array([0.0, 3.0, 0.0])
SHIFT = np.array([0.1, 0.05, -0.1])  # the instance's translation: c_w = SHIFT (the icosphere's box is centred)


def _translation(t):
    m = np.eye(4)
    m[3, :3] = t
    return m


def _lone(tmp_path, f, *, occluder=None, boundary=(1.5, 0.2), name="s"):
    """(scene file, asset file): a constant-S^ sphere (radius 0.5 about SHIFT) under a point light at LIGHT, seen
    from +z; ``occluder``: (centre, size) of a black horizontal quad (out of the camera's view)."""
    asset = constant_neupress_asset(tmp_path / f"{name}{f}.usdc", subsurface=(S_HAT,) * 3, boundary=boundary,
                                    near_field_fetch=f)
    b = SceneBuilder()
    b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), focal=60.0)
    _point_light(b, LIGHT, 20.0)
    b.asset("Obj", "./" + asset.name, _translation(SHIFT))
    if occluder is not None:
        b.quad("Blocker", occluder[0], occluder[1], normal=(0.0, -1.0, 0.0), diffuse=(0.0, 0.0, 0.0))
    return b.write(tmp_path / f"{name}{f}.usda"), asset


def _image(scene_file, **kw):
    scene = load_scene(scene_file)
    return render(scene, RenderSettings(width=40, height=40, spp=4, seed=1, **kw)).image[..., 0], scene.lights[0].I[0]


def _direct(scene_file, o, d):
    """(L [n] red, hits, integrator): the light-sample term of camera rays (o, d) through the renderer's own loop
    (max_depth 1, light sampling only: the A sample's rays find no emitter under a point light)."""
    from nasset_reference_renderer.integrator import PathIntegrator, prepare_assets, resolve_settings

    scene = load_scene(scene_file)
    s = resolve_settings(RenderSettings(max_depth=1, neupress_sampling="dome"), scene)
    plan = make_plan(scene, width=8, height=8, spp=1, max_depth=1, tile=8, batch=4096, neupress_sampling="dome")
    prepare_assets(scene, plan, s)
    integ = PathIntegrator(scene, plan, s)
    L = integ.radiance(o, d, np.random.default_rng(0))
    return L[:, 0], integ.accel.trace(o, d), integ


def test_full_fetch_closed_form_with_surface_reflection(tmp_path):
    """f = 1 under a point light: every hit's light-sample term is (S^ + f_r(x) V_self(x)) I / |l - c_w|^2, with the
    direction w_i = (l - c_w) / |l - c_w| for every hit, f_r the SDK's surface_reflection at x (its normal and w_o) and
    V_self the sphere's own shadow from x along w_i. Checked exactly on camera rays to 400 points of the sphere, away
    from the terminator; f = 0 takes another value on nearly all of them."""
    from nasset_sdk.asset import Asset

    scene1, asset1 = _lone(tmp_path, 1.0)
    scene0, _ = _lone(tmp_path, 0.0)
    eye = np.array([0.0, 0.0, 3.0])
    g = np.linspace(-0.42, 0.42, 20)
    target = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    target = np.concatenate([target, np.zeros((len(target), 1))], 1) + SHIFT
    target = target[np.hypot(*(target - SHIFT)[:, :2].T) < 0.45]
    d = target - eye
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.repeat(eye[None], len(d), 0)
    L1, hits, integ = _direct(scene1, o, d)
    L0, _, _ = _direct(scene0, o, d)
    assert (hits.prim >= 0).all()
    tri = integ.scene.triangles[hits.prim]
    x = tri[:, 0] * (1 - hits.u - hits.v)[:, None] + tri[:, 1] * hits.u[:, None] + tri[:, 2] * hits.v[:, None]
    cn = integ.asset_corner_n[0][integ.scene.tri_local[hits.prim]]
    n = cn[:, 0] * (1 - hits.u - hits.v)[:, None] + cn[:, 1] * hits.u[:, None] + cn[:, 2] * hits.v[:, None]
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    wi = (LIGHT - SHIFT) / np.linalg.norm(LIGHT - SHIFT)
    fr = Asset.open(asset1, load="all").evaluator().surface_reflection(n, -d, np.tile(wi, (len(d), 1)))[:, 0]
    e = integ.scene.lights[0].I[0] / np.sum((LIGHT - SHIFT) ** 2)
    facing = (x - SHIFT) @ wi / 0.5  # > 0: the sphere does not lie between x and the light
    lit, dark = facing > 0.1, facing < -0.1
    assert lit.sum() > 100 and dark.sum() > 100 and fr[lit].max() > 0.2 * S_HAT  # a highlight among the lit points
    np.testing.assert_allclose(L1[lit], (S_HAT + fr[lit]) * e, rtol=1e-5)
    np.testing.assert_allclose(L1[dark], S_HAT * e, rtol=1e-5)
    assert np.isclose(L0, L1, rtol=1e-3).mean() < 0.05


def test_full_fetch_gives_the_image_one_value_without_reflection(tmp_path):
    """f = 1 and eta 1 (no surface reflection): every covered pixel is S^ I / |l - c_w|^2; f = 0 varies over it."""
    img1, intensity = _image(_lone(tmp_path, 1.0, boundary=(1.0, 0.2))[0])
    img0, _ = _image(_lone(tmp_path, 0.0, boundary=(1.0, 0.2))[0])
    expected = S_HAT * intensity / np.sum((LIGHT - SHIFT) ** 2)
    v1, v0 = img1[img1 > 0], img0[img0 > 0]
    assert len(v1) > 150 and len(v1) == len(v0)
    assert v1.max() <= expected * (1 + 1e-6)
    assert np.isclose(v1, expected, rtol=1e-6).mean() > 0.7  # every pixel inside the silhouette
    assert np.isclose(v0, expected, rtol=1e-6).mean() < 0.05
    assert v0.max() > 1.3 * expected  # the top of the sphere, nearer the light


def test_fetch_point_decides_other_objects_and_x_decides_v_self(tmp_path):
    """f = 1: an occluder on the line from c_w to the light darkens the whole asset, one that shadows part of the
    surface from the light but not c_w changes nothing; f = 0: the other way round. (V_self from x: the lit upper
    half shows the surface reflection, the lower half none, with f = 1 as with f = 0.)"""
    on_centre_line = ((SHIFT[0], 1.5, SHIFT[2]), 0.16)
    off_centre_line = ((-0.35, 0.95, -0.1), 0.6)  # shadows the upper left of the sphere only
    free1, _ = _image(_lone(tmp_path, 1.0, name="free")[0])
    free0, _ = _image(_lone(tmp_path, 0.0, name="free")[0])
    a1, _ = _image(_lone(tmp_path, 1.0, occluder=on_centre_line, name="a")[0])
    a0, _ = _image(_lone(tmp_path, 0.0, occluder=on_centre_line, name="a")[0])
    b1, _ = _image(_lone(tmp_path, 1.0, occluder=off_centre_line, name="b")[0])
    b0, _ = _image(_lone(tmp_path, 0.0, occluder=off_centre_line, name="b")[0])
    covered = free0 > 0
    assert covered.sum() > 150
    assert np.all(a1 == 0.0)
    assert (a0[covered] > 0).mean() > 0.8
    assert np.allclose(b1, free1, rtol=1e-6, atol=0.0)
    lost = covered & (b0 == 0.0)
    assert lost.sum() > 20 and not (covered & (free1 == 0.0)).any()
    rows, cols = np.nonzero(lost)
    assert rows.mean() < 20 and cols.mean() < 20  # upper left of the image


def test_explicit_zero_renders_the_same_bits_as_no_attribute(tmp_path):
    """f = 0 authored keeps the format 0.2 code path (same random numbers, same bits) in every sampling mode; f = 0.5
    on the same file renders another image."""
    plain = example_builder("neupress", size="tiny", seed=5).write(tmp_path / "plain.usdc")
    files = {"plain": plain, "zero": _with_fetch(plain, tmp_path / "zero.usdc", 0.0),
             "half": _with_fetch(plain, tmp_path / "half.usdc", 0.5)}
    for mode in ("mis", "dome", "lobe"):
        images = {}
        for name, file in files.items():
            b = SceneBuilder()
            b.camera((0.0, 1.0, 3.2), (0.0, 0.0, 0.0))
            b.quad("Floor", (0.0, -0.5, 0.0), 6.0, diffuse=(0.6, 0.6, 0.6))
            b.sphere_light("Bulb", (0.7, 0.2, 0.6), 0.1, 6.0)
            b.distant("Sun", (0.3, 1.0, -0.4), 1.5)
            b.asset("Obj", "./" + file.name)
            images[name] = render(load_scene(b.write(tmp_path / f"{name}.usda")),
                                  RenderSettings(width=16, height=16, spp=4, seed=5, neupress_sampling=mode)).image
        assert np.array_equal(images["plain"], images["zero"]), mode
        assert not np.allclose(images["plain"], images["half"], rtol=0.05, atol=0.0), mode


def _on_floor(tmp_path, f, seed):
    """Constant-S^ sphere (no surface reflection) resting on a white floor, a sun straight above: under it the floor
    is in its shadow, lit beyond. Camera low, looking at the sphere's lower half. The A samples (uniform sphere, mis)
    gather the floor's light."""
    asset = constant_neupress_asset(tmp_path / f"floor{f}.usdc", subsurface=(0.1,) * 3, boundary=(1.0, 0.2),
                                    near_field_fetch=f)
    b = SceneBuilder()
    b.camera((0.0, -0.25, 3.0), (0.0, -0.25, 0.0), focal=70.0)
    b.quad("Floor", (0.0, -0.5, 0.0), 40.0, diffuse=(0.9, 0.9, 0.9))
    b.distant("Sun", (0.0, 1.0, 0.0), 3.0)
    b.asset("Obj", "./" + asset.name)
    scene = load_scene(b.write(tmp_path / f"floor{f}.usda"))
    r = render(scene, RenderSettings(width=32, height=32, spp=32, seed=seed, max_depth=2, neupress_sampling="mis"))
    return r.image[..., 0], r.variance[..., 0]


def test_continuation_from_the_fetch_point_sees_past_the_contact_shadow(tmp_path):
    """The A sample's rays from p (f = 1: the centre) start higher above the floor than from the bottom of the
    sphere: they see more lit floor, so the lower band of the asset is brighter with f = 1 than with f = 0 (its
    direct light, from the sun straight above, is the same for both); the top, whose rays now start nearer the
    floor, darker. A statistical test: the difference of band means against its standard error (measured:
    17 standard errors in the lower band, -6 in the top one; 0.3 with the A sample's ray left at x)."""
    img0, var0 = _on_floor(tmp_path, 0.0, seed=2)
    img1, var1 = _on_floor(tmp_path, 1.0, seed=3)

    def change(band):  # (mean with f = 1 - mean with f = 0) / its standard error
        se = np.sqrt(var0[band].sum() + var1[band].sum()) / img0[band].size
        return (img1[band].mean() - img0[band].mean()) / se

    assert change(np.s_[19:25, 10:22]) > 6  # the sphere's lower part, just above its contact with the floor
    assert change(np.s_[2:10, 10:22]) < 0


@pytest.mark.parametrize("mode", ["mis", "lobe"])
def test_sampling_modes_agree_with_light_sampling_on_a_near_sphere_light(tmp_path, mode):
    """f = 0.5, a large SphereLight close to the asset (its solid angle and pdf change several-fold between x and
    p): the A samples leaving p (lobe: weight 1; mis: weighted with the light's pdf seen from p) estimate the same
    image as light samples drawn at p (dome), within 4 standard errors of the image sums (measured: at most 2.1;
    one standard error is 0.9 % of the image for mis, 4 % for lobe)."""
    asset = _with_fetch(example_builder("neupress", size="tiny", seed=5).write(tmp_path / "a.usdc"),
                        tmp_path / "half.usdc", 0.5)
    b = SceneBuilder()
    b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0))
    b.sphere_light("Bulb", (0.7, 0.7, 0.5), 0.4, 3.0)
    b.asset("A", "./" + asset.name)
    scene = b.write(tmp_path / "scene.usda")
    runs = {m: render(load_scene(scene), RenderSettings(spp=128, width=16, height=16, seed=i, max_depth=1,
                                                        neupress_sampling=m))
            for i, m in enumerate(("dome", mode))}
    diff = runs[mode].image.sum((0, 1)) - runs["dome"].image.sum((0, 1))
    se = np.sqrt(runs[mode].variance.sum((0, 1)) + runs["dome"].variance.sum((0, 1)))
    assert np.all(np.abs(diff) < 4 * se), diff / se


def test_plan_explains_the_fetch(tmp_path):
    """``--explain`` says where a neupress asset with f > 0 takes its light; without the attribute it says nothing."""
    notes = {}
    for f in (0.0, 0.25):
        scene_file, _ = _lone(tmp_path, f, name="e")
        plan = make_plan(load_scene(scene_file), width=8, height=8, spp=1, max_depth=5, tile=64, batch=65536)
        notes[f] = plan.explain()
    assert "light fetched at x + 0.25 (c_w - x)" in notes[0.25] and "kinds/neupress.md" in notes[0.25]
    assert "near-field" not in notes[0.0]


def test_prt_mode_is_unchanged(tmp_path):
    """PRT mode (a dome is the same from every point) renders the same bits with f = 0.5 as without the attribute,
    and ``--explain`` says the fetch is unused there."""
    plain = example_builder("neupress", size="tiny", seed=5).write(tmp_path / "plain.usdc")
    files = {"plain": plain, "half": _with_fetch(plain, tmp_path / "half.usdc", 0.5)}
    images, notes = {}, {}
    for name, file in files.items():
        b = SceneBuilder()
        b.camera((0.0, 0.3, 3.0), (0.0, 0.0, 0.0))
        b.dome("Dome", 0.6, color=(1.0, 0.8, 0.6))
        b.asset("Obj", "./" + file.name)
        scene = b.write(tmp_path / f"{name}.usda")
        images[name] = render(load_scene(scene), RenderSettings(width=16, height=16, spp=2, seed=5, prt=True)).image
        notes[name] = make_plan(load_scene(scene), width=8, height=8, spp=1, max_depth=5, tile=64, batch=65536,
                                prt=True).explain()
    assert images["plain"].max() > 0 and np.array_equal(images["plain"], images["half"])
    assert "near-field fetch unused" in notes["half"] and "near-field" not in notes["plain"]
