"""What the trainers share: torch loaded on demand (typed error when missing), the device choice,
the resumable training checkpoint, the held-out PSNR every bake reports (spec/bake.md#psnr) and the
check of the written asset against torch."""

from __future__ import annotations

import math

import numpy as np

from nasset_sdk.errors import UsageError, error


def require_torch():
    try:
        import torch
    except ImportError as exc:
        raise error("CONVERT_BACKEND", f"torch is not installed ({exc}); pip install 'nasset-sdk[train]'") from None
    return torch


#: --device values: auto (CUDA when torch sees a device, else CPU), cpu, cuda, cuda:N
DEVICES = ("auto", "cpu", "cuda")


def pick_device(torch, want: str):
    """The torch device for ``--device want``; UsageError for an unknown name, CONVERT_BACKEND for
    CUDA asked for where torch sees none."""
    want = str(want or "auto")
    base, _, index = want.partition(":")
    if base not in DEVICES or (index and (base != "cuda" or not index.isdigit())):
        raise UsageError(f"--device must be auto, cpu, cuda or cuda:N, got {want!r}")
    if base == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if base == "cuda" and (not torch.cuda.is_available() or int(index or 0) >= torch.cuda.device_count()):
        raise error("CONVERT_BACKEND", f"--device {want}: torch {torch.__version__} sees "
                    f"{torch.cuda.device_count() if torch.cuda.is_available() else 'no'} CUDA device(s)")
    return torch.device(want)


def display_psnr(pred: np.ndarray, gt: np.ndarray) -> tuple[float, float, float]:
    """(PSNR dB, linear MSE, peak): both normalised by the ground truth's 99.5th percentile and
    clipped to [0, 1] (a fixed exposure on a display), peak 1; over asset pixels only."""
    gt = np.asarray(gt, np.float64)
    pred = np.asarray(pred, np.float64)
    mse_lin = float(np.mean((pred - gt) ** 2)) if gt.size else float("nan")
    peak = float(np.percentile(gt, 99.5)) if gt.size else 0.0
    if peak <= 0 or not np.isfinite(peak):
        return float("nan"), mse_lin, peak
    a = np.clip(pred / peak, 0.0, 1.0)
    b = np.clip(gt / peak, 0.0, 1.0)
    mse = float(np.mean((a - b) ** 2))
    return (10.0 * math.log10(1.0 / max(mse, 1e-20))), mse_lin, peak


class BestEpoch:
    """The model state of the epoch with the highest held-out display PSNR (``display_psnr``: references
    normalised by their 99.5th percentile and clipped, so that the rare fireflies of path-traced references
    do not decide): what a bake exports with ``keep = "best"``, as the RNA paper keeps its best checkpoint
    (spec/bake.md#training; not the default, spec/accuracy.md#best-epoch). ``saved``: ``to_dict()`` of a checkpoint, to resume."""

    def __init__(self, saved: dict | None = None) -> None:
        saved = saved or {}
        self.epoch = int(saved.get("epoch", -1))
        self.psnr = float(saved.get("psnr", -math.inf))
        self.state = saved.get("state")

    def offer(self, epoch: int, psnr: float, model) -> None:
        """Keep ``model``'s state (a CPU copy) when ``psnr`` (dB) is finite and the highest so far."""
        if math.isfinite(psnr) and psnr > self.psnr:
            self.epoch, self.psnr = int(epoch), float(psnr)
            self.state = {k: v.detach().cpu().clone() for k, v in model.state_dict().items()}

    def restore(self, model) -> int:
        """Load the kept state into ``model`` (on its device); returns the kept epoch (0-based), -1 if none."""
        if self.state is not None:
            model.load_state_dict(self.state)
        return self.epoch

    def to_dict(self) -> dict:
        return {"epoch": self.epoch, "psnr": self.psnr, "state": self.state}


def training_key(settings) -> dict:
    """The training settings (a dataclass) that shape the training state, for a checkpoint's key: all but
    ``energy_gain`` and ``plane_blur``, which act after the last epoch, so a bake interrupted before they existed
    still resumes."""
    return {k: v for k, v in settings.__dict__.items() if k not in ("energy_gain", "plane_blur")}


def state_fits(model, saved) -> bool:
    """``saved`` (a state dict) has exactly ``model``'s tensor names and shapes."""
    mine = model.state_dict()
    return isinstance(saved, dict) and saved.keys() == mine.keys() and all(
        getattr(saved[k], "shape", None) == v.shape for k, v in mine.items())


class TorchCheckpoint:
    """Training state in the dataset folder; read back with ``weights_only=True`` (no pickle code)."""

    def __init__(self, path, key: dict) -> None:
        self.path = path
        self.key = key

    def load(self):
        import json
        import os

        torch = require_torch()
        if not os.path.exists(self.path):
            return None
        try:
            state = torch.load(self.path, map_location="cpu", weights_only=True)
        except Exception:
            return None
        if state.get("key") != json.dumps(self.key, sort_keys=True):
            return None
        return state

    def restore(self, model, opt, sched) -> dict | None:
        """Put a matching checkpoint's model, optimiser and scheduler state back; returns it (None: start fresh).
        A checkpoint whose tensors do not fit ``model`` (names or shapes: a preset's network changed under the same
        settings) is not this bake's and is left unread, rather than half loaded."""
        state = self.load()
        if state and not state_fits(model, state.get("model")):
            state = None
        if state:
            model.load_state_dict(state["model"])
            opt.load_state_dict(state["opt"])
            sched.load_state_dict(state["sched"])
        return state or None

    def save(self, state: dict) -> None:
        import json
        import os

        torch = require_torch()
        tmp = str(self.path) + ".part"
        torch.save({**state, "key": json.dumps(self.key, sort_keys=True)}, tmp)
        os.replace(tmp, self.path)


def held_out_accuracy(pred: np.ndarray, val_data: dict) -> dict | None:
    """Figures of spec/accuracy.md#metrics of held-out predictions [N, 3] against the unclamped two-half
    reference (``rgb_a``, ``rgb_b``), with the held-out views as the independent units (``view`` [N], when
    present: one view is one camera and light, and the asset's error is correlated within it); None for
    datasets without halves."""
    from nasset_sdk.metrics import accuracy

    if "rgb_a" not in val_data or not len(pred):
        return None
    return accuracy(pred, val_data["rgb_a"], val_data["rgb_b"], flip=False, groups=val_data.get("view")).to_dict()


#: the energy gain is applied to a channel only where the training set measures the network's share of its energy
#: to this standard error (views as units): a `tiny` bake's 12-16 views measure it to +-5-20 %, shadowed branches to
#: +-100 % and more, and a gain from that would add error instead of removing it
MAX_GAIN_SE = 0.02


def energy_gain(pred: np.ndarray, target: np.ndarray, views: np.ndarray | None, max_se: float = MAX_GAIN_SE) -> dict:
    """The output gain that gives a trained network its training set's energy (spec/bake.md#energy-gain).

    ``pred`` [N, 3]: the network's clamped predictions of the training samples, ``target`` [N, 3] their unclamped
    path-traced values, ``views`` [N] the view of each sample (the units of the standard error). Returns {ratio [3]:
    sum(pred) / sum(target) per channel; se [3]: its standard error with the views as units (None with fewer than 2
    views); gain [3]: 1 / ratio where that se is at most ``max_se``, else 1; applied [3]; samples}. L2 training's
    minimiser matches the targets' mean, but a network stopped by a learning-rate schedule does not reach it: the
    small neupress example kept 96-98 % of its training energy."""
    p = np.asarray(pred, np.float64)
    y = np.asarray(target, np.float64)
    sp, sy = p.sum(0), y.sum(0)
    ok = np.isfinite(sp) & np.isfinite(sy) & (sp > 0) & (sy > 0)
    ratio = np.where(ok, sp / np.where(ok, sy, 1.0), 1.0)
    se = np.full(3, np.inf)
    if views is not None and len(p):
        v = np.unique(np.asarray(views), return_inverse=True)[1]
        k = int(v.max()) + 1
        if k > 1:
            vp = np.stack([np.bincount(v, p[:, c], k) for c in range(3)], 1)
            vy = np.stack([np.bincount(v, y[:, c], k) for c in range(3)], 1)
            resid = vp - ratio * vy  # the ratio estimator linearised over views
            se = np.sqrt(k / (k - 1) * (resid ** 2).sum(0)) / np.where(ok, sy, 1.0)
    applied = ok & (se <= max_se)
    return {"gain": np.where(applied, 1.0 / ratio, 1.0).tolist(), "ratio": ratio.tolist(),
            "se": se.tolist() if np.isfinite(se).all() else None, "applied": applied.tolist(), "samples": int(len(p))}


def scale_output_layer(layer, gain) -> None:
    """Multiply a torch ``Linear`` output layer's rows (weights and bias) by ``gain`` [out] (the energy gain: a linear
    output scaled by a positive gain scales its clamped value too)."""
    torch = require_torch()
    with torch.no_grad():
        g = torch.as_tensor(np.asarray(gain, np.float32), device=layer.weight.device)
        layer.weight.mul_(g[:, None])
        layer.bias.mul_(g)


def reopen_asset(path):
    """(asset, evaluator) of the written asset, re-opened with the SDK and fully loaded."""
    from nasset_sdk.asset import Asset

    asset = Asset.open(path)
    asset.load("all")
    return asset, asset.evaluator()


def check_against_torch(path, val_data: dict, sdk_eval, torch_eval, shown=None) -> tuple[dict, object, object]:
    """Re-open the written asset with the SDK, evaluate it on the held-out samples and compare with torch.

    ``sdk_eval(ev) -> y_sdk`` and ``torch_eval(lo, hi) -> y_torch`` ([N, k], clamped at 0 here) give the two
    predictions; ``shown(y_sdk) -> [N, 3]`` the radiance compared with ``val_data["rgb"]`` (default: y_sdk).
    Returns ({psnr_db, max_abs_diff, accuracy}, asset, evaluator) for kind-specific further checks.
    """
    asset, ev = reopen_asset(path)
    y_sdk = sdk_eval(ev)
    lo, hi = asset.domain
    y_torch = np.maximum(torch_eval(lo, hi), 0.0)
    diff = float(np.max(np.abs(y_sdk - y_torch))) if len(y_sdk) else 0.0
    y = y_sdk if shown is None else shown(y_sdk)
    return {"psnr_db": display_psnr(y, val_data["rgb"])[0], "max_abs_diff": diff, "accuracy": held_out_accuracy(y, val_data)}, asset, ev
