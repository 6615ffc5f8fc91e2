"""Example counting for the numerical stress suite.

Every stress test records, per function under test, how many hypothesis examples it ran and how
many input rows those examples held. At the end of the session the totals are printed in the
terminal summary and written as JSON under pytest's temporary directory (never into the tree).
"""

from __future__ import annotations

import json
from collections import defaultdict

import pytest

_COUNTS: dict[str, list[int]] = defaultdict(lambda: [0, 0])
_STATE: dict[str, str] = {}


class Counter:
    """counts.add(name, rows): one more example of ``name`` with ``rows`` inputs, all checked finite."""

    def add(self, name: str, rows: int = 1) -> None:
        c = _COUNTS[name]
        c[0] += 1
        c[1] += int(rows)


@pytest.fixture(scope="session")
def counts(tmp_path_factory):
    yield Counter()
    if _COUNTS:
        path = tmp_path_factory.getbasetemp() / "stress_counts.json"
        path.write_text(json.dumps({k: {"examples": v[0], "inputs": v[1]} for k, v in sorted(_COUNTS.items())}, indent=1))
        _STATE["path"] = str(path)


def pytest_terminal_summary(terminalreporter):
    if not _COUNTS:
        return
    tr = terminalreporter
    tr.section("numerical stress: examples / inputs per function (all outputs checked finite)")
    width = max(len(k) for k in _COUNTS)
    for name, (ex, rows) in sorted(_COUNTS.items()):
        tr.write_line(f"{name:<{width}}  {ex:6d} examples  {rows:8d} inputs")
    tr.write_line(f"total: {sum(v[0] for v in _COUNTS.values())} examples, {sum(v[1] for v in _COUNTS.values())} inputs")
    if "path" in _STATE:
        tr.write_line(f"written to {_STATE['path']}")
