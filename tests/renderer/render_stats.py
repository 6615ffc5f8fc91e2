"""Checks of rendered images: per-image mean and standard error, finite renders, and the agreement of two
renders within their Monte Carlo noise (the chi-squared test of samplers is in ``tests/stats.py``)."""

from __future__ import annotations

import numpy as np


def mean_and_stderr(image, variance, mask=None):
    """Mean over pixels and its standard error, from the film's per-pixel variance of the mean."""
    img = np.asarray(image)
    var = np.asarray(variance)
    if mask is None:
        mask = np.ones(img.shape[:2], bool)
    k = int(mask.sum())
    return img[mask].mean(0), np.sqrt(var[mask].sum(0)) / k


def render_finite(path, **settings):
    """Render a scene file (default 16x16) and check image and variance are finite."""
    from nasset_reference_renderer import RenderSettings, load_scene, render

    settings.setdefault("width", 16)
    settings.setdefault("height", 16)
    res = render(load_scene(path), RenderSettings(**settings))
    assert np.isfinite(res.image).all() and np.isfinite(res.variance).all()
    return res


def pixel_fraction_bound(k, null_rate, alpha=1e-6):
    """Largest fraction of ``k`` pixel values beyond the z threshold that a correct renderer exceeds with probability
    ``alpha``, when each exceeds it independently with probability ``null_rate`` (binomial upper tail)."""
    from scipy.stats import binom

    return float(binom.isf(alpha, k, null_rate)) / k


def assert_renders_agree(a, b, *, z_mean, z_pixel, pixel_fraction=None, pixel_null_rate=None):
    """Two independent renders estimate the same image: per-channel means within ``z_mean`` standard errors,
    and at most ``pixel_fraction`` of pixels beyond ``z_pixel`` sigma -- or, given ``pixel_null_rate`` (the measured
    chance that one pixel value of two correct renders lies beyond ``z_pixel``), at most the binomial bound
    :func:`pixel_fraction_bound`. Returns the per-channel mean z."""
    ia, ib, va, vb = a.image, b.image, a.variance, b.variance
    k = ia.shape[0] * ia.shape[1]
    se = np.sqrt(va.sum((0, 1)) + vb.sum((0, 1))) / k
    z = np.abs(ia.mean((0, 1)) - ib.mean((0, 1))) / np.maximum(se, 1e-12)
    assert (z < z_mean).all(), (ia.mean((0, 1)), ib.mean((0, 1)), z)
    den = va + vb
    m = den > 0
    zp = np.abs(ia - ib)[m] / np.sqrt(den[m])
    if pixel_null_rate is not None:
        pixel_fraction = pixel_fraction_bound(len(zp), pixel_null_rate)
    assert (zp > z_pixel).mean() <= pixel_fraction, ((zp > z_pixel).mean(), pixel_fraction)
    return z
