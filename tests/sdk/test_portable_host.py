"""A non-Python host evaluates an asset: Node.js runs the stored portable graph with onnxruntime-web's
WASM backend (tools/portable-host/host.mjs, the runtime a browser viewer uses) on raw float32 query
files; its outputs must equal the SDK evaluator's. scripts/setup.sh installs the host; in CI (``CI``
set) a missing host fails the test instead of skipping it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from nasset_sdk import Asset, portable
from nasset_sdk.examples import example_builder
from tests.sdk.test_portable import ATOL

HOST = Path(__file__).resolve().parents[2] / "tools" / "portable-host"
#: wall-clock bound of one host run (WASM compilation takes a few seconds on a loaded 2-core machine)
HOST_TIMEOUT_S = 120


def host_or_skip() -> str:
    node = shutil.which("node")
    missing = ("node is not on PATH" if node is None else
               None if (HOST / "node_modules" / "onnxruntime-web").is_dir() else
               f"onnxruntime-web is not installed in {HOST} (run scripts/setup.sh)")
    if missing:
        if os.environ.get("CI"):
            pytest.fail(f"portable host unavailable in CI: {missing}")
        pytest.skip(f"portable host unavailable outside CI: {missing}")
    return node


def run_host(node: str, blob: bytes, queries: dict[str, np.ndarray], work: Path) -> dict[str, np.ndarray]:
    """Write the graph and the queries as files, run the Node host, read its outputs back."""
    portable.write_model(work / "graph.onnx", blob)
    job = {"model": "graph.onnx", "inputs": {}, "outputDir": "out"}
    for name, v in queries.items():
        np.ascontiguousarray(v, "<f4").tofile(work / f"{name}.bin")
        job["inputs"][name] = {"file": f"{name}.bin", "shape": list(v.shape)}
    (work / "job.json").write_text(json.dumps(job))
    r = subprocess.run([node, str(HOST / "host.mjs"), str(work / "job.json")], capture_output=True, text=True,
                       timeout=HOST_TIMEOUT_S)
    assert r.returncode == 0, r.stderr[-2000:]
    shapes = json.loads((work / "out" / "outputs.json").read_text())
    return {name: np.fromfile(work / "out" / f"{name}.bin", "<f4").reshape(shape) for name, shape in shapes.items()}


@pytest.mark.parametrize("kind,variant", [("rna", "fiber"), ("neupress", "surface"), ("8dna", "surface")])
def test_node_host_matches_the_evaluator(tmp_path, kind, variant):
    node = host_or_skip()
    src = tmp_path / "a.usdc"
    example_builder(kind, variant=variant, size="small", seed=5).write(src)
    portable.add_portable(src, tmp_path / "p.usdc")
    asset = Asset.open(tmp_path / "p.usdc", load="all")
    (name,) = asset.network_refs("portable")
    q = portable.random_queries(asset, 1024, np.random.default_rng(11))
    got = run_host(node, asset.network_bytes("portable", name), q, tmp_path)
    want = portable.reference_outputs(asset, q)
    assert set(got) == set(want)
    for out, ref in want.items():
        assert np.abs(ref).max() > 0.1
        np.testing.assert_allclose(got[out], ref, rtol=0, atol=ATOL[kind], err_msg=f"node host, {kind}/{variant} {out}")
