"""nasset_sdk.metrics on synthetic images with known bias and noise (spec/accuracy.md#metrics).

Statistical checks use fixed seeds and 4-sigma bounds: for a fresh seed each would fail with
probability ~6e-5 (two-sided normal tail at 4 sigma); with the seeds below they are deterministic.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from nasset_sdk.errors import UsageError
from nasset_sdk.metrics import accuracy, noise_variance


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
