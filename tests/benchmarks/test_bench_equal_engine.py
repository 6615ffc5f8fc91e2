"""Smoke test of ``nasset bench error-vs-time SCENE.xml --replace ID=ASSET`` (the equal-engine benchmark)
at toy scale (16x16), and its typed errors. A tiny random rna asset with the ball's geometry stands in for a
bake, so the numbers mean nothing; the pipeline (reference halves, both curves, variance subtraction, floor,
cost ratio, plot, JSON) runs whole."""

from __future__ import annotations

import json
import math
import textwrap

import pytest

pytest.importorskip("mitsuba")

from nasset_sdk.errors import NassetError  # noqa: E402

SCENE = textwrap.dedent("""\
    <scene version="3.0.0">
      <integrator type="path"><integer name="max_depth" value="4"/></integrator>
      <sensor type="perspective"><float name="fov" value="40"/>
        <transform name="to_world"><lookat origin="0,1,3" target="0,0,0" up="0,1,0"/></transform>
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film></sensor>
      <shape type="sphere" id="ball"><float name="radius" value="0.5"/><bsdf type="diffuse"/></shape>
      <shape type="rectangle" id="floor"><transform name="to_world"><rotate x="1" angle="-90"/><translate y="-0.5"/>
        <scale value="3"/></transform><bsdf type="diffuse"/></shape>
      <emitter type="directional"><vector name="direction" value="0.3,-1,-0.2"/></emitter>
      <emitter type="constant"><rgb name="radiance" value="0.2"/></emitter>
    </scene>""")


@pytest.fixture
def rna_asset_path(tmp_path):
    """A random-network rna asset whose geometry is SCENE's ball (as a bake of it stores it)."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_sdk.examples import example_builder

    mi = load_mitsuba()
    (tmp_path / "ball_scene.xml").write_text(SCENE)
    sc = msc.load_scene(mi, tmp_path / "ball_scene.xml")
    b = example_builder("rna", size="tiny", seed=1)
    b.set_geometry(msc.mesh_geometry(mi, msc.pick_shapes(sc, ["ball"])))
    return b.write(tmp_path / "ball_rna.usdc")


def test_equal_engine_smoke(tmp_path, rna_asset_path, capsys):
    from nasset_sdk.cli import main

    (tmp_path / "scene.xml").write_text(SCENE)
    rc = main(["bench", "error-vs-time", str(tmp_path / "scene.xml"), "--replace", f"ball={rna_asset_path}", "-o", str(tmp_path / "out"),
               "--res", "16", "--gt-spp", "64", "--mi-spp", "1,4", "--nr-spp", "1,4", "--json"])
    assert rc == 0
    r = json.loads(capsys.readouterr().out)
    assert [p["spp"] for p in r["path_tracing_points"]] == [1, 4] and [p["spp"] for p in r["asset_points"]] == [1, 4]
    var = r["reference"]["noise_variance"]
    for p in r["path_tracing_points"] + r["asset_points"]:
        assert p["time_s"] > 0 and math.isfinite(p["mse"]) and p["mse_raw"] - p["mse"] == pytest.approx(var)
    assert r["mitsuba"]["settings"] == {"max_depth": 4, "rr_depth": 5}
    c = r["per_sample_cost"]
    assert c["spp"] == 4 and c["ratio"] > 0 and c["pairs"] == 3 and c["paired_median"] > 0
    # the random asset is not the ball: its render converges elsewhere, a floor well above the reference's noise
    assert r["bias_floor_mse"] > 10 * var
    assert (tmp_path / "out" / "error_vs_time.png").is_file() and (tmp_path / "out" / "error_vs_time.json").is_file()
    # the same over the ball's pixels: Mitsuba's own mask (a sphere of radius 0.5 at distance 3.16, fov 40: about
    # 15 % of the frame), and the floor there is the random asset's, larger per pixel than over the whole image
    o = r["object"]
    assert 0.05 * 256 < o["pixels"] < 0.25 * 256
    assert len(o["equal_error"]) == 2 and o["bias_floor_mse"] > r["bias_floor_mse"]
    assert len(o["energy_ratio"]) == 3 and all(math.isfinite(e) and e > 0 for e in o["energy_ratio"])


def test_per_sample_cost_alternates_the_two_renders():
    """The cost is timed in pairs (path tracing, then asset), so a burst of another job lands on both sides of a
    pair. On a clock where the asset takes twice as long and the second pair runs 4x slower, the pairs' median
    and the least-of ratio are both exactly 2; timing the two sides in blocks, with the burst on the asset's
    block only, would read 4 or more."""
    from nasset_benchmarks.equal_engine import alternating_cost

    now, calls = [0.0], []

    def render(name, seconds):
        def f(spp, seed):
            calls.append(name)
            now[0] += seconds * (4 if len(calls) in (3, 4) else 1)
        return f

    c = alternating_cost(render("pt", 1.0), render("na", 2.0), 16, 3, clock=lambda: now[0])
    assert calls == ["pt", "na"] * 3
    assert c["pairs"] == 3 and c["spp"] == 16
    assert c["paired_median"] == 2.0 and c["ratio"] == 2.0


def test_equal_engine_unknown_shape(tmp_path, rna_asset_path):
    from nasset_benchmarks.equal_engine import bench_equal_engine

    (tmp_path / "scene.xml").write_text(SCENE)
    with pytest.raises(NassetError) as exc:
        bench_equal_engine(tmp_path / "scene.xml", {"nope": rna_asset_path}, tmp_path / "out", res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,))
    assert exc.value.code == "CONVERT_SHAPE_UNKNOWN" and "nope" in exc.value.message


def test_equal_engine_scene_without_integrator(tmp_path, rna_asset_path):
    from nasset_benchmarks.equal_engine import bench_equal_engine

    bare = SCENE.replace('<integrator type="path"><integer name="max_depth" value="4"/></integrator>', "")
    assert "<integrator" not in bare
    (tmp_path / "scene.xml").write_text(bare)
    with pytest.raises(NassetError) as exc:
        bench_equal_engine(tmp_path / "scene.xml", {"ball": rna_asset_path}, tmp_path / "out", res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,))
    assert exc.value.code == "CONVERT_SCENE_LOAD" and "integrator" in exc.value.message


def test_equal_engine_scene_mitsuba_cannot_load(tmp_path, rna_asset_path):
    from nasset_benchmarks.equal_engine import bench_equal_engine

    (tmp_path / "scene.xml").write_text(SCENE.replace('type="path"', 'type="no_such_integrator"'))
    with pytest.raises(NassetError) as exc:
        bench_equal_engine(tmp_path / "scene.xml", {"ball": rna_asset_path}, tmp_path / "out", res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,))
    assert exc.value.code == "CONVERT_SCENE_LOAD" and exc.value.file == str(tmp_path / "scene.xml"), exc.value


def test_equal_engine_unbounded_scene_depth(tmp_path, rna_asset_path):
    """Mitsuba's default max_depth (-1, printed unsigned) gives the plugin's unbounded 1024, not 2^32 - 1."""
    from nasset_benchmarks.equal_engine import bench_equal_engine

    (tmp_path / "scene.xml").write_text(SCENE.replace('<integrator type="path"><integer name="max_depth" value="4"/></integrator>',
                                                      '<integrator type="path"/>'))
    r = bench_equal_engine(tmp_path / "scene.xml", {"ball": rna_asset_path}, tmp_path / "out", res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,),
                           quiet=True)
    assert r["mitsuba"]["settings"] == {"max_depth": -1, "rr_depth": 5}


def test_equal_engine_refuses_an_asset_of_another_object_or_kind(tmp_path, rna_asset_path):
    """Before: any readable asset stood in for the shape, and the benchmark measured it against the wrong object."""
    from nasset_benchmarks.equal_engine import bench_equal_engine
    from nasset_sdk.examples import example_builder

    (tmp_path / "scene.xml").write_text(SCENE)
    with pytest.raises(NassetError) as exc:
        bench_equal_engine(tmp_path / "scene.xml", {"floor": rna_asset_path}, tmp_path / "out", res=8, gt_spp=4,
                           mi_spp=(1,), nr_spp=(1,))
    assert exc.value.code == "BENCH_ASSET_MISMATCH" and "floor" in exc.value.message
    fiber = example_builder("rna", variant="fiber", size="tiny", seed=1).write(tmp_path / "fiber.usdc")
    with pytest.raises(NassetError) as exc:
        bench_equal_engine(tmp_path / "scene.xml", {"ball": fiber}, tmp_path / "out", res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,))
    assert exc.value.code == "BENCH_ASSET_KIND"
