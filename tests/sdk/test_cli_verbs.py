"""CLI verbs and error codes the rest of the suite never reached: ``nasset example``, ``nasset bench neupress|8dna``
(options and argument errors; the runs themselves are benchmarks), bake dispatch by kind and source,
``conformance --spp-scale/--timeout``, and NETWORK_TOO_LARGE."""

from __future__ import annotations

import contextlib
import io
import sys

import numpy as np
import pytest

from nasset_sdk.asset import Asset
from nasset_sdk.cli import build_parser, main
from nasset_sdk.errors import NassetError, UsageError


@pytest.mark.parametrize("kind,variant", [("rna", "surface"), ("rna", "fiber"), ("neupress", "surface"), ("8dna", "surface")])
def test_example_verb_writes_a_valid_asset_of_each_kind(tmp_path, kind, variant):
    from nasset_sdk.validate import validate_file

    out = tmp_path / f"{kind}_{variant}.usdc"
    assert main(["example", "-o", str(out), "--kind", kind, "--variant", variant, "--size", "tiny", "--seed", "3"]) == 0
    report = validate_file(out)
    assert report.ok, report.format_text()
    a = Asset.open(out)
    assert (a.kind, a.variant) == (kind, variant)


def test_example_verb_rejects_unknown_kind(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["example", "-o", str(tmp_path / "a.usdc"), "--kind", "nerf"])
    assert e.value.code == 2 and "invalid choice" in capsys.readouterr().err


def _parse(argv):
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()) as out, contextlib.redirect_stderr(err):
        try:
            return build_parser().parse_args(argv), 0, out.getvalue() + err.getvalue()
        except SystemExit as e:
            return None, e.code, out.getvalue() + err.getvalue()


@pytest.mark.parametrize("name", ["neupress", "8dna"])
def test_bench_verbs_parse_quick_and_reject_bad_arguments(name):
    args, code, text = _parse(["bench", name, "--help"])
    assert code == 0 and "--quick" in text
    args, code, _ = _parse(["bench", name, "--quick"])
    assert code == 0 and args.which == name and args.quick
    for bad in (["--no-such-option"], ["--res", "big"]):
        _, code, text = _parse(["bench", name, *bad])
        assert code == 2 and "error" in text, (bad, text)
    _, code, text = _parse(["bench", "nerf"])
    assert code == 2 and "invalid choice" in text


def test_bake_dispatch_by_kind_and_source(tmp_path, capsys):
    from nasset_bakers import baker_for

    assert baker_for("neupress", "s.xml", None).__module__ == "nasset_bakers.mitsuba.neupress"
    assert baker_for("8dna", None, "default").__module__ == "nasset_bakers.mitsuba.eightdna"
    assert baker_for("rna", "s.blend", None).__module__ == "nasset_bakers.blender.rna"
    assert baker_for("rna", None, "blender-hair").__module__ == "nasset_bakers.blender.rna"
    assert callable(baker_for("rna", "s.xml", None))
    for kind in ("neupress", "8dna"):
        with pytest.raises(UsageError, match="Blender scenes bake to kind rna only"):
            baker_for(kind, "scene.BLEND", None)
    with pytest.raises(UsageError, match="unknown rna example"):
        baker_for("rna", None, "teapot")(None, None, tmp_path / "t.usdc", example="teapot", quiet=True)
    # through the CLI: a usage error, exit status 2, nothing written
    out = tmp_path / "a.usdc"
    assert main(["bake", str(tmp_path / "s.blend"), "--kind", "8dna", "-o", str(out)]) == 2
    assert "Blender scenes bake to kind rna only" in capsys.readouterr().err and not out.exists()
    assert main(["bake", "--example", "blender-surface", "--kind", "neupress", "-o", str(out)]) == 2
    assert not out.exists()


def _fake_renderer(tmp_path, body):
    script = tmp_path / "fake_renderer.py"
    script.write_text("import sys, time\n" + body)
    return f"{sys.executable} {script} {{scene}} {{out}} {{spp}}"


def test_conformance_spp_scale_and_timeout(tmp_path, capsys):
    from nasset_sdk import conformance as cf

    assert main(["conformance", "--spp-scale", "0", "--cases", "rna_distant_fp16"]) == 2
    assert main(["conformance", "--timeout", "0", "--cases", "rna_distant_fp16"]) == 2
    capsys.readouterr()
    # --spp-scale K hands K x the case's spp to the renderer (the fake one records it, then fails)
    tpl = _fake_renderer(tmp_path, "open(sys.argv[2] + '.spp', 'w').write(sys.argv[3]); sys.exit(3)\n")
    case = cf.load_cases(cf.find_suite(), ["rna_distant_fp16"])[0]
    report = cf.run_suite(tpl, cases=["rna_distant_fp16"], workdir=tmp_path / "w", spp_scale=3)
    row = report["cases"][0]
    assert row["status"] == "error" and "status 3" in row["message"]
    got = int(open(row["image"] + ".spp").read())
    assert got == row["spp"] == 3 * int(case["spp"])
    assert report["spp_scale"] == 3
    # --timeout: a renderer slower than the limit is stopped and reported
    slow = _fake_renderer(tmp_path, "time.sleep(30)\n")
    row = cf.run_suite(slow, cases=["rna_distant_fp16"], workdir=tmp_path / "t", timeout=0.5)["cases"][0]
    assert row["status"] == "error" and "timed out after 0.5 s" in row["message"] and row["seconds"] < 10
    # and through the CLI
    rc = main(["conformance", "--renderer", slow, "--cases", "rna_distant_fp16", "--timeout", "0.5", "--json",
               "--workdir", str(tmp_path / "c")])
    assert rc == 1 and "timed out" in capsys.readouterr().out


def test_network_too_large(monkeypatch, tmp_path):
    from nasset_sdk import limits
    from nasset_sdk.examples import example_builder
    from nasset_sdk.networks import check_model_bytes, random_mlp
    from nasset_sdk.validate import validate_file

    blob = random_mlp(np.random.default_rng(0), [4, 8, 3])
    check_model_bytes(blob)
    path = example_builder("rna", size="tiny", seed=1).write(tmp_path / "a.usdc")
    assert validate_file(path).ok
    monkeypatch.setattr(limits, "MAX_NETWORK_BYTES", len(blob) - 1)
    with pytest.raises(NassetError) as e:
        check_model_bytes(blob)
    assert e.value.code == "NETWORK_TOO_LARGE"
    report = validate_file(path, probe=False)
    assert "NETWORK_TOO_LARGE" in report.codes("error"), report.format_text()


def _seed_options(parser, path=()):
    """(command path, action) of every ``--seed`` option of ``parser`` and its sub-commands."""
    import argparse

    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from _seed_options(sub, (*path, name))
        elif "--seed" in action.option_strings:
            yield path, action


def test_every_seed_option_is_checked():
    """A negative seed used to reach numpy and Mitsuba and end in a traceback (ValueError: expected non-negative
    integer): every ``--seed`` now takes 0 .. 2^32 - 1 and refuses anything else as a usage error (exit 2)."""
    from nasset_sdk.cli import MAX_SEED, seed_arg

    found = list(_seed_options(build_parser()))
    assert len(found) >= 8 and all(a.type is seed_arg for _, a in found), [(p, a.type) for p, a in found]
    for path, _ in found:
        for bad in ("-1", str(MAX_SEED + 1), "1.5"):
            _, code, text = _parse([*path, "--seed", bad])
            assert code == 2 and "seed" in text, (path, bad, text)
    assert seed_arg("0") == 0 and seed_arg(str(MAX_SEED)) == MAX_SEED


def test_no_command_line_parses_a_seed_as_a_bare_int():
    """The stand-alone command lines (the Mitsuba plugin's and renderer's ``render``, the benchmark modules) are built
    inside their ``main``; they share the type too: no product source declares ``--seed`` with ``type=int``."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    packages = ("nasset_sdk", "bakers", "benchmarks", "converters", "reference_renderer", "mitsuba_plugin",
                "mitsuba_renderer", "tools")
    offenders = [str(f.relative_to(root)) for pkg in packages for f in (root / pkg).rglob("*.py")
                 if '"--seed", type=int' in f.read_text()]
    assert not offenders, offenders


def test_bounded_integer_options_refuse_values_outside_their_range():
    """Every integer option declared with ``count_arg`` (the benchmarks' image sizes, sample counts, depths) refuses
    one below and one above its range with exit code 2: ``bench accuracy --res 100000`` used to end in a Mitsuba
    error minutes in, and ``--res 0`` silently meant the default."""
    import argparse
    import re

    def walk(parser, path=()):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield from walk(sub, (*path, name))
            elif action.option_strings and getattr(action.type, "__name__", "").startswith("integer in "):
                yield path, action

    found = list(walk(build_parser()))
    assert len(found) >= 15, [(p, a.option_strings) for p, a in found]
    required = {("bench", "accuracy"): ["x.xml", "--replace", "a=b.usdc"]}
    for path, action in found:
        lo, hi = map(int, re.findall(r"-?\d+", action.type.__name__))
        for bad in (lo - 1, hi + 1):
            _, code, text = _parse([*path, *required.get(path, []), action.option_strings[-1], str(bad)])
            assert code == 2 and f"must be in {lo} .. {hi}" in text, (path, action.option_strings, bad, text)
    args, code, _ = _parse(["bench", "8dna", "--converged-spp", "0"])  # 0: skip the converged renders (as --quick)
    assert code == 0 and args.converged_spp == 0
