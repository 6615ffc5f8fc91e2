"""The evaluator written from the spec alone (tests/spec_evaluator/evaluator.py) reproduces the SDK's
answers on the evaluator test vectors, through ``nasset conformance --evaluator``."""

from __future__ import annotations

import ast
import json
import shlex
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
COMMAND = f"{shlex.quote(sys.executable)} -m tests.spec_evaluator.evaluator {{asset}} {{input}} {{output}}"


def test_spec_evaluator_imports_nothing_from_the_repository():
    tree = ast.parse((HERE / "evaluator.py").read_text())
    names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
    assert names <= {"__future__", "math", "sys", "numpy", "onnxruntime", "pxr"}, names


def test_spec_evaluator_passes_the_vectors_exactly(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "nasset_sdk.cli", "conformance", "--evaluator", COMMAND,
                           "--workdir", str(tmp_path), "--json"], capture_output=True, text=True, cwd=ROOT)
    report = json.loads(proc.stdout)
    rows = {r["case"]: r for r in report["cases"]}
    assert proc.returncode == 0, {k: r["message"] for k, r in rows.items()}
    assert {r["tier"] for r in rows.values()} == {"exact"}, {k: r["problems"] for k, r in rows.items()}
