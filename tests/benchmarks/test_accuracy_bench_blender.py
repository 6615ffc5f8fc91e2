"""``nasset bench accuracy SCENE.blend`` (spec/accuracy.md#in-scene-accuracy): the Cycles side.

The assets have random networks (nasset_sdk.examples) with the geometry the Blender bake exports
for the example objects, so no training is needed. The mask Cycles gives is checked against the
reference renderer's own camera rays on the converted scene (an independent intersector).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")

from nasset_sdk.errors import NassetError  # noqa: E402


@pytest.fixture(scope="module")
def blend(tmp_path_factory):
    """The built-in Blender surface example saved as a .blend, as a user would have it."""
    from nasset_converters.blender.examples import write_example_blend

    return write_example_blend("blender-surface", tmp_path_factory.mktemp("acc_blend"))


def _asset(tmp_path, blend, names, *, variant="surface", name="a.usdc", shift=0.0):
    """A random-network asset with the geometry of these objects (as the Blender bake exports it)."""
    from nasset_converters.blender import scene as bsc
    from nasset_sdk.examples import example_builder

    bsc.open_blend(blend)
    b = example_builder("rna", variant=variant, size="tiny", seed=3)
    if variant == "surface":
        _, geo, _ = bsc.asset_geometry(bsc.pick_objects(names))
        geo.points = np.asarray(geo.points) + np.float32(shift)
        b.set_geometry(geo)
    return b.write(tmp_path / name)


def _run(blend, replace, out, **kw):
    from nasset_benchmarks.accuracy import bench_accuracy

    return bench_accuracy(blend, replace, out, quiet=True, **kw)


def test_unknown_object_and_wrong_variant_and_mismatch(blend, tmp_path):
    a = _asset(tmp_path, blend, ["Monkey"])
    with pytest.raises(NassetError) as e:
        _run(blend, [f"Monkee={a}"], tmp_path / "o", res=8, spp=2, nr_spp=1)
    assert e.value.code == "CONVERT_SHAPE_UNKNOWN" and "Monkey" in str(e.value)
    fiber = _asset(tmp_path, blend, [], variant="fiber", name="f.usdc")
    with pytest.raises(NassetError) as e:
        _run(blend, [f"Monkey={fiber}"], tmp_path / "o", res=8, spp=2, nr_spp=1)
    assert e.value.code == "BENCH_ASSET_KIND" and "fiber" in str(e.value)
    moved = _asset(tmp_path, blend, ["Monkey"], name="m.usdc", shift=0.5)
    with pytest.raises(NassetError) as e:
        _run(blend, [f"Monkey={moved}"], tmp_path / "o", res=8, spp=2, nr_spp=1)
    assert e.value.code == "BENCH_ASSET_MISMATCH"


@pytest.mark.parametrize("camera", ["none", "PANO"])
def test_a_scene_without_a_perspective_camera(blend, tmp_path, camera):
    """The Mitsuba side's rule (test_accuracy_bench.py): the Blender scene's active camera must be a perspective or
    orthographic one (a panoramic one is not converted).
    Without one Cycles stopped the bench with a RuntimeError traceback ("Cannot render, no camera")."""
    import bpy

    from nasset_converters.blender import scene as bsc

    a = _asset(tmp_path, blend, ["Monkey"])
    bsc.open_blend(blend)
    if camera == "none":
        bpy.context.scene.camera = None
    else:
        bpy.context.scene.camera.data.type = camera
    bad = tmp_path / "bad.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(bad), copy=True)
    with pytest.raises(NassetError) as e:
        _run(bad, [f"Monkey={a}"], tmp_path / "o", res=8, spp=2, nr_spp=1)
    assert e.value.code == "CONVERT_SCENE_LOAD" and "perspective" in str(e.value) and "bad.blend" in str(e.value)


def test_unknown_scene_type_and_missing_file(tmp_path):
    with pytest.raises(NassetError) as e:
        _run(tmp_path / "scene.obj", ["a=b.usdc"], tmp_path / "o")
    assert e.value.code == "USAGE"
    with pytest.raises(NassetError) as e:
        _run(tmp_path / "nope.blend", ["a=b.usdc"], tmp_path / "o")
    assert e.value.code == "CONVERT_SCENE_MISSING"


def _renderer_coverage(usd_path, hw, sub: int = 4) -> np.ndarray:
    """Fraction [H, W] of stratified camera rays whose first hit is a neural asset, by the reference renderer's intersector."""
    import warnings

    from nasset_reference_renderer import load_scene
    from nasset_reference_renderer.accel import Accel

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        sc = load_scene(str(usd_path))
    h, w = hw
    j, i = np.meshgrid(np.arange(w), np.arange(h))
    s = (np.arange(sub) + 0.5) / sub
    px = (j[..., None, None] + s[None, None, None, :]).repeat(sub, 2).reshape(-1)
    py = (i[..., None, None] + s[None, None, :, None]).repeat(sub, 3).reshape(-1)
    o, d = sc.camera.generate_rays(px, py, w, h)
    hits = Accel(sc.triangles, sc.tri_inst).trace(o, d)
    neural = np.array([inst.kind == "neural" for inst in sc.instances])
    hit = (hits.prim >= 0) & neural[sc.tri_inst[np.maximum(hits.prim, 0)]]
    return hit.reshape(h, w, sub * sub).mean(-1)


def test_tiny_run_mask_from_cycles_matches_the_geometry(blend, tmp_path):
    a = _asset(tmp_path, blend, ["Monkey"])
    out = tmp_path / "bench"
    r = _run(blend, [f"Monkey={a}"], out, res=32, spp=8, nr_spp=1)
    assert r["reference"]["renderer"].startswith("cycles") and r["reference"]["halves"] == 2
    for name in ("reference_a.exr", "reference_b.exr", "neural.exr", "mask.png", "error.png", "accuracy.md"):
        assert (out / name).is_file(), name
    o = r["object"]
    assert o["pixels"] == r["mask"]["pixels"] > 20 and all(np.isfinite(o["energy_ratio"]))
    from PIL import Image

    mask = np.asarray(Image.open(out / "mask.png"))[..., 0] > 127
    ours = _renderer_coverage(out / "scene_neural.usda", mask.shape) >= 0.5
    iou = (mask & ours).sum() / max((mask | ours).sum(), 1)
    assert iou > 0.85, iou  # a flipped, shifted or inverted mask gives far less


def test_depth_follows_the_scenes_bounce_limit(blend, tmp_path):
    """Cycles renders the reference with the scene's own bounce limit B and the reference renderer goes B + 1
    scattering vertices deep, the converted stage's nasset:maxDepth (spec/accuracy.md#in-scene-accuracy,
    spec/bake-blender.md#scene-conversion); a fixed 32/32 pair was one bounce short."""
    import bpy

    from nasset_converters.blender import scene as bsc

    bsc.open_blend(blend)
    bpy.context.scene.cycles.max_bounces = 3
    three = tmp_path / "three.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(three), check_existing=False)
    a = _asset(tmp_path, three, ["Monkey"])
    r = _run(three, [f"Monkey={a}"], tmp_path / "bench", res=8, spp=2, nr_spp=1)
    assert r["reference"]["integrator"]["max_bounces"] == 3
    assert r["estimate"]["max_depth"] == 4
    assert bpy.context.scene.cycles.max_bounces == bpy.context.scene.cycles.diffuse_bounces == 3  # as Cycles rendered
    r = _run(three, [f"Monkey={a}"], tmp_path / "bench2", res=8, spp=2, nr_spp=1, max_depth=2)
    assert r["estimate"]["max_depth"] == 2  # --max-depth still overrides


def test_ground_truth_settings_leave_no_biased_shortcut_on(blend):
    """Whatever the scene sets, the Cycles ground truth (``setup_cycles``: bench accuracy, bench blender, the
    fidelity scenes) renders without clamps, Filter Glossy (+15-19 % on the dense hair example), Fast GI or
    dropped caustics, and with the bounce limit for every bounce type."""
    import bpy

    from nasset_converters.blender import scene as bsc
    from nasset_converters.blender.cycles import setup_cycles

    bsc.open_blend(blend)
    c = bpy.context.scene.cycles
    c.blur_glossy, c.use_fast_gi, c.caustics_reflective, c.caustics_refractive = 1.0, True, False, False
    c.sample_clamp_direct = c.sample_clamp_indirect = 10.0
    c.glossy_bounces = c.volume_bounces = 1
    c.use_denoising = c.use_adaptive_sampling = True
    setup_cycles(bpy, 16, max_bounces=12)
    assert (c.blur_glossy, c.use_fast_gi, c.caustics_reflective, c.caustics_refractive) == (0.0, False, True, True)
    assert (c.sample_clamp_direct, c.sample_clamp_indirect, c.use_denoising, c.use_adaptive_sampling) == (0.0, 0.0, False, False)
    assert {c.max_bounces, c.diffuse_bounces, c.glossy_bounces, c.transmission_bounces, c.volume_bounces,
            c.transparent_max_bounces} == {12}
