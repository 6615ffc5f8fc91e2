"""The 8dna trainer's exponential weight average (spec/bake-8dna.md#weight-average): the recursion, its start, its
checkpointed state, and that it changes what is exported, not how training goes."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch")

from nasset_bakers.train.eightdna import TrainSettings, WeightAverage, train  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402
from tests.bakers.test_train_parallel import _Tuples  # noqa: E402


def _steps(values):
    """A parameter set to each of ``values`` in turn, as an optimiser would leave it after each step."""
    p = torch.nn.Parameter(torch.zeros(3, dtype=torch.float64))
    for v in values:
        with torch.no_grad():
            p.copy_(torch.as_tensor(v, dtype=torch.float64))
        yield p


def test_the_average_is_the_exponential_recursion_from_its_start():
    rng = np.random.default_rng(0)
    values = rng.normal(size=(10, 3))
    decay, start = 0.7, 4
    want = values[start].copy()  # the first averaged step copies the weights
    for v in values[start + 1:]:
        want = decay * want + (1 - decay) * v
    avg = None
    for step, p in enumerate(_steps(values)):
        avg = avg or WeightAverage(torch, [p], decay, start)
        avg.update(step)
        if step < start:
            assert avg.shadow is None
    avg.apply()
    np.testing.assert_allclose(p.detach().numpy(), want, rtol=1e-12)


def test_a_resumed_average_continues_where_the_checkpoint_left_it():
    values = np.random.default_rng(1).normal(size=(8, 3))
    whole, first = None, None
    for step, p in enumerate(_steps(values)):
        whole = whole or WeightAverage(torch, [p], 0.5, 2)
        whole.update(step)
    for step, p in enumerate(_steps(values[:5])):
        first = first or WeightAverage(torch, [p], 0.5, 2)
        first.update(step)
    saved = [s.clone() for s in first.shadow]
    p = torch.nn.Parameter(torch.zeros(3, dtype=torch.float64))
    resumed = WeightAverage(torch, [p], 0.5, 2, saved)
    for step in range(5, 8):
        with torch.no_grad():
            p.copy_(torch.as_tensor(values[step]))
        resumed.update(step)
    np.testing.assert_allclose(resumed.shadow[0].numpy(), whole.shadow[0].numpy(), rtol=1e-12)


def test_decay_zero_keeps_the_last_step_and_a_bad_decay_is_refused():
    p = torch.nn.Parameter(torch.ones(2))
    avg = WeightAverage(torch, [p], 0.0, 0)
    avg.update(0)
    avg.apply()
    assert avg.shadow is None and p.detach().tolist() == [1.0, 1.0]
    for bad in (1.0, -0.1):
        with pytest.raises(NassetError) as e:
            WeightAverage(torch, [p], bad, 0)
        assert e.value.code == "CONVERT_TRAINING"


def test_averaging_changes_the_export_not_the_training():
    """Same seed and tuples: the losses of every step are the same with and without the average, the exported
    weights are not (they are the average of the second half's)."""
    box = ((-0.5,) * 3, (0.5,) * 3)
    runs = [train(_Tuples(), box, TrainSettings(size="tiny", steps=20, batch=256, device="cpu", seed=4, average=a))
            for a in (0.0, 0.8)]
    assert [h["nll"] for h in runs[0].history] == [h["nll"] for h in runs[1].history]
    last, averaged = (dict(r.model.named_parameters()) for r in runs)
    moved = max(float((last[k] - averaged[k]).detach().abs().max()) for k in last)
    assert moved > 1e-6
    for r in runs:
        assert all(np.isfinite(t).all() for t in r.tensors.values()) and r.onnx_max_abs_diff < 1e-4
