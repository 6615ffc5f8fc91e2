"""``nasset bench 8dna --light X,Y,Z`` and the figures over the blob's own pixels (spec/bake-8dna.md#weight-average):
the light is checked before any work, the blob's pixels are the ones an independent ray cast puts on the blob and not
on the lamp, and the blob figures recover a known bias and energy."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_sdk.errors import NassetError  # noqa: E402

BACKLIT = (0.25, -0.10, -0.25)
IN_VIEW = (-0.30, 0.15, 0.20)  # left of the blob and in front of it: the lamp is in the picture


def test_lights_inside_the_blobs_box_or_not_three_finite_numbers_are_refused(tmp_path):
    from nasset_benchmarks.eightdna import bench_8dna, check_light
    from nasset_sdk.cli import main

    assert check_light(BACKLIT) == BACKLIT
    for bad in ((0.0, 0.0, 0.0), (0.21, 0.0, 0.0), (1.0, 2.0), (np.nan, 1.0, 1.0), "abc", None):
        with pytest.raises(NassetError) as exc:
            check_light(bad)
        assert exc.value.code == "USAGE"
    with pytest.raises(NassetError):  # before any bake or render
        bench_8dna(tmp_path / "o", size="tiny", light=(0.0, 0.1, 0.0), quiet=True)
    assert not (tmp_path / "o").exists()  # nothing written, not even the output folder
    with pytest.raises(SystemExit) as stop:  # argparse: exit code 2
        main(["bench", "8dna", "--light", "1,2", "-o", str(tmp_path / "p")])
    assert stop.value.code == 2 and not (tmp_path / "p").exists()


def test_blob_pixels_are_the_blob_and_never_the_lamp():
    """Against an independent cast: the bench's own camera rays (numpy) through pixel centres, intersected with the
    blob mesh (trimesh) and the lamp sphere (analytic)."""
    from trimesh.ray import ray_pyembree

    from nasset_benchmarks.eightdna import _mi_sensor, blob_pixels, camera_rays
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.eightdna_example import CAMERA, LIGHT_RADIUS, blob_mesh, write_example_scene

    res = 32
    mi = load_mitsuba()
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        scene = mi.load_file(str(write_example_scene(folder, res=res, light_center=IN_VIEW)))
        mask = blob_pixels(mi, scene, _mi_sensor(mi, res, CAMERA), res)

    class Half:  # pixel centres
        def random(self, n):
            return np.full(n, 0.5)

    o, d, _ = camera_rays(res, Half(), CAMERA)
    mesh = blob_mesh()
    hit_blob = np.zeros(len(d), bool)
    loc, idx, _ = ray_pyembree.RayMeshIntersector(mesh).intersects_location(o, d, multiple_hits=False)
    hit_blob[idx] = True
    t_blob = np.full(len(d), np.inf)
    t_blob[idx] = np.linalg.norm(loc - o[idx], axis=1)
    oc = o - np.asarray(IN_VIEW)
    b = (oc * d).sum(1)
    disc = b * b - ((oc * oc).sum(1) - LIGHT_RADIUS**2)
    t_lamp = np.where(disc >= 0, -b - np.sqrt(np.maximum(disc, 0)), np.inf)
    lamp_first = (t_lamp > 0) & (t_lamp < t_blob)
    assert lamp_first.sum() >= 2, "the lamp must be in view for this test"
    mask = mask.ravel()
    assert mask.sum() > 0.5 * hit_blob.sum()  # most blob pixels are whole blob pixels at 32 x 32
    assert not (mask & ~hit_blob).any() and not (mask & lamp_first).any()


def test_blob_figures_recover_a_known_bias_and_energy():
    from nasset_benchmarks.eightdna import blob_figures

    rng = np.random.default_rng(0)
    gt = rng.uniform(0.5, 1.5, (20, 20, 3))
    blob = np.zeros((20, 20), bool)
    blob[5:15, 4:12] = True
    img = gt * np.array([1.1, 1.0, 0.9])
    img[~blob] += 100.0  # outside the blob: ignored
    var = np.full_like(gt, 2e-3)
    noise = np.full_like(gt, 1e-3)
    f = blob_figures(img, var, gt, noise, blob)
    assert f["pixels"] == 80
    np.testing.assert_allclose(f["energy"], [1.1, 1.0, 0.9], rtol=1e-12)
    want = float(np.mean((img[blob] - gt[blob]) ** 2))
    np.testing.assert_allclose(f["mse_minus_variance"], want - 2e-3, rtol=1e-12)
    np.testing.assert_allclose(f["bias2"], want - 3e-3, rtol=1e-12)
    assert blob_figures(img, var, gt, None, blob)["bias2"] is None


def test_a_backlit_bench_reports_the_blob_figures(tmp_path):
    """The light moved behind the blob: the scene, the report and its markdown carry it, and the converged rows have
    their figures over the blob (random assets of the blob's geometry: nothing is trained, the numbers are not
    judged)."""
    from nasset_benchmarks.eightdna import bench_8dna, summary_markdown
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS, write_example_scene
    from nasset_sdk.examples import example_builder

    mi = load_mitsuba()
    sc = msc.load_scene(mi, write_example_scene(tmp_path / "geo"))
    geo = msc.mesh_geometry(mi, msc.pick_shapes(sc, list(EXAMPLE_ASSET_IDS)))
    paths = {}
    for name, model in (("eight", "8D"), ("six", "6D far-field baseline")):
        b = example_builder("8dna", size="tiny", seed=2)
        b.set_geometry(geo)
        b.provenance = {**(b.provenance or {}), "model": model}
        paths[name] = b.write(tmp_path / f"{name}.usdc")
    r = bench_8dna(tmp_path / "o", asset=paths["eight"], farfield=paths["six"], res=16, spp=2, gt_spp=4, converged_spp=4,
                   light=BACKLIT, quiet=True)
    assert r["light"]["center"] == list(BACKLIT)
    assert "0.25, -0.1, -0.25" in (tmp_path / "o" / "scene" / "scene.xml").read_text()
    assert r["reference"]["blob_pixels"] > 0 and r["reference"]["noise_variance_blob"] >= 0
    for row in r["table"][1:3]:
        blob = row["converged"]["blob"]
        assert blob["pixels"] == r["reference"]["blob_pixels"] and np.isfinite(blob["energy"]).all()
        assert np.isfinite(blob["bias2"])
    assert "Over the blob's" in summary_markdown(r)
    with np.load(tmp_path / "o" / "bench_8dna_images.npz") as z:
        assert z["reference_noise_map"].shape == (16, 16, 3)
    # the images file is a reference of that light: reused under another light it is refused, under the same one taken
    npz = tmp_path / "o" / "bench_8dna_images.npz"
    kw = dict(asset=paths["eight"], farfield=paths["six"], res=16, spp=2, gt_spp=4, converged_spp=4, quiet=True)
    with pytest.raises(NassetError) as exc:
        bench_8dna(tmp_path / "o2", reference_npz=npz, **kw)
    assert exc.value.code == "USAGE" and "0.25,-0.1,-0.25" in exc.value.message
    again = bench_8dna(tmp_path / "o3", reference_npz=npz, light=BACKLIT, **kw)
    assert again["reference"]["noise_variance_blob"] == pytest.approx(r["reference"]["noise_variance_blob"], rel=1e-6)
