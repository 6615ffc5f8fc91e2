"""The Mitsuba JIT plugin (``nasset_mitsuba_plugin``): rna evaluation against the SDK evaluator,
renders against a closed form and against the reference renderer's conformance references,
scenes mixing plain shapes and instanced assets, and typed errors for bad input."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.plugins import register  # noqa: E402
from nasset_mitsuba_plugin.render import render  # noqa: E402
from nasset_mitsuba_plugin.rna import RnaJit  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape, load_file  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_asset  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.errors import AssetReadError, NassetError, SceneError  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from nasset_sdk.networks import mlp_onnx  # noqa: E402

RENDER_CMD = [sys.executable, "-m", "nasset_mitsuba_plugin.render"]


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()  # any failure to load a JIT variant fails (setup installs libLLVM), never skips
    register(mi)
    return mi


def _vec(mi, a):
    return mi.Vector3f(*[mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)])


def _baked_style_asset(path, seed):
    """A tiny rna asset whose decoder is the bakers' model (angular features: Slice, ReduceSum, Sqrt, Div,
    Exp, Concat before the MLP) exported by torch with random weights."""
    import torch

    from nasset_bakers.train.rna import build_model, export_onnx

    torch.manual_seed(seed)
    model = build_model("tiny", init_std=0.5, seed=seed)
    for p in model.decoder.parameters():
        torch.nn.init.normal_(p, std=0.5)
    b = example_builder("rna", size="tiny", seed=seed)
    b.component("core").add_network("decoder", export_onnx(model))
    b.write(path)


@pytest.mark.parametrize("kind", ["tiny", "small", "baked"])
def test_rna_transport_matches_sdk_evaluator(mi, tmp_path, rng, kind):
    """Dr.Jit triplane + traced decoder = the SDK's numpy + onnxruntime evaluator on random inputs
    (points inside and outside the encoding box, unnormalised and zero directions), for the SDK's random
    MLPs and for the bakers' decoder graph. Tolerance 2e-4 (abs) + 2e-4 (rel): Dr.Jit's texture computes
    the bilinear fraction in float32 from (xn + 1) / 2, the SDK from the spec's formula, ~1e-5 apart on
    R = 64 planes."""
    path = tmp_path / f"rna_{kind}.usdc"
    seed = int(rng.integers(1 << 30))
    if kind == "baked":
        _baked_style_asset(path, seed)
    else:
        example_builder("rna", size=kind, seed=seed).write(path)
    sdk = Asset.open(path).evaluator()
    jit = RnaJit(mi, str(path))
    lo, hi = (np.asarray(v) for v in Asset.open(path).domain)
    n = 3000
    x = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (n, 3))
    frame, wo, wi = (rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, (n, 1)) for _ in range(3))
    frame[:5] = 0.0  # safe_normalize's fallback
    u_ref, s_ref = sdk.evaluate(x, frame, wo, wi)
    u, s = jit.transport(mi.Point3f(_vec(mi, x)), _vec(mi, frame), _vec(mi, wo), _vec(mi, wi))
    u, s = np.asarray(u.numpy()).T, np.asarray(s.numpy()).T
    assert np.abs(u_ref).max() > 0.1 and np.abs(s_ref).max() > 0.1  # the comparison sees real outputs
    np.testing.assert_allclose(u, u_ref, atol=2e-4, rtol=2e-4)
    np.testing.assert_allclose(s, s_ref, atol=2e-4, rtol=2e-4)


@pytest.mark.parametrize("lit_from_camera", [True, False])
def test_constant_asset_closed_form(tmp_path, lit_from_camera):
    """Lone convex asset, delta DistantLight of irradiance E: every visible point shows T E, with T the
    unshadowed output when the light is behind the camera and the shadowed one when it is behind the
    asset (the continuation from a lone asset reaches nothing)."""
    unsh, sh = (1.0, 0.5, 0.25), (0.1, 0.2, 0.3)
    asset = constant_rna_asset(tmp_path / "const.usda", unshadowed=unsh, shadowed=sh)
    e = 2.5
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 0, 1) if lit_from_camera else (0, 0, -1), e)
    b.asset("A", asset)
    img = render(b.write(tmp_path / "scene.usda"), 4, width=16, height=16, seed=3)
    cover = img / (e * np.asarray(unsh if lit_from_camera else sh))
    assert np.allclose(cover, cover[..., :1], atol=1e-5), "pixels are not multiples of T E"
    assert cover.max() == pytest.approx(1.0, abs=1e-5)
    assert (cover[..., 0] > 0.999).sum() > 20  # the asset covers whole pixels


def test_light_surface_after_an_asset_is_not_the_asset(tmp_path):
    """A sphere light registered after the asset (USD scenes add lights last), seen by the camera next
    to a constant asset: its pixels show its radiance Le exactly (a light surface ends the path,
    spec/renderer.md#light-surfaces). A shape id past the asset table read as the last asset once added
    the asset's transport lit by the light there (+3 % green in rna_sphere_light)."""
    asset = constant_rna_asset(tmp_path / "const.usda", unshadowed=(1.0, 0.5, 0.25), shadowed=(0.1, 0.2, 0.3))
    le = np.array([3.0, 2.0, 1.0])
    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0))
    left = np.eye(4)
    left[3, 0] = -0.8  # USD row-vector translation
    b.asset("A", asset, left)
    b.sphere_light("Bulb", (0.8, 0.0, 0.0), 0.4, 1.0, color=tuple(le))
    img = render(b.write(tmp_path / "scene.usda"), 4, width=32, height=16, seed=2)
    bulb = img[6:10, 24:28].reshape(-1, 3)  # the light's centre, away from its silhouette
    np.testing.assert_allclose(bulb, np.broadcast_to(le, bulb.shape), rtol=1e-5)
    assert img[5:11, 6:11, 0].mean() > 0.3  # the asset beside it is lit


@pytest.mark.parametrize("max_depth", [1, 2])
def test_max_depth_counts_scattering_vertices(tmp_path, max_depth):
    """``max_depth`` of the render command counts scattering vertices (spec/renderer.md#integrator): 1 is
    direct lighting, so a Lambertian quad under an overhead delta light of irradiance E shows rho E / pi
    (F0 = 0, viewed and lit along the normal: no specular term), and 2 adds nothing to a lone quad."""
    rho, e = 0.5, 2.0
    b = SceneBuilder()
    b.camera((0, 3, 0), (0, 0, 0))
    b.quad("Floor", (0, 0, 0), 4.0, diffuse=(rho, rho, rho), specular=(0.0, 0.0, 0.0))
    b.distant("Sun", (0, 1, 0), e)
    img = render(b.write(tmp_path / "scene.usda"), 2, width=8, height=8, seed=1, max_depth=max_depth)
    np.testing.assert_allclose(img[2:6, 2:6], rho * e / np.pi, rtol=1e-4)


def test_scene_far_from_origin_renders_like_at_the_origin(tmp_path):
    """A scene whose bounding box is centred on the origin (a constant asset resting on a floor, light
    from the side), and the same scene under a /World translation of (700, 100, -700): the renderer
    recentres it, so both render the same image with the same seed (1e-4). Without recentring, Mitsuba's
    ray offset (1 + max |p|) * RayEpsilon is about 0.09 there and the contact shadow changes."""
    from pxr import Gf, UsdGeom

    asset = constant_rna_asset(tmp_path / "const.usda", unshadowed=(1.0, 0.5, 0.25), shadowed=(0.1, 0.2, 0.3))
    images = []
    for shift in (None, (700.0, 100.0, -700.0)):
        b = SceneBuilder()
        if shift is not None:
            UsdGeom.Xformable(b.stage.GetPrimAtPath("/World")).AddTranslateOp().Set(Gf.Vec3d(*shift))
        b.camera((0, 1, 2), (0, -0.5, 0))  # with the floor: bounding box [-2, 2] x [-1, 1] x [-2, 2]
        b.quad("Floor", (0, -1, 0), 4.0, diffuse=(0.5, 0.5, 0.5))
        b.distant("Sun", (0.8, 0.5, 0.3), 3.0)
        b.asset("A", asset, np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, -0.5, 0, 1]], np.float64))
        images.append(render(b.write(tmp_path / f"scene{len(images)}.usda"), 4, width=32, height=32, seed=1))
    assert images[0].max() > 0.1
    np.testing.assert_allclose(images[1], images[0], atol=1e-4)


def _asset_without(tmp_path, kind: str, name: str):
    """Path of a tiny example asset of ``kind`` whose prims named ``name`` (a tensor or network) were removed
    after writing, as an edit by another tool would."""
    from pxr import Sdf

    path = tmp_path / f"{kind}_without_{name}.usdc"
    example_builder(kind, size="tiny", seed=3).write(path)
    layer = Sdf.Layer.FindOrOpen(str(path))
    found = []
    layer.Traverse(Sdf.Path.absoluteRootPath, lambda p: found.append(p) if p.IsPrimPath() and p.name == name else None)
    assert found
    for p in found:
        del layer.GetPrimAtPath(p.GetParentPath()).nameChildren[p.name]
    layer.Save()
    return path


def _run_case(name, tmp_path, spp_scale=1):
    from nasset_sdk.conformance import find_suite, load_cases, run_case

    (case,) = load_cases(find_suite(), [name])
    template = " ".join(RENDER_CMD) + " {scene} {out} --spp {spp} --width {width} --height {height} --seed {seed}"
    return run_case(case, template, tmp_path, seed=0, timeout=300, spp_scale=spp_scale)


@pytest.mark.parametrize("case", ["rna_instances_transforms", "rna_shadow_on_asset", "rna_distant_angle", "rna_scale_tiny",
                                  "rna_sphere_light", "rna_near_field_fetch", "rna_beckmann", "rna_light_spread", "rna_spot_radius",
                                  "neupress_distant",
                                  "neupress_near_field_fetch",
                                  pytest.param("neupress_direct", marks=pytest.mark.slow)])
def test_conformance_cases(tmp_path, case):
    """The plugin passes conformance cases through the ``nasset conformance`` machinery (reference:
    the reference renderer at the case's ref_spp; tolerance from the case's measured noise)."""
    row = _run_case(case, tmp_path)
    assert row["passed"], row


def test_mixed_scene_with_two_instances(mi, tmp_path):
    """A dict scene with a plain floor, a plain sphere and two instances of one asset (one mirrored
    and scaled) renders finite, both instances lit, and the floor darker where they shadow it."""
    path = tmp_path / "rna.usdc"
    example_builder("rna", size="tiny", seed=5).write(path)
    t = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45, "to_world": t().look_at(origin=[0, 2.5, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 48, "height": 32, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": t().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(4),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
        "ball": {"type": "sphere", "center": [0, 0, -1.2], "radius": 0.4, "bsdf": {"type": "diffuse"}},
        "left": asset_shape(path, t().translate([-0.9, 0, 0]), mi=mi),
        "right": asset_shape(path, t().translate([0.9, 0.1, 0]).scale([-1.2, 0.8, 1.0]), mi=mi),
        "sun": {"type": "directional", "direction": [0, -1, 0], "irradiance": {"type": "rgb", "value": 3.0}},
    })
    integ = mi.load_dict({"type": "nasset_path", "max_depth": 4})
    img = np.asarray(mi.render(scene, integrator=integ, spp=16, seed=1))
    assert img.shape == (32, 48, 3) and np.isfinite(img).all()
    lum = img.mean(-1)
    # plain path tracing: open Lambertian floor far behind = rho E / pi (indirect light there is < 1 %)
    assert np.median(lum[6:8]) == pytest.approx(0.5 * 3.0 / np.pi, rel=0.02)
    # both instances are lit by their transports
    assert lum[14:18, 8:14].mean() > 0.5 and lum[14:18, 34:42].mean() > 0.5
    # the floor below each instance lies in its shadow (the sun is overhead)
    assert lum[20:24, 8:18].mean() < 0.6 * np.median(lum[6:8]) and lum[20:24, 30:40].mean() < 0.6 * np.median(lum[6:8])



@pytest.mark.parametrize("sides", ["double", "one", "back_material", "mirrored"])
def test_reflection_of_each_side_as_the_spec_says(tmp_path, sides):
    """A Lambertian quad lit and seen along its normal, from its front and from its back, shows rho E / pi on a side
    that reflects (spec/renderer.md#sidedness): both sides of a double-sided quad, the front alone of a one-sided one
    (its back ends the path: 0), the back material's rho_b on the back, and the front of its own space on a mirrored
    one-sided prim. The plugin shaded both sides with the front material before (doubleSided and backMaterial
    dropped silently)."""
    from pxr import UsdGeom

    rho, rho_b, e = 0.5, 0.2, 2.0
    out = {}
    for toward in (1.0, -1.0):  # the quad's own front (+z, counter-clockwise winding) toward the camera, then away
        b = SceneBuilder()
        b.camera((0, 0, 3), (0, 0, 0))
        b.distant("Sun", (0, 0, 1), e)
        m = np.eye(4)
        if sides == "mirrored":
            m[0, 0] = -1.0
        pts = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
        q = b.mesh("Quad", pts, [[0, 1, 2, 3]] if toward > 0 else [[0, 3, 2, 1]], matrix=m, diffuse=(rho, rho, rho),
                   specular=(0.0, 0.0, 0.0))
        if sides in ("one", "mirrored"):
            UsdGeom.Mesh(q.GetPrim()).CreateDoubleSidedAttr(False)
        if sides == "back_material":
            back = b.material("BackLook", diffuse=(rho_b, rho_b, rho_b))
            q.GetPrim().CreateRelationship("nasset:backMaterial").AddTarget(back.GetPath())
        out[toward] = render(b.write(tmp_path / f"quad_{toward}.usda"), 4, width=8, height=8, seed=1, max_depth=1)[4, 4]
    expect_back = {"double": rho, "one": 0.0, "back_material": rho_b, "mirrored": 0.0}[sides] * e / np.pi
    np.testing.assert_allclose(out[1.0], rho * e / np.pi, rtol=1e-4)
    np.testing.assert_allclose(out[-1.0], expect_back, rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("sides", ["double", "one", "back_material", "mirrored"])
def test_emission_leaves_the_sides_the_spec_says(tmp_path, sides):
    """An emissive quad seen from its front and from its back (spec/renderer.md#sidedness): a double-sided one emits
    E on both, a one-sided one on its front only, one with a back material emits that material's emission on its
    back, and a mirrored one-sided prim keeps the front of its own space (its world winding reversed). Mitsuba's
    ``area`` emitter lit the winding's side only: the back of a double-sided quad rendered 0."""
    from pxr import UsdGeom

    e, e_back = 2.0, 0.5
    out = {}
    for toward in (1.0, -1.0):  # the quad's own front (+z, counter-clockwise winding) toward the camera, then away
        b = SceneBuilder()
        b.camera((0, 0, 3), (0, 0, 0))
        m = np.eye(4)
        if sides == "mirrored":
            m[0, 0] = -1.0
        pts = np.array([[-0.5, -0.5, 0.0], [0.5, -0.5, 0.0], [0.5, 0.5, 0.0], [-0.5, 0.5, 0.0]])
        q = b.mesh("Lamp", pts, [[0, 1, 2, 3]] if toward > 0 else [[0, 3, 2, 1]], matrix=m, diffuse=(0.0, 0.0, 0.0),
                   emission=(e, e, e))
        if sides in ("one", "mirrored"):
            UsdGeom.Mesh(q.GetPrim()).CreateDoubleSidedAttr(False)
        if sides == "back_material":
            back = b.material("BackLook", diffuse=(0.0, 0.0, 0.0), emission=(e_back, e_back, e_back))
            q.GetPrim().CreateRelationship("nasset:backMaterial").AddTarget(back.GetPath())
        img = render(b.write(tmp_path / f"lamp_{toward}.usda"), 4, width=8, height=8, seed=1, max_depth=1)
        out[toward] = img[4, 4]
    expect_back = {"double": e, "one": 0.0, "back_material": e_back, "mirrored": 0.0}[sides]
    np.testing.assert_allclose(out[1.0], e, rtol=1e-5)
    np.testing.assert_allclose(out[-1.0], expect_back, rtol=1e-5, atol=1e-6)


def test_a_double_sided_mesh_light_is_sampled_from_its_back(tmp_path):
    """Light sampling of mesh emission (spec/renderer.md#mesh-lights): a diffuse floor under a double-sided emissive
    quad gets the same direct light whether the quad's winding faces the floor or away from it (floor means within
    3 %; their standard errors are about 0.5 % at 32 spp). With Mitsuba's ``area`` emitter the floor under its back
    was black."""
    means = []
    for down in (True, False):
        b = SceneBuilder()
        b.camera((0, 1.5, 3), (0, 0, 0))
        b.quad("Floor", (0, 0, 0), 3.0, diffuse=(0.5, 0.5, 0.5))
        b.quad("Lamp", (0, 1, 0), 0.6, normal=(0, -1, 0) if down else (0, 1, 0), diffuse=(0.0, 0.0, 0.0), emission=(3.0, 3.0, 3.0))
        img = render(b.write(tmp_path / f"mesh_light_{down}.usda"), 32, width=16, height=16, seed=2, max_depth=1)
        means.append(float(img[12:, :, 0].mean()))
    assert means[0] > 0.01
    assert means[1] == pytest.approx(means[0], rel=0.03), means

# -- bad input -------------------------------------------------------------------------------------


def test_missing_asset_file(mi, tmp_path):
    with pytest.raises(AssetReadError) as exc:
        asset_shape(tmp_path / "nope.usdc", mi=mi)
    assert exc.value.code == "FILE_NOT_FOUND" and "nope.usdc" in str(exc.value)


def test_load_file_refuses_arguments_that_are_not_paths(mi, tmp_path, rna_asset_path):
    """``load_file(None)`` and a ``replace`` value that is not a path were bare TypeErrors."""
    from nasset_mitsuba_plugin.scene import load_file
    from nasset_sdk.errors import UsageError

    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><shape type="sphere" id="ball"/></scene>')
    with pytest.raises(UsageError, match="the scene must be a file path"):
        load_file(None, mi=mi)
    with pytest.raises(UsageError, match=r"replace\['ball'\] must be a file path"):
        load_file(tmp_path / "s.xml", mi=mi, replace={"ball": None})
    assert load_file(tmp_path / "s.xml", mi=mi, replace={"ball": str(rna_asset_path)}) is not None


def test_invalid_asset_file(mi, tmp_path):
    bad = tmp_path / "bad.usdc"
    bad.write_bytes(b"PXR-USDC not really a crate")
    with pytest.raises(AssetReadError) as exc:
        asset_shape(bad, mi=mi)
    assert exc.value.code == "FILE_UNREADABLE"


def test_network_failing_the_runtime_probe_is_not_evaluated(mi, tmp_path):
    """A decoder with NaN outputs on probe inputs: refused before DrJit evaluates it (spec/security.md#networks)."""
    from pxr import Sdf, Usd

    from tests.corpus.gen_networks import DEC, _output_family
    from tests.corpus.make_corpus import _set_model

    base = example_builder("rna", size="tiny", seed=0).write(tmp_path / "base.usdc")
    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
    with Usd.EditContext(stage, layer):
        _set_model(stage, DEC, _output_family()["out_log_negative_nan"].SerializeToString())
        stage.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(17)
    assert layer.Export(str(tmp_path / "nan.usdc"))
    with pytest.raises(NassetError) as exc:
        asset_shape(tmp_path / "nan.usdc", mi=mi)
    assert exc.value.code == "NETWORK_OUTPUT" and exc.value.prim.endswith("/core/decoder")


def test_wrong_kind(mi, tmp_path, monkeypatch):
    """Every kind of the format has a Dr.Jit class now; a kind without one (here neupress, taken out of the
    table as a future kind would be missing from it) is SCENE_UNSUPPORTED naming it, not a KeyError."""
    from nasset_mitsuba_plugin import plugins

    monkeypatch.delitem(plugins.JIT_KINDS, "neupress")
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=1).write(path)
    with pytest.raises(SceneError) as exc:
        asset_shape(path, mi=mi)
    assert exc.value.code == "SCENE_UNSUPPORTED" and "neupress" in exc.value.message


def test_decoder_the_plugin_cannot_run(mi, tmp_path, rng):
    """A valid rna asset whose decoder ends in a Softsign (in the format's allow-list, not among the operators the plugin runs)."""
    b = example_builder("rna", size="tiny", seed=2)
    w = [rng.normal(size=(16, 8)).astype(np.float32), rng.normal(size=(8, 6)).astype(np.float32)]
    b.component("core").add_network("decoder", mlp_onnx(w, [np.zeros(8, np.float32), np.zeros(6, np.float32)],
                                                        output_activation="Softsign"))
    path = tmp_path / "sig.usdc"
    b.write(path)
    with pytest.raises(SceneError) as exc:
        asset_shape(path, mi=mi)
    assert exc.value.code == "SCENE_UNSUPPORTED" and "Softsign" in exc.value.message


def test_xml_scene(mi, tmp_path, rna_asset_path):
    """``<shape type="nasset">`` in a Mitsuba XML scene; without a filename: SCENE_INVALID."""
    xml = textwrap.dedent(f"""\
        <scene version="3.0.0">
          <sensor type="perspective"><float name="fov" value="40"/>
            <transform name="to_world"><lookat origin="0,0,3" target="0,0,0" up="0,1,0"/></transform>
            <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="16"/></film></sensor>
          <shape type="nasset" id="a"><string name="filename" value="{rna_asset_path}"/>
            <transform name="to_world"><scale value="1.5"/></transform></shape>
          <emitter type="directional"><vector name="direction" value="0,0,-1"/></emitter>
        </scene>""")
    (tmp_path / "ok.xml").write_text(xml)
    scene = load_file(tmp_path / "ok.xml", mi=mi)
    img = np.asarray(mi.render(scene, integrator=mi.load_dict({"type": "nasset_path"}), spp=2))
    assert np.isfinite(img).all() and img.max() > 0
    (tmp_path / "bad.xml").write_text(xml.replace(f'<string name="filename" value="{rna_asset_path}"/>', ""))
    with pytest.raises(SceneError) as exc:
        load_file(tmp_path / "bad.xml", mi=mi)
    assert exc.value.code == "SCENE_INVALID" and exc.value.prim == "a"


@pytest.mark.parametrize("integrator, warns", [
    ('<integrator type="path"/>', True),
    ('<integrator type="volpath"/>', True),
    ('<integrator type="nasset_path"/>', False),
    ('<integrator type="aov"><string name="aovs" value="d:depth"/><integrator type="nasset_path"/></integrator>', False),
    ("", False),  # none: Mitsuba asks for one when rendering
])
def test_a_scene_integrator_that_renders_assets_black_is_warned(mi, tmp_path, rna_asset_path, integrator, warns):
    """Any integrator but ``nasset_path`` shades the ``nasset`` BSDF black (measured: the asset's pixel 0 under
    ``path``, 0.11 / 0.25 / 0.27 under ``nasset_path``); a user scene with ``path`` rendered its assets black silently."""
    import warnings

    (tmp_path / "s.xml").write_text(
        f'<scene version="3.0.0">{integrator}<shape type="nasset"><string name="filename" value="{rna_asset_path}"/>'
        '</shape><emitter type="constant"/></scene>')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        load_file(tmp_path / "s.xml", mi=mi)
        load_file(tmp_path / "s.xml", mi=mi, own_integrator=True)  # a caller rendering with its own nasset_path
    said = [str(w.message) for w in caught if "does not shade neural assets" in str(w.message)]
    assert len(said) == (1 if warns else 0), said


def test_not_a_jit_variant():
    with pytest.raises(NassetError) as exc:
        jit_mitsuba("scalar_rgb")
    assert exc.value.code == "CONVERT_BACKEND"


def test_no_llvm_gives_typed_error(tmp_path, rna_asset_path):
    """Without a usable libLLVM the command line reports CONVERT_BACKEND, not a Dr.Jit traceback."""
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 0, 1), 1.0)
    b.asset("A", str(rna_asset_path))
    scene = b.write(tmp_path / "scene.usda")
    env = dict(os.environ, DRJIT_LIBLLVM_PATH=str(tmp_path / "no-libLLVM.so"))
    proc = subprocess.run(RENDER_CMD + [scene, str(tmp_path / "o.exr"), "--spp", "1"], env=env, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert "[CONVERT_BACKEND]" in proc.stderr and "Traceback" not in proc.stderr


def test_scene_files_are_removed_when_the_process_ends(tmp_path, rna_asset_path):
    """The PLY files a USD scene's meshes and assets are written to (Mitsuba scene dicts name meshes by file) are in one
    folder per process, removed at exit; every process that rendered a USD scene left its folder in the temporary
    directory before (a conformance run: one per case), each mesh numbered by listing the folder (a scene of 3000 meshes
    took 12 s to build, a second one 31 s; now 5.3 and 3.4 s)."""
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 0, 1), 1.0)
    for k in range(3):
        b.quad(f"Q{k}", (k - 1.0, -0.6, 0.0), 0.5)
    b.asset("A", str(rna_asset_path))
    scene = b.write(tmp_path / "scene.usda")
    code = ("import sys; from nasset_mitsuba_plugin.scene import usd_scene, _cache_dir; "
            "a = usd_scene(sys.argv[1]); b = usd_scene(sys.argv[1]); "
            "files = [e['filename'] for d in (a, b) for e in d.values() if isinstance(e, dict) and 'filename' in e]; "
            "print(_cache_dir()); print(len(files), len(set(files)))")
    proc = subprocess.run([sys.executable, "-c", code, scene], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    folder, counts = proc.stdout.split()[-3], proc.stdout.split()[-2:]
    assert counts == ["8", "7"], counts  # 3 meshes per scene, the asset's fallback mesh shared by both
    assert not os.path.exists(folder), os.listdir(folder)


def test_asset_without_the_triplane(mi, tmp_path):
    """An rna asset whose core component lost its triplane (edited after writing): the SDK's
    TENSOR_MISSING naming it, not a Dr.Jit error."""
    with pytest.raises(NassetError) as exc:
        asset_shape(_asset_without(tmp_path, "rna", "triplane"), mi=mi)
    assert exc.value.code == "TENSOR_MISSING" and "triplane" in exc.value.message


def test_replace_finds_shapes_declared_in_included_files(mi, tmp_path, rna_asset_path):
    """``load_file(replace=...)`` (``bench error-vs-time SCENE --replace``) replaced shapes of the top file only: a shape
    an ``<include>`` declares gave CONVERT_SHAPE_UNKNOWN, though convert-scene, bakes and the accuracy bench find it.
    Included files are inlined first, their relative mesh paths kept next to them."""
    (tmp_path / "parts" / "deeper").mkdir(parents=True)
    (tmp_path / "parts" / "deeper" / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "parts" / "deeper" / "props.xml").write_text(
        '<scene version="3.0.0"><shape type="obj" id="prop"><string name="filename" value="tri.obj"/></shape>'
        '<shape type="obj" id="kept"><string name="filename" value="tri.obj"/></shape></scene>')
    (tmp_path / "parts" / "set.xml").write_text('<scene version="3.0.0"><include filename="deeper/props.xml"/></scene>')
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><integrator type="nasset_path"/><sensor type="perspective"><film type="hdrfilm">'
        '<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>'
        '<include filename="parts/set.xml"/></scene>')
    scene = load_file(tmp_path / "s.xml", mi=mi, replace={"prop": str(rna_asset_path)})
    ids = sorted(s.id() for s in scene.shapes())
    assert "prop" not in ids and "kept" in ids and any(i.startswith("nasset_asset") for i in ids)


def test_replace_refuses_a_shape_inside_a_shapegroup(mi, tmp_path, rna_asset_path):
    """As convert-scene, bakes and the accuracy bench do (they do not see such a shape as one of the scene's): the XML
    replacement took the shape out of the group, so every instance lost it."""
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><integrator type="nasset_path"/><shape type="shapegroup" id="g"><shape type="sphere" '
        'id="ball"/></shape><shape type="instance" id="i"><ref id="g"/></shape></scene>')
    with pytest.raises(SceneError) as exc:
        load_file(tmp_path / "s.xml", mi=mi, replace={"ball": str(rna_asset_path)})
    assert exc.value.code == "CONVERT_SHAPE_UNKNOWN" and "shapegroup 'g'" in exc.value.message


def test_an_asset_rewritten_in_place_is_read_again(tmp_path):
    """The plugin cached assets and their fallback meshes by path: a bake to the same path rendered the old asset in
    the same process (tests/stage_scenes.py::check_rewritten_asset_is_read_again); the cache now keys the file's
    version (mtime, size, inode)."""
    from tests.stage_scenes import check_rewritten_asset_is_read_again

    check_rewritten_asset_is_read_again(lambda scene, spp, w, h: render(scene, spp, width=w, height=h, max_depth=1),
                                        tmp_path)
