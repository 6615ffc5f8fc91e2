"""Training of the ``neupress`` kind in PyTorch (paper sec. 3-4; spec/bake-neupress.md#training).

Three fits, all against the format contract of ``nasset_sdk.kinds.neupress``:

* **appearance**: S(x_o, w_o, w_i) from the Fourier features gamma(v) = [cos 2 pi G v, sin 2 pi G v] of
  v = [xn, theta_o/pi, phi_o/2pi, theta_i/pi, phi_i/2pi] (7; G [M, 7] ~ N(0, 0.25) by default, the paper's N(18, 1) as a setting),
  a ReLU MLP with skip connections between alternate layers (the input of hidden layer i is
  concatenated to the input of layer i + 2, exactly ``nasset_sdk.networks.mlp_onnx``'s layout), no
  output activation, L2 loss, Adam with the learning rate halved every 20 % of the epochs; then the output
  layer scaled per channel so the network keeps its training set's energy (spec/bake.md#energy-gain).
* **sampling**: log sigma of the Gaussian lobe around n from the Fourier features of [xn, theta_o, phi_o]
  (5). Target: the trained appearance network's luminance on B x B bins of the azimuthal-equidistant
  disk |p| <= pi around n, turned into a distribution over bins (times the projection's area factor
  sin r / r); loss: the KL divergence KL(target || lobe) with the lobe's bin probabilities
  softmax(-|p_k|^2 / (2 sigma^2)) (the truncated Gaussian discretised on the same bins).
* **PRT**: degree-2 SH coefficients a_k(x_v, w_o) = integral S(w_i; x_v, w_o) Y_k(w_i) dw_i per mesh vertex
  and w_o bin (bin centres, the SDK's local frame of the vertex normal), by quasi-Monte Carlo over the
  network with K spherical-Fibonacci directions of weight 4 pi / K.

Inputs are built with the SDK's own encoding functions (to_unit_box, spherical_coords) and the Fourier
phase is computed in float64 like ``encodings.fourier_features``, so the exported ONNX (written by
``mlp_onnx`` from the trained weights) reproduces torch to float32 rounding.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import numpy as np

from nasset_bakers import presets
from nasset_sdk.errors import error
from nasset_sdk.kinds.encodings import azimuthal_equidistant_inverse, from_local, sh9, spherical_coords, to_unit_box
from nasset_sdk.kinds.neupress import FOURIER_MEAN, FOURIER_STD, SIGMA_MAX, SIGMA_MIN, SIZES  # noqa: F401 (paper's G)

from .common import (
    BestEpoch,
    TorchCheckpoint,
    check_against_torch,
    display_psnr,
    energy_gain,
    held_out_accuracy,
    require_torch,
    scale_output_layer,
)
from .parallel import data_parallel

__all__ = ["TRAIN_PRESETS", "NeupressTrainSettings", "TorchCheckpoint", "train_appearance", "train_sampling",
           "prt_coefficients", "appearance_inputs", "sampling_inputs", "export_skip_mlp", "export_mlp", "check_asset"]


@dataclass(frozen=True)
class NeupressTrainSettings:
    size: str = "small"
    epochs: int = 40
    batch: int = 2048
    lr: float = 1e-3
    decay_every: float = 0.2  # fraction of epochs between learning-rate halvings
    # G ~ N(mean, std) elementwise. The paper's N(18, 1) (FOURIER_MEAN, FOURIER_STD) generalises worse from our
    # small datasets than a low-frequency N(0, 0.25) (measured: spec/bake-neupress.md#deviations)
    fourier_mean: float = 0.0
    fourier_std: float = 0.25
    sampling_epochs: int = 30
    sampling_samples: int = 4096  # (x, n, wo) records whose binned appearance is the KL target
    sampling_bins: int = 16  # B x B bins over [-pi, pi]^2 (those with |p| < pi)
    sampling_lr: float = 2e-3
    prt_dirs: int = 256  # K quasi-Monte Carlo directions per (vertex, w_o bin)
    seed: int = 0
    device: str = "auto"
    keep: str = "last"  # appearance network: the last epoch, or "best": the highest held-out display PSNR (spec/accuracy.md#best-epoch)
    energy_gain: bool = True  # scale the output to the training set's energy after training (spec/bake.md#energy-gain)


TRAIN_PRESETS = presets.NEUPRESS_TRAIN  # the table lives in nasset_bakers/presets.py

LUMA = np.array([0.2126, 0.7152, 0.0722])


# ----------------------------------------------------------------------------------------
# inputs (exactly the SDK's, float32 v)


def appearance_inputs(x, wo, wi, lo, hi) -> np.ndarray:
    """v [N, 7] float32 = [xn, theta_o/pi, phi_o/2pi, theta_i/pi, phi_i/2pi] (NeupressEvaluator.appearance_input)."""
    return np.concatenate([to_unit_box(x, lo, hi), spherical_coords(wo), spherical_coords(wi)], axis=1)


def sampling_inputs(x, wo, lo, hi) -> np.ndarray:
    """v [N, 5] float32 = [xn, theta_o/pi, phi_o/2pi] (NeupressEvaluator.sigma)."""
    return np.concatenate([to_unit_box(x, lo, hi), spherical_coords(wo)], axis=1)


def _features(torch, G64, v32):
    """gamma(v) [N, 2M] float32 with the phase in float64 (encodings.fourier_features)."""
    phase = 2.0 * math.pi * (v32.double() @ G64.T)
    return torch.cat([torch.cos(phase), torch.sin(phase)], 1).float()


# ----------------------------------------------------------------------------------------
# models


def skip_layout(layers: int) -> list[tuple[int, int]]:
    """(src, dst) skips of nasset_sdk.kinds.neupress.skip_mlp: (i, i + 2), i = 0, 2, ..., i + 2 < layers."""
    return [(i, i + 2) for i in range(0, layers, 2) if i + 2 < layers]


def build_skip_mlp(in_width: int, hidden: int, layers: int, out: int):
    """ReLU MLP with ``layers`` hidden layers and alternate-layer skips, in mlp_onnx's layout."""
    torch = require_torch()
    nn = torch.nn
    skips = skip_layout(layers)
    skip_src = {d: s for s, d in skips}

    class SkipMLP(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            widths_in, lin = [], []
            width = in_width
            for i in range(layers + 1):
                w_in = width + (widths_in[skip_src[i]] if i in skip_src else 0)
                widths_in.append(width)
                w_out = out if i == layers else hidden
                lin.append(nn.Linear(w_in, w_out))
                width = w_out
            self.lin = nn.ModuleList(lin)
            self.skips = skips

        def forward(self, x):
            inputs = []
            h = x
            for i, layer in enumerate(self.lin):
                inputs.append(h)
                if i in skip_src:
                    h = torch.cat([h, inputs[skip_src[i]]], 1)
                h = layer(h)
                if i < layers:
                    h = torch.relu(h)
            return h

    return SkipMLP()


def build_mlp(widths):
    torch = require_torch()
    mods = []
    for i, (a, b) in enumerate(zip(widths[:-1], widths[1:], strict=True)):
        mods.append(torch.nn.Linear(a, b))
        if i < len(widths) - 2:
            mods.append(torch.nn.ReLU())
    return torch.nn.Sequential(*mods)


def export_skip_mlp(model, name: str = "neupress_appearance") -> bytes:
    """ONNX bytes of a SkipMLP through nasset_sdk.networks.mlp_onnx (Gemm/Relu/Concat, opset 17)."""
    from nasset_sdk.networks import mlp_onnx

    ws = [m.weight.detach().cpu().numpy().T.copy() for m in model.lin]
    bs = [m.bias.detach().cpu().numpy().copy() for m in model.lin]
    return mlp_onnx(ws, bs, skips=model.skips, name=name)


def export_mlp(model, name: str = "neupress_sigma") -> bytes:
    from nasset_sdk.networks import mlp_onnx

    lin = [m for m in model if hasattr(m, "weight")]
    return mlp_onnx([m.weight.detach().cpu().numpy().T.copy() for m in lin],
                    [m.bias.detach().cpu().numpy().copy() for m in lin], name=name)


# ----------------------------------------------------------------------------------------
# appearance


@dataclass
class AppearanceResult:
    model: object
    G: np.ndarray  # [M, 7] float32 as stored
    history: list
    val: dict
    seconds: float
    device: str
    energy_gain: dict | None = None  # common.energy_gain of the kept network, before the gain; None when off


def predict_appearance(model, G: np.ndarray, v: np.ndarray, batch: int = 65536) -> np.ndarray:
    """Raw network output [N, 3] (no clamp) for inputs v [N, 7]."""
    torch = require_torch()
    dev = next(model.parameters()).device
    G64 = torch.as_tensor(np.asarray(G, np.float64), device=dev)
    out = []
    model.eval()
    with torch.no_grad():
        for s in range(0, len(v), batch):
            vb = torch.as_tensor(np.ascontiguousarray(v[s:s + batch], np.float32), device=dev)
            out.append(model(_features(torch, G64, vb)).cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, 3), np.float32)


def train_appearance(train_data: dict, val_data: dict, domain, settings: NeupressTrainSettings, *, progress=None,
                     checkpoint=None) -> AppearanceResult:
    """Fit S; ``progress(epoch, loss, val_psnr)`` per epoch; ``checkpoint`` (TorchCheckpoint) resumes.

    Under ``torchrun`` the processes train data-parallel as the rna trainer does
    (nasset_bakers.train.parallel): same global batches, each process its share, the steps one
    process would take; only rank 0 saves checkpoints."""
    torch = require_torch()
    t0 = time.perf_counter()
    m, layers, hidden, *_ = SIZES[settings.size]
    rng = np.random.default_rng(settings.seed)
    G = rng.normal(settings.fourier_mean, settings.fourier_std, (m, 7)).astype(np.float32)
    torch.manual_seed(settings.seed)
    dp = data_parallel(torch, settings.device)
    dev = dp.device
    lo, hi = domain
    v = appearance_inputs(train_data["x"], train_data["wo"], train_data["wi"], lo, hi)
    y = np.asarray(train_data["rgb"], np.float32)
    if len(v) == 0 or not np.isfinite(y).all():
        raise error("CONVERT_TRAINING", f"no usable training samples ({len(v)} samples, finite={np.isfinite(y).all()})")
    v_val = appearance_inputs(val_data["x"], val_data["wo"], val_data["wi"], lo, hi)
    model = build_skip_mlp(2 * m, hidden, layers, 3).to(dev)
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr)
    step = max(1, round(settings.epochs * settings.decay_every))
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=step, gamma=0.5)
    history: list = []
    start = 0
    state = checkpoint.restore(model, opt, sched) if checkpoint is not None else None
    if state is not None:
        G = state["G"].numpy()
        history = list(state.get("history", []))
        start = int(state["epoch"]) + 1
    best = BestEpoch(state.get("best") if state is not None else None)
    if settings.keep not in ("best", "last"):
        raise error("CONVERT_TRAINING", f"keep must be 'best' or 'last', got {settings.keep!r}")
    G64 = torch.as_tensor(G.astype(np.float64), device=dev)
    V = torch.as_tensor(v, device=dev)
    Y = torch.as_tensor(y, device=dev)
    net = dp.wrap(torch, model)
    gen = torch.Generator().manual_seed(settings.seed)
    for epoch in range(start, settings.epochs):
        model.train()
        perm = torch.randperm(len(V), generator=gen).to(dev)
        tot, cnt = 0.0, 0
        for s in range(0, len(V), settings.batch):
            batch = perm[s:s + settings.batch]
            if len(batch) < dp.world:  # a last batch with fewer samples than processes: skipped by all
                continue
            idx = dp.share(batch)
            pred = net(_features(torch, G64, V[idx]))
            loss = torch.mean((pred - Y[idx]) ** 2)
            if not math.isfinite(dp.mean(torch, float(loss.detach()))):  # every process stops at the same step
                raise error("CONVERT_TRAINING", f"non-finite appearance loss at epoch {epoch}")
            opt.zero_grad(set_to_none=True)
            (loss * dp.weight(len(idx), len(batch))).backward()
            opt.step()
            tot += float(loss.detach()) * len(idx)
            cnt += len(idx)
        sched.step()
        pv = np.maximum(predict_appearance(model, G, v_val), 0.0)  # every epoch: the kept one is chosen by it
        val_psnr, val_mse, _ = display_psnr(pv, val_data["rgb"])  # val_mse: linear, for the history
        best.offer(epoch, val_psnr, model)
        mean_loss = dp.mean(torch, tot / max(cnt, 1))
        history.append({"epoch": epoch, "loss": mean_loss, "val_psnr": val_psnr, "val_mse": val_mse})
        if checkpoint is not None and dp.is_main:
            checkpoint.save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                             "G": torch.as_tensor(G), "history": history, "epoch": epoch, "best": best.to_dict()})
        if progress:
            progress(epoch, mean_loss, val_psnr)
    kept = best.restore(model) if settings.keep == "best" and best.state is not None else settings.epochs - 1
    model = model.cpu().eval()
    gain = None
    if settings.energy_gain:
        gain = energy_gain(np.maximum(predict_appearance(model, G, v), 0.0), y, train_data.get("view"))
        scale_output_layer(model.lin[-1], gain["gain"])
    pred = predict_appearance(model, G, v_val)
    psnr, mse, peak = display_psnr(np.maximum(pred, 0.0), val_data["rgb"])
    val = {"psnr_db": psnr, "mse": mse, "peak": peak, "samples": int(len(v_val)),
           "mean_gt": float(np.mean(val_data["rgb"])) if len(v_val) else float("nan"),
           "mean_pred": float(np.mean(np.maximum(pred, 0.0))) if len(v_val) else float("nan"),
           "accuracy": held_out_accuracy(np.maximum(pred, 0.0), val_data),
           "kept_epoch": kept + 1, "epochs": settings.epochs, "keep": settings.keep}
    return AppearanceResult(model, G, history, val, time.perf_counter() - t0, str(dev), gain)


# ----------------------------------------------------------------------------------------
# sampling network (KL against binned appearance outputs)


def disk_bins(b: int) -> np.ndarray:
    """Centres [K, 2] of the B x B grid over [-pi, pi]^2 that lie inside the disk |p| < pi (radians)."""
    c = (np.arange(b) + 0.5) / b * 2 * np.pi - np.pi
    px, py = np.meshgrid(c, c, indexing="ij")
    p = np.stack([px.ravel(), py.ravel()], 1)
    return p[np.hypot(p[:, 0], p[:, 1]) < np.pi]


def binned_targets(app_model, G, x, n, wo, lo, hi, bins: int) -> tuple[np.ndarray, np.ndarray]:
    """(P [N, K] target bin probabilities, bin centres [K, 2]) from the appearance network's luminance.

    P_k ∝ lum S(w_i(p_k)) * sin r_k / r_k (density per unit projected area of sampling w_i ∝ S); rows with
    no energy get the uniform-sphere target."""
    p = disk_bins(bins)
    K = len(p)
    r = np.hypot(p[:, 0], p[:, 1])
    area = np.where(r < 1e-6, 1.0, np.sin(r) / np.maximum(r, 1e-12))
    N = len(x)
    wi = azimuthal_equidistant_inverse(np.tile(p, (N, 1)), np.repeat(n, K, axis=0))
    v = appearance_inputs(np.repeat(x, K, 0), np.repeat(wo, K, 0), wi, lo, hi)
    s = np.maximum(predict_appearance(app_model, G, v), 0.0).astype(np.float64) @ LUMA
    w = s.reshape(N, K) * area[None]
    tot = w.sum(1, keepdims=True)
    uniform = np.broadcast_to(area / area.sum(), (N, K))
    P = np.where(tot > 1e-12, w / np.maximum(tot, 1e-300), uniform)
    return P.astype(np.float32), p


@dataclass
class SamplingResult:
    model: object
    G: np.ndarray  # [S, 5]
    history: list
    kl: float  # mean KL(target || lobe) on the training records (nats)
    kl_uniform: float  # the same for sigma -> infinity (uniform over the disk bins)
    kl_best: float  # the same for the per-record best sigma (grid search): the lobe family's floor
    seconds: float


def lobe_log_q(torch, log_sigma, r2):
    """log bin probabilities [N, K] of the truncated Gaussian discretised on bins with |p_k|^2 = r2 [K]."""
    sigma2 = torch.exp(2.0 * log_sigma.clamp(math.log(SIGMA_MIN), math.log(SIGMA_MAX)))
    return torch.log_softmax(-r2[None, :] / (2.0 * sigma2[:, None]), dim=1)


def train_sampling(app, records: dict, domain, settings: NeupressTrainSettings, *, progress=None) -> SamplingResult:
    """Fit log sigma(x, wo) by the KL loss against :func:`binned_targets` of ``records`` (x, n, wo)."""
    torch = require_torch()
    t0 = time.perf_counter()
    _, _, _, ms, s_hidden, *_ = SIZES[settings.size]
    lo, hi = domain
    rng = np.random.default_rng(settings.seed + 1)
    N = min(settings.sampling_samples, len(records["x"]))
    if N == 0:
        raise error("CONVERT_TRAINING", "no records for the sampling network")
    pick = rng.choice(len(records["x"]), N, replace=False)
    x, n, wo = (np.asarray(records[k], np.float32)[pick] for k in ("x", "n", "wo"))
    P, p = binned_targets(app.model, app.G, x, n, wo, lo, hi, settings.sampling_bins)
    Gs = rng.normal(settings.fourier_mean, settings.fourier_std, (ms, 5)).astype(np.float32)
    torch.manual_seed(settings.seed + 1)
    model = build_mlp([2 * ms, *s_hidden, 1])
    with torch.no_grad():  # start at sigma = 1 rad (a broad lobe)
        model[-1].bias.zero_()
        model[-1].weight.mul_(0.1)
    G64 = torch.as_tensor(Gs.astype(np.float64))
    F = _features(torch, G64, torch.as_tensor(sampling_inputs(x, wo, lo, hi)))
    PT = torch.as_tensor(P)
    r2 = torch.as_tensor((p ** 2).sum(1), dtype=torch.float32)
    ent = float((PT * torch.log(PT.clamp_min(1e-30))).sum(1).mean())
    opt = torch.optim.Adam(model.parameters(), lr=settings.sampling_lr)
    batch = 256
    history = []
    gen = torch.Generator().manual_seed(settings.seed + 1)
    for epoch in range(settings.sampling_epochs):
        perm = torch.randperm(N, generator=gen)
        tot = 0.0
        for s in range(0, N, batch):
            idx = perm[s:s + batch]
            logq = lobe_log_q(torch, model(F[idx])[:, 0], r2)
            loss = -(PT[idx] * logq).sum(1).mean()  # cross-entropy = KL + entropy(P)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            tot += float(loss.detach()) * len(idx)
        history.append({"epoch": epoch, "kl": tot / N + ent})
        if progress:
            progress(epoch, tot / N + ent)
    model.eval()
    with torch.no_grad():
        kl = float(-(PT * lobe_log_q(torch, model(F)[:, 0], r2)).sum(1).mean()) + ent
        kl_uniform = float(-(PT * torch.log_softmax(torch.zeros_like(PT), 1)).sum(1).mean()) + ent
        grid = torch.linspace(math.log(0.02), math.log(SIGMA_MAX), 80)
        ce = torch.stack([-(PT * lobe_log_q(torch, torch.full((N,), float(g)), r2)).sum(1) for g in grid], 1)
        kl_best = float(ce.min(1).values.mean()) + ent
    return SamplingResult(model, Gs, history, kl, kl_uniform, kl_best, time.perf_counter() - t0)


def predict_log_sigma(model, Gs, v5: np.ndarray) -> np.ndarray:
    torch = require_torch()
    with torch.no_grad():
        return model(_features(torch, torch.as_tensor(np.asarray(Gs, np.float64)),
                               torch.as_tensor(np.ascontiguousarray(v5, np.float32))))[:, 0].numpy()


# ----------------------------------------------------------------------------------------
# SH PRT


def fibonacci_sphere(k: int) -> np.ndarray:
    """K spherical-Fibonacci unit directions [K, 3] (equal-area quasi-random points)."""
    i = np.arange(k) + 0.5
    z = 1.0 - 2.0 * i / k
    phi = np.pi * (1.0 + 5 ** 0.5) * i
    s = np.sqrt(np.maximum(1.0 - z * z, 0.0))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], 1)


def wo_bin_centres(t_bins: int, p_bins: int) -> np.ndarray:
    """Local directions [T, P, 3] at the centres of the format's w_o bins (spec/kinds/neupress.md#component-prt)."""
    cos_t = 1.0 - (np.arange(t_bins) + 0.5) / t_bins
    phi = (np.arange(p_bins) + 0.5) / p_bins * 2 * np.pi - np.pi
    c, ph = np.meshgrid(cos_t, phi, indexing="ij")
    s = np.sqrt(np.maximum(1.0 - c * c, 0.0))
    return np.stack([s * np.cos(ph), s * np.sin(ph), c], -1)


def vertex_normals(geo) -> np.ndarray:
    """Unit vertex normals [V, 3]: the geometry's own, else area-weighted face normals (the renderer's rule)."""
    if geo.normals is not None and len(geo.normals) == len(geo.points):
        vn = np.asarray(geo.normals, np.float64)
    else:
        p = np.asarray(geo.points, np.float64)[geo.faces]
        fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        vn = np.zeros((len(geo.points), 3))
        for j in range(3):
            np.add.at(vn, geo.faces[:, j], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)


def prt_coefficients(app, points, normals, domain, settings: NeupressTrainSettings, *, progress=None) -> np.ndarray:
    """a [V, T, P, 9, 3] float32: a_k = sum_j S(w_j; x_v, w_o) Y_k(w_j) 4 pi / K over K Fibonacci directions."""
    _, _, _, _, _, t_bins, p_bins = SIZES[settings.size]
    lo, hi = domain
    K = settings.prt_dirs
    dirs = fibonacci_sphere(K)
    Y = sh9(dirs) * (4.0 * np.pi / K)  # [K, 9]
    wo_loc = wo_bin_centres(t_bins, p_bins).reshape(-1, 3)  # [B, 3]
    B = len(wo_loc)
    V = len(points)
    out = np.zeros((V, t_bins, p_bins, 9, 3), np.float32)
    per = max(1, 65536 // (B * K))
    for s in range(0, V, per):
        e = min(V, s + per)
        nv = np.repeat(np.asarray(normals[s:e], np.float64), B, 0)
        wo = from_local(np.tile(wo_loc, (e - s, 1)), nv)  # [(e-s)*B, 3]
        xx = np.repeat(np.asarray(points[s:e], np.float64), B, 0)
        v = appearance_inputs(np.repeat(xx, K, 0), np.repeat(wo, K, 0), np.tile(dirs, (len(wo), 1)), lo, hi)
        S = np.maximum(predict_appearance(app.model, app.G, v), 0.0).reshape(len(wo), K, 3)
        a = np.einsum("nkc,kj->njc", S.astype(np.float64), Y)
        out[s:e] = a.reshape(e - s, t_bins, p_bins, 9, 3)
        if progress:
            progress(e)
    return out


def settings_dict(settings: NeupressTrainSettings) -> dict:
    return asdict(settings)


def check_asset(path, val_data: dict, app, samp, sh) -> dict:
    """Re-open the asset with the SDK: held-out PSNR, SDK vs torch on the held-out samples, sigma and PRT round trips."""
    v = val_data
    check, asset, ev = check_against_torch(
        path, v, lambda ev: ev.evaluate(v["x"], v["n"], v["wo"], v["wi"]),
        lambda lo, hi: predict_appearance(app.model, app.G, appearance_inputs(v["x"], v["wo"], v["wi"], lo, hi)))
    lo, hi = asset.domain
    k = min(4096, len(v["x"]))
    s_sdk = np.log(ev.sigma(v["x"][:k], v["wo"][:k]))
    s_torch = np.clip(predict_log_sigma(samp.model, samp.G, sampling_inputs(v["x"][:k], v["wo"][:k], lo, hi)),
                      np.log(1e-3), np.log(1e3))
    prt = ev.prt_coefficients()
    comp = {name: int(sum(r.nbytes for r in asset.tensor_refs(name).values())
                      + sum(len(asset.network_bytes(name, n)) for n in asset.network_refs(name)))
            for name in asset.components()}
    return {**check,
            "sigma_max_abs_log_diff": float(np.max(np.abs(s_sdk - s_torch))) if k else 0.0,
            "prt_max_abs": float(np.max(np.abs(prt - sh.astype(np.float16).astype(np.float32)))),
            "component_bytes": comp}
