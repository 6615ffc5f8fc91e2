"""The held-out figures of a bake take the held-out views as the independent units (spec/accuracy.md#metrics)."""

from __future__ import annotations

import numpy as np

from nasset_bakers.stages import accuracy_lines
from nasset_bakers.train.common import held_out_accuracy


def test_held_out_figures_take_the_views_as_units():
    """The bake's held-out figures (spec/accuracy.md#held-out-figures-in-bakes) group the samples by view, and the
    summary line says so with the per-view spread."""
    rng = np.random.default_rng(5)
    truth = rng.uniform(0.2, 1.0, (400, 3))
    labels = np.repeat(np.arange(4), 100)
    est = truth * np.array([0.9, 1.0, 1.05, 1.1])[labels][:, None]  # one error per view
    a = truth + rng.normal(0.0, 0.02, truth.shape)
    b = truth + rng.normal(0.0, 0.02, truth.shape)
    acc = held_out_accuracy(est, {"rgb_a": a, "rgb_b": b, "rgb": 0.5 * (a + b), "view": labels})
    assert acc["groups"]["count"] == 4
    line = accuracy_lines(acc)[0]
    assert "4 views as units" in line and "per view" in line
    assert "views" not in accuracy_lines(held_out_accuracy(est, {"rgb_a": a, "rgb_b": b}))[0]
