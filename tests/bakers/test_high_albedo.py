"""The high-albedo translucent example (spec/accuracy.md#examples): a tiny bake keeps the object's energy in its scene.

The bake (``--kind rna --example high-albedo --size tiny``, default settings: no clamp, L2 loss) is put
back into its own scene and measured by ``nasset bench accuracy`` against an unclamped two-half
Mitsuba reference, over the pebble's pixels (mask from Mitsuba).

Bound (tiny preset: 8^2 x 4 triplane, 2 x 16 decoder, 16 views of 24^2 at 8 spp): every channel's
energy within ENERGY_BOUNDS of Mitsuba's. Measured (seed 0, 48 px, reference 1024 spp, estimate 16 spp):
72.8 / 89.5 / 70.2 % (+-2.0 / 2.1 / 1.4). The pre-accuracy bake (clamp 10 /sr, which removed 15 / 14 / 13 %
of the training targets' energy, and the log(1 + T) loss) scores 51.1 / 70.4 / 53.4 % and fails it
(``test_old_clamped_bake_misses_the_bound``, slow). The issue's target for the *small*
preset is +-3 %; tiny is a smoke-size model and far from it (spec/accuracy.md#ablation).
"""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")
pytest.importorskip("torch")

#: allowed in-scene energy ratio per channel for the tiny bake (see the module docstring)
ENERGY_BOUNDS = (0.6, 1.4)
BENCH = dict(res=48, spp=1024, nr_spp=16)


def _bake_and_measure(tmp_path, **bake_options) -> dict:
    from nasset_bakers.mitsuba.rna import bake
    from nasset_benchmarks.accuracy import bench_accuracy

    out = tmp_path / "pebble.usdc"
    summary = bake(None, None, out, size="tiny", example="high-albedo", quiet=True, **bake_options)
    xml = tmp_path / "pebble.usdc.bake" / "example_scene" / "scene.xml"
    report = bench_accuracy(xml, [f"pebble={out}"], tmp_path / "bench", quiet=True, **BENCH)
    return {"summary": summary, "report": report}


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    return _bake_and_measure(tmp_path_factory.mktemp("high_albedo"))


def test_high_albedo_example_scene():
    from nasset_converters.mitsuba.high_albedo_example import ALBEDO, EXAMPLE_ASSET_IDS

    assert min(ALBEDO) >= 0.99 and EXAMPLE_ASSET_IDS == ("pebble",)


def test_bake_keeps_energy_in_scene(measured):
    s, r = measured["summary"], measured["report"]
    assert s["clamp"] == 0.0 and s["clamp_removed"]["fraction"] == [0.0, 0.0, 0.0]
    o = r["object"]
    lo, hi = ENERGY_BOUNDS
    assert r["reference"]["clamp"] is None and r["reference"]["halves"] == 2
    for c, ratio in enumerate(o["energy_ratio"]):
        assert lo <= ratio <= hi, f"channel {c}: {100 * ratio:.1f} % of Mitsuba's energy (bound {lo}-{hi}); all {o['energy_ratio']}"
    # held-out figures are against the unclamped two-half reference and come with its ceiling
    h = s["sdk_val_accuracy"]
    assert h is not None and h["ceiling_db"] > 0 and "claimed_psnr" in h


def test_provenance_records_reference_and_depth(measured):
    from nasset_sdk.asset import Asset

    prov = Asset.open(measured["summary"]["asset"], load="none").provenance
    assert prov["data"]["clamp"] == 0.0 and prov["data"]["reference"].startswith("held-out views unclamped")
    assert prov["data"]["max_depth"] == 128  # the scene integrator's depth, not the dataset's default 24
    assert prov["validation"]["accuracy"]["ceiling_db"] > 0


@pytest.mark.slow
def test_old_clamped_bake_misses_the_bound(tmp_path):
    """The bake as it was (clamp 10 /sr on training targets, log(1 + T) loss) fails the bound above."""
    m = _bake_and_measure(tmp_path, clamp=10.0, loss="log")
    assert m["summary"]["clamp_removed"]["fraction"][0] > 0.1  # the clamp removes a large share of the energy
    lo, hi = ENERGY_BOUNDS
    assert any(not (lo <= r <= hi) for r in m["report"]["object"]["energy_ratio"])


def test_near_field_fetch_is_measured_and_stored(measured):
    """The bake's near-field stage (spec/bake.md#near-field) measured f on this surface asset and stored it in the file
    and in provenance with what it was measured against."""
    from nasset_sdk.asset import Asset

    s = measured["summary"]
    asset = Asset.open(s["asset"], load="none")
    near = asset.provenance["near_field"]
    assert near["measured"] and near == {**s["near_field"]}
    assert 0.0 <= near["fetch"] <= 1.0 and asset.near_field_fetch == pytest.approx(near["fetch"], abs=1e-6)
    assert near["pixels"] > 0 and len(near["energy_ratio_f0"]) == 3 and len(near["fetch_halves"]) == 2
    assert asset.spec_version == ("0.3" if near["fetch"] > 0 else "0.1")
