"""Shared fixtures: small example assets written once per session."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_sdk.examples import example_builder
from tests.stats import stat_seed


@pytest.fixture(scope="session")
def rna_asset_path(tmp_path_factory):
    """A tiny rna surface asset with random networks, written as .usdc."""
    path = tmp_path_factory.mktemp("assets") / "rna_tiny.usdc"
    example_builder("rna", size="tiny", seed=1).write(path)
    return path


@pytest.fixture
def rng():
    return np.random.default_rng(stat_seed(1234))  # 1234 unless the seed sweep (tests/stats_sweep.py) shifts it
