"""nasset_sdk.metrics on synthetic images with known bias and noise (spec/accuracy.md#metrics).

Statistical checks use fixed seeds and 4-sigma bounds: for a fresh seed each would fail with
probability ~6e-5 (two-sided normal tail at 4 sigma); with the seeds below they are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from nasset_sdk.errors import UsageError
from nasset_sdk.metrics import Accuracy, accuracy, group_figures, noise_variance


def _scene(rng, h=64, w=64):
    truth = rng.uniform(0.05, 1.0, (h, w, 3))
    truth[..., 1] *= 0.8
    mask = np.zeros((h, w), bool)
    mask[8:56, 12:52] = True
    return truth, mask


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("bias", [-0.25, -0.03, 0.0, 0.05])
def test_energy_bias_recovered_within_its_standard_error(seed, bias):
    rng = np.random.default_rng(seed)
    truth, mask = _scene(rng)
    sigma = 0.3
    a = truth + rng.normal(0, sigma, truth.shape)
    b = truth + rng.normal(0, sigma, truth.shape)
    est = truth * (1.0 + bias)  # exact up to a known multiplicative bias
    acc = accuracy(est, a, b, mask, flip=False)
    for c in range(3):
        assert abs(acc.energy_error[c] - bias) < 4 * acc.energy_se[c] + 1e-12, (c, acc.energy_error, acc.energy_se)
        # the standard error itself is right: sqrt(n var_r) / S_ref * ratio
        n = mask.sum()
        se = math.sqrt(n * sigma ** 2 / 2) / truth[mask][:, c].sum() * (1 + bias)
        assert acc.energy_se[c] == pytest.approx(se, rel=0.1)


def test_ceiling_matches_the_injected_noise():
    rng = np.random.default_rng(7)
    truth, mask = _scene(rng, 128, 128)
    sigma = 0.2
    a = truth + rng.normal(0, sigma, truth.shape)
    b = truth + rng.normal(0, sigma, truth.shape)
    n = mask.sum() * 3
    v = noise_variance(a, b, mask)
    # Var(r) = sigma^2 / 2; the estimate's relative standard error is sqrt(2 / n)
    assert abs(v / (sigma ** 2 / 2) - 1) < 4 * math.sqrt(2 / n)
    acc = accuracy(truth, a, b, mask, flip=False)
    ceiling = 10 * math.log10(acc.peak ** 2 / (sigma ** 2 / 2))
    tol_db = 10 * math.log10(1 + 4 * math.sqrt(2 / n))  # 4 standard errors of v, in dB
    assert acc.ceiling_db == pytest.approx(ceiling, abs=tol_db)
    # an exact image scores the ceiling and is reported at the ceiling, never above it
    assert acc.psnr_db == pytest.approx(acc.ceiling_db, abs=tol_db)
    assert acc.at_ceiling and acc.psnr_corrected_db is None
    assert "at the ceiling" in acc.claimed_psnr()


def test_bias_corrected_mse_recovers_the_estimates_own_error():
    rng = np.random.default_rng(3)
    truth, mask = _scene(rng, 128, 128)
    a = truth + rng.normal(0, 0.15, truth.shape)
    b = truth + rng.normal(0, 0.15, truth.shape)
    err = rng.normal(0, 0.05, truth.shape)  # the estimate's own error: MSE 2.5e-3, below the reference noise 1.1e-2
    acc = accuracy(truth + err, a, b, mask, flip=False)
    true_mse = float((err[mask] ** 2).mean())
    assert abs(acc.mse_corrected - true_mse) < 4 * acc.mse_corrected_se
    assert acc.mse > 4 * true_mse  # the raw MSE is dominated by the reference's noise
    assert not acc.at_ceiling
    assert acc.psnr_corrected_db > acc.psnr_db


def test_estimate_variance_is_subtracted():
    rng = np.random.default_rng(4)
    truth, mask = _scene(rng, 96, 96)
    a = truth + rng.normal(0, 0.1, truth.shape)
    b = truth + rng.normal(0, 0.1, truth.shape)
    est = truth + rng.normal(0, 0.2, truth.shape)  # an unbiased but noisy estimate
    acc = accuracy(est, a, b, mask, est_var=np.full(truth.shape, 0.04), flip=False)
    assert abs(acc.mse_corrected) < 4 * acc.mse_corrected_se
    assert acc.at_ceiling


def test_unresolved_error_is_not_claimed_at_the_ceiling():
    """A biased estimate so noisy that its error is within 2 standard errors of 0: it is not "at the ceiling"
    (that needs the error's 2-sigma upper bound within the reference's noise), and the claim is the bound."""
    rng = np.random.default_rng(11)
    truth, mask = _scene(rng, 32, 32)
    a = truth + rng.normal(0, 0.05, truth.shape)
    b = truth + rng.normal(0, 0.05, truth.shape)
    bias = 0.06  # bias^2 3.6e-3, three times the reference's noise variance 1.25e-3
    est = truth + bias + rng.normal(0, 0.6, truth.shape)  # the estimate's own variance 0.36
    acc = accuracy(est, a, b, mask, est_var=np.full(truth.shape, 0.36), flip=False)
    assert acc.mse_corrected < 2 * acc.mse_corrected_se  # the premise: the bias is not resolved
    assert not acc.at_ceiling and acc.psnr_corrected_db is None
    true_psnr = 10 * math.log10(acc.peak ** 2 / bias ** 2)
    assert acc.psnr_bound_db < true_psnr < acc.ceiling_db
    assert acc.claimed_psnr().startswith(">= ") and "ceiling" not in acc.claimed_psnr()


def test_psnr_bound_holds_in_95_percent_of_draws():
    """The bound 10 log10(peak^2 / (max(mse_corrected, 0) + 2 se)) is a 2-sigma lower bound of the PSNR of the
    estimate's own error: over 400 draws of noisy, biased estimates it exceeds the true value in at most
    ~2.3 % + sampling slack (one-sided normal tail at 2 sigma; 4-sigma binomial slack: < 6 %)."""
    rng = np.random.default_rng(5)
    truth, mask = _scene(rng, 24, 24)
    over = 0
    draws = 400
    for _ in range(draws):
        a = truth + rng.normal(0, 0.1, truth.shape)
        b = truth + rng.normal(0, 0.1, truth.shape)
        est = truth + 0.03 + rng.normal(0, 0.3, truth.shape)
        acc = accuracy(est, a, b, mask, est_var=np.full(truth.shape, 0.09), peak=1.0, flip=False)
        over += acc.psnr_bound_db > 10 * math.log10(1.0 / 0.03 ** 2)
    assert over / draws < 0.023 + 4 * math.sqrt(0.023 * 0.977 / draws)


def test_peak_convention_and_psnr_value():
    truth = np.full((16, 16, 3), 0.5)
    a = truth.copy()
    b = truth.copy()
    b[0, 0, 0] += 1e-3  # a nonzero noise estimate
    est = truth + 0.05
    acc = accuracy(est, a, b, flip=False)
    assert acc.peak == pytest.approx(np.percentile(0.5 * (a + b), 99.5))
    assert acc.psnr_db == pytest.approx(10 * math.log10(acc.peak ** 2 / 0.0025), abs=1e-3)
    assert acc.energy_ratio == pytest.approx([1.1, 1.1, 1.1], rel=1e-3)


def test_flip_reported_for_images():
    pytest.importorskip("flip_evaluator")
    rng = np.random.default_rng(5)
    truth, mask = _scene(rng, 32, 32)
    same = accuracy(truth, truth, truth + 1e-6, mask)
    off = accuracy(truth * 0.5, truth, truth + 1e-6, mask)
    assert same.flip is not None and off.flip is not None
    assert same.flip < 0.01 < off.flip


def test_bad_input_is_a_usage_error():
    x = np.ones((4, 4, 3))
    with pytest.raises(UsageError):
        accuracy(x, x, np.ones((4, 5, 3)))
    with pytest.raises(UsageError):
        accuracy(x, x, x, np.zeros((4, 4), bool))
    bad = x.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(UsageError):
        accuracy(bad, x, x)
    with pytest.raises(UsageError):
        accuracy(np.ones((4, 4)), np.ones((4, 4)), np.ones((4, 4)))


def test_bad_input_types_and_shapes_are_usage_errors():
    """Strings, a peak that is not a positive number, an estimate variance that does not broadcast, and two halves
    or FLIP images of other shapes: USAGE (they were numpy ValueError / IndexError and flip-evaluator's
    RuntimeError, or a silently undefined PSNR)."""
    from nasset_sdk.metrics import flip_mean, noise_variance

    x = np.ones((8, 8, 3))
    for call, words in ((lambda: accuracy([["a", "b", "c"]], x, x), "est must be a real number array"),
                        (lambda: accuracy(x, x, x, peak=0.0), "peak must be a finite number > 0"),
                        (lambda: accuracy(x, x, x, peak=float("nan")), "peak must be a finite number > 0"),
                        (lambda: accuracy(x, x, x, est_var=np.zeros((2, 2))), "est_var of shape"),
                        (lambda: noise_variance(x, x[:4]), "a and b shapes differ"),
                        (lambda: noise_variance(x, x, np.ones((4, 4), bool)), "mask shape"),
                        (lambda: flip_mean(x, x[:4]), "images \\[H, W, 3\\] of one shape")):
        with pytest.raises(UsageError, match=words):
            call()
    r = accuracy(x, x, x, est_var=np.zeros(3), peak=1.0)  # a variance per channel broadcasts
    assert r.pixels == 64


def _grouped(rng, groups=8, per=200, spread=0.07, sigma=0.02):
    """Samples [G*per, 3] of an estimate whose error is one multiplicative bias per group (N(0, spread)),
    against a two-half reference with independent noise sigma; returns (est, a, b, labels)."""
    truth = rng.uniform(0.2, 1.0, (groups * per, 3))
    labels = np.repeat(np.arange(groups), per)
    est = truth * (1.0 + rng.normal(0.0, spread, groups))[labels][:, None]
    a = truth + rng.normal(0.0, sigma, truth.shape)
    b = truth + rng.normal(0.0, sigma, truth.shape)
    return est, a, b, labels


def test_group_standard_error_is_calibrated():
    """With groups as the units the energy standard error matches the ratio's spread over repeated draws;
    pixels taken as independent it is several times too small (a held-out set of 8 views with a 7 %
    per-view error: spec/accuracy.md#metrics). Bounds: 4 standard errors of the variance estimates."""
    rng = np.random.default_rng(11)
    trials = 6000
    ratios, se2 = np.empty((trials, 3)), np.empty((trials, 3))
    for t in range(trials):
        est, a, b, labels = _grouped(rng)
        se, _ = group_figures(est, 0.5 * (a + b), labels)
        ratios[t] = est.sum(0) / (0.5 * (a + b)).sum(0)
        se2[t] = se ** 2
    var = ratios.var(0, ddof=1)
    # relative standard errors: sample variance sqrt(2 / (T - 1)); mean of se^2 (a scaled chi^2 with
    # G - 1 = 7 degrees of freedom) sqrt(2 / 7 / T)
    tol = 4 * math.sqrt(2 / (trials - 1) + 2 / 7 / trials)
    for c in range(3):
        assert abs(se2[:, c].mean() / var[c] - 1) < tol, (c, se2[:, c].mean(), var[c], tol)
    est, a, b, labels = _grouped(rng)
    pixels = accuracy(est, a, b, flip=False)
    views = accuracy(est, a, b, flip=False, groups=labels)
    assert views.energy_ratio == pixels.energy_ratio
    assert min(views.energy_se) > 4 * max(pixels.energy_se)


def test_group_spread_and_report():
    rng = np.random.default_rng(3)
    est, a, b, labels = _grouped(rng, groups=5, spread=0.0, sigma=0.0)
    est[labels == 2] *= 0.8  # one view 20 % dark, the others exact
    acc = accuracy(est, a, b, flip=False, groups=labels)
    g = acc.to_dict()["groups"]
    assert g["count"] == 5
    assert g["ratio_min"] == pytest.approx([0.8] * 3) and g["ratio_max"] == pytest.approx([1.0] * 3)
    assert g["ratio_sd"] == pytest.approx([0.08] * 3)  # population sd of (1, 1, 0.8, 1, 1)
    one = accuracy(est, a, b, flip=False, groups=np.zeros(len(est), int))
    assert one.to_dict()["energy_se"] == [None] * 3  # one group: no standard error, never a number
    with pytest.raises(UsageError):
        accuracy(est, a, b, flip=False, groups=labels[:-1])



def test_a_black_reference_claims_nothing_and_prints_no_nan():
    """A held-out reference with no energy over the mask (a clear glass ball under a sun: the refracted sun misses
    every held-out view) has no PSNR peak: the claim says so, and no 'nan' reaches the lines people read. The bake
    summary used to stop with a TypeError formatting None after the whole training."""
    from nasset_bakers.stages import accuracy_lines

    rng = np.random.default_rng(0)
    est = rng.random((64, 3))
    acc = accuracy(est, np.zeros((64, 3)), np.zeros((64, 3)), flip=False)
    assert acc.claimed_psnr() == "undefined (black reference)"
    assert "nan" not in acc.line().lower()
    [line] = accuracy_lines(acc.to_dict())
    assert "nan" not in line.lower() and "undefined (black reference)" in line
    stored = acc.to_dict()  # as read back from a report: non-finite figures are null
    again = Accuracy(**{k: v for k, v in stored.items() if k in Accuracy.__dataclass_fields__})
    assert again.claimed_psnr() == "undefined (black reference)" and "n/a dB" in again.line()
