"""Evaluator test vectors (spec/evaluator-vectors.md): the shipped files are a fresh generation, the SDK
passes them through the ``--evaluator`` protocol, and the comparison and runner report every failure."""

from __future__ import annotations

import json
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from nasset_sdk.conformance_evaluator import SDK_EVALUATOR, compare, load_vector_cases, run_suite
from nasset_sdk.evaluator_vectors import CASES, VECTORS_DIR, generate, read_npz, write_npz

PY = shlex.quote(sys.executable)


def test_shipped_vectors_equal_a_fresh_generation(tmp_path):
    generate(tmp_path)
    for name in CASES:
        shipped, fresh = VECTORS_DIR / name, tmp_path / name
        assert (shipped / "case.json").read_text() == (fresh / "case.json").read_text(), name
        for f in ("inputs.npz", "expected.npz"):
            a, b = read_npz(shipped / f), read_npz(fresh / f)
            assert a.keys() == b.keys(), (name, f)
            for k in a:
                assert a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=True), (name, f, k)
        # the stages' values, not the crate file's bytes: those change with the usd-core release that writes them, and
        # the example geometry's normals with the mesh library's rounding (1e-16)
        a, b = _stage_values(shipped / "asset.usdc"), _stage_values(fresh / "asset.usdc")
        assert a.keys() == b.keys(), f"{name}: regenerate with scripts/make_evaluator_vectors.py"
        for key in a:
            va, vb = a[key], b[key]
            if isinstance(va, np.ndarray) and isinstance(vb, np.ndarray) and va.dtype.kind == "f":
                same = va.shape == vb.shape and np.allclose(va, vb, rtol=1e-6, atol=1e-12, equal_nan=True)
            else:
                same = np.array_equal(va, vb) if isinstance(va, np.ndarray) else va == vb
            assert same, f"{name}: {key} differs; regenerate with scripts/make_evaluator_vectors.py"


def _stage_values(path: Path) -> dict:
    """(prim path, attribute or metadata name) -> value: numeric arrays as numpy, the rest as repr."""
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    out = {("", "customLayerData"): repr(stage.GetRootLayer().customLayerData)}
    for prim in stage.Traverse():
        out[(str(prim.GetPath()), "type")] = prim.GetTypeName()
        out[(str(prim.GetPath()), "customData")] = repr(prim.GetCustomData())
        for attr in prim.GetAttributes():
            v = attr.Get()
            try:
                arr = np.asarray(v)
                out[(str(prim.GetPath()), attr.GetName())] = arr if arr.dtype.kind in "fiub" else repr(v)
            except Exception:  # noqa: BLE001 - a value numpy cannot hold is compared as text
                out[(str(prim.GetPath()), attr.GetName())] = repr(v)
    return out


def test_vectors_are_package_data():
    text = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    assert '"evaluator_cases/*/*"' in text
    assert sorted(c["name"] for c in load_vector_cases()) == sorted(CASES)


def test_vectors_cover_edge_cases():
    inp = read_npz(VECTORS_DIR / "neupress" / "inputs.npz")
    wo = inp["subsurface.wo"]
    signs = {tuple(np.signbit(r)) for r in wo if (r[:2] == 0).all()}
    assert (True, True, True) in signs and (False, False, False) in signs  # (-0, -0, -1) and (+0, +0, +1)
    assert (~np.isfinite(wo)).any() and (np.abs(wo) >= 1e20).any()


def test_sdk_passes_every_case_exactly(tmp_path):
    report = run_suite(SDK_EVALUATOR, workdir=tmp_path)
    assert report["ok"], [r["message"] for r in report["cases"]]
    assert {r["tier"] for r in report["cases"]} == {"exact"}


@pytest.fixture(scope="module")
def case():
    c = load_vector_cases(None, ["neupress"])[0]
    return c, read_npz(c["dir"] / "expected.npz")


def test_compare_tolerance_and_tiers(case):
    c, want = case
    assert compare(c, dict(want), want) == {"passed": True, "exact": True, "worst": 0.0, "problems": []}
    got = dict(want)
    got["subsurface.y"] = want["subsurface.y"] * np.float32(1 + 3e-5)  # inside rtol 1e-4: passes, not exact
    res = compare(c, got, want)
    assert res["passed"] and not res["exact"] and 0 < res["worst"] < 1
    got["subsurface.y"] = want["subsurface.y"] + np.float32(1e-3)  # beyond atol + rtol |y|
    res = compare(c, got, want)
    assert not res["passed"] and "subsurface.y" in res["problems"][0] and res["worst"] > 1


def test_compare_reports_missing_shape_nonfinite_and_network_input(case):
    c, want = case
    got = {k: v for k, v in want.items() if k != "sigma.sigma"}
    got["prt.y"] = want["prt.y"][:-1]
    bad = want["lobe_pdf.pdf"].copy()
    bad[3] = np.nan
    got["lobe_pdf.pdf"] = bad
    inp = want["subsurface.input"].copy()
    inp[5, 2] = np.nextafter(inp[5, 2], np.float32(2))  # one ulp in one feature
    got["subsurface.input"] = inp
    res = compare(c, got, want)
    text = " | ".join(res["problems"])
    assert not res["passed"] and not res["exact"]
    assert "sigma.sigma: missing" in text and "prt.y: shape" in text and "lobe_pdf.pdf: non-finite value at row 3" in text
    assert "subsurface.input (exact tier): 1 values differ, first at row 5 column 2" in text
    only_input = dict(want)
    only_input["subsurface.input"] = inp
    res = compare(c, only_input, want)
    assert res["passed"] and not res["exact"]  # a network-input mismatch costs the exact tier only


def _fake(tmp_path, body: str) -> str:
    script = tmp_path / "fake_evaluator.py"
    script.write_text("import sys, time\nasset, inp, out = sys.argv[1:]\n" + body)
    return f"{PY} {shlex.quote(str(script))} {{asset}} {{input}} {{output}}"


@pytest.mark.parametrize("body, reason, timeout", [
    ("sys.exit(3)", "exited with status 3", 60.0),
    ("pass", "wrote no output", 60.0),
    ("open(out, 'w').write('not an npz')", "cannot read the output NPZ", 60.0),
    ("time.sleep(60)", "timed out after 2 s", 2.0),
    ("import numpy as np\nnp.savez(out, **{'transport.unshadowed': np.zeros((2, 3))})", "transport.unshadowed: shape", 60.0),
])
def test_runner_reports_failures(tmp_path, body, reason, timeout):
    report = run_suite(_fake(tmp_path, body), cases=["rna_surface"], workdir=tmp_path / "w", timeout=timeout)
    row = report["cases"][0]
    assert not report["ok"] and not row["passed"] and reason in row["message"], row["message"]


def test_cli_evaluator_exit_codes(tmp_path):
    cli = [sys.executable, "-m", "nasset_sdk.cli", "conformance", "--cases", "rna_surface", "--workdir", str(tmp_path)]
    ok = subprocess.run(cli + ["--evaluator", "sdk", "--json"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stdout + ok.stderr
    assert json.loads(ok.stdout)["cases"][0]["tier"] == "exact"
    bad = subprocess.run(cli + ["--evaluator", _fake(tmp_path, "sys.exit(1)")], capture_output=True, text=True)
    assert bad.returncode == 1 and "ERROR" in bad.stdout and "exited with status 1" in bad.stdout
    usage = subprocess.run(cli + ["--evaluator", "x {nope}"], capture_output=True, text=True)
    assert usage.returncode == 2 and "--evaluator: bad placeholder" in usage.stderr


def test_write_npz_is_atomic_and_deterministic(tmp_path):
    arrays = {"b.x": np.arange(6.0).reshape(2, 3), "a.y": np.array([-0.0, np.nan])}
    write_npz(tmp_path / "one.npz", arrays)
    write_npz(tmp_path / "two.npz", dict(reversed(list(arrays.items()))))
    assert (tmp_path / "one.npz").read_bytes() == (tmp_path / "two.npz").read_bytes()
    back = read_npz(tmp_path / "one.npz")
    assert np.signbit(back["a.y"][0]) and np.isnan(back["a.y"][1])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.npz", "two.npz"]


def test_fused_8dna_evaluator_passes_within_tolerance(monkeypatch):
    """The renderer's 8dna evaluator fuses the flows' first layers (another float32 summation order):
    not bit-exact, but within the vectors' tolerance tier -- and the fusion does change the numbers."""
    from nasset_sdk import evaluator_adapter
    from nasset_sdk.asset import Asset

    c = load_vector_cases(None, ["8dna"])[0]
    expected = read_npz(c["dir"] / "expected.npz")
    real_open = Asset.open

    def fused(*a, **kw):  # the adapter's evaluator with the render-time default
        asset = real_open(*a, **kw)
        make = asset.evaluator
        asset.evaluator = lambda **opts: make()
        return asset

    monkeypatch.setattr(Asset, "open", staticmethod(fused))
    got = evaluator_adapter.answer(c["dir"] / "asset.usdc", read_npz(c["dir"] / "inputs.npz"))
    r = compare(c, got, expected)
    assert r["passed"] and not r["exact"], r
