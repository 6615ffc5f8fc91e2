"""The built-in benches (``nasset bench 8dna``, ``neupress``, ``error-vs-time`` without a scene): what is given (an
asset, a stored reference) is checked before anything is baked or rendered, with the typed errors of ``bench
accuracy`` (spec/accuracy.md#errors), instead of a traceback, a bake, or a report on an asset of another kind or
object.

The assets here have random networks (nasset_sdk.examples); none is trained, and no test renders."""

from __future__ import annotations

from pathlib import Path

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
def test_8dna_missing_or_unreadable_asset_fails_before_any_bake(tmp_path, flag):
    junk = tmp_path / "junk.usdc"
    junk.write_bytes(b"not a USD file")
    for path in (tmp_path / "missing.usdc", junk):
        out = tmp_path / "o"
        with pytest.raises(NassetError) as exc:
            _bench(out, **{flag: path})
        assert exc.value.code == "CONVERT_ASSET_REFERENCE" and f"--{flag}" in exc.value.message
        assert path.name in str(exc.value)
        assert _nothing_baked(out)


def test_8dna_an_asset_of_another_kind_is_bench_asset_kind(tmp_path):
    from nasset_sdk.examples import example_builder

    rna = example_builder("rna", size="tiny", seed=1).write(tmp_path / "rna.usdc")
    with pytest.raises(NassetError) as exc:
        _bench(tmp_path / "o", asset=rna)
    assert exc.value.code == "BENCH_ASSET_KIND" and "rna" in exc.value.message
    assert _nothing_baked(tmp_path / "o")


def test_8dna_the_pair_swapped_is_bench_asset_kind(blob_asset, tmp_path):
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
    for far_field in (True, False):
        checked = check_given_asset(unsaid, far_field=far_field)
        assert checked.kind == "8dna" and Path(checked.path) == Path(unsaid)


def test_8dna_an_asset_of_another_object_is_a_mismatch_before_any_bake(blob_asset, tmp_path):
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
    with pytest.raises(NassetError) as exc:  # the far-field baseline is not given: it would be baked after the check
        _bench(tmp_path / "o3", asset=other)
    assert exc.value.code == "BENCH_ASSET_MISMATCH" and _nothing_baked(tmp_path / "o3")


def test_8dna_a_stored_reference_that_is_not_one_is_a_usage_error(blob_asset, tmp_path):
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


def test_8dna_cli_exit_codes(tmp_path):
    from nasset_sdk.cli import main
    from nasset_sdk.examples import example_builder

    rna = example_builder("rna", size="tiny", seed=1).write(tmp_path / "rna.usdc")
    assert main(["bench", "8dna", "--asset", str(rna), "-o", str(tmp_path / "o"), "--json"]) == 1
    assert main(["bench", "8dna", "--asset", str(tmp_path / "missing.usdc"), "-o", str(tmp_path / "o")]) == 1


# --- nasset bench neupress and error-vs-time (the built-in rna example) ------------------------------------------


def _neupress(out, asset):
    from nasset_benchmarks.neupress import bench_neupress

    return bench_neupress(out, asset=asset, size="tiny", res=8, gt_spp=4, spp=(1,), equal_spp=1, quiet=True)


def _error_vs_time(out, asset):
    from nasset_benchmarks.error_vs_time import bench_error_vs_time

    return bench_error_vs_time(out, asset=asset, res=8, gt_spp=4, mi_spp=(1,), nr_spp=(1,), quiet=True)


@pytest.mark.parametrize("bench", [_neupress, _error_vs_time])
def test_builtin_bench_refuses_a_missing_or_unreadable_asset(tmp_path, bench):
    junk = tmp_path / "junk.usdc"
    junk.write_bytes(b"not a USD file")
    for path in (tmp_path / "missing.usdc", junk):
        with pytest.raises(NassetError) as exc:
            bench(tmp_path / "o", path)
        assert exc.value.code == "CONVERT_ASSET_REFERENCE" and "--asset" in exc.value.message
        assert _nothing_baked(tmp_path / "o")


@pytest.mark.parametrize("kind", ["rna", "8dna"])
def test_neupress_bench_refuses_another_kind(tmp_path, kind):
    """Before: an rna or 8dna asset ran the whole table with every neupress figure 'n/a', exit code 0."""
    from nasset_sdk.examples import example_builder

    other = example_builder(kind, size="tiny", seed=1).write(tmp_path / f"{kind}.usdc")
    with pytest.raises(NassetError) as exc:
        _neupress(tmp_path / "o", other)
    assert exc.value.code == "BENCH_ASSET_KIND" and "neupress" in exc.value.message


def test_error_vs_time_refuses_an_asset_of_another_object_or_a_fiber_asset(tmp_path):
    """Before: any readable asset stood in for the example's shell and jelly, whatever its geometry."""
    from nasset_sdk.examples import example_builder
    from nasset_sdk.geometry import MeshGeometry

    b = example_builder("rna", size="tiny", seed=1)
    g = b.geometry
    b.set_geometry(MeshGeometry(points=g.points * 0.2 + 3.0, faces=g.faces))  # another object: smaller, elsewhere
    moved = b.write(tmp_path / "moved.usdc")
    with pytest.raises(NassetError) as exc:
        _error_vs_time(tmp_path / "o", moved)
    assert exc.value.code == "BENCH_ASSET_MISMATCH" and "moved.usdc" in exc.value.message
    fiber = example_builder("rna", variant="fiber", size="tiny", seed=1).write(tmp_path / "fiber.usdc")
    with pytest.raises(NassetError) as exc:
        _error_vs_time(tmp_path / "o", fiber)
    assert exc.value.code == "BENCH_ASSET_KIND"
