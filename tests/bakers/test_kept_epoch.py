"""The epoch a bake keeps (spec/bake.md#training, ``keep``): with ``"best"`` the exported model is the state of
the epoch with the lowest held-out MSE, with ``"last"`` the last one. Synthetic data where the best epoch is
known not to be the last: the training targets are 0.6 and the held-out targets 0.2, so the prediction
(≈ 0 at the start) passes the held-out value on its way to the training value."""

from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("torch", reason="training tests need torch (pip install torch==2.13.0)")

from nasset_bakers.train import neupress as tn  # noqa: E402
from nasset_bakers.train import rna as tr  # noqa: E402
from nasset_bakers.train.common import BestEpoch, held_out_mse  # noqa: E402

DOMAIN = (np.full(3, -1.0), np.full(3, 1.0))
EPOCHS = 8


def _samples(n: int, rgb: float, seed: int) -> dict:
    """n rows: x in the box, unit n / w_o / w_i [N, 3], all visible, constant targets rgb [N, 3]."""
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    return {"x": rng.uniform(-0.9, 0.9, (n, 3)), "n": unit(rng.normal(size=(n, 3))), "wo": unit(rng.normal(size=(n, 3))),
            "wi": unit(rng.normal(size=(n, 3))), "vis": np.ones(n, bool), "rgb": np.full((n, 3), rgb)}


TRAIN, VAL = _samples(64, 0.6, 0), _samples(128, 0.2, 1)


def _rna(keep: str):
    s = tr.TrainSettings(size="tiny", epochs=EPOCHS, batch=16, lr=1e-2, plane_lr=1e-2, decay_every=1.0, device="cpu", keep=keep)
    r = tr.train(TRAIN, VAL, DOMAIN, s)
    pred = tr.select_branch(np.maximum(tr.predict(r.model, tr._tensors(tr.require_torch(), VAL, *DOMAIN, "cpu")), 0.0), VAL["vis"])
    return r, held_out_mse(pred, VAL["rgb"])


def _neupress(keep: str):
    s = tn.NeupressTrainSettings(size="tiny", epochs=EPOCHS, batch=16, lr=1e-2, decay_every=1.0, device="cpu", keep=keep)
    a = tn.train_appearance(TRAIN, VAL, DOMAIN, s)
    v = tn.appearance_inputs(VAL["x"], VAL["wo"], VAL["wi"], *DOMAIN)
    return a, held_out_mse(np.maximum(tn.predict_appearance(a.model, a.G, v), 0.0), VAL["rgb"])


@pytest.mark.parametrize("fit", [_rna, _neupress], ids=["rna", "neupress"])
def test_best_keeps_the_epoch_with_the_lowest_held_out_mse(fit):
    best, best_mse = fit("best")
    curve = [h["val_mse"] for h in best.history]
    k = int(np.argmin(curve))
    assert k < EPOCHS - 1 and curve[-1] > 1.5 * curve[k], curve  # the data make the last epoch worse
    assert best.val["kept_epoch"] == k + 1 and best.val["keep"] == "best"
    # the exported model, evaluated afresh, is the kept epoch's (rna: planes rounded to float16)
    assert math.isclose(best_mse, curve[k], rel_tol=2e-2), (best_mse, curve)
    last, last_mse = fit("last")
    assert last.val["kept_epoch"] == EPOCHS
    assert math.isclose(last_mse, last.history[-1]["val_mse"], rel_tol=2e-2)
    assert best_mse < last_mse / 1.5


def test_best_epoch_keeps_a_copy_and_skips_non_finite():
    torch = tr.require_torch()
    model = torch.nn.Linear(2, 1)
    b = BestEpoch()
    b.offer(0, float("nan"), model)
    assert b.state is None and b.epoch == -1
    b.offer(1, 0.5, model)
    kept = model.weight.detach().clone()
    with torch.no_grad():
        model.weight += 1.0  # training goes on
    b.offer(2, 0.7, model)  # worse: not kept
    assert b.restore(model) == 1 and torch.equal(model.weight, kept)
    again = BestEpoch(b.to_dict())  # through a checkpoint
    assert again.epoch == 1 and again.mse == 0.5 and torch.equal(again.state["weight"], kept)


def test_keep_must_be_best_or_last():
    from nasset_sdk.errors import NassetError

    with pytest.raises(NassetError, match="keep must be"):
        tr.train(TRAIN, VAL, DOMAIN, tr.TrainSettings(size="tiny", epochs=1, batch=16, device="cpu", keep="first"))
