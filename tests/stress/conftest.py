"""Example counting for the numerical stress suite.

Every stress test records, per function under test, how many hypothesis examples it ran and how
many input rows those examples held. At the end of the session the totals (summed over the test
workers, tests/conftest.py) are printed in the terminal summary and written as JSON under pytest's
temporary directory (never into the tree).
"""

from __future__ import annotations

import pytest

from tests.stress.counting import Counter


@pytest.fixture(scope="session")
def counts():
    return Counter()
