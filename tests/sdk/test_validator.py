"""Validator: every bad-input corpus case yields its code, valid assets of every kind are clean,
CLI exit codes, JSON report shape, rule table and spec/validation.md kept in sync."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

import nasset_sdk
from nasset_sdk.errors import CODES, NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.validate import RULES, path_escapes, validate_file
from tests.corpus.make_corpus import make_corpus

HERE = Path(__file__).resolve().parents[1]  # tests/

RAW = {"garbage_bytes", "empty_file", "truncated_half", "truncated_header", "crate_magic_only", "crate_section_flip",
       "usda_syntax_error", "usda_as_usdc_bytes", "missing_file"}


@pytest.fixture(scope="session")
def corpus(tmp_path_factory):
    cases = make_corpus(tmp_path_factory.mktemp("corpus"))
    return {c.name: c for c in cases}


def _case_names():
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        return [c.name for c in make_corpus(d)]


CASE_NAMES = _case_names()


def test_corpus_is_large_and_covers_codes():
    assert len(CASE_NAMES) >= 40
    assert len(set(CASE_NAMES)) == len(CASE_NAMES)


@pytest.mark.parametrize("name", CASE_NAMES)
def test_corpus_case_yields_its_code(corpus, name):
    case = corpus[name]
    # files the corpus wrote through the Sdf API are structurally sound: the crash probe (one child
    # process each) only runs for raw byte-level cases, which is what it guards against
    try:
        report = validate_file(case.path, probe=name in RAW)
    except NassetError as exc:  # pragma: no cover - validate_file reports, it should not raise
        pytest.fail(f"validate_file raised {exc}")
    assert case.code in report.codes(case.severity), report.format_text()
    assert "CHECK_FAILED" not in report.codes(), report.format_text()
    if case.severity == "error":
        assert not report.ok
    for f in report.findings:
        assert f.code in CODES and f.severity in ("error", "warning", "info")
        if f.code not in ("FILE_UNREADABLE", "FILE_NOT_FOUND", "CHECK_FAILED") and case.path.suffix != ".usda":
            assert f.prim, f"finding without a prim path: {f}"


#: codes whose cases live in tests/corpus/gen_paths.py and gen_layers.py (tests/test_security_paths.py)
SECURITY_CORPUS_CODES = {"LAYER_EXTERNAL", "VARIANT_SET_UNEXPECTED", "TIME_SAMPLES", "ARRAY_TOO_LARGE"}


def test_corpus_codes_cover_rules(corpus):
    expected = {c.code for c in corpus.values()}
    not_covered = {r.code for r in RULES} - expected - SECURITY_CORPUS_CODES - {"USD_CHECK", "CHECK_FAILED", "NETWORK_TOO_LARGE"}
    assert not not_covered, f"rules without a corpus case: {sorted(not_covered)}"


def _valid_configs():
    for kind, contract in sorted(nasset_sdk.KINDS.items()):
        for variant in contract.variants:
            for qv in (False, True):
                yield pytest.param(kind, variant, qv, id=f"{kind}-{variant}-{'qv' if qv else 'plain'}")


@pytest.mark.parametrize("kind,variant,quality_variants", list(_valid_configs()))
def test_valid_assets_have_no_errors(tmp_path, kind, variant, quality_variants):
    path = example_builder(kind, variant=variant, size="tiny", seed=3, quality_variants=quality_variants).write(tmp_path / "a.usdc")
    report = validate_file(path, probe=False)
    assert report.ok and report.counts["warning"] == 0, report.format_text()
    assert report.kind == kind and report.variant == variant
    comps = report.checked["components"]
    if quality_variants:  # every quality of every required component was loaded and checked
        for name in nasset_sdk.get_kind(kind).required_components(variant):
            assert f"{name}[small]" in comps and f"{name}[hq]" in comps, comps
    # every optional component the example builders write ('portable' is added by nasset_sdk.portable.add_portable
    # and validated in tests/sdk/test_portable.py)
    optional = [n for n, c in nasset_sdk.get_kind(kind).components(variant).items() if not c.required and n != "portable"]
    for name in optional:
        assert any(c.split("[")[0] == name for c in comps), f"optional {name} not checked: {comps}"


def test_usd_checks_clean_and_probe_used(tmp_path):
    path = example_builder("rna", size="tiny").write(tmp_path / "a.usdc")
    report = validate_file(path, usd_checks=True)
    assert report.ok and report.checked.get("usd_checks") and "probe_s" in report.checked, report.format_text()


@pytest.mark.parametrize("value,escapes", [
    ("tex/a.png", False), ("./a/../b.png", False), ("pkg.usdz[inner/a.png]", False), ("", False),
    ("/etc/passwd", True), ("../a.png", True), ("a/../../b", True), ("http://x/y.usda", True), ("C:\\x.png", True),
    ("file:///x", True), ("~/x", True), ("`${HOME}/x`", True), ("a\\..\\..\\b", True),
])
def test_path_escapes(value, escapes):
    assert (path_escapes(value) is not None) == escapes


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "nasset_sdk.cli", "validate", *args], capture_output=True, text=True, timeout=120)


def test_cli_exit_codes_and_json(tmp_path, corpus):
    good = example_builder("rna", size="tiny").write(tmp_path / "good.usdc")
    r = _cli(str(good))
    assert r.returncode == 0, r.stdout + r.stderr
    r = _cli(str(corpus["tensor_nan"].path), "--json")
    assert r.returncode == 1
    data = json.loads(r.stdout)
    assert set(data) >= {"file", "ok", "counts", "findings", "kind", "specVersion"}
    assert data["ok"] is False and data["counts"]["error"] >= 1
    f = next(f for f in data["findings"] if f["code"] == "TENSOR_NONFINITE")
    assert set(f) == {"code", "severity", "message", "prim", "attribute"}
    assert f["prim"].endswith("/core/triplane") and f["attribute"] == "values"
    r = _cli(str(corpus["garbage_bytes"].path))
    assert r.returncode == 1 and "FILE_UNREADABLE" in r.stdout
    r = _cli()
    assert r.returncode == 2


def test_cli_dump_rules():
    r = _cli("--dump-rules", "--json")
    assert r.returncode == 0
    rows = json.loads(r.stdout)
    assert [row["code"] for row in rows] == [rule.code for rule in RULES]
    for row in rows:
        assert row["code"] in CODES and row["severity"] in ("error", "warning", "info") and ("#" in row["spec"] or row["spec"].endswith(".md"))
    text = _cli("--dump-rules")
    assert text.returncode == 0 and "ASSET_PATH_ESCAPES" in text.stdout


def test_rules_use_catalogue_codes_once():
    codes = [r.code for r in RULES]
    assert len(codes) == len(set(codes))
    assert set(codes) <= set(CODES)


def test_spec_validation_table_up_to_date():
    from nasset_sdk.validate.specdoc import render

    assert (HERE.parent / "spec" / "validation.md").read_text() == render(), "run: python -m nasset_sdk.validate.specdoc"


def test_usd_checks_report_openusd_validator_errors(tmp_path):
    """USD_CHECK: a material binding without MaterialBindingAPI applied is an error of OpenUSD's own validators
    (usdShadeValidators), reported only with --usd-checks, at the prim, and it fails the file."""
    from pxr import Usd, UsdShade

    path = example_builder("rna", size="tiny").write(tmp_path / "no_binding_api.usdc")
    stage = Usd.Stage.Open(str(path))
    geometry = next(p for p in stage.Traverse() if p.HasAPI(UsdShade.MaterialBindingAPI))
    geometry.RemoveAPI(UsdShade.MaterialBindingAPI)  # the material:binding relationship stays
    stage.GetRootLayer().Save()
    assert validate_file(path).findings == []
    report = validate_file(path, usd_checks=True)
    assert [(f.code, f.severity, f.prim) for f in report.findings] == [("USD_CHECK", "error", str(geometry.GetPath()))]
    assert "MaterialBindingAPI" in report.findings[0].message and not report.ok
    r = _cli(str(path), "--usd-checks", "--json")
    assert r.returncode == 1, r.stdout + r.stderr
    assert [f["code"] for f in json.loads(r.stdout)["findings"]] == ["USD_CHECK"]
    assert _cli(str(path)).returncode == 0
