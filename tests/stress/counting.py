"""The stress suite's example counts: function name -> [examples, input rows], for this process."""

from __future__ import annotations

from collections import defaultdict

COUNTS: dict[str, list[int]] = defaultdict(lambda: [0, 0])


class Counter:
    """counts.add(name, rows): one more example of ``name`` with ``rows`` inputs, all checked finite."""

    def add(self, name: str, rows: int = 1) -> None:
        c = COUNTS[name]
        c[0] += 1
        c[1] += int(rows)


def merge(other: dict[str, list[int]]) -> None:
    """Add another process's counts (a test worker's) to this one's."""
    for name, (examples, rows) in other.items():
        c = COUNTS[name]
        c[0] += examples
        c[1] += rows
