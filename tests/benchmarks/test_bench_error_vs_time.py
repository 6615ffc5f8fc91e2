"""Smoke test of ``nasset bench error-vs-time`` at toy scale (8x8; ~8 s), and the equal-error arithmetic.

The smoke run uses a tiny random-network rna asset with the geometry of the example's shell and jelly
in place of a bake (baking takes minutes): it exercises the whole pipeline (example scene, conversion with --replace, Mitsuba
ground truth and curve, reference-renderer curve, table, plot) but its numbers mean nothing.
"""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("mitsuba")

from nasset_benchmarks.error_vs_time import equal_error_speedup  # noqa: E402


def test_equal_error_speedup_arithmetic():
    # Mitsuba: MSE = 1 / spp, time = 0.1 + 0.01 spp; neural point at MSE 0.01 in 0.5 s -> Mitsuba 100 spp, 1.1 s
    mi = [{"spp": s, "mse": 1.0 / s, "time_s": 0.1 + 0.01 * s} for s in (1, 4, 16, 64)]
    nr = [{"spp": 1, "mse": 0.01, "time_s": 0.5}, {"spp": 2, "mse": -1e-9, "time_s": 1.0}]
    out = equal_error_speedup(mi, nr)
    assert out[0]["mitsuba_spp"] == pytest.approx(100.0)
    assert out[0]["mitsuba_time_s"] == pytest.approx(1.1)
    assert out[0]["speedup"] == pytest.approx(2.2)
    assert out[1]["speedup"] is None  # within the ground truth's noise: no equal-error point


@pytest.fixture
def example_rna_asset(tmp_path):
    """A random-network rna asset whose geometry is the example scene's shell and jelly (as a bake stores it)."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene
    from nasset_sdk.examples import example_builder

    mi = load_mitsuba()
    sc = msc.load_scene(mi, write_example_scene(tmp_path / "example"))
    b = example_builder("rna", size="tiny", seed=1)
    b.set_geometry(msc.mesh_geometry(mi, msc.pick_shapes(sc, list(EXAMPLE_ASSET_IDS))))
    return b.write(tmp_path / "rna_example.usdc")


def test_bench_smoke(tmp_path, example_rna_asset, capsys):
    from nasset_sdk.cli import main

    rc = main(["bench", "error-vs-time", "-o", str(tmp_path / "o"), "--asset", str(example_rna_asset), "--res", "8",
               "--gt-spp", "16", "--mi-spp", "1,2", "--nr-spp", "1,2", "--max-depth", "2", "--json"])
    assert rc == 0
    report = json.loads(capsys.readouterr().out)
    assert [p["spp"] for p in report["mitsuba_points"]] == [1, 2]
    assert [p["spp"] for p in report["neural_points"]] == [1, 2]
    assert all(p["time_s"] > 0 and math.isfinite(p["mse"]) for p in report["mitsuba_points"] + report["neural_points"])
    assert math.isfinite(report["bias_floor_mse"])
    assert (tmp_path / "o" / "error_vs_time.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert json.loads((tmp_path / "o" / "error_vs_time.json").read_text())["resolution"] == [8, 8]
    assert (tmp_path / "o" / "scene" / "scene_neural.usda").is_file()
