"""Training of the ``rna`` kind in PyTorch (paper sec. 4.2-4.3; spec/bake.md#training).

Model: three feature planes (XY, YZ, ZX) sampled bilinearly and summed, concatenated with
(xn, n, wo, wi) and decoded by a ReLU MLP into two RGB transports (unshadowed, shadowed). The
exported decoder starts with a parameter-free feature step (encoding "lobes": n.wi, n.wo, n.h,
wo.wi and exp(k (n.h - 1)) for k in LOBE_SHARPNESS) computed from that same input row. The
lookup is ``torch.nn.functional.grid_sample(align_corners=False, padding_mode="border")``, which
is the format's ``encodings.grid_sample_2d`` (texel centres, edge clamp); ``check_parity``
verifies it numerically against the SDK.

Loss: plain L2 on linear T (default; unbiased for noisy, heavy-tailed targets: its minimiser is the
targets' mean, spec/accuracy.md#loss), only on the output matching the sample's light visibility.
``loss = "log"`` (the paper's L2 of log(1 + T)) is biased on noisy targets (its minimiser is
exp(E log(1 + y)) - 1 < E[y]) and kept for ablations; ``"rel"`` is L2 relative to the detached
prediction (Noise2Noise), also unbiased. Early feature-grid blur: a Gaussian of footprint 4 texels shrinking
to 1 texel over the first 20 % of epochs, then kept at 1 texel; the exported planes are the trained planes
blurred with that footprint or with a wider one where the held-out views show it helps (spec/bake.md#plane-blur).
Adam, learning rate halved every 20 % of epochs; then each branch's output
scaled per channel so the decoder keeps its training set's energy (spec/bake.md#energy-gain).

This module is the only place that imports torch; the SDK itself never does.
"""

from __future__ import annotations

import io
import math
import time
import warnings
from dataclasses import asdict, dataclass

import numpy as np

from nasset_bakers import presets
from nasset_sdk.errors import error
from nasset_sdk.kinds.encodings import TRIPLANE_AXES
from nasset_sdk.kinds.rna import SIZES

from .common import (
    BestEpoch,
    check_against_torch,
    display_psnr,
    energy_gain,
    held_out_accuracy,
    require_torch,
    scale_output_layer,
)
from .parallel import data_parallel


@dataclass(frozen=True)
class TrainSettings:
    size: str = "small"
    epochs: int = 60
    batch: int = 8192
    lr: float = 1e-3
    plane_lr: float = 1e-2
    decay_every: float = 0.2  # fraction of epochs between halvings
    blur_start: float = 4.0  # texels (footprint; Gaussian sigma = footprint / 2)
    blur_end: float = 1.0
    blur_until: float = 0.2  # fraction of epochs
    init_std: float = 0.1
    loss: str = "l2"  # "l2": L2 of T (unbiased); "log": L2 of log(1 + T) (paper; biased on noisy targets); "rel": L2 / sg(pred)^2
    rel_eps: float = 0.01  # "rel": (pred - y)^2 / (sg(pred) + rel_eps)^2
    encoding: str = "lobes"  # decoder-internal features of the fixed input row: "raw" or "lobes"
    plane_res: int = 0  # triplane resolution R; 0: the preset's (nasset_sdk.kinds.rna.SIZES)
    plane_channels: int = 0  # triplane channels C; 0: the preset's
    hidden: int = 0  # decoder width; 0: the preset's
    seed: int = 0
    device: str = "auto"
    keep: str = "last"  # "last" epoch, or "best": the highest held-out display PSNR (the paper's best checkpoint; spec/accuracy.md#best-epoch)
    plane_blur: str = "select"  # "select": the final blur footprint chosen on the held-out views (spec/bake.md#plane-blur); "schedule": blur_end
    energy_gain: bool = True  # scale each branch's output to the training set's energy after training (spec/bake.md#energy-gain)


TRAIN_PRESETS = presets.RNA_TRAIN  # the table lives in nasset_bakers/presets.py


#: sharpness k of the lobe features exp(k (n.h - 1)) (encoding "lobes")
LOBE_SHARPNESS = (4.0, 16.0, 64.0)


def build_model(size: str, *, init_std: float = 0.1, seed: int = 0, plane_res: int = 0, plane_channels: int = 0,
                hidden_width: int = 0, encoding: str = "lobes", fiber: bool = False):
    """The rna model for a preset of ``nasset_sdk.kinds.rna.SIZES`` (the MLP's depth fixed by the preset;
    the triplane's R and C and the decoder's width may be overridden). ``fiber``: the fiber variant, whose frame input is
    [t (3), h (1)] (``n`` passed as [N, 4]), with the azimuth cosine as an extra feature and lobes
    exp(-k (t.h)^2) (spec/bake-blender.md#training)."""
    torch = require_torch()
    nn = torch.nn
    F = torch.nn.functional
    res, ch, layers, hidden = SIZES[size]
    res, ch, hidden = plane_res or res, plane_channels or ch, hidden_width or hidden

    class DirectionFeatures(nn.Module):
        """Part of the exported decoder: appends angular features computed from the contract's input
        row [zeta (C), xn, n, wo, wi] -- n.wi, n.wo, n.h, wo.wi and lobes exp(k (n.h - 1)), h the
        half vector -- so the MLP need not build a highlight out of ReLUs of raw directions."""

        def __init__(self, c: int) -> None:
            super().__init__()
            self.c = c
            self.register_buffer("k", torch.tensor(LOBE_SHARPNESS))

        def forward(self, x):
            c, f = self.c, int(fiber)
            n, wo, wi = x[:, c + 3:c + 6], x[:, c + 6 + f:c + 9 + f], x[:, c + 9 + f:c + 12 + f]
            h = wo + wi
            h = h / torch.sqrt((h * h).sum(1, keepdim=True) + 1e-8)
            nh = (n * h).sum(1, keepdim=True)
            nwi, nwo = (n * wi).sum(1, keepdim=True), (n * wo).sum(1, keepdim=True)
            dots = [nwi, nwo, nh, (wo * wi).sum(1, keepdim=True)]
            if fiber:  # cos of the azimuth between wo and wi around the tangent (Marschner's phi)
                a, b = wo - nwo * n, wi - nwi * n
                dots.append((a * b).sum(1, keepdim=True) / torch.sqrt((a * a).sum(1, keepdim=True) * (b * b).sum(1, keepdim=True) + 1e-8))
            lobes = torch.exp(-self.k * nh * nh) if fiber else torch.exp(self.k * (nh - 1.0))
            return torch.cat([x, *dots, lobes], dim=1)

    extra = {"raw": 0, "lobes": 4 + int(fiber) + len(LOBE_SHARPNESS)}
    if encoding not in extra:
        raise ValueError(f"unknown encoding {encoding!r}")

    class RnaModel(nn.Module):
        def __init__(self) -> None:
            super().__init__()
            g = torch.Generator().manual_seed(seed)
            # torch layout [plane, C, v, u]; exported as [plane, v, u, C]
            self.planes = nn.Parameter(torch.randn(3, ch, res, res, generator=g) * init_std)
            self.in_width = ch + 12 + int(fiber)
            widths = [self.in_width + extra[encoding]] + [hidden] * layers + [6]
            mods = [DirectionFeatures(ch)] if encoding == "lobes" else []
            for i, (a, b) in enumerate(zip(widths[:-1], widths[1:], strict=False)):
                mods.append(nn.Linear(a, b))
                if i < len(widths) - 2:
                    mods.append(nn.ReLU())
            self.decoder = nn.Sequential(*mods)
            self.register_buffer("fixed_planes", torch.zeros(0))  # set by freeze_planes()

        # -- encoding ------------------------------------------------------------------------
        def effective_planes(self, sigma: float):
            if self.fixed_planes.numel():
                return self.fixed_planes
            return blur_planes(self.planes, sigma)

        def features(self, xn, sigma: float):
            planes = self.effective_planes(sigma)
            grid = torch.stack([torch.stack([xn[:, a], xn[:, b]], dim=-1) for a, b in TRIPLANE_AXES])  # [3, N, 2]
            f = F.grid_sample(planes, grid[:, None], mode="bilinear", padding_mode="border", align_corners=False)
            return f[:, :, 0, :].sum(0).transpose(0, 1)  # [N, C]

        def network_input(self, xn, n, wo, wi, sigma: float = 0.0):
            frame = [F.normalize(n[:, :3], dim=1), n[:, 3:4].clamp(-1.0, 1.0)] if fiber else [F.normalize(n, dim=1)]
            return torch.cat([self.features(xn, sigma), xn, *frame, F.normalize(wo, dim=1), F.normalize(wi, dim=1)], dim=1)

        def forward(self, xn, n, wo, wi, sigma: float = 0.0):
            return self.decoder(self.network_input(xn, n, wo, wi, sigma))

        def freeze_planes(self, planes_cvu) -> None:
            """Evaluate with these planes from now on (e.g. the stored float16 planes)."""
            self.fixed_planes = planes_cvu.detach().clone()

    return RnaModel()


def blur_planes(planes, sigma: float):
    """Separable Gaussian blur of [3, C, R, R] planes with edge-replicate padding; sigma in texels."""
    torch = require_torch()
    F = torch.nn.functional
    if sigma <= 1e-3:
        return planes
    rad = max(1, int(math.ceil(3.0 * sigma)))
    rad = min(rad, planes.shape[-1] - 1) if planes.shape[-1] > 1 else 0
    if rad <= 0:
        return planes
    t = torch.arange(-rad, rad + 1, dtype=planes.dtype, device=planes.device)
    k = torch.exp(-0.5 * (t / sigma) ** 2)
    k = k / k.sum().clamp_min(1e-12)
    p, c, h, w = planes.shape
    x = planes.reshape(p * c, 1, h, w)
    x = F.pad(x, (rad, rad, 0, 0), mode="replicate")
    x = F.conv2d(x, k.view(1, 1, 1, -1))
    x = F.pad(x, (0, 0, rad, rad), mode="replicate")
    x = F.conv2d(x, k.view(1, 1, -1, 1))
    return x.reshape(p, c, h, w)


def blur_sigma(settings: TrainSettings, epoch: int) -> float:
    """Gaussian sigma (texels) for an epoch of the schedule."""
    until = max(1.0, settings.blur_until * settings.epochs)
    t = min(1.0, epoch / until)
    footprint = settings.blur_start + (settings.blur_end - settings.blur_start) * t
    return 0.5 * footprint


def log_transport(p):
    """log(1 + p) for p >= 0, continued linearly below 0 so that negative outputs are pushed up."""
    torch = require_torch()
    return torch.log1p(torch.relu(p)) - torch.relu(-p)


def loss_fn(pred, y, settings: TrainSettings):
    """Training loss (spec/bake.md#training) of the visibility-selected prediction vs target y."""
    torch = require_torch()
    y = y.clamp_min(0)
    if settings.loss == "log":
        return torch.mean((log_transport(pred) - torch.log1p(y)) ** 2)
    if settings.loss == "rel":
        w = 1.0 / (pred.detach().clamp_min(0) + settings.rel_eps) ** 2
        return torch.mean(w * (pred - y) ** 2)
    if settings.loss == "l2":
        return torch.mean((pred - y) ** 2)
    raise ValueError(f"unknown loss {settings.loss!r}")


def select_branch(y: np.ndarray, vis: np.ndarray) -> np.ndarray:
    """Pick unshadowed (vis=1) or shadowed (vis=0) RGB from [N,6] outputs."""
    v = np.asarray(vis).astype(bool)[:, None]
    return np.where(v, y[:, :3], y[:, 3:6])


@dataclass
class TrainResult:
    model: object
    planes: np.ndarray  # [3, R, R, C] float16, as stored
    onnx: bytes
    history: list
    val: dict
    onnx_max_abs_diff: float
    seconds: float
    device: str
    energy_gain: dict | None = None  # apply_energy_gain's figures; None when off
    plane_blur: dict | None = None  # choose_plane_blur's figures; None when off


def _tensors(torch, data: dict, lo, hi, device):
    from nasset_sdk.kinds.encodings import to_unit_box

    xn = to_unit_box(data["x"], lo, hi)
    t = lambda a: torch.as_tensor(np.ascontiguousarray(a, np.float32), device=device)  # noqa: E731
    frame = np.concatenate([data["n"], np.asarray(data["h"]).reshape(-1, 1)], 1) if "h" in data else data["n"]  # fiber: [t, h]
    return {
        "xn": t(xn), "n": t(frame), "wo": t(data["wo"]), "wi": t(data["wi"]),
        "vis": torch.as_tensor(np.asarray(data["vis"]).astype(bool), device=device), "rgb": t(data["rgb"]),
    }


def predict(model, T: dict, batch: int = 65536, sigma: float = 0.0) -> np.ndarray:
    torch = require_torch()
    out = []
    with torch.no_grad():
        for s in range(0, len(T["xn"]), batch):
            sl = slice(s, s + batch)
            out.append(model(T["xn"][sl], T["n"][sl], T["wo"][sl], T["wi"][sl], sigma).cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, 6), np.float32)


def export_onnx(model) -> bytes:
    """The decoder MLP as ONNX (opset 17, input 'x' [N, C+12], output 'y' [N, 6], dynamic N)."""
    torch = require_torch()
    dec = model.decoder.cpu().eval()
    width = model.in_width
    buf = io.BytesIO()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(dec, (torch.zeros(2, width),), buf, dynamo=False, opset_version=17,
                          input_names=["x"], output_names=["y"], dynamic_axes={"x": {0: "N"}, "y": {0: "N"}})
    return buf.getvalue()


def onnx_parity(model, onnx_bytes: bytes, n: int = 4096, seed: int = 0) -> float:
    """Max |onnxruntime - torch| of the decoder on random inputs."""
    torch = require_torch()
    from nasset_sdk.networks import make_session

    dec = model.decoder.cpu().eval()
    width = model.in_width
    x = np.random.default_rng(seed).normal(0, 1, (n, width)).astype(np.float32)
    for a in range(width - 9, width, 3):  # n, wo, wi are unit vectors (the SDK normalises them)
        x[:, a:a + 3] /= np.maximum(np.linalg.norm(x[:, a:a + 3], axis=1, keepdims=True), 1e-6)
    with torch.no_grad():
        ref = dec(torch.from_numpy(x)).numpy()
    got = make_session(onnx_bytes).run(None, {"x": x})[0]
    return float(np.max(np.abs(got - ref)))


def train(train_data: dict, val_data: dict, domain, settings: TrainSettings, *, progress=None,
          checkpoint=None) -> TrainResult:
    """Fit the model; ``progress(epoch, loss, val_psnr)`` is called per epoch (tqdm hook).

    ``checkpoint``: optional object with ``load() -> dict|None`` and ``save(dict)`` (resume).
    Under ``torchrun`` the processes train data-parallel (nasset_bakers.train.parallel): each holds the
    whole training set and takes its share of every batch; only rank 0 saves checkpoints.
    """
    torch = require_torch()
    from nasset_sdk.networks import check_model_bytes

    t0 = time.perf_counter()
    torch.manual_seed(settings.seed)
    dp = data_parallel(torch, settings.device)
    device = dp.device
    lo, hi = domain
    if len(train_data["x"]) == 0:
        raise error("CONVERT_TRAINING", "no training samples: no camera ray hit the asset")
    T = _tensors(torch, train_data, lo, hi, device)
    V = _tensors(torch, val_data, lo, hi, device)
    model = build_model(settings.size, init_std=settings.init_std, seed=settings.seed, plane_res=settings.plane_res,
                        plane_channels=settings.plane_channels, hidden_width=settings.hidden, encoding=settings.encoding,
                        fiber="h" in train_data).to(device)
    opt = torch.optim.Adam([
        {"params": [model.planes], "lr": settings.plane_lr},
        {"params": model.decoder.parameters(), "lr": settings.lr},
    ])
    step = max(1, int(round(settings.decay_every * settings.epochs)))
    sched = torch.optim.lr_scheduler.StepLR(opt, step_size=step, gamma=0.5)
    state = checkpoint.restore(model, opt, sched) if checkpoint is not None else None
    history: list = list(state.get("history", [])) if state else []
    start = int(state["epoch"]) if state else 0
    best = BestEpoch(state.get("best") if state else None)
    if settings.keep not in ("best", "last"):
        raise error("CONVERT_TRAINING", f"keep must be 'best' or 'last', got {settings.keep!r}")
    if settings.plane_blur not in ("select", "schedule"):
        raise error("CONVERT_TRAINING", f"plane_blur must be 'select' or 'schedule', got {settings.plane_blur!r}")
    net = dp.wrap(torch, model)
    n = len(T["xn"])
    g = torch.Generator(device="cpu").manual_seed(settings.seed)
    for epoch in range(start, settings.epochs):
        model.train()
        sigma = blur_sigma(settings, epoch)
        perm = torch.randperm(n, generator=g).to(device)
        total, count = 0.0, 0
        for s in range(0, n, settings.batch):
            batch = perm[s:s + settings.batch]
            if len(batch) < dp.world:  # a last batch with fewer samples than processes: skipped by all
                continue
            idx = dp.share(batch)
            y = net(T["xn"][idx], T["n"][idx], T["wo"][idx], T["wi"][idx], sigma)
            pred = torch.where(T["vis"][idx][:, None], y[:, :3], y[:, 3:])
            loss = loss_fn(pred, T["rgb"][idx], settings)
            opt.zero_grad(set_to_none=True)
            (loss * dp.weight(len(idx), len(batch))).backward()
            opt.step()
            total += float(loss.detach()) * len(idx)
            count += len(idx)
        sched.step()
        mean_loss = dp.mean(torch, total / max(count, 1))
        if not math.isfinite(mean_loss):
            raise error("CONVERT_TRAINING", f"loss became non-finite at epoch {epoch}")
        model.eval()  # held-out figures every epoch: the kept epoch is chosen by them
        pv = select_branch(np.maximum(predict(model, V, sigma=sigma), 0.0), val_data["vis"])
        val_psnr, val_mse, _ = display_psnr(pv, val_data["rgb"])  # val_mse: linear, for the history
        best.offer(epoch, val_psnr, model)
        history.append({"epoch": epoch, "loss": mean_loss, "val_psnr": val_psnr, "val_mse": val_mse, "sigma": sigma})
        if progress is not None:
            progress(epoch, mean_loss, val_psnr)
        if checkpoint is not None and dp.is_main and (epoch % 5 == 4 or epoch == settings.epochs - 1):
            checkpoint.save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(),
                             "epoch": epoch + 1, "history": history, "best": best.to_dict()})
    train_s = time.perf_counter() - t0

    # the kept state: the best epoch's (its blur) or the last one's
    kept = best.restore(model) if settings.keep == "best" and best.state is not None else settings.epochs - 1
    model.eval()
    footprint = 2.0 * blur_sigma(settings, kept)
    blur = choose_plane_blur(model, V, val_data, footprint) if settings.plane_blur == "select" else None
    if blur is not None:
        footprint = blur["chosen"]
    # freeze what is stored: blurred planes rounded to float16
    with torch.no_grad():
        eff = blur_planes(model.planes, 0.5 * footprint).detach()
        planes16 = eff.permute(0, 2, 3, 1).cpu().numpy().astype(np.float16)  # [3, R(v), R(u), C]
        model.freeze_planes(torch.from_numpy(planes16.astype(np.float32)).permute(0, 3, 1, 2).to(device))
    if not np.isfinite(planes16.astype(np.float32)).all():
        raise error("CONVERT_TRAINING", "feature planes overflow float16")
    gain = apply_energy_gain(model, T, train_data) if settings.energy_gain else None
    yv = np.maximum(predict(model, V), 0.0)
    pv = select_branch(yv, val_data["vis"])
    psnr, mse_lin, peak = display_psnr(pv, val_data["rgb"])
    acc = held_out_accuracy(pv, val_data)
    log_mse = float(np.mean((np.log1p(pv) - np.log1p(np.maximum(val_data["rgb"], 0))) ** 2)) if len(pv) else float("nan")
    onnx_bytes = export_onnx(model)
    check_model_bytes(onnx_bytes)
    diff = onnx_parity(model, onnx_bytes, seed=settings.seed)
    model.to(device)
    return TrainResult(
        model=model, planes=planes16, onnx=onnx_bytes, history=history,
        val={"psnr_db": psnr, "mse": mse_lin, "log_mse": log_mse, "peak": peak, "samples": int(len(pv)), "accuracy": acc,
             "kept_epoch": kept + 1, "epochs": settings.epochs, "keep": settings.keep},
        onnx_max_abs_diff=diff, seconds=train_s, device=str(device), energy_gain=gain, plane_blur=blur,
    )


#: blur footprints (texels; Gaussian sigma = footprint / 2) tried on the planes after training, up to R / 4
#: (spec/bake.md#plane-blur)
PLANE_BLUR_FOOTPRINTS = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0)


def choose_plane_blur(model, V: dict, val_data: dict, footprint: float, sigmas: float = 2.0) -> dict | None:
    """The final blur of the trained planes (spec/bake.md#plane-blur): the schedule's ``footprint`` or a wider one
    from PLANE_BLUR_FOOTPRINTS, whichever predicts the held-out views with the lowest squared error, where it beats
    the schedule's by more than ``sigmas`` standard errors (held-out views as the independent units; a wider blur
    averages away the noise of the training targets that the planes learned, and the held-out references decide
    whether it also averages away the asset's detail). ``V``: the held-out tensors of ``_tensors``. Returns
    {"footprints", "mse" (per footprint, linear, against the held-out mean), "schedule", "chosen", "views"}, or None
    with fewer than 2 held-out views. The model's planes are left as they were."""
    torch = require_torch()
    views = val_data.get("view")
    if views is None or len(np.unique(views)) < 2:
        return None
    _, unit = np.unique(np.asarray(views), return_inverse=True)
    res = int(model.planes.shape[-1])
    fps = [float(footprint)] + [f for f in PLANE_BLUR_FOOTPRINTS if footprint + 1e-9 < f <= res / 4]
    y = np.asarray(val_data["rgb"], np.float64)
    raw = model.planes.detach().clone()
    per_view = []
    try:
        for f in fps:
            with torch.no_grad():
                model.planes.copy_(blur_planes(raw, 0.5 * f))
            p = select_branch(np.maximum(predict(model, V), 0.0), val_data["vis"]).astype(np.float64)
            per_view.append(np.bincount(unit, ((p - y) ** 2).sum(1)))
    finally:
        with torch.no_grad():
            model.planes.copy_(raw)
    per_view = np.asarray(per_view)  # [F, views]
    d = per_view - per_view[0]  # paired by view against the schedule's footprint
    se = np.sqrt(d.shape[1]) * d.std(1, ddof=1)  # standard error of the summed difference (views independent)
    better = d.sum(1) + sigmas * se < 0
    total = per_view.sum(1)
    chosen = int(np.argmin(np.where(better, total, np.inf))) if better.any() else 0
    count = y.size
    return {"footprints": fps, "mse": [float(t / count) for t in total], "schedule": fps[0], "chosen": fps[chosen],
            "views": int(d.shape[1])}


def apply_energy_gain(model, T: dict, train_data: dict) -> dict:
    """Scale the decoder's output rows so that each branch keeps its training samples' energy (spec/bake.md#energy-gain):
    the unshadowed outputs by the gain over the samples whose light was visible, the shadowed ones over the others.
    Returns {"unshadowed": ..., "shadowed": ...} (``common.energy_gain`` before the gain; None for a branch without
    samples)."""
    y = np.maximum(predict(model, T), 0.0)
    vis = np.asarray(train_data["vis"]).astype(bool)
    views = train_data.get("view")
    out, gains = {}, []
    for name, rows, cols in (("unshadowed", vis, slice(0, 3)), ("shadowed", ~vis, slice(3, 6))):
        g = energy_gain(y[rows, cols], train_data["rgb"][rows], None if views is None else np.asarray(views)[rows]) \
            if rows.any() else None
        out[name] = g
        gains.extend(g["gain"] if g else [1.0, 1.0, 1.0])
    scale_output_layer(model.decoder[-1], gains)
    return out


def settings_dict(settings: TrainSettings) -> dict:
    return asdict(settings)


def check_asset(path, val_data: dict, result) -> dict:
    """Re-open the asset and evaluate it with the SDK on the held-out samples (rna surface, or fiber with ``h``)."""
    dev = next(result.model.parameters()).device
    v = val_data
    check, _, _ = check_against_torch(
        path, v, lambda ev: np.concatenate(ev.evaluate(v["x"], v["n"], v["wo"], v["wi"], v.get("h")), axis=1),
        lambda lo, hi: predict(result.model, _tensors(require_torch(), v, lo, hi, dev)),
        lambda y: select_branch(y, v["vis"]))
    return check
