"""The 8dna albedo renormalised for the flow mass a renderer cannot light (spec/bake-8dna.md#renormalise).

A renderer counts a flow sample (u_i, w_i) with n_u . w_i <= 0, or whose back-traced ray u_i - t w_i misses
the asset, as zero (spec/kinds/8dna.md#quantity). A trained flow of finite capacity leaves a share
1 - V^c(x_o, w_o) of its mass there, so the render's expected transport is alpha^c V^c, not
alpha^c = E[beta^c]: energy is lost. This stage measures V^c by sampling the exported flow and fits the
albedo network alone (grids and flows frozen) to alpha^c / V^c; the renderer then integrates alpha^c against
the flow restricted to its valid set and renormalised, the density the flow was trained to be.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .common import require_torch
from .eightdna import prepare, to_torch

#: flow samples per (x_o, w_o) and channel for V (binomial: relative bias of 1/V ~ (1 - V) / (M V), < 0.5 % at V >= 0.8)
SAMPLES = 32
#: V is floored here before dividing (a point whose flow is almost all invalid is not amplified beyond 1/FLOOR)
FLOOR = 0.25


@dataclass
class Renormalised:
    valid_mass: list  # per channel: mean V over the fitted points
    floored: float  # share of (point, channel) pairs with V < FLOOR
    albedo_scale: list  # per channel: mean(alpha after) / mean(alpha before)
    fit_rel_rms: float  # rms(alpha after - alpha / V) / mean(alpha / V) on the fitted points
    points: int
    samples: int
    seconds: float


def valid_mass(ev, backtrace_hits, x: np.ndarray, wo: np.ndarray, *, samples: int = SAMPLES, seed: int = 0,
               chunk: int = 1 << 16) -> np.ndarray:
    """V [N,3]: per channel c, the share of p^c(u_i, w_i | x_o, w_o) a renderer can light (Monte Carlo, ``samples`` each).

    ``ev``: the asset's evaluator; ``backtrace_hits(u [M,3], w [M,3]) -> bool [M]``: the ray u - t w hits the asset."""
    rng = np.random.default_rng(seed)
    n = len(x)
    xr, wr = np.repeat(np.asarray(x, np.float64), samples, 0), np.repeat(np.asarray(wo, np.float64), samples, 0)
    ok = np.zeros((len(xr), 3), bool)
    for c in range(3):
        for s in range(0, len(xr), chunk):
            e = min(s + chunk, len(xr))
            u, w, _ = ev.sample(xr[s:e], wr[s:e], np.full(e - s, c), u=rng.random((e - s, 4)))
            good = (ev.box.face_normal(u) * w).sum(1) > 0
            k = np.nonzero(good)[0]
            good[k] = backtrace_hits(u[k], w[k])
            ok[s:e, c] = good
    return ok.reshape(n, samples, 3).mean(1)


def renormalise_albedo(model, batch: dict, V: np.ndarray, lo, hi, *, steps: int = 400, batch_size: int = 4096,
                       lr: float = 1e-3, seed: int = 0) -> Renormalised:
    """Fit ``model.albedo`` (in place) to alpha / max(V, FLOOR) on the tuples' (x_o, w_o) [N]; V [N,3] from :func:`valid_mass`."""
    import time

    torch = require_torch()
    t0 = time.perf_counter()
    dev = next(model.parameters()).device
    B = to_torch(torch, prepare(batch, lo, hi, model.size), dev)
    Vt = torch.as_tensor(np.maximum(V, FLOOR), dtype=torch.float32, device=dev)
    with torch.no_grad():
        feats = model.base(B)
        alpha0 = model.albedo(feats).clamp_min(0.0)
        target = alpha0 / Vt
    opt = torch.optim.Adam(model.albedo.parameters(), lr=lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(steps, 1), eta_min=0.05 * lr)
    gen = torch.Generator(device="cpu").manual_seed(seed)
    n = len(feats)
    model.albedo.train()
    for _ in range(steps):
        idx = torch.randint(0, n, (min(batch_size, n),), generator=gen).to(dev)
        loss = ((model.albedo(feats[idx]) - target[idx]) ** 2).mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        sched.step()
    model.albedo.eval()
    with torch.no_grad():
        alpha1 = model.albedo(feats).clamp_min(0.0)
        rel = float(torch.sqrt(((alpha1 - target) ** 2).mean()) / target.mean().clamp_min(1e-12))
        scale = (alpha1.mean(0) / alpha0.mean(0).clamp_min(1e-12)).cpu().numpy()
    return Renormalised(valid_mass=[float(v) for v in V.mean(0)], floored=float((V < FLOOR).mean()),
                        albedo_scale=[float(s) for s in scale], fit_rel_rms=rel, points=int(n),
                        samples=SAMPLES, seconds=time.perf_counter() - t0)
