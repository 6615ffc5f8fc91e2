"""Chi-square goodness-of-fit test for direction samplers (the idea of Mitsuba's ChiSquareTest).

Directions are binned on the sphere by (cos theta, phi); each bin's expected count is the
sampler's pdf integrated over the bin (midpoint rule on a finer sub-grid); bins with small
expected counts are pooled; the statistic is compared with the chi² distribution.
"""

from __future__ import annotations

import numpy as np
from scipy import stats


def _bin_index(v, n_theta, n_phi):
    z = np.clip(v[:, 2], -1, 1)
    it = np.clip(((1 - z) * 0.5 * n_theta).astype(int), 0, n_theta - 1)
    phi = np.mod(np.arctan2(v[:, 1], v[:, 0]), 2 * np.pi)
    ip = np.clip((phi / (2 * np.pi) * n_phi).astype(int), 0, n_phi - 1)
    return it * n_phi + ip


def chi2_test(sample_fn, pdf_fn, *, n=200_000, n_theta=20, n_phi=40, sub=8, seed=0, min_expected=5.0):
    """Returns (p_value, dof, pdf_integral). ``sample_fn(u [N,2]) -> dirs [N,3]`` (rows with NaN
    or zero-length = failed samples); ``pdf_fn(dirs) -> pdf [N]`` in solid angle."""
    rng = np.random.default_rng(seed)
    v = sample_fn(rng.random((n, 2)))
    ok = np.isfinite(v).all(1) & (np.linalg.norm(v, axis=1) > 0.5)
    obs = np.bincount(_bin_index(v[ok], n_theta, n_phi), minlength=n_theta * n_phi).astype(float)
    # expected: integrate pdf over each bin (uniform in z and phi -> equal solid angle cells)
    ft, fp = n_theta * sub, n_phi * sub
    z = 1 - (np.arange(ft) + 0.5) / ft * 2
    phi = (np.arange(fp) + 0.5) / fp * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(np.maximum(0, 1 - zz ** 2))
    dirs = np.stack([r * np.cos(pp), r * np.sin(pp), zz], -1).reshape(-1, 3)
    dA = 4 * np.pi / (ft * fp)
    pdf = pdf_fn(dirs).reshape(ft, fp)
    integral = float(pdf.sum() * dA)
    exp = (pdf.reshape(n_theta, sub, n_phi, sub).sum((1, 3)) * dA * n).ravel()
    order = np.argsort(exp)
    obs_s, exp_s = obs[order], exp[order]
    # pool small bins
    pooled_o, pooled_e, acc_o, acc_e = [], [], 0.0, 0.0
    for o, e in zip(obs_s, exp_s, strict=True):
        acc_o += o
        acc_e += e
        if acc_e >= min_expected:
            pooled_o.append(acc_o)
            pooled_e.append(acc_e)
            acc_o = acc_e = 0.0
    if acc_e > 0 or acc_o > 0:
        if pooled_e:
            pooled_o[-1] += acc_o
            pooled_e[-1] += acc_e
        else:
            pooled_o.append(acc_o)
            pooled_e.append(acc_e)
    po, pe = np.array(pooled_o), np.array(pooled_e)
    if (pe <= 0).any() and (po[pe <= 0] > 0).any():
        return 0.0, len(po) - 1, integral
    m = pe > 0
    chi2 = float(((po[m] - pe[m]) ** 2 / pe[m]).sum())
    dof = int(m.sum()) - 1
    return float(stats.chi2.sf(chi2, dof)), dof, integral


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


def assert_renders_agree(a, b, *, z_mean, z_pixel, pixel_fraction):
    """Two independent renders estimate the same image: per-channel means within ``z_mean`` standard errors,
    and at most ``pixel_fraction`` of pixels beyond ``z_pixel`` sigma. Returns the per-channel mean z."""
    ia, ib, va, vb = a.image, b.image, a.variance, b.variance
    k = ia.shape[0] * ia.shape[1]
    se = np.sqrt(va.sum((0, 1)) + vb.sum((0, 1))) / k
    z = np.abs(ia.mean((0, 1)) - ib.mean((0, 1))) / np.maximum(se, 1e-12)
    assert (z < z_mean).all(), (ia.mean((0, 1)), ib.mean((0, 1)), z)
    den = va + vb
    m = den > 0
    zp = np.abs(ia - ib)[m] / np.sqrt(den[m])
    assert (zp > z_pixel).mean() < pixel_fraction, (zp > z_pixel).mean()
    return z
