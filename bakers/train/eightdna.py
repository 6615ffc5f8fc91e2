"""Training of the ``8dna`` kind in PyTorch (paper §3; spec/bake-8dna.md#training).

Model, exactly as the SDK evaluates it (spec/kinds/8dna.md): feature grids (triplane of x_o, cube map
of w_o, 1D grids of s1 / s3, cube map of the direction d12(s1, s2)) and five ReLU MLPs -- the albedo
alpha(x_o, w_o) (RGB) and four conditioners of an autoregressive rational-quadratic spline flow over
t in [0, 1]^4 (t = the bounding-box cylindrical parameters s rescaled), one spline per RGB channel.

Encodings are linear in the grid values, so each lookup is written as taps: flat texel indices and
weights [N, T] computed in numpy by the same rules as ``nasset_sdk.kinds.encodings`` (edge clamp,
cube-map seam re-projection, corner averaging), then ``sum_T grid[idx] * w`` in torch. The spline is
the SDK's (Durkan et al.) in torch; training needs only the inverse direction (pdf of given t).

Losses (paper Eq. 6-8), summed over colour channels c, on tuples (x_o, w_o, u_i, w_i, beta) from
:mod:`nasset_converters.mitsuba.eightdna_sampler`: L_p = -mean(beta^c log p^c_t(t)) (the constant Jacobians
1/16 pi^2 and J(u_i) do not depend on the weights and are dropped) and L_alpha = mean((alpha^c - beta^c)^2).

``far_field=True`` trains the 6D far-field baseline with the same machinery: the u_i inputs are replaced
by the constant s1 = s2 = 0 (d12 = +X), so conditioners 3-4 model p(w_i | x_o, w_o) only and
conditioners 1-2 are left untrained (spec/bake-8dna.md#far-field).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from nasset_bakers import presets
from nasset_sdk.errors import error
from nasset_sdk.kinds.eightdna import FLOWS, SIZES
from nasset_sdk.kinds.encodings import TRIPLANE_AXES, cube_face_dir, cube_face_uv, to_unit_box
from nasset_sdk.kinds.spline import MIN_BIN_HEIGHT, MIN_BIN_WIDTH, MIN_DERIVATIVE, S_PER_T, BoxParam, cylindrical_to_direction

from .common import reopen_asset, require_torch
from .parallel import data_parallel


@dataclass(frozen=True)
class TrainSettings:
    size: str = "small"
    steps: int = 3000
    batch: int = 4096
    lr: float = 2e-3
    grid_lr: float = 1e-2
    buffer: int = 1 << 18  # tuples per online-buffer fill (paper: 128^4)
    reuse: int = 1  # passes over each buffer fill before it is regenerated (paper: 1)
    init_std: float = 0.05
    average: float = 0.0  # decay of the exponential weight average exported (over the second half of training); 0: the last step's
    far_field: bool = False
    seed: int = 0
    device: str = "auto"


TRAIN_PRESETS = presets.EIGHTDNA_TRAIN  # the table lives in nasset_bakers/presets.py
MINIMUMS = (MIN_BIN_WIDTH, MIN_BIN_HEIGHT, MIN_DERIVATIVE)


# ----------------------------------------------------------------------------------------
# encoding taps (numpy): the SDK's lookups as (flat texel index, weight) pairs


def taps_plane(u: np.ndarray, v: np.ndarray, h: int, w: int) -> tuple[np.ndarray, np.ndarray]:
    """encodings.grid_sample_2d on an [H, W] plane: indices [N,4] into H*W rows, weights [N,4]."""
    def texel(x, n):
        f = np.clip(np.nan_to_num((np.asarray(x, np.float32) + 1.0) * 0.5 * n - 0.5, nan=0.0), 0.0, n - 1)
        i0 = f.astype(np.int64)
        return i0, (f - i0).astype(np.float64)

    u0, au = texel(u, w)
    v0, av = texel(v, h)
    i00 = v0 * w + u0
    i01 = i00 + (u0 < w - 1)
    dv = (v0 < h - 1) * w
    idx = np.stack([i00, i01, i00 + dv, i01 + dv], 1)
    wt = np.stack([(1 - au) * (1 - av), au * (1 - av), (1 - au) * av, au * av], 1)
    return idx, wt


def taps_triplane(xn: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """encodings.triplane: indices [N,12] into 3*R*R rows (plane-major), weights [N,12]."""
    idx, wt = [], []
    for k, (a, b) in enumerate(TRIPLANE_AXES):
        i, w = taps_plane(xn[:, a], xn[:, b], r, r)
        idx.append(i + k * r * r)
        wt.append(w)
    return np.concatenate(idx, 1), np.concatenate(wt, 1)


def taps_grid1d(t: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
    """encodings.grid_1d: indices [N,2] into K rows, weights [N,2]."""
    f = np.nan_to_num(np.clip((np.asarray(t, np.float64).reshape(-1) + 1.0) * 0.5 * k - 0.5, 0.0, k - 1), nan=0.0)
    i0 = np.minimum(f.astype(np.int64), k - 1)
    a = f - i0
    return np.stack([i0, np.minimum(i0 + 1, k - 1)], 1), np.stack([1 - a, a], 1)


def taps_cubemap(d: np.ndarray, r: int) -> tuple[np.ndarray, np.ndarray]:
    """encodings.cubemap on [6, R, R]: indices [N,4] into 6*R*R rows, weights [N,4] (seams re-projected,
    a tap beyond a cube corner replaced by the mean of the other three)."""
    face, s, t = cube_face_uv(d)
    fs, ft = s * r - 0.5, t * r - 0.5
    i0, j0 = np.floor(fs).astype(np.int64), np.floor(ft).astype(np.int64)
    a_s, a_t = fs - i0, ft - j0
    idx, corner = [], []
    for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1)):
        i, j, f = i0 + di, j0 + dj, face.copy()
        out_i, out_j = (i < 0) | (i >= r), (j < 0) | (j >= r)
        out = out_i | out_j
        if out.any():
            sc = 2.0 * (i[out] + 0.5) / r - 1.0
            tc = 2.0 * (j[out] + 0.5) / r - 1.0
            f2, s2, t2 = cube_face_uv(cube_face_dir(face[out], sc, tc))
            f[out] = f2
            i, j = i.copy(), j.copy()
            i[out] = np.minimum(np.floor(s2 * r).astype(np.int64), r - 1)
            j[out] = np.minimum(np.floor(t2 * r).astype(np.int64), r - 1)
        idx.append(np.clip(f * r * r + j * r + i, 0, 6 * r * r - 1))
        corner.append(out_i & out_j)
    idx = np.stack(idx, 1)
    wt = np.stack([(1 - a_s) * (1 - a_t), a_s * (1 - a_t), (1 - a_s) * a_t, a_s * a_t], 1)
    corner = np.stack(corner, 1)
    if corner.any():
        share = np.where(corner, wt, 0.0).sum(1, keepdims=True)  # at most one corner tap per row
        wt = np.where(corner, 0.0, wt + share / 3.0)
    return idx, wt


def prepare(batch: dict, lo, hi, size: str, *, far_field: bool = False) -> dict:
    """numpy tuples -> model inputs: unit-box x_o, w_o, t [N,4], encoding taps, beta."""
    r, c, q, ln, k, *_ = SIZES[size]
    box = BoxParam(lo, hi)
    xn = to_unit_box(batch["xo"], lo, hi)
    wo = batch["wo"] / np.maximum(np.linalg.norm(batch["wo"], axis=1, keepdims=True), 1e-12)
    s, jac = box.from_rays(batch["ui"], batch["wi"])
    if far_field:
        s[:, 0] = 0.0
        s[:, 1] = 0.0
    t = box.t_from_s(s)
    d12 = cylindrical_to_direction(s[:, 0], s[:, 1])
    out = {"xn": xn, "wo": wo, "s": s, "t": t, "d12": d12, "jac": jac, "beta": np.asarray(batch["beta"], np.float64)}
    out["tri_i"], out["tri_w"] = taps_triplane(xn, r)
    out["wo_i"], out["wo_w"] = taps_cubemap(wo, q)
    out["s1_i"], out["s1_w"] = taps_grid1d(s[:, 0], ln)
    out["s3_i"], out["s3_w"] = taps_grid1d(s[:, 2], ln)
    out["d12_i"], out["d12_w"] = taps_cubemap(d12, q)
    return out


def to_torch(torch, p: dict, device) -> dict:
    return {k: torch.as_tensor(np.ascontiguousarray(v), device=device,
                               dtype=torch.int64 if v.dtype.kind in "iu" else torch.float32) for k, v in p.items()}


# ----------------------------------------------------------------------------------------
# model


def rqs_inverse_logdet(torch, raw, y, k: int, mins=MINIMUMS):
    """log|dz/dy| of the inverse rational-quadratic spline (spec/kinds/8dna.md#spline); raw [..., 3K+1], y [...] in [0, 1]."""
    mw, mh, md = mins
    F = torch.nn.functional
    w = mw + (1 - mw * k) * F.softmax(raw[..., :k], -1)
    h = mh + (1 - mh * k) * F.softmax(raw[..., k:2 * k], -1)
    d = md + F.softplus(raw[..., 2 * k:])
    zeros = torch.zeros_like(w[..., :1])
    ones = torch.ones_like(w[..., :1])
    xk = torch.cat([zeros, torch.cumsum(w, -1)[..., :-1], ones], -1)
    yk = torch.cat([zeros, torch.cumsum(h, -1)[..., :-1], ones], -1)
    y = y.clamp(0.0, 1.0)
    b = (y[..., None] >= yk[..., 1:-1]).sum(-1, keepdim=True)
    g = lambda a, i: torch.gather(a, -1, i)[..., 0]  # noqa: E731
    x0, x1, y0, y1 = g(xk, b), g(xk, b + 1), g(yk, b), g(yk, b + 1)
    d0, d1 = g(d, b), g(d, b + 1)
    wk = (x1 - x0).clamp_min(1e-30)
    hk = (y1 - y0).clamp_min(1e-30)
    s = hk / wk
    dy = y - y0
    delta = d1 + d0 - 2 * s
    qa = hk * (s - d0) + dy * delta
    qb = hk * d0 - dy * delta
    qc = -s * dy
    disc = (qb * qb - 4 * qa * qc).clamp_min(1e-20)
    den = -qb - torch.sqrt(disc)
    safe = den < -1e-30
    xi = torch.where(safe, 2 * qc / torch.where(safe, den, -torch.ones_like(den)), torch.zeros_like(den)).clamp(0.0, 1.0)
    tt = xi * (1 - xi)
    dd = (s + delta * tt).clamp_min(1e-30)
    deriv = s * s * (d1 * xi * xi + 2 * s * tt + d0 * (1 - xi) ** 2) / (dd * dd)
    return -torch.log(deriv.clamp_min(1e-30))


def build_model(size: str, *, init_std: float = 0.05, seed: int = 0):
    torch = require_torch()
    nn = torch.nn
    r, c, q, ln, k, f_layers, f_width, a_layers, a_width = SIZES[size]
    g_width = 3 * (3 * k + 1)
    torch.manual_seed(seed)

    def mlp(width_in, hidden, layers, out):
        mods, w = [], width_in
        for _ in range(layers):
            mods += [nn.Linear(w, hidden), nn.ReLU()]
            w = hidden
        mods.append(nn.Linear(w, out))
        net = nn.Sequential(*mods)
        with torch.no_grad():
            net[-1].weight.mul_(0.1)  # near-uniform splines / small albedo at the start
            net[-1].bias.zero_()
        return net

    class EightDnaModel(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            self.size, self.k, self.c = size, k, c
            p = lambda *shape: nn.Parameter(torch.randn(*shape) * init_std)  # noqa: E731
            self.triplane = p(3 * r * r, c)  # rows: plane, v, u
            self.wo_cube = p(6 * q * q, c)  # rows: face, t, s
            self.s1_grid = p(ln, c)
            self.s3_grid = p(ln, c)
            self.s12_cube = p(6 * q * q, c)
            self.albedo = mlp(2 * c + 6, a_width, a_layers, 3)
            self.flows = nn.ModuleList([mlp(w, f_width, f_layers, g_width)
                                        for w in (2 * c + 6, 3 * c + 7, 3 * c + 9, 4 * c + 10)])

        @staticmethod
        def lookup(grid, idx, wt):
            return (torch.nn.functional.embedding(idx, grid) * wt[..., None]).sum(1)

        def base(self, B):
            return torch.cat([self.lookup(self.triplane, B["tri_i"], B["tri_w"]), B["xn"],
                              self.lookup(self.wo_cube, B["wo_i"], B["wo_w"]), B["wo"]], 1)

        def flow_inputs(self, B, base):
            s = B["s"]
            f12 = [self.lookup(self.s12_cube, B["d12_i"], B["d12_w"]), B["d12"]]
            return [base,
                    torch.cat([base, self.lookup(self.s1_grid, B["s1_i"], B["s1_w"]), s[:, :1]], 1),
                    torch.cat([base, *f12], 1),
                    torch.cat([base, *f12, self.lookup(self.s3_grid, B["s3_i"], B["s3_w"]), s[:, 2:3]], 1)]

        def forward(self, B, steps=(1, 2, 3, 4)):
            """(alpha [N,3], log p_t [N,3] over t-space summed over ``steps``)."""
            base = self.base(B)
            alpha = self.albedo(base)
            ins = self.flow_inputs(B, base)
            logp = torch.zeros_like(alpha)
            for j in steps:
                raw = self.flows[j - 1](ins[j - 1]).view(-1, 3, 3 * self.k + 1)
                logp = logp + rqs_inverse_logdet(torch, raw, B["t"][:, j - 1:j].expand(-1, 3), self.k)
            return alpha, logp

    return EightDnaModel()


def loss_terms(model, B, steps):
    alpha, logp = model(B, steps)
    beta = B["beta"]
    nll = -(beta * logp).sum(1).mean()
    l2 = ((alpha - beta) ** 2).sum(1).mean()
    return nll, l2


# ----------------------------------------------------------------------------------------
# training and export


@dataclass
class TrainResult:
    model: object
    tensors: dict  # name -> numpy array in the asset's layout
    networks: dict  # name -> ONNX bytes
    history: list
    seconds: float
    device: str
    onnx_max_abs_diff: float
    refreshes: int


def train(buffer, domain, settings: TrainSettings, *, progress=None, checkpoint=None) -> TrainResult:
    """Fit the model on tuples from ``buffer`` (an OnlineBuffer); ``progress(step, nll, l2)`` is called every 10 steps.

    Under ``torchrun`` the processes train data-parallel (nasset_bakers.train.parallel): ``buffer``
    must serve every process the same global batches (e.g. the same deterministic fills); each
    process takes its share of every batch and the steps are one process's. Only rank 0 saves."""
    torch = require_torch()
    t0 = time.perf_counter()
    dp = data_parallel(torch, settings.device)
    device = dp.device
    lo, hi = domain
    model = build_model(settings.size, init_std=settings.init_std, seed=settings.seed).to(device)
    grids = [model.triplane, model.wo_cube, model.s1_grid, model.s3_grid, model.s12_cube]
    opt = torch.optim.Adam([{"params": grids, "lr": settings.grid_lr},
                            {"params": list(model.albedo.parameters()) + list(model.flows.parameters()), "lr": settings.lr}])
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, T_max=max(settings.steps, 1), eta_min=0.05 * settings.lr)
    steps = (3, 4) if settings.far_field else (1, 2, 3, 4)
    state = checkpoint.restore(model, opt, sched) if checkpoint is not None else None
    history: list = list(state.get("history", [])) if state else []
    start = int(state["step"]) if state else 0
    average = WeightAverage(torch, list(model.parameters()), settings.average, settings.steps // 2,
                            state.get("average") if state else None)
    acc = [0.0, 0.0, 0]
    net = dp.wrap(torch, model)
    for step in range(start, settings.steps):
        model.train()
        batch = buffer.next(settings.batch)
        n = len(batch["beta"])
        idx = dp.share(np.arange(n))
        part = {k: v[idx] for k, v in batch.items()} if dp.world > 1 else batch
        B = to_torch(torch, prepare(part, lo, hi, settings.size, far_field=settings.far_field), device)
        nll, l2 = loss_terms(net, B, steps)
        loss = nll + l2
        if not math.isfinite(dp.mean(torch, float(loss.detach()))):  # every process stops at the same step
            raise error("CONVERT_TRAINING", f"8dna loss became non-finite at step {step}")
        opt.zero_grad(set_to_none=True)
        (loss * dp.weight(len(idx), n)).backward()
        opt.step()
        sched.step()
        average.update(step)
        acc[0] += dp.mean(torch, float(nll.detach()) * dp.weight(len(idx), n))
        acc[1] += dp.mean(torch, float(l2.detach()) * dp.weight(len(idx), n))
        acc[2] += 1
        if (step + 1) % 10 == 0 or step == settings.steps - 1:
            history.append({"step": step + 1, "nll": acc[0] / acc[2], "albedo_l2": acc[1] / acc[2]})
            acc = [0.0, 0.0, 0]
            if progress is not None:
                progress(step + 1, history[-1]["nll"], history[-1]["albedo_l2"])
        if checkpoint is not None and dp.is_main and ((step + 1) % 250 == 0 or step == settings.steps - 1):
            checkpoint.save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                             "step": step + 1, "history": history, "average": average.shadow})
    seconds = time.perf_counter() - t0
    average.apply()
    model.eval()
    tensors, networks = export(model)
    diff = onnx_parity(model, networks)
    return TrainResult(model, tensors, networks, history, seconds, str(device), diff, getattr(buffer, "refreshes", 0))


class WeightAverage:
    """Exponential average of the weights over the second half of training (Polyak averaging), exported in place
    of the last step's: ``shadow = decay * shadow + (1 - decay) * weights`` after every step from ``start`` on.
    ``decay`` 0 keeps the last step's weights. ``shadow``: the averaged tensors (checkpointed), None before ``start``."""

    def __init__(self, torch, params: list, decay: float, start: int, shadow: list | None = None) -> None:
        if not 0.0 <= decay < 1.0:
            raise error("CONVERT_TRAINING", f"weight average decay {decay} outside [0, 1)")
        self.torch, self.params, self.decay, self.start = torch, params, float(decay), int(start)
        self.shadow = None if shadow is None or not decay else [s.to(p.device) for s, p in zip(shadow, params, strict=True)]

    def update(self, step: int) -> None:
        """After optimiser step ``step`` (0-based)."""
        if not self.decay or step < self.start:
            return
        with self.torch.no_grad():
            if self.shadow is None:
                self.shadow = [p.detach().clone() for p in self.params]
            else:
                for s, p in zip(self.shadow, self.params, strict=True):
                    s.mul_(self.decay).add_(p.detach(), alpha=1.0 - self.decay)

    def apply(self) -> None:
        """Copy the average into the weights (nothing when there is none)."""
        if self.shadow is None:
            return
        with self.torch.no_grad():
            for s, p in zip(self.shadow, self.params, strict=True):
                p.copy_(s)


def export(model) -> tuple[dict, dict]:
    """Tensors (asset layouts, float32) and ONNX networks (opset 17) of a trained model."""
    from nasset_sdk.networks import check_model_bytes, mlp_onnx

    r, c, q, ln, *_ = SIZES[model.size]
    a = lambda p: p.detach().cpu().numpy().astype(np.float32)  # noqa: E731
    tensors = {
        "triplane": a(model.triplane).reshape(3, r, r, c),
        "woCube": a(model.wo_cube).reshape(6, q, q, c),
        "s1Grid": a(model.s1_grid),
        "s3Grid": a(model.s3_grid),
        "s12Cube": a(model.s12_cube).reshape(6, q, q, c),
        "splineMinimums": np.array(MINIMUMS, np.float32),
    }
    for name, arr in tensors.items():
        if not np.isfinite(arr).all():
            raise error("CONVERT_TRAINING", f"trained tensor {name} holds NaN/Inf")

    def onnx(seq, out_name):
        lin = [m for m in seq if hasattr(m, "weight")]
        data = mlp_onnx([a(m.weight).T for m in lin], [a(m.bias) for m in lin], output_name=out_name)
        check_model_bytes(data)
        return data

    networks = {"albedo": onnx(model.albedo, "y")}
    for name, seq in zip(FLOWS, model.flows, strict=True):
        networks[name] = onnx(seq, "g")
    return tensors, networks


def onnx_parity(model, networks: dict, n: int = 2048, seed: int = 0) -> float:
    """Max |onnxruntime - torch| over the five MLPs on random inputs."""
    torch = require_torch()
    from nasset_sdk.networks import make_session

    rng = np.random.default_rng(seed)
    worst = 0.0
    for name, seq in [("albedo", model.albedo)] + list(zip(FLOWS, model.flows, strict=True)):
        width = seq[0].in_features
        x = rng.normal(0, 1, (n, width)).astype(np.float32)
        with torch.no_grad():
            ref = seq.cpu()(torch.from_numpy(x)).numpy()
        sess = make_session(networks[name])
        got = sess.run(None, {sess.get_inputs()[0].name: x})[0]
        worst = max(worst, float(np.max(np.abs(got - ref))))
    return worst


def torch_eval(model, batch: dict, lo, hi, *, far_field: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """(alpha [N,3], pdf [N,3] per unit box area and steradian) of the torch model on numpy tuples."""
    torch = require_torch()
    p = prepare(batch, lo, hi, model.size, far_field=far_field)
    B = to_torch(torch, p, next(model.parameters()).device)
    with torch.no_grad():
        alpha, logp = model(B, (3, 4) if far_field else (1, 2, 3, 4))
    alpha = np.maximum(alpha.cpu().numpy().astype(np.float64), 0.0)
    logp = logp.cpu().numpy().astype(np.float64)
    if far_field:
        return alpha, np.exp(np.minimum(logp, 700.0)) / (4.0 * math.pi)
    return alpha, np.exp(np.minimum(logp, 700.0)) / S_PER_T * p["jac"][:, None]


def parity_with_sdk(model, asset_path, batch: dict, *, far_field: bool = False) -> dict:
    """Torch vs the SDK evaluator (numpy + onnxruntime) of the written asset on held-out tuples."""
    asset, ev = reopen_asset(asset_path)
    lo, hi = asset.domain
    a_t, p_t = torch_eval(model, batch, lo, hi, far_field=far_field)
    a_s = ev.albedo(batch["xo"], batch["wo"]).astype(np.float64)
    if far_field:
        ui = np.tile(ev.box.center + np.array([ev.box.half[0], 0, 0]), (len(a_s), 1))
        p_s = np.stack([ev.pdf_direction(batch["xo"], batch["wo"], ui, batch["wi"], c) for c in range(3)], 1)
    else:
        p_s = ev.pdf_rgb(batch["xo"], batch["wo"], batch["ui"], batch["wi"])
    rel = np.abs(p_s - p_t) / np.maximum(np.abs(p_s), 1e-12)
    return {"albedo_max_abs": float(np.max(np.abs(a_s - a_t))) if len(a_s) else 0.0,
            "pdf_max_rel": float(np.max(rel)) if len(rel) else 0.0,
            "pdf_median_rel": float(np.median(rel)) if len(rel) else 0.0,
            "samples": int(len(a_s))}


def heldout_nll(model, batch: dict, lo, hi, *, far_field: bool = False) -> float:
    """Held-out beta-weighted negative log-likelihood per unit of beta (nats, in t-space; lower is better)."""
    torch = require_torch()
    B = to_torch(torch, prepare(batch, lo, hi, model.size, far_field=far_field), next(model.parameters()).device)
    with torch.no_grad():
        _, logp = model(B, (3, 4) if far_field else (1, 2, 3, 4))
    beta = B["beta"]
    return float(-(beta * logp).sum() / beta.sum().clamp_min(1e-12))


def settings_dict(settings: TrainSettings) -> dict:
    return asdict(settings)
