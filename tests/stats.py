"""Statistical helpers for sampler tests: one Pearson chi-squared goodness-of-fit test, and its
domain for direction samplers on the sphere (the idea of Mitsuba's ChiSquareTest).

Usage: bin the samples (``observed`` counts), integrate the pdf over the same bins (``expected``
probabilities), and call :func:`chi2_test`. Bins whose expected count is below ``min_expected``
(5, the usual validity rule of the chi-squared approximation) are pooled, smallest first, into one
bin; if the pool itself stays below ``min_expected`` it is merged with the next-smallest bin.
A sample falling in a bin of zero expected probability fails the test outright (p = 0) unless
``strict_zero=False``.
Tests use the significance level :data:`SIGNIFICANCE`: a correct sampler fails one seed with that
probability, and the seeds are fixed, so results are reproducible.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

SIGNIFICANCE = 0.01


def chi2_test(observed, expected_prob, *, min_expected: float = 5.0, normalize: bool = True, strict_zero: bool = True):
    """(statistic, degrees of freedom, p-value) of observed counts against expected bin probabilities.

    With ``normalize`` the probabilities are rescaled to sum to 1 (quadrature leaves a small deficit;
    tests check the integral separately). With ``strict_zero`` a sample in a bin of zero expected
    probability fails the test; without, such bins join the pool of small bins (for expectations from
    a quadrature that can miss a sliver of the support, as at the rim of a cone).
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
    if strict_zero and (obs[p <= 0] > 0).any():
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


def _sphere_bin(v, n_theta, n_phi):
    z = np.clip(v[:, 2], -1, 1)
    it = np.clip(((1 - z) * 0.5 * n_theta).astype(int), 0, n_theta - 1)
    phi = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2 * np.pi)
    ip = np.clip((phi / (2 * np.pi) * n_phi).astype(int), 0, n_phi - 1)
    return it * n_phi + ip


def direction_chi2_test(sample_fn, pdf_fn, *, n=200_000, n_theta=20, n_phi=40, sub=8, seed=0, min_expected=5.0):
    """:func:`chi2_test` of a direction sampler against its pdf; returns (p_value, dof, pdf_integral).

    Directions are binned on the sphere by (cos theta, phi), equal solid-angle cells; each bin's
    expected probability is the pdf integrated over the bin (midpoint rule on a ``sub`` x ``sub`` finer
    grid). ``sample_fn(u [N,2]) -> dirs [N,3]`` (rows with NaN or zero length = failed samples, which
    count against the pdf's mass); ``pdf_fn(dirs) -> pdf [N]`` in solid angle."""
    rng = np.random.default_rng(seed)
    v = sample_fn(rng.random((n, 2)))
    ok = np.isfinite(v).all(1) & (np.linalg.norm(v, axis=1) > 0.5)
    obs = np.bincount(_sphere_bin(v[ok], n_theta, n_phi), minlength=n_theta * n_phi).astype(float)
    ft, fp = n_theta * sub, n_phi * sub
    z = 1 - (np.arange(ft) + 0.5) / ft * 2
    phi = (np.arange(fp) + 0.5) / fp * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(np.maximum(0, 1 - zz ** 2))
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], -1).reshape(-1, 3)
    d_omega = 4 * np.pi / (ft * fp)
    pdf = pdf_fn(dirs).reshape(ft, fp)
    integral = float(pdf.sum() * d_omega)
    prob = (pdf.reshape(n_theta, sub, n_phi, sub).sum((1, 3)) * d_omega).ravel()
    # failed samples: one more bin holding the pdf's missing mass (never pooled away from it)
    obs = np.append(obs, n - ok.sum())
    prob = np.append(prob, max(1.0 - prob.sum(), 0.0))
    _, dof, p = chi2_test(obs, prob, min_expected=min_expected, normalize=False, strict_zero=False)
    return p, dof, integral

