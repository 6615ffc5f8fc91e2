"""The rna near-field fetch in the reference renderer (spec/kinds/rna.md#near-field-fetch): light samples and
continuation rays of an asset with f > 0 take their light at p = x + f (c_w - x), the branch is chosen from x, and
f = 0 written explicitly renders the same bits as an asset without the attribute."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("embreex")

from nasset_reference_renderer import RenderSettings, load_scene, render  # noqa: E402
from nasset_reference_renderer.testscenes import (  # noqa: E402
    SceneBuilder,
    constant_rna_asset,
    constant_rna_fiber_asset,
    random_rna_asset,
)
from nasset_sdk.errors import SceneError  # noqa: E402

TU, TS = 0.3, 0.1  # constant transports (1/sr)
LIGHT = np.array([0.0, 3.0, 0.0])


def _point_light(b, position, intensity):
    from pxr import UsdLux

    lt = b.sphere_light("Point", tuple(position), 0.0, intensity)
    UsdLux.SphereLight(lt.GetPrim()).CreateTreatAsPointAttr(True)


def _with_fetch(src, dst, f):
    """A copy of the asset file ``src`` with nasset:nearFieldFetch = f authored (0 included) and specVersion 0.3."""
    from pxr import Sdf, Usd

    stage = Usd.Stage.Open(str(src))
    root = stage.GetDefaultPrim()
    root.CreateAttribute("nasset:nearFieldFetch", Sdf.ValueTypeNames.Float).Set(float(f))
    root.GetAttribute("nasset:specVersion").Set("0.3")
    stage.GetRootLayer().Export(str(dst))
    return dst


def test_explicit_zero_renders_the_same_bits_as_no_attribute(tmp_path):
    """f = 0 authored is the rule of format 0.2 on its own code path: the same random numbers, the same bits. (That
    the attribute is read at all: f = 0.5 on the same file renders another image.)"""
    from nasset_sdk.asset import Asset

    plain = random_rna_asset(tmp_path / "plain.usdc", seed=3)
    files = {"plain": plain, "zero": _with_fetch(plain, tmp_path / "zero.usdc", 0.0),
             "half": _with_fetch(plain, tmp_path / "half.usdc", 0.5)}
    a = Asset.open(files["zero"], load="none")
    assert a.stage.GetDefaultPrim().GetAttribute("nasset:nearFieldFetch").HasAuthoredValue()
    assert a.near_field_fetch == 0.0
    images = {}
    for name, file in files.items():
        b = SceneBuilder()
        b.camera((0.0, 1.0, 3.2), (0.0, 0.0, 0.0))
        b.quad("Floor", (0.0, -0.5, 0.0), 6.0, diffuse=(0.6, 0.6, 0.6))
        b.sphere_light("Bulb", (0.7, 0.2, 0.6), 0.1, 6.0)
        b.asset("Obj", "./" + file.name)
        images[name] = render(load_scene(b.write(tmp_path / f"{name}.usda")),
                              RenderSettings(width=16, height=16, spp=4, seed=5)).image
    assert np.array_equal(images["plain"], images["zero"])
    assert not np.allclose(images["plain"], images["half"], rtol=0.05, atol=0.0)


def _lone_asset(tmp_path, f, *, occluder=None, shadowed=TS, matrix=None, name="s"):
    """Constant-transport sphere (radius 0.5 at the origin unless ``matrix``) under a point light at LIGHT, seen
    from +z; ``occluder``: (centre, size) of a black horizontal quad (out of the camera's view)."""
    asset = constant_rna_asset(tmp_path / f"{name}{f}.usdc", unshadowed=(TU,) * 3, shadowed=(shadowed,) * 3,
                               near_field_fetch=f)
    b = SceneBuilder()
    b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0), focal=60.0)
    _point_light(b, LIGHT, 20.0)
    b.asset("Obj", "./" + asset.name, matrix)
    if occluder is not None:
        b.quad("Blocker", occluder[0], occluder[1], normal=(0.0, -1.0, 0.0), diffuse=(0.0, 0.0, 0.0))
    scene = load_scene(b.write(tmp_path / f"{name}{f}.usda"))
    return render(scene, RenderSettings(width=40, height=40, spp=4, seed=1)).image[..., 0], scene.lights[0].I[0]


def test_full_fetch_takes_the_light_at_the_world_box_centre(tmp_path):
    """f = 1: every hit's light is the point light's at c_w (the instance moves and scales the box): one value,
    T I / |l - c_w|^2, on every pixel the asset covers; f = 0 varies as 1 / |l - x|^2 over the surface."""
    m = np.diag([0.8, 0.8, 0.8, 1.0])
    m[3, :3] = (0.1, 0.05, -0.1)
    centre = np.array([0.1, 0.05, -0.1])
    img1, intensity = _lone_asset(tmp_path, 1.0, shadowed=TU, matrix=m)
    img0, _ = _lone_asset(tmp_path, 0.0, shadowed=TU, matrix=m)
    expected = TU * intensity / np.sum((LIGHT - centre) ** 2)
    v1, v0 = img1[img1 > 0], img0[img0 > 0]
    assert len(v1) > 150 and len(v1) == len(v0)
    assert v1.max() <= expected * (1 + 1e-6)
    assert np.isclose(v1, expected, rtol=1e-6).mean() > 0.7  # every pixel inside the silhouette
    assert np.isclose(v0, expected, rtol=1e-6).mean() < 0.05
    assert v0.max() > 1.3 * expected  # the top of the sphere, nearer the light


def test_fetch_point_decides_other_objects_and_x_decides_the_branch(tmp_path):
    """f = 1: an occluder on the line from c_w to the light darkens the whole asset, one that shadows part of the
    surface from the light but not c_w changes nothing; without occluders the lower half still takes the shadowed
    branch (rays from x, not from p, which lies inside the asset). f = 0: the other way round."""
    on_centre_line = ((0.0, 1.5, 0.0), 0.16)  # blocks c_w's line to the light, no hit's line but those near the top
    off_centre_line = ((-0.45, 0.9, 0.0), 0.6)  # x in [-0.75, -0.15]: shadows the upper left of the sphere only
    free1, intensity = _lone_asset(tmp_path, 1.0, name="free")
    free0, _ = _lone_asset(tmp_path, 0.0, name="free")
    a1, _ = _lone_asset(tmp_path, 1.0, occluder=on_centre_line, name="a")
    a0, _ = _lone_asset(tmp_path, 0.0, occluder=on_centre_line, name="a")
    b1, _ = _lone_asset(tmp_path, 1.0, occluder=off_centre_line, name="b")
    b0, _ = _lone_asset(tmp_path, 0.0, occluder=off_centre_line, name="b")
    e = intensity / np.sum(LIGHT ** 2)
    # branch from x: upper half unshadowed, lower half shadowed, both with the light at c_w
    assert np.allclose(free1[12, 18:22], TU * e, rtol=1e-6)
    assert np.allclose(free1[28, 18:22], TS * e, rtol=1e-6)
    assert set(np.round(free1[free1 > 0] / e, 5)) >= {TU, TS}
    # occluder on the centre's line: f = 1 black everywhere; f = 0 mostly lit
    covered = free0 > 0
    assert np.all(a1 == 0.0)
    assert (a0[covered] > 0).mean() > 0.8
    # occluder off the centre's line: f = 1 unchanged; f = 0 loses the upper left
    assert np.allclose(b1, free1, rtol=1e-6, atol=0.0)
    lost = covered & (b0 == 0.0)
    assert lost.sum() > 20 and not (covered & (free1 == 0.0)).any()
    rows, cols = np.nonzero(lost)
    assert rows.mean() < 20 and cols.mean() < 20  # upper left of the image


def _on_floor(tmp_path, f, seed):
    """Constant-transport sphere resting on a white floor, a sun straight above: under it the floor is in its shadow,
    lit beyond. Camera low, looking at the sphere's lower half."""
    asset = constant_rna_asset(tmp_path / f"floor{f}.usdc", unshadowed=(0.1,) * 3, shadowed=(0.1,) * 3,
                               near_field_fetch=f)
    b = SceneBuilder()
    b.camera((0.0, -0.25, 3.0), (0.0, -0.25, 0.0), focal=70.0)
    b.quad("Floor", (0.0, -0.5, 0.0), 40.0, diffuse=(0.9, 0.9, 0.9))
    b.distant("Sun", (0.0, 1.0, 0.0), 3.0)
    b.asset("Obj", "./" + asset.name)
    scene = load_scene(b.write(tmp_path / f"floor{f}.usda"))
    r = render(scene, RenderSettings(width=32, height=32, spp=32, seed=seed, max_depth=2))
    return r.image[..., 0], r.variance[..., 0]


def test_continuation_from_the_fetch_point_sees_past_the_contact_shadow(tmp_path):
    """Continuation rays from p (f = 1: the centre) start higher above the floor than from the bottom of the
    sphere: they see less of the asset's shadow under it and more lit floor, so the lower band of the asset is
    brighter with f = 1 than with f = 0 (the sun's direct light, the same for both, is the shadowed branch there);
    the top, whose rays now start nearer the floor, darker. A statistical test: the difference of band means
    against its standard error (measured: about 13 standard errors in the lower band, 4 in the top one)."""
    img0, var0 = _on_floor(tmp_path, 0.0, seed=2)
    img1, var1 = _on_floor(tmp_path, 1.0, seed=3)

    def change(band):  # (mean with f = 1 - mean with f = 0) / its standard error
        se = np.sqrt(var0[band].sum() + var1[band].sum()) / img0[band].size
        return (img1[band].mean() - img0[band].mean()) / se

    assert change(np.s_[19:25, 10:22]) > 6  # the sphere's lower part, just above its contact with the floor
    assert change(np.s_[2:10, 10:22]) < 0


def test_fiber_hits_fetch_at_the_box_centre_too(tmp_path):
    """Fiber assets: f = 1 gives every fully covered fibre pixel the light at c_w (rays from p without offset); the
    centre is that of the asset's encoding box (domainMin, domainMax), moved by the instance."""
    from nasset_sdk.asset import Asset

    curves = [np.array([[x, -0.4, 0.0], [x + 0.05, 0.0, 0.1], [x, 0.4, 0.0]]) for x in (-0.3, 0.0, 0.3)]
    images = {}
    for f in (0.0, 1.0):
        asset = constant_rna_fiber_asset(tmp_path / f"fib{f}.usdc", curves, 0.12, unshadowed=(TU,) * 3,
                                         shadowed=(TU,) * 3, near_field_fetch=f)
        b = SceneBuilder()
        b.camera((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), focal=50.0)
        _point_light(b, LIGHT, 20.0)
        b.asset("Obj", "./" + asset.name, np.eye(4) + _shift(0.05, 0.1, 0.0))
        scene = load_scene(b.write(tmp_path / f"fib{f}.usda"))
        images[f] = render(scene, RenderSettings(width=32, height=32, spp=4, seed=1)).image[..., 0]
    lo, hi = Asset.open(tmp_path / "fib1.0.usdc", load="none").domain
    centre = 0.5 * (lo + hi) + [0.05, 0.1, 0.0]
    expected = TU * scene.lights[0].I[0] / np.sum((LIGHT - centre) ** 2)
    v1, v0 = images[1.0][images[1.0] > 0], images[0.0][images[0.0] > 0]
    assert v1.max() <= expected * (1 + 1e-6)
    assert np.isclose(v1, expected, rtol=1e-6).sum() > 20
    assert np.isclose(v0, expected, rtol=1e-6).mean() < 0.05


def _shift(x, y, z):
    m = np.zeros((4, 4))
    m[3, :3] = (x, y, z)
    return m


def test_invalid_fetch_in_a_referenced_asset_is_scene_invalid(tmp_path):
    """An asset file whose nasset:nearFieldFetch is outside [0, 1] (untrusted input) is SCENE_INVALID naming the prim,
    with the SDK's NEAR_FIELD_INVALID message."""
    bad = _with_fetch(constant_rna_asset(tmp_path / "c.usdc"), tmp_path / "bad.usdc", 1.5)
    b = SceneBuilder()
    b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0))
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    b.asset("Obj", "./" + bad.name)
    with pytest.raises(SceneError) as info:
        load_scene(b.write(tmp_path / "bad.usda"))
    assert info.value.code == "SCENE_INVALID"
    assert "/World/Obj" in str(info.value) and "nearFieldFetch" in str(info.value)


def test_plan_explains_the_fetch(tmp_path):
    """``--explain`` says where an asset with f > 0 takes its light; an asset without the attribute keeps its note."""
    from nasset_reference_renderer.plan import make_plan

    notes = {}
    for f in (0.0, 0.25):
        asset = constant_rna_asset(tmp_path / f"e{f}.usdc", near_field_fetch=f)
        b = SceneBuilder()
        b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0))
        b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
        b.asset("Obj", "./" + asset.name)
        plan = make_plan(load_scene(b.write(tmp_path / f"e{f}.usda")), width=8, height=8, spp=1, max_depth=5, tile=64,
                         batch=65536)
        notes[f] = plan.explain()
    assert "light fetched at x + 0.25 (c_w - x), branch from x" in notes[0.25]
    assert "near-field" not in notes[0.0]


@pytest.mark.parametrize("f", [0.5, 1.0])
def test_light_samples_and_continuations_agree_on_a_near_sphere_light(tmp_path, f):
    """Both estimators of the light reaching p from a large SphereLight close to the asset (its solid angle and pdf
    change several-fold between x and p) agree: the full render (light samples MIS-weighted with the continuations
    that leave from p and reach the light, weighted with its pdf seen from p) against light samples alone
    (max_depth 1, weight 1), within 4 standard errors of their sums (measured: 0.3-0.4 of one; one standard error
    is 0.4 % of the image, so a bias of 2 % fails). A tiny black quad far away turns continuations on. (The
    continuations reaching a sphere light carry little MIS weight: continuations left at x shift the sum by only
    one standard error here; test_continuation_from_the_fetch_point_sees_past_the_contact_shadow catches that.)"""
    asset = constant_rna_asset(tmp_path / "c.usdc", unshadowed=(TU,) * 3, shadowed=(TS,) * 3, subdivisions=2,
                               near_field_fetch=f)
    b = SceneBuilder()
    b.camera((0.0, 0.0, 3.0), (0.0, 0.0, 0.0))
    b.sphere_light("Bulb", (0.7, 0.7, 0.5), 0.4, 3.0)
    b.quad("Speck", (0.0, 0.0, -40.0), 0.01, normal=(0.0, 0.0, 1.0), diffuse=(0.0, 0.0, 0.0))
    b.asset("A", "./" + asset.name)
    scene = b.write(tmp_path / "scene.usda")
    full = render(load_scene(scene), RenderSettings(spp=256, width=16, height=16, seed=5, max_depth=3))
    direct = render(load_scene(scene), RenderSettings(spp=256, width=16, height=16, seed=6, max_depth=1))
    total = direct.image.sum((0, 1))
    diff = full.image.sum((0, 1)) - total
    se = np.sqrt(full.variance.sum((0, 1)) + direct.variance.sum((0, 1)))
    assert np.all(np.abs(diff) < 4 * se), (diff / total, se / total)
    assert np.all(se < 0.01 * total), se / total
