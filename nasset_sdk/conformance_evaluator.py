"""``nasset conformance --evaluator CMD``: run a third-party evaluator on the evaluator test vectors
(spec/evaluator-vectors.md) and compare its outputs with the SDK's.

CMD is a command template with ``{asset} {input} {output}`` placeholders, split like a shell command
line (no shell runs it). It is called once per case: it reads the asset and the query NPZ and writes
an NPZ with one array per ``query.output``. Exit code 0 when every case passes, 1 otherwise.
"""

from __future__ import annotations

import json
import shlex
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .conformance import format_command, run_tool
from .errors import UsageError
from .evaluator_vectors import NETWORK_INPUT, VECTORS_DIR, read_npz

#: the SDK's own evaluator command (its answers are the expected outputs); ``--evaluator sdk``
SDK_EVALUATOR = shlex.quote(sys.executable) + " -m nasset_sdk.evaluator_adapter {asset} {input} {output}"
PLACEHOLDERS = ("asset", "input", "output")


def load_vector_cases(suite=None, names=None) -> list[dict]:
    """Case folders (with case.json) of ``suite`` (default: the vectors installed with the SDK)."""
    root = Path(suite) if suite else VECTORS_DIR
    if (root / "case.json").is_file():
        folders = [root]
    elif root.is_dir():
        folders = sorted(p for p in root.iterdir() if (p / "case.json").is_file())
    else:
        folders = []
    if not folders:
        raise UsageError(f"no evaluator vector cases in {root}")
    by_name = {p.name: p for p in folders}
    if names:
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise UsageError(f"unknown evaluator vector cases {unknown}; the suite has: {', '.join(by_name)}")
        folders = [by_name[n] for n in names]
    return [{"name": p.name, "dir": p, **json.loads((p / "case.json").read_text())} for p in folders]


def compare(case: dict, got: dict[str, np.ndarray], expected: dict[str, np.ndarray]) -> dict:
    """Compare one case's outputs: {'passed', 'exact', 'worst', 'problems': [str], 'outputs': {key: ratio}}.

    An output passes when finite, of the expected shape and within |got - want| <= atol + rtol |want|
    everywhere; ``worst`` is the largest error / allowed ratio. ``exact`` holds when every output (and
    every network-input row the evaluator wrote) equals the expected float32 values bit for bit."""
    problems, ratios, exact = [], {}, True
    for q, spec in case["queries"].items():
        for o, tol in spec["outputs"].items():
            key = f"{q}.{o}"
            want = np.asarray(expected[key], np.float64)
            if key not in got:
                problems.append(f"{key}: missing from the output")
                exact = False
                continue
            g = np.asarray(got[key])
            if g.shape != want.shape:
                problems.append(f"{key}: shape {g.shape}, expected {want.shape}")
                exact = False
                continue
            if g.dtype.kind not in "fiu":
                problems.append(f"{key}: dtype {g.dtype} is not numeric")
                exact = False
                continue
            g = g.astype(np.float64)
            exact &= bool(np.array_equal(g.astype(np.float32), want.astype(np.float32)))
            if not np.isfinite(g).all():
                bad = int(np.flatnonzero(~np.isfinite(g).reshape(len(g), -1).all(1))[0])
                problems.append(f"{key}: non-finite value at row {bad}")
                ratios[key] = float("inf")
                continue
            allowed = tol["atol"] + tol["rtol"] * np.abs(want)
            r = np.abs(g - want) / allowed
            ratios[key] = float(r.max(initial=0.0))
            if ratios[key] > 1.0:
                row = int(np.unravel_index(np.argmax(r), r.shape)[0])
                problems.append(f"{key}: |error| {float(np.abs(g - want).max()):.3g} is {ratios[key]:.3g} x the tolerance "
                                f"(worst at row {row})")
        key = f"{q}.{NETWORK_INPUT}"
        if spec.get("network_input") and key in got:
            g = np.asarray(got[key])
            if g.shape != expected[key].shape or not np.array_equal(g.astype(np.float32), expected[key], equal_nan=True):
                exact = False
                if g.shape == expected[key].shape:
                    diff = g.astype(np.float32) != expected[key]
                    rows, cols = np.nonzero(diff)
                    problems.append(f"{key} (exact tier): {len(rows)} values differ, first at row {rows[0]} column {cols[0]}")
                else:
                    problems.append(f"{key} (exact tier): shape {g.shape}, expected {expected[key].shape}")
    tolerance_problems = [p for p in problems if "(exact tier)" not in p]
    return {"passed": not tolerance_problems, "exact": exact and not problems,
            "worst": max(ratios.values(), default=0.0), "problems": problems}


def run_case(case: dict, template: str, workdir: Path, *, timeout: float = 300.0) -> dict:
    """Run the evaluator on one case; the report row."""
    name = case["name"]
    out_dir = Path(workdir) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    out = (out_dir / "output.npz").resolve()
    if out.exists():
        out.unlink()
    cmd = format_command(template, option="--evaluator", placeholders=PLACEHOLDERS,
                         asset=(case["dir"] / "asset.usdc").resolve(), input=(case["dir"] / "inputs.npz").resolve(), output=out)
    row = {"case": name, "status": "error", "passed": False, "tier": None, "worst": None, "seconds": None,
           "message": "", "problems": [], "command": cmd, "output": str(out)}
    if not run_tool(cmd, row, "evaluator", out_dir / "evaluator.log", timeout=timeout):
        return row
    if not out.is_file():
        row["message"] = f"evaluator wrote no output at {out}"
        return row
    try:
        got = read_npz(out)
    except Exception as exc:  # noqa: BLE001 - any unreadable output fails the case
        row["message"] = f"cannot read the output NPZ: {exc}"
        return row
    res = compare(case, got, read_npz(case["dir"] / "expected.npz"))
    row.update(passed=res["passed"], worst=res["worst"], problems=res["problems"], status="pass" if res["passed"] else "fail",
               tier=("exact" if res["exact"] else "tolerance") if res["passed"] else None)
    row["message"] = "; ".join(res["problems"][:4])
    return row


def run_suite(template: str = SDK_EVALUATOR, *, suite=None, cases=None, workdir=None, timeout: float = 300.0, progress=None) -> dict:
    selected = load_vector_cases(suite, cases)
    workdir = Path(workdir) if workdir else Path(tempfile.mkdtemp(prefix="nasset-evaluator-"))
    workdir.mkdir(parents=True, exist_ok=True)
    rows = []
    t0 = time.perf_counter()
    for c in selected:
        row = run_case(c, template, workdir, timeout=timeout)
        rows.append(row)
        if progress:
            progress(row)
    n_pass = sum(r["passed"] for r in rows)
    return {"ok": n_pass == len(rows), "evaluator": template, "workdir": str(workdir), "passed": n_pass,
            "failed": len(rows) - n_pass, "seconds": round(time.perf_counter() - t0, 2), "cases": rows}


def format_row(r: dict) -> str:
    worst = "-" if r["worst"] is None else f"{r['worst']:.3g}"
    line = f"{r['case']:<14} {r['status'].upper():<5} {(r['tier'] or '-'):<9} {worst:>9}"
    return line + (f"  {r['message']}" if r["message"] else "")


def run(args) -> int:
    """CLI: nasset conformance --evaluator CMD."""
    if args.timeout <= 0:
        raise UsageError("--timeout must be > 0")
    template = args.evaluator if args.evaluator != "sdk" else SDK_EVALUATOR
    if args.list:
        for c in load_vector_cases(args.suite, args.cases):
            print(f"{c['name']:<14} {c['kind']}/{c['variant']}  queries: {', '.join(c['queries'])}")
        return 0
    format_command(template, option="--evaluator", placeholders=PLACEHOLDERS, **{p: "x" for p in PLACEHOLDERS})
    progress = None if args.json else (lambda r: print(format_row(r), flush=True))
    if progress:
        print(f"{'case':<14} {'':<5} {'tier':<9} {'worst':>9}", flush=True)
    report = run_suite(template, suite=args.suite, cases=args.cases, workdir=args.workdir,
                       timeout=args.timeout, progress=progress)
    if args.json:
        print(json.dumps(report, indent=2, default=str))
    else:
        print(f"{report['passed']}/{len(report['cases'])} cases pass ({report['seconds']:.1f} s); outputs in {report['workdir']}")
    return 0 if report["ok"] else 1

