"""Shared fixtures: small example assets written once per session; the stress suite's counts over test workers."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pytest

from nasset_sdk.examples import example_builder
from tests.stats import stat_seed
from tests.stress import counting


@pytest.fixture(scope="session")
def rna_asset_path(tmp_path_factory):
    """A tiny rna surface asset with random networks, written as .usdc."""
    path = tmp_path_factory.mktemp("assets") / "rna_tiny.usdc"
    example_builder("rna", size="tiny", seed=1).write(path)
    return path


@pytest.fixture
def rng():
    return np.random.default_rng(stat_seed(1234))  # 1234 unless the seed sweep (tests/stats_sweep.py) shifts it


# -- the order test files run in ----------------------------------------------------------------------------------
#: the longest test files (seconds of one worker on the 2-core machine, 2026-12-07: 200, 177, 147, 138, 124, 90, 80, 65,
#: 60, 53, 53): they start first, so that the two workers end together instead of one running a long file alone at
#: the end (pytest-xdist's default order is by number of tests: the one-test hostile corpus ran last). scripts/test.sh
#: passes --no-loadscope-reorder so that this order is kept.
LONGEST_FILES = ("tests/renderer/test_conformance.py", "tests/sdk/test_hostile_corpus.py",
                 "tests/mitsuba_renderer/test_near_field.py", "tests/sdk/test_security_paths.py",
                 "tests/mitsuba_renderer/test_mitsuba_impl.py", "tests/bakers/test_train_parallel.py",
                 "tests/converters/test_blender_fidelity.py", "tests/bakers/test_neupress_bake.py",
                 "tests/sdk/test_security_networks.py", "tests/bakers/test_8dna_bake.py", "tests/bakers/test_cluster.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {f: k for k, f in enumerate(LONGEST_FILES)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))  # stable: files stay whole


# -- the stress suite's example counts (tests/stress): each test worker hands its counts to the main process ----


def pytest_sessionfinish(session):
    workeroutput = getattr(session.config, "workeroutput", None)  # set in a pytest-xdist worker only
    if workeroutput is not None:
        workeroutput["stress_counts"] = json.dumps(counting.COUNTS)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    counting.merge(json.loads(getattr(node, "workeroutput", {}).get("stress_counts", "{}")))


def pytest_terminal_summary(terminalreporter):
    if not counting.COUNTS or hasattr(terminalreporter.config, "workeroutput"):
        return
    tr, counts = terminalreporter, counting.COUNTS
    tr.section("numerical stress: examples / inputs per function (all outputs checked finite)")
    width = max(len(k) for k in counts)
    for name, (ex, rows) in sorted(counts.items()):
        tr.write_line(f"{name:<{width}}  {ex:6d} examples  {rows:8d} inputs")
    tr.write_line(f"total: {sum(v[0] for v in counts.values())} examples, {sum(v[1] for v in counts.values())} inputs")
    factory = getattr(tr.config, "_tmp_path_factory", None)
    base = factory.getbasetemp() if factory is not None else Path(tempfile.mkdtemp(prefix="nasset-stress-"))
    path = base / "stress_counts.json"
    path.write_text(json.dumps({k: {"examples": v[0], "inputs": v[1]} for k, v in sorted(counts.items())}, indent=1))
    tr.write_line(f"written to {path}")
