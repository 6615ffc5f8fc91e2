"""The epoch a bake keeps (spec/bake.md#training, ``keep``): with ``"best"`` the exported model is the state of
the epoch with the highest held-out display PSNR, with ``"last"`` the last one. Synthetic data where the best
epoch is known not to be the last: the training targets are 0.6 and the held-out targets 0.2-0.5, so the
prediction (≈ 0 at the start) passes the held-out values on its way to the training value."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch", reason="training tests need torch (pip install torch==2.13.0)")

from nasset_bakers.train import neupress as tn  # noqa: E402
from nasset_bakers.train import rna as tr  # noqa: E402
from nasset_bakers.train.common import BestEpoch, display_psnr  # noqa: E402

DOMAIN = (np.full(3, -1.0), np.full(3, 1.0))
EPOCHS = 8


def _samples(n: int, lo: float, hi: float, seed: int) -> dict:
    """n rows: x in the box, unit n / w_o / w_i [N, 3], all visible, grey targets uniform in [lo, hi] [N, 3]."""
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    return {"x": rng.uniform(-0.9, 0.9, (n, 3)), "n": unit(rng.normal(size=(n, 3))), "wo": unit(rng.normal(size=(n, 3))),
            "wi": unit(rng.normal(size=(n, 3))), "vis": np.ones(n, bool), "rgb": np.repeat(rng.uniform(lo, hi, (n, 1)), 3, 1)}


TRAIN, VAL = _samples(64, 0.6, 0.6, 0), _samples(128, 0.2, 0.5, 1)


def _rna(keep: str):
    s = tr.TrainSettings(size="tiny", epochs=EPOCHS, batch=16, lr=3e-3, plane_lr=3e-3, decay_every=1.0, device="cpu", keep=keep,
                         energy_gain=False)  # the kept epoch as trained
    r = tr.train(TRAIN, VAL, DOMAIN, s)
    pred = tr.select_branch(np.maximum(tr.predict(r.model, tr._tensors(tr.require_torch(), VAL, *DOMAIN, "cpu")), 0.0), VAL["vis"])
    return r, display_psnr(pred, VAL["rgb"])[0]


def _neupress(keep: str):
    s = tn.NeupressTrainSettings(size="tiny", epochs=EPOCHS, batch=16, lr=2e-2, decay_every=1.0, device="cpu", keep=keep,
                                 energy_gain=False)
    a = tn.train_appearance(TRAIN, VAL, DOMAIN, s)
    v = tn.appearance_inputs(VAL["x"], VAL["wo"], VAL["wi"], *DOMAIN)
    return a, display_psnr(np.maximum(tn.predict_appearance(a.model, a.G, v), 0.0), VAL["rgb"])[0]


@pytest.mark.parametrize("fit", [_rna, _neupress], ids=["rna", "neupress"])
def test_best_keeps_the_epoch_with_the_highest_held_out_psnr(fit):
    best, best_db = fit("best")
    curve = [h["val_psnr"] for h in best.history]
    k = int(np.argmax(curve))
    assert k < EPOCHS - 1 and curve[-1] < curve[k] - 0.5, curve  # the data make the last epoch worse
    assert best.val["kept_epoch"] == k + 1 and best.val["keep"] == "best"
    # the exported model, evaluated afresh, is the kept epoch's (rna: planes rounded to float16)
    assert abs(best_db - curve[k]) < 0.1, (best_db, curve)
    last, last_db = fit("last")
    assert last.val["kept_epoch"] == EPOCHS
    assert abs(last_db - last.history[-1]["val_psnr"]) < 0.1
    assert best_db > last_db + 0.5


def test_best_epoch_keeps_a_copy_and_skips_non_finite():
    torch = tr.require_torch()
    model = torch.nn.Linear(2, 1)
    b = BestEpoch()
    b.offer(0, float("nan"), model)
    assert b.state is None and b.epoch == -1
    b.offer(1, 25.0, model)
    kept = model.weight.detach().clone()
    with torch.no_grad():
        model.weight += 1.0  # training goes on
    b.offer(2, 24.0, model)  # worse: not kept
    assert b.restore(model) == 1 and torch.equal(model.weight, kept)
    again = BestEpoch(b.to_dict())  # through a checkpoint
    assert again.epoch == 1 and again.psnr == 25.0 and torch.equal(again.state["weight"], kept)


def test_keep_must_be_best_or_last():
    from nasset_sdk.errors import NassetError

    with pytest.raises(NassetError, match="keep must be"):
        tr.train(TRAIN, VAL, DOMAIN, tr.TrainSettings(size="tiny", epochs=1, batch=16, device="cpu", keep="first"))
