"""CONVERT_TRAINING: each raise site of the rna and neupress trainers, triggered through the public train functions
with small synthetic datasets (no scene render needed)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("torch", reason="training tests need torch (pip install torch==2.13.0)")

from nasset_bakers.train import neupress as tn  # noqa: E402
from nasset_bakers.train import rna as tr  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402

DOMAIN = (np.full(3, -1.0), np.full(3, 1.0))


def _samples(n: int, rgb: float = 0.5, seed: int = 0) -> dict:
    """A synthetic training split of n rows: x in the box, unit n / w_o / w_i [N,3], vis [N], rgb [N,3]."""
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    return {"x": rng.uniform(-0.9, 0.9, (n, 3)), "n": unit(rng.normal(size=(n, 3))), "wo": unit(rng.normal(size=(n, 3))),
            "wi": unit(rng.normal(size=(n, 3))), "vis": rng.random(n) < 0.8, "rgb": np.full((n, 3), rgb)}


def _raises_training(fn, match: str) -> None:
    with pytest.raises(NassetError, match=match) as e:
        fn()
    assert e.value.code == "CONVERT_TRAINING", e.value.code


RNA = tr.TrainSettings(size="tiny", epochs=1, batch=256, device="cpu")


def test_rna_no_training_samples():
    _raises_training(lambda: tr.train(_samples(0), _samples(8), DOMAIN, RNA), "no training samples")


def test_rna_loss_non_finite():
    # targets of 1e30 are finite, their squared error overflows float32: the epoch's loss is inf
    _raises_training(lambda: tr.train(_samples(512, rgb=1e30), _samples(8), DOMAIN, RNA), "non-finite at epoch 0")


def test_rna_feature_planes_overflow_float16():
    # planes ~ N(0, 1e7) stay far above float16's 65504 after the final blur (plane_lr 0: training leaves them)
    s = tr.TrainSettings(size="tiny", epochs=1, batch=256, device="cpu", init_std=1e7, plane_lr=0.0, lr=0.0, loss="log")
    _raises_training(lambda: tr.train(_samples(512), _samples(8), DOMAIN, s), "overflow float16")


NEUPRESS = tn.NeupressTrainSettings(size="tiny", epochs=1, batch=256, device="cpu")


@pytest.mark.parametrize("rows,rgb", [(0, 0.5), (64, np.inf)], ids=["empty", "nonfinite_target"])
def test_neupress_no_usable_samples(rows, rgb):
    _raises_training(lambda: tn.train_appearance(_samples(rows, rgb), _samples(8), DOMAIN, NEUPRESS),
                     "no usable training samples")


def test_neupress_appearance_loss_non_finite():
    _raises_training(lambda: tn.train_appearance(_samples(256, rgb=1e30), _samples(8), DOMAIN, NEUPRESS),
                     "non-finite appearance loss at epoch 0")


def test_neupress_sampling_without_records():
    # the record count is checked before the appearance model is used
    _raises_training(lambda: tn.train_sampling(None, {"x": np.zeros((0, 3)), "n": np.zeros((0, 3)), "wo": np.zeros((0, 3))},
                                               DOMAIN, NEUPRESS), "no records")
