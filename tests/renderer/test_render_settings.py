"""Render settings read from the stage: the Gaussian pixel filter's sample offsets (chi² against the filter)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer.film import pixel_offsets
from tests.stats import chi2_test, stat_seed


@pytest.mark.parametrize("stddev", [0.5, 0.7])
def test_gaussian_offsets_follow_mitsubas_truncated_gaussian(stddev):
    # Mitsuba's gaussian: exp(-x^2 / 2s^2) - exp(-r^2 / 2s^2) on |x| < r = 4 s around the pixel centre, per axis
    r, n, bins = 4 * stddev, 200_000, 40
    off = pixel_offsets(np.random.default_rng(stat_seed(11)), n, "gaussian", stddev) - 0.5
    assert np.abs(off).max() <= r
    edges = np.linspace(-r, r, bins + 1)
    x = np.linspace(-r, r, bins * 512 + 1)  # fine midpoint quadrature of the density per bin
    mid = 0.5 * (x[1:] + x[:-1])
    f = np.exp(-mid ** 2 / (2 * stddev ** 2)) - np.exp(-r ** 2 / (2 * stddev ** 2))
    prob = f.reshape(bins, -1).sum(1)
    for axis in (0, 1):
        counts, _ = np.histogram(off[:, axis], edges)
        _, _, p = chi2_test(counts, prob)
        assert p > 1e-4, (axis, p)
    assert abs(np.corrcoef(off[:, 0], off[:, 1])[0, 1]) < 0.01  # separable: independent axes


def test_box_offsets_are_uniform_over_the_pixel():
    off = pixel_offsets(np.random.default_rng(stat_seed(12)), 100_000, "box")
    assert off.min() >= 0 and off.max() < 1
    counts, _ = np.histogram(off[:, 0], np.linspace(0, 1, 21))
    assert chi2_test(counts, np.full(20, 0.05))[2] > 1e-4
