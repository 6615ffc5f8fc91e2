"""Statistical helpers for sampler tests: a Pearson chi-squared goodness-of-fit test.

Usage: bin the samples (``observed`` counts), integrate the pdf over the same bins (``expected``
probabilities), and call :func:`chi2_test`. Bins whose expected count is below ``min_expected``
(5, the usual validity rule of the chi-squared approximation) are pooled, smallest first, into one
bin; if the pool itself stays below ``min_expected`` it is merged with the next-smallest bin.
A sample falling in a bin of zero expected probability fails the test outright (p = 0).
Tests use the significance level :data:`SIGNIFICANCE`: a correct sampler fails one seed with that
probability, and the seeds are fixed, so results are reproducible.

:func:`sphere_chi2` is the direction-sampler form (bins on the sphere, expected counts by quadrature of the
pdf); it checks that its quadrature is accurate enough for the sample count (see :data:`MAX_QUADRATURE_SHIFT`).
:func:`adaptive_quad` / :func:`adaptive_quad_2d` integrate a pdf over bins by adaptive Gauss-Legendre, for pdfs
whose narrow peaks a fixed midpoint rule misses (the 8dna spline flow).
``tests/stats_sweep.py`` reruns every chi-squared test of the default suite over many seeds
(:func:`stat_seed` shifts every fixed seed by ``NASSET_STAT_SEED``) and checks the p-values are uniform.
"""

from __future__ import annotations

import os

import numpy as np
from scipy import stats

#: per-test significance level. The default suite holds about 45 chi-squared tests and a similar number of
#: z-tests at >= 4.5 sigma (two-sided 6.8e-6); 1e-6 per chi-squared test keeps the chance that a correct
#: implementation fails some statistical test of one run at about 1e-4 (the seeds are fixed, so a run either
#: passes or fails every time: this is the chance that the fixed seeds are unlucky). Real bugs give p << 1e-20
#: at these sample counts.
SIGNIFICANCE = 1e-6
#: largest allowed non-centrality n * sum (dp^2 / p) of the chi-squared statistic caused by quadrature error in the
#: expected bin probabilities (estimated as the change between the quadrature and one at half the resolution).
#: Under the null the statistic has standard deviation sqrt(2 dof) >= 10 here; a shift of 2 moves p-values a little.
MAX_QUADRATURE_SHIFT = 2.0
#: p-values of every chi-squared test of this process, (test id, p): read by the seed sweep.
RECORD: list[tuple[str, float]] = []


def stat_seed(base: int) -> int:
    """A test's fixed seed, shifted by the environment variable NASSET_STAT_SEED (0 by default; the seed sweep sets it)."""
    return int(base) + int(os.environ.get("NASSET_STAT_SEED", "0")) * 1000003


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
    pval = float(stats.chi2.sf(stat, dof))
    RECORD.append((os.environ.get("PYTEST_CURRENT_TEST", "?").split(" ")[0], pval))
    return stat, dof, pval


def _sphere_bin(v, n_theta, n_phi):
    z = np.clip(v[:, 2], -1, 1)
    it = np.clip(((1 - z) * 0.5 * n_theta).astype(int), 0, n_theta - 1)
    phi = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2 * np.pi)
    ip = np.clip((phi / (2 * np.pi) * n_phi).astype(int), 0, n_phi - 1)
    return it * n_phi + ip


def _sphere_bin_prob(pdf_fn, n_theta, n_phi, bins, sub):
    """Probability of the (z, phi) bins ``bins``: midpoint rule on sub x sub nodes per bin (equal solid-angle cells)."""
    it, ip = np.divmod(np.asarray(bins), n_phi)
    g = (np.arange(sub) + 0.5) / sub
    z = 1 - 2 * (it[:, None, None] + g[None, :, None]) / n_theta
    phi = 2 * np.pi * (ip[:, None, None] + g[None, None, :]) / n_phi
    z, phi = np.broadcast_arrays(z, phi)
    r = np.sqrt(np.maximum(0, 1 - z ** 2))
    out = np.empty(len(it))
    step = max(1, 2_000_000 // (sub * sub))
    for k in range(0, len(it), step):
        sl = slice(k, k + step)
        dirs = np.stack([r[sl] * np.cos(phi[sl]), r[sl] * np.sin(phi[sl]), z[sl]], -1).reshape(-1, 3)
        out[sl] = pdf_fn(dirs).reshape(-1, sub * sub).sum(1)
    return out * (4 * np.pi / (n_theta * n_phi * sub * sub))


def sphere_bin_probabilities(pdf_fn, n_theta, n_phi, sub, n, max_sub=256):
    """Bin probabilities accurate enough for ``n`` samples: the midpoint rule at ``sub`` x ``sub`` nodes per bin,
    refined (doubling ``sub``) in the bins that dominate the difference to the rule at half the resolution, until
    the difference could shift the statistic by less than :data:`MAX_QUADRATURE_SHIFT` (a discontinuous pdf, e.g.
    a light's cone edge, needs more nodes near its edge). Returns (probabilities, estimated shift)."""
    bins = np.arange(n_theta * n_phi)
    prob = _sphere_bin_prob(pdf_fn, n_theta, n_phi, bins, sub)
    coarse = _sphere_bin_prob(pdf_fn, n_theta, n_phi, bins, max(sub // 2, 1))
    subs = np.full(len(bins), sub)
    while True:
        contrib = n * np.where(prob > 0, (prob - coarse) ** 2 / np.where(prob > 0, prob, 1), 0.0)
        shift = float(contrib.sum())
        if shift < MAX_QUADRATURE_SHIFT or subs.max() >= max_sub:
            return prob, shift
        order = np.argsort(contrib)[::-1]
        top = order[: int(np.searchsorted(np.cumsum(contrib[order]), 0.99 * shift)) + 1]
        coarse[top] = prob[top]
        for sb in np.unique(subs[top]):
            sel = top[subs[top] == sb]
            prob[sel] = _sphere_bin_prob(pdf_fn, n_theta, n_phi, sel, 2 * sb)
            subs[sel] = 2 * sb


def sphere_chi2(sample_fn, pdf_fn, *, n=200_000, n_theta=20, n_phi=40, sub=16, seed=0, min_expected=5.0,
                pdf_total: float | None = None):
    """chi-squared test of a direction sampler: (p_value, dof, pdf_integral).

    ``sample_fn(u [N,2]) -> dirs [N,3]`` (rows with NaN or zero length = failed samples); ``pdf_fn(dirs) -> pdf [N]``
    per steradian. Bins are equal solid-angle (z, phi) cells; their probabilities are the pdf integrated by the
    midpoint rule on ``sub`` x ``sub`` nodes per bin, refined where needed (:func:`sphere_bin_probabilities`); if even
    the finest rule could shift the statistic by more than :data:`MAX_QUADRATURE_SHIFT`, the test itself is wrong
    and fails with an AssertionError naming ``sub``.

    Failed samples form one more bin of probability 1 - integral. ``pdf_total`` is the pdf's exact integral when it is
    known (1 for a sampler that never fails, e.g. a light's): that bin then gets 1 - pdf_total, not the quadrature's
    deficit (which would expect a few failed samples that a correct sampler never produces and pull p-values low).
    """
    rng = np.random.default_rng(stat_seed(seed))
    v = sample_fn(rng.random((n, 2)))
    ok = np.isfinite(v).all(1) & (np.linalg.norm(v, axis=1) > 0.5)
    obs = np.bincount(_sphere_bin(v[ok], n_theta, n_phi), minlength=n_theta * n_phi).astype(float)
    prob, shift = sphere_bin_probabilities(pdf_fn, n_theta, n_phi, sub, n)
    # a bin the pdf's support only grazes can get no node with pdf > 0: integrate such bins that hold samples finely
    # (a few at most; a sample where the pdf really is 0 still fails the test)
    grazed = np.nonzero((obs > 0) & (prob <= 0))[0][:16]
    prob[grazed] = _sphere_bin_prob(pdf_fn, n_theta, n_phi, grazed, 1024)
    integral = float(prob.sum())
    assert shift < MAX_QUADRATURE_SHIFT, f"expected-count quadrature too coarse (sub={sub}): shift {shift:.3g}"
    # one more bin for failed samples (e.g. a reflection below the horizon), of probability 1 - integral
    obs = np.append(obs, n - ok.sum())
    prob = np.append(prob, max(0.0, 1.0 - (integral if pdf_total is None else pdf_total)))
    _, dof, pval = chi2_test(obs, prob, min_expected=min_expected)
    return pval, dof, integral


def midpoints(lo: float, hi: float, n: int) -> np.ndarray:
    """n midpoint-rule nodes on [lo, hi]."""
    return lo + (np.arange(n) + 0.5) * (hi - lo) / n


#: Gauss-Legendre nodes and weights on [-1, 1] of :func:`adaptive_quad` (exact for polynomials of degree 9)
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)


def _gauss(f, rows, a, b):
    """5-node Gauss-Legendre integral of f over the cells [a, b] [M] of rows [M] -> [M]."""
    t = 0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * _GL_X[None, :]
    v = np.asarray(f(np.repeat(rows, len(_GL_X)), t.reshape(-1)), np.float64).reshape(t.shape)
    return 0.5 * (b - a) * (v @ _GL_W)


def adaptive_quad(f, lo, hi, *, tol: float = 1e-6, cells: int = 32, max_rounds: int = 48, max_active: int = 64):
    """Integrals of R integrands over [lo_r, hi_r]: globally adaptive bisection of Gauss-Legendre cells.

    ``f(rows [M] int, t [M]) -> [M]`` evaluates integrand ``rows`` at ``t``; lo, hi [R]. A cell is accepted when
    the sum over its two halves differs from its own estimate by at most ``tol`` times its share of [lo, hi], so the
    summed error is about ``tol`` per integrand; otherwise it is halved. A peak narrower than a cell of the initial
    ``cells`` that no node sees can still be missed (callers check the integral against an independent value).
    Refinement stops (unconverged) when more than ``max_active`` cells per integrand would be open (a kink or jump
    everywhere, e.g. a broken density, must not exhaust memory). Returns (integrals [R], converged [R] bool).
    """
    lo = np.atleast_1d(np.asarray(lo, np.float64))
    hi = np.atleast_1d(np.asarray(hi, np.float64))
    r = len(lo)
    rows = np.repeat(np.arange(r), cells)
    k = np.tile(np.arange(cells), r)
    span = hi - lo
    a = lo[rows] + span[rows] * k / cells
    b = lo[rows] + span[rows] * (k + 1) / cells
    whole = _gauss(f, rows, a, b)
    total = np.zeros(r)
    converged = np.ones(r, bool)
    for _ in range(max_rounds):
        if not len(rows) or len(rows) > max_active * r:
            break
        m = 0.5 * (a + b)
        both = _gauss(f, np.concatenate([rows, rows]), np.concatenate([a, m]), np.concatenate([m, b]))
        left, right = both[: len(rows)], both[len(rows):]
        ok = np.abs(left + right - whole) <= tol * (b - a) / np.where(span[rows] > 0, span[rows], 1.0)
        total += np.bincount(rows[ok], left[ok] + right[ok], minlength=r)
        bad = ~ok
        rows = np.concatenate([rows[bad], rows[bad]])
        a, b = np.concatenate([a[bad], m[bad]]), np.concatenate([m[bad], b[bad]])
        whole = np.concatenate([left[bad], right[bad]])
    if len(rows):
        total += np.bincount(rows, whole, minlength=r)
        converged[np.unique(rows)] = False
    return total, converged


def adaptive_quad_2d(f, lo, hi, *, tol: float = 1e-6, cells: int = 32):
    """Integrals of R integrands over rectangles [lo_r, hi_r] (lo, hi [R, 2]) by nested :func:`adaptive_quad`.

    ``f(rows [M] int, t [M, 2]) -> [M]``. The inner integral over the second coordinate is computed (adaptively, per
    node) at every node of the outer one. Returns (integrals [R], converged [R] bool)."""
    lo = np.atleast_2d(np.asarray(lo, np.float64))
    hi = np.atleast_2d(np.asarray(hi, np.float64))
    inner_ok = np.ones(len(lo), bool)

    def outer(rows, t1):
        def inner(nodes, t2):
            return f(rows[nodes], np.stack([t1[nodes], t2], axis=1))

        val, ok = adaptive_quad(inner, lo[rows, 1], hi[rows, 1], tol=tol, cells=cells)
        inner_ok[np.unique(rows[~ok])] = False
        return val

    total, ok = adaptive_quad(outer, lo[:, 0], hi[:, 0], tol=tol, cells=cells)
    return total, ok & inner_ok
