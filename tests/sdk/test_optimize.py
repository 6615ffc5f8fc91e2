"""nasset optimize: re-encode, drop components or quality levels, report size and accuracy change."""

from __future__ import annotations

import json

import numpy as np
import pytest

import nasset_sdk as ns
from nasset_sdk.cli import main
from nasset_sdk.examples import example_builder
from nasset_sdk.optimize import OptimizeOptions, format_report, optimize, query_set
from nasset_sdk.validate import validate_file


def _fp32(kind, path, **kw):
    """An example asset with every tensor stored as float32 with values float16 cannot hold (plain builder API)."""
    b = example_builder(kind, size="tiny", seed=6, **kw)
    rng = np.random.default_rng(6)
    for levels in b.components.values():
        for data in levels.values():
            for name, (arr, _, layout) in list(data.tensors.items()):
                data.add_tensor(name, arr * (1 + 1e-3 * rng.normal(size=arr.shape)), dtype="float32", layout=layout)
    return b.write(path)


def _run(capsys, *argv):
    rc = main(["optimize", *map(str, argv)])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_fp16_reencode_halves_tensors_and_reports_the_change(tmp_path, capsys):
    src = _fp32("rna", tmp_path / "a.usdc")
    rc, out, _ = _run(capsys, src, "-o", tmp_path / "b.usdc", "--dtype", "float16", "--json")
    assert rc == 0
    r = json.loads(out)
    assert r["ok"] and r["file_bytes"]["after"] < r["file_bytes"]["before"]
    assert r["tensor_bytes_default"]["after"] * 2 == r["tensor_bytes_default"]["before"]
    a, b = ns.Asset.open(src), ns.Asset.open(tmp_path / "b.usdc")
    for name, ref in a.tensor_refs("core").items():
        got = b.tensor("core", name)
        assert got.dtype == np.float16 and b.tensor_refs("core")[name].layout == ref.layout
        np.testing.assert_array_equal(got, a.tensor("core", name).astype(np.float16))
    assert b.network_bytes("core", "decoder") == a.network_bytes("core", "decoder")
    # the reported accuracy is the evaluator's difference on the fixed query set
    q = query_set(a)
    d = np.abs(b.evaluator().radiance(q).astype(np.float64) - a.evaluator().radiance(q))
    acc = r["accuracy"]
    assert acc["max_abs_diff"] == pytest.approx(d.max()) and acc["mean_abs_diff"] == pytest.approx(d.mean())
    assert 0 < acc["mean_abs_diff"] <= acc["max_abs_diff"]
    assert acc["preview_psnr_db"] is not None and acc["preview_psnr_db"] > 20
    assert validate_file(tmp_path / "b.usdc", probe=False).ok
    # text report: sizes and accuracy in words
    text = format_report(r)
    assert "file size" in text and "radiance diff max" in text and "PSNR" in text


def test_lossless_options_report_zero_change(tmp_path, capsys):
    src = _fp32("rna", tmp_path / "a.usdc")
    acc = optimize(src, tmp_path / "b.usdc", OptimizeOptions(dtype="float32", probe=False))["accuracy"]
    assert acc["max_abs_diff"] == 0 and acc["preview_identical"]


def test_drop_optional_components_and_keep_one_quality(tmp_path, capsys):
    src = example_builder("neupress", size="tiny", seed=1).write(tmp_path / "n.usdc")
    r = optimize(src, tmp_path / "n2.usdc", OptimizeOptions(drop=("sampling", "prt"), probe=False, preview=False))
    assert r["components"] == {"before": ["core", "prt", "sampling"], "after": ["core"]}
    assert r["accuracy"]["max_abs_diff"] == 0  # radiance needs core only
    assert r["file_bytes"]["after"] < r["file_bytes"]["before"]
    assert validate_file(tmp_path / "n2.usdc", probe=False).ok

    q = example_builder("rna", size="tiny", seed=1, quality_variants=True).write(tmp_path / "q.usdc")
    r = optimize(q, tmp_path / "q2.usdc", OptimizeOptions(keep_quality=("hq",), probe=False, preview=False))
    assert r["accuracy"]["max_abs_diff"] > 0  # the default changed from small to hq
    flat = ns.Asset.open(tmp_path / "q2.usdc")
    assert flat.components()["core"].qualities == ()
    hq = ns.Asset.open(q, quality="hq")
    np.testing.assert_array_equal(flat.tensor("core", "triplane"), hq.tensor("core", "triplane"))
    assert validate_file(tmp_path / "q2.usdc", probe=False).ok


def test_bad_input_exit_codes(tmp_path, capsys):
    src = example_builder("neupress", size="tiny").write(tmp_path / "n.usdc")
    rc, _, err = _run(capsys, src, "-o", tmp_path / "x.usdc", "--drop", "core")
    assert rc == 2 and "[USAGE]" in err and "required" in err
    rc, _, err = _run(capsys, src, "-o", tmp_path / "x.usdc", "--keep-quality", "hq")
    assert rc == 2 and "no component has quality" in err
    rc, _, err = _run(capsys, src, "-o", src)
    assert rc == 2 and "another file" in err
    rc, out, _ = _run(capsys, tmp_path / "missing.usdc", "-o", tmp_path / "x.usdc", "--json")
    assert rc == 1 and json.loads(out)["error"]["code"] == "FILE_NOT_FOUND"
    assert not (tmp_path / "x.usdc").exists()
    for argv in (["--dtype", "int8"], []):
        with pytest.raises(SystemExit) as e:
            main(["optimize", str(src), *argv])  # no -o / a bad choice: argparse usage error
        assert e.value.code == 2
    with pytest.raises(SystemExit) as e:
        main(["optimize", "--help"])
    assert e.value.code == 0 and "--keep-quality" in capsys.readouterr().out


def test_portable_pass_adds_graphs_that_match_the_evaluator(tmp_path):
    """``nasset optimize --portable``: the component is added and its graph reproduces the evaluator of the optimized file."""
    from nasset_sdk.asset import Asset
    from nasset_sdk.portable import PortableEvaluator, random_queries, reference_outputs

    src = example_builder("rna", size="tiny", seed=4).write(tmp_path / "a.usdc")
    out = tmp_path / "b.usdc"
    assert main(["optimize", str(src), "-o", str(out), "--dtype", "float16", "--portable", "--no-preview", "--json"]) == 0
    assert Asset.open(out, load="none").provenance["optimize"]["portable"] is True
    a = Asset.open(out, load="all")
    assert "portable" in a.components() and not a.components()["portable"].required
    q = random_queries(a, 512, np.random.default_rng(1))
    got = PortableEvaluator(a).run("decoder", **q)
    for name, ref in reference_outputs(a, q).items():
        np.testing.assert_allclose(got[name], ref, atol=2e-4, rtol=1e-3)
