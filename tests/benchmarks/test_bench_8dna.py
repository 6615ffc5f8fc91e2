"""``nasset bench 8dna``: what is given (assets, a stored reference) is checked before anything is baked or
rendered, with the typed errors of the other benches (spec/accuracy.md#errors) instead of a traceback or a bake.

The assets here have random networks (nasset_sdk.examples); none is trained, and no test renders."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_sdk.errors import NassetError  # noqa: E402


def _bench(out, **kw):
    from nasset_benchmarks.eightdna import bench_8dna

    return bench_8dna(out, size="tiny", res=16, spp=2, gt_spp=4, quiet=True, **kw)


@pytest.fixture(scope="module")
def blob_asset(tmp_path_factory):
    """Writer of random 8dna assets with the geometry of the bench example's blob and a given provenance model."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS, write_example_scene
    from nasset_sdk.examples import example_builder

    folder = tmp_path_factory.mktemp("bench8")
    mi = load_mitsuba()
    sc = msc.load_scene(mi, write_example_scene(folder / "scene"))
    geo = msc.mesh_geometry(mi, msc.pick_shapes(sc, list(EXAMPLE_ASSET_IDS)))

    def write(name: str, model: str | None):
        b = example_builder("8dna", size="tiny", seed=2)
        b.set_geometry(geo)
        if model is not None:
            b.provenance = {**(b.provenance or {}), "model": model}
        return b.write(folder / name)

    return write


def _nothing_baked(out):
    return not out.exists() or not list(out.glob("*.usdc"))


@pytest.mark.parametrize("flag", ["asset", "farfield"])
def test_missing_or_unreadable_asset_fails_before_any_bake(tmp_path, flag):
    junk = tmp_path / "junk.usdc"
    junk.write_bytes(b"not a USD file")
    for path in (tmp_path / "missing.usdc", junk):
        out = tmp_path / "o"
        with pytest.raises(NassetError) as exc:
            _bench(out, **{flag: path})
        assert exc.value.code == "CONVERT_ASSET_REFERENCE" and f"--{flag}" in exc.value.message
        assert path.name in str(exc.value)
        assert _nothing_baked(out)


def test_an_asset_of_another_kind_is_bench_asset_kind(tmp_path):
    from nasset_sdk.examples import example_builder

    rna = example_builder("rna", size="tiny", seed=1).write(tmp_path / "rna.usdc")
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "o", asset=rna)
    assert exc.value.code == "BENCH_ASSET_KIND" and "rna" in exc.value.message
    assert _nothing_baked(tmp_path / "o")


def test_the_pair_swapped_is_bench_asset_kind(blob_asset, tmp_path):
    """The provenance says which model a bake holds: the 6D baseline as --asset, or an 8D asset as --farfield, is
    refused; an asset whose provenance does not say (another tool's) is accepted as given."""
    eight = blob_asset("eight.usdc", "8D")
    six = blob_asset("six.usdc", "6D far-field baseline (conditioners 3-4 ignore u_i; flows 1-2 untrained)")
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "a", asset=six)
    assert exc.value.code == "BENCH_ASSET_KIND" and "6D far-field baseline" in exc.value.message
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "b", asset=eight, farfield=eight)
    assert exc.value.code == "BENCH_ASSET_KIND" and "--farfield" in exc.value.message
    from nasset_benchmarks.eightdna import check_given_asset

    unsaid = blob_asset("unsaid.usdc", None)
    assert check_given_asset(unsaid, far_field=True) == unsaid
    assert check_given_asset(unsaid, far_field=False) == unsaid


def test_an_asset_of_another_object_is_a_mismatch(blob_asset, tmp_path):
    from nasset_sdk.examples import example_builder

    other = example_builder("8dna", size="tiny", seed=1).write(tmp_path / "other.usdc")  # the example's own shape
    blob = blob_asset("blob.usdc", "8D")
    far = blob_asset("far.usdc", "6D far-field baseline")
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "o", asset=other, farfield=far)
    assert exc.value.code == "BENCH_ASSET_MISMATCH" and "other.usdc" in exc.value.message
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "o2", asset=blob, farfield=other)
    assert exc.value.code == "BENCH_ASSET_MISMATCH"


def test_a_stored_reference_that_is_not_one_is_a_usage_error(blob_asset, tmp_path):
    from nasset_sdk.errors import UsageError

    blob = blob_asset("blob2.usdc", "8D")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"zip? no")
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, reference=np.zeros((8, 8, 3)), reference_noise_variance=1e-4, reference_spp=64)
    keys = tmp_path / "keys.npz"
    np.savez(keys, image=np.zeros((16, 16, 3)))
    for npz, words in ((tmp_path / "missing.npz", "not the images file"), (bad, "not the images file"),
                       (keys, "not the images file"), (wrong, "8x8 image, not 16x16")):
        out = tmp_path / f"o_{npz.stem}"
        with pytest.raises(UsageError) as exc:
            _bench(out, asset=blob, reference_npz=npz)
        assert words in str(exc.value)
        assert _nothing_baked(out)


def test_cli_exit_codes(tmp_path):
    from nasset_sdk.cli import main
    from nasset_sdk.examples import example_builder

    rna = example_builder("rna", size="tiny", seed=1).write(tmp_path / "rna.usdc")
    assert main(["bench", "8dna", "--asset", str(rna), "-o", str(tmp_path / "o"), "--json"]) == 1
    assert main(["bench", "8dna", "--asset", str(tmp_path / "missing.usdc"), "-o", str(tmp_path / "o")]) == 1
