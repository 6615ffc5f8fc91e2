"""Statistical helpers for sampler tests: a Pearson chi-squared goodness-of-fit test.

Usage: bin the samples (``observed`` counts), integrate the pdf over the same bins (``expected``
probabilities), and call :func:`chi2_test`. Bins whose expected count is below ``min_expected``
(5, the usual validity rule of the chi-squared approximation) are pooled, smallest first, into one
bin; if the pool itself stays below ``min_expected`` it is merged with the next-smallest bin.
A sample falling in a bin of zero expected probability fails the test outright (p = 0).
Tests use the significance level :data:`SIGNIFICANCE`: a correct sampler fails one seed with that
probability, and the seeds are fixed, so results are reproducible.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

SIGNIFICANCE = 0.01


def chi2_test(observed, expected_prob, *, min_expected: float = 5.0, normalize: bool = True):
    """(statistic, degrees of freedom, p-value) of observed counts against expected bin probabilities.

    With ``normalize`` the probabilities are rescaled to sum to 1 (quadrature leaves a small deficit;
    tests check the integral separately).
    """
    obs = np.asarray(observed, np.float64).reshape(-1)
    p = np.asarray(expected_prob, np.float64).reshape(-1)
    if obs.shape != p.shape:
        raise ValueError("observed and expected must have the same number of bins")
    if not np.isfinite(p).all() or (p < 0).any():
        raise ValueError("expected probabilities must be finite and >= 0")
    n = obs.sum()
    if normalize:
        p = p / p.sum()
    if (obs[p <= 0] > 0).any():
        return np.inf, 0, 0.0
    exp = p * n
    order = np.argsort(exp)
    exp_s, obs_s = exp[order], obs[order]
    low = np.cumsum(exp_s) < min_expected  # pool the smallest bins until the pool reaches min_expected
    k = int(low.sum())
    if k > 0:
        k = min(k + 1, len(exp_s))  # the bin that lifts the pool over the threshold joins it
        exp_s = np.concatenate([[exp_s[:k].sum()], exp_s[k:]])
        obs_s = np.concatenate([[obs_s[:k].sum()], obs_s[k:]])
    keep = exp_s > 0
    exp_s, obs_s = exp_s[keep], obs_s[keep]
    dof = len(exp_s) - 1
    if dof < 1:
        return 0.0, 0, 1.0
    stat = float(((obs_s - exp_s) ** 2 / exp_s).sum())
    return stat, dof, float(stats.chi2.sf(stat, dof))


def midpoints(lo: float, hi: float, n: int) -> np.ndarray:
    """n midpoint-rule nodes on [lo, hi]."""
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n
