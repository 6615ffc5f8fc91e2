"""Accuracy of an image (or of a set of samples) against an unbiased reference given in two halves.

Normative definitions: spec/accuracy.md#metrics. numpy only (FLIP through the optional
``flip-evaluator`` package, when installed).

The reference is two *independent, unbiased* estimates ``a`` and ``b`` of the same converged image
(two renders with different seeds, no clamp). Their mean ``r = (a + b) / 2`` is the reference; their
disagreement measures the reference's own noise: for independent a, b with the same mean and
per-pixel variance s^2, ``E[(a - b)^2] = 2 s^2`` and ``Var(r) = s^2 / 2``, so

    v = mean over the mask of (a - b)^2 / 4

is an unbiased estimate of the mean noise variance of ``r``. Everything is computed over the
pixels (samples) of ``mask`` and all channels:

* **energy ratio** per channel ``sum(est) / sum(r)``; its standard error from the reference's
  (and optionally the estimate's) per-pixel variance, pixels taken as independent.
* **groups** (optional, e.g. the held-out view of each sample): an estimate's error is correlated
  within a group (one view, one light), so the groups, not the pixels, are the independent units.
  Per group g the ratio ``E_g / R_g``; their spread; and the standard error of the overall ratio
  with groups as units, ``sqrt(G / (G - 1) * sum_g (E_g - ratio R_g)^2) / sum_g R_g`` (delta method,
  cluster-robust), which replaces the per-pixel one. It holds the reference's noise and the
  estimate's group-to-group error alike.
* **PSNR** ``10 log10(peak^2 / MSE)``, ``MSE = mean (est - r)^2``, linear radiance, no clipping;
  ``peak`` = the 99.5th percentile of ``r`` over the mask (all channels), unless given.
* **ceiling** ``10 log10(peak^2 / v)``: the PSNR an exact image scores in expectation against
  this reference. No figure above it can be claimed.
* **bias-corrected MSE** ``MSE - v`` (minus the estimate's own variance when given) and its PSNR;
  when it is not significantly above 0 (``< 2`` standard errors) no corrected PSNR is given. Its
  upper bound ``B = max(MSE - v, 0) + 2 se`` gives the **PSNR bound** ``10 log10(peak^2 / B)``. Only when
  ``B <= v`` (whatever error is left is within the reference's own noise) is the estimate **at the
  ceiling** and the claimed PSNR "at the ceiling"; a noisy estimate whose error the comparison cannot
  resolve claims ">= bound" instead, never the ceiling.
* **FLIP** (HDR-FLIP of ``est`` against ``r``, mean over the mask) when ``flip-evaluator`` is
  importable and the inputs are images; else None.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np

from .arrays import real_array, real_dtype
from .errors import UsageError

#: percentile of the reference (over the mask, all channels) used as the PSNR peak
PEAK_PERCENTILE = 99.5
#: a bias-corrected MSE within this many standard errors of 0 is "at the ceiling"
CEILING_SIGMAS = 2.0


@dataclass
class Accuracy:
    """Figures of one estimate against a two-half reference (see the module docstring)."""

    pixels: int
    energy_ratio: list  # per channel: sum(est) / sum(ref)
    energy_error: list  # per channel: ratio - 1
    energy_se: list  # per channel: standard error of the ratio (with groups: groups as the units)
    peak: float
    mse: float
    ref_noise_var: float  # v: the reference's own noise variance (mean over mask and channels)
    mse_corrected: float  # mse - v - est_var
    mse_corrected_se: float
    psnr_db: float  # against the mean-of-halves reference, raw
    ceiling_db: float  # the PSNR an exact image would score against this reference
    psnr_corrected_db: float | None  # from the bias-corrected MSE; None when that is within 2 s.e. of 0 (not resolved)
    at_ceiling: bool
    flip: float | None = None
    psnr_bound_db: float | None = None  # 10 log10(peak^2 / (max(mse_corrected, 0) + 2 se)): a 2-sigma lower bound
    notes: list = field(default_factory=list)
    groups: dict | None = None  # with groups: {count, ratio_sd, ratio_min, ratio_max} per channel, see group_figures

    def claimed_psnr(self) -> str:
        """The PSNR one may state: a number, ">= bound" when the error is not resolved, "at the ceiling (C dB)", or
        "undefined" when the reference has no peak (black over the mask: nothing to compare)."""
        if not all(v is not None and math.isfinite(v) for v in (self.psnr_db, self.ceiling_db)):  # None: from JSON
            return "undefined (black reference)"
        if self.at_ceiling:
            return f"at the ceiling ({self.ceiling_db:.1f} dB)"
        if self.psnr_corrected_db is None:
            bound = self.psnr_bound_db if self.psnr_bound_db is not None else self.psnr_db
            return f">= {min(max(bound, self.psnr_db), self.ceiling_db):.1f} dB (error not resolved)"
        return f"{min(self.psnr_db, self.ceiling_db):.1f} dB"

    def to_dict(self) -> dict:
        d = asdict(self)
        d["claimed_psnr"] = self.claimed_psnr()
        return {k: _finite(v) for k, v in d.items()}

    def line(self) -> str:
        """One human-readable line: energy per channel, PSNR with the ceiling, FLIP."""
        def num(x, scale=1.0, digits=1) -> str:
            return f"{scale * x:.{digits}f}" if x is not None and math.isfinite(x) else "n/a"

        e = "/".join(num(r, 100) for r in self.energy_ratio)
        se = "/".join(num(s, 100) for s in self.energy_se)
        f = "" if self.flip is None else f", FLIP {num(self.flip, digits=3)}"
        return (f"energy {e} % of the reference (RGB, +-{se}), PSNR {num(self.psnr_db)} dB "
                f"(ceiling {num(self.ceiling_db)} dB; claimed {self.claimed_psnr()}){f}")


def _finite(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, list):
        return [_finite(x) for x in v]
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    return v


def _as3(x, name: str) -> np.ndarray:
    a = real_array(x, f"{name} must be a real number array [..., 3]", dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] != 3:
        raise UsageError(f"{name} must have 3 channels in its last axis, got shape {a.shape}")
    return a


def _psnr(peak: float, mse: float) -> float:
    if not (peak > 0 and math.isfinite(peak)):
        return float("nan")
    return 10.0 * math.log10(peak * peak / max(mse, 1e-30))


def noise_variance(a, b, mask=None) -> float:
    """v = mean((a - b)^2) / 4 over the mask: the mean noise variance of (a + b) / 2."""
    a, b = _as3(a, "a"), _as3(b, "b")
    if a.shape != b.shape:
        raise UsageError(f"a and b shapes differ: {a.shape}, {b.shape}")
    m = np.ones(a.shape[:-1], bool) if mask is None else np.asarray(mask, bool)
    if m.shape != a.shape[:-1]:
        raise UsageError(f"mask shape {m.shape} does not match images {a.shape[:-1]}")
    d = (a[m] - b[m]) ** 2
    return float(d.mean() / 4.0) if d.size else float("nan")


def group_figures(est: np.ndarray, ref: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, dict]:
    """Cluster-robust standard error [3] of ``sum(est) / sum(ref)`` with groups as the independent units,
    and the per-group ratios' spread {count, ratio_sd, ratio_min, ratio_max} (lists of 3).

    ``est``, ``ref``: [N, 3]; ``groups``: int [N] labels. With fewer than 2 groups the error is inf."""
    _, g = np.unique(np.asarray(groups).ravel(), return_inverse=True)
    count = int(g.max()) + 1 if g.size else 0
    e_g = np.stack([np.bincount(g, est[:, c], count) for c in range(3)], 1)  # [G, 3] per-group sums
    r_g = np.stack([np.bincount(g, ref[:, c], count) for c in range(3)], 1)
    s_ref = r_g.sum(0)
    safe = np.where(s_ref != 0, s_ref, np.nan)
    ratio = e_g.sum(0) / safe
    if count >= 2:
        z = e_g - ratio * r_g
        se = np.sqrt(count / (count - 1) * (z ** 2).sum(0)) / np.abs(safe)
    else:
        se = np.full(3, np.inf)
    with np.errstate(divide="ignore", invalid="ignore"):
        per = np.where(r_g != 0, e_g / np.where(r_g != 0, r_g, 1.0), np.nan)
    lists = {}
    for name, f in (("ratio_sd", np.nanstd), ("ratio_min", np.nanmin), ("ratio_max", np.nanmax)):
        lists[name] = [float(x) for x in f(per, axis=0)] if np.isfinite(per).any() else [float("nan")] * 3
    return se, {"count": count, **lists}


def accuracy(est, ref_a, ref_b, mask=None, *, est_var=None, peak: float | None = None, flip: bool = True,
             groups=None) -> Accuracy:
    """Figures of ``est`` against the reference given as two independent unbiased halves.

    ``est``, ``ref_a``, ``ref_b``: [..., 3] linear radiance of the same shape (images [H, W, 3] or
    samples [N, 3]); ``mask``: bool [...] (default all); ``est_var``: optional per-pixel-channel
    variance of ``est``'s own mean (a Monte Carlo estimate), subtracted from the MSE and added to
    the energy standard error; ``peak``: PSNR peak (default: the reference's 99.5th percentile
    over the mask); ``groups``: optional int labels [...] (the shape of the mask; e.g. each held-out
    sample's view): the energy standard error then takes groups as the independent units, and
    ``Accuracy.groups`` holds the per-group ratios' spread (:func:`group_figures`). Non-finite values
    in any input are a UsageError (never silently dropped)."""
    est, a, b = _as3(est, "est"), _as3(ref_a, "ref_a"), _as3(ref_b, "ref_b")
    if not (est.shape == a.shape == b.shape):
        raise UsageError(f"est, ref_a, ref_b shapes differ: {est.shape}, {a.shape}, {b.shape}")
    m = np.ones(est.shape[:-1], bool) if mask is None else np.asarray(mask, bool)
    if m.shape != est.shape[:-1]:
        raise UsageError(f"mask shape {m.shape} does not match images {est.shape[:-1]}")
    if peak is not None and not (isinstance(peak, (int, float, np.number)) and math.isfinite(peak) and peak > 0):
        raise UsageError(f"peak must be a finite number > 0, got {peak!r}")
    e, aa, bb = est[m], a[m], b[m]
    ev = None
    if est_var is not None:
        try:
            if real_dtype(est_var) is None:
                raise ValueError("not real numbers")
            ev = np.broadcast_to(np.asarray(est_var, np.float64), est.shape)[m]
        except ValueError:
            raise UsageError(f"est_var of shape {np.shape(est_var)} is not real numbers that broadcast to the images "
                             f"{est.shape}") from None
    for name, x in (("est", e), ("ref_a", aa), ("ref_b", bb)) + ((("est_var", ev),) if ev is not None else ()):
        if not np.isfinite(x).all():
            raise UsageError(f"{name} has non-finite values inside the mask")
    n = int(m.sum())
    if n == 0:
        raise UsageError("the mask selects no pixels")
    if groups is not None and np.shape(groups) != m.shape:
        raise UsageError(f"groups shape {np.shape(groups)} does not match images {est.shape[:-1]}")
    r = 0.5 * (aa + bb)
    d2 = (aa - bb) ** 2
    pix_var = d2 / 4.0  # per pixel-channel estimate of Var(r)
    s_ref, s_est = r.sum(0), e.sum(0)
    ratio = s_est / np.where(s_ref != 0, s_ref, np.nan)
    # delta method: Var(S_est / S_ref) ~ (Var S_est + ratio^2 Var S_ref) / S_ref^2
    var_ratio = (pix_var.sum(0) * ratio ** 2 + (ev.sum(0) if ev is not None else 0.0)) / np.where(s_ref != 0, s_ref, np.nan) ** 2
    pk = float(np.percentile(r, PEAK_PERCENTILE)) if peak is None else float(peak)
    err2 = (e - r) ** 2
    mse = float(err2.mean())
    v = float(pix_var.mean())
    q = err2 - pix_var - (ev if ev is not None else 0.0)
    mse_c = float(q.mean())
    se = float(q.std(ddof=1) / math.sqrt(q.size)) if q.size > 1 else float("inf")
    resolved = mse_c >= CEILING_SIGMAS * se
    bound = max(mse_c, 0.0) + CEILING_SIGMAS * se  # the error's upper bound
    at_ceiling = not resolved and bound <= v
    notes = []
    if not (pk > 0):
        notes.append("the reference is black over the mask: PSNR undefined")
    energy_se = np.sqrt(np.maximum(var_ratio, 0.0))
    spread = None
    if groups is not None:
        energy_se, spread = group_figures(e, r, np.asarray(groups)[m])
    out = Accuracy(
        pixels=n, energy_ratio=[float(x) for x in ratio], energy_error=[float(x - 1.0) for x in ratio],
        energy_se=[float(x) for x in energy_se], peak=pk, mse=mse, ref_noise_var=v, groups=spread,
        mse_corrected=mse_c, mse_corrected_se=se, psnr_db=_psnr(pk, mse), ceiling_db=_psnr(pk, v),
        psnr_corrected_db=_psnr(pk, mse_c) if resolved else None, at_ceiling=bool(at_ceiling), notes=notes,
        psnr_bound_db=_psnr(pk, bound) if math.isfinite(bound) else None,
    )
    if flip and est.ndim == 3 and est.shape[0] >= 8 and est.shape[1] >= 8:
        out.flip = flip_mean(est, 0.5 * (a + b), m)
    return out


def flip_map(est, ref):
    """HDR-FLIP error map [H, W] of ``est`` against ``ref`` (linear images), or None without flip-evaluator."""
    est_a, ref_a = _as3(est, "est"), _as3(ref, "ref")
    if est_a.ndim != 3 or est_a.shape != ref_a.shape:
        raise UsageError(f"est and ref must be images [H, W, 3] of one shape, got {est_a.shape}, {ref_a.shape}")
    try:
        import flip_evaluator
    except ImportError:
        return None
    ref = np.ascontiguousarray(np.maximum(np.nan_to_num(np.asarray(ref, np.float32)), 0.0))
    est = np.ascontiguousarray(np.maximum(np.nan_to_num(np.asarray(est, np.float32)), 0.0))
    if float(ref.max()) <= 0.0:
        return None
    fmap, _, _ = flip_evaluator.evaluate(ref, est, "HDR", inputsRGB=False, applyMagma=False, computeMeanError=False)
    fmap = np.asarray(fmap, np.float64)
    return fmap[..., 0] if fmap.ndim == 3 else fmap


def flip_mean(est, ref, mask=None) -> float | None:
    """Mean HDR-FLIP over the mask (None without flip-evaluator or for a black reference)."""
    fmap = flip_map(est, ref)
    if fmap is None:
        return None
    m = np.ones(fmap.shape, bool) if mask is None else np.asarray(mask, bool)
    return float(fmap[m].mean()) if m.any() else None
