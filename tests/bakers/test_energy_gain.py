"""The energy gain (spec/bake.md#energy-gain): after training, the output layer is scaled so the network's clamped
predictions of its own training samples carry their energy, per channel (rna: per branch), where the training set
measures that share to 2 % (views as units)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_bakers.train.common import MAX_GAIN_SE, energy_gain


def _views(rng, n_views: int, per_view: int, share: float, spread: float):
    """Heavy-tailed targets [N, 3] (lognormal per sample), predictions = share x a per-view factor of sd ``spread``
    x the view's mean target (a network that gets each view's level wrong, not its pixels), view ids [N]."""
    views = np.repeat(np.arange(n_views), per_view)
    y = rng.lognormal(0.0, 1.0, (len(views), 3))
    level = np.stack([y[views == v].mean(0) for v in range(n_views)])
    factor = share * (1.0 + spread * rng.standard_normal((n_views, 1)))
    return y, (level * factor)[views], views


def test_gain_restores_the_energy_and_its_standard_error_matches_the_spread_between_data_sets():
    rng = np.random.default_rng(0)
    ratios, ses = [], []
    for _ in range(300):
        y, p, v = _views(rng, 80, 30, 0.9, 0.05)
        g = energy_gain(p, y, v)
        assert all(g["applied"])
        assert np.allclose(np.asarray(g["gain"]) * p.sum(0), y.sum(0), rtol=1e-12)  # exactly the training energy
        ratios.append(g["ratio"])
        ses.append(g["se"])
    ratios, ses = np.asarray(ratios), np.asarray(ses)
    assert np.allclose(ratios.mean(0), 0.9, atol=3 * ratios.std(0).max() / np.sqrt(len(ratios)) + 1e-3)
    # the reported standard error is the spread of the ratio between independent training sets (within 15 %)
    assert np.allclose(ses.mean(0), ratios.std(0, ddof=1), rtol=0.15), (ses.mean(0), ratios.std(0, ddof=1))


def test_gain_is_not_applied_where_the_training_set_does_not_measure_it():
    rng = np.random.default_rng(1)
    y, p, v = _views(rng, 4, 30, 0.8, 0.5)  # a `tiny` bake: few views, each badly off
    g = energy_gain(p, y, v)
    assert not any(g["applied"]) and g["gain"] == [1.0, 1.0, 1.0]
    assert min(g["se"]) > MAX_GAIN_SE
    one = energy_gain(p, y, np.zeros(len(y), int))  # one view: no standard error at all
    assert one["se"] is None and one["gain"] == [1.0, 1.0, 1.0]
    dark = energy_gain(np.zeros_like(y), y, v)  # nothing predicted: no gain can fix it, and none is invented
    assert dark["gain"] == [1.0, 1.0, 1.0] and np.isfinite(dark["ratio"]).all()


torch = pytest.importorskip("torch", reason="training tests need torch (pip install torch==2.13.0)")

from nasset_bakers.train import neupress as tn  # noqa: E402
from nasset_bakers.train import rna as tr  # noqa: E402

DOMAIN = (np.full(3, -1.0), np.full(3, 1.0))


def _samples(n: int, seed: int, views: int = 40) -> dict:
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    return {"x": rng.uniform(-0.9, 0.9, (n, 3)), "n": unit(rng.normal(size=(n, 3))), "wo": unit(rng.normal(size=(n, 3))),
            "wi": unit(rng.normal(size=(n, 3))), "vis": rng.random(n) < 0.6,
            "rgb": rng.uniform(0.2, 1.0, (n, 3)) * np.array([1.0, 0.7, 0.4]), "view": np.arange(n) % views}


TRAIN, VAL = _samples(4000, 0), _samples(400, 1)


@pytest.mark.parametrize("on", [True, False])
def test_neupress_training_keeps_its_training_energy(on):
    # two short epochs at a low rate: the network stops well below the targets' mean
    s = tn.NeupressTrainSettings(size="tiny", epochs=2, batch=256, lr=2e-3, device="cpu", energy_gain=on)
    a = tn.train_appearance(TRAIN, VAL, DOMAIN, s)
    v = tn.appearance_inputs(TRAIN["x"], TRAIN["wo"], TRAIN["wi"], *DOMAIN)
    kept = np.maximum(tn.predict_appearance(a.model, a.G, v), 0.0).sum(0) / TRAIN["rgb"].sum(0)
    if on:
        assert all(a.energy_gain["applied"]) and np.allclose(kept, 1.0, atol=1e-4), kept
        assert np.allclose(a.energy_gain["ratio"], 1.0 / np.asarray(a.energy_gain["gain"]))
        assert max(abs(r - 1.0) for r in a.energy_gain["ratio"]) > 0.05  # it had something to correct
    else:
        assert a.energy_gain is None and np.abs(kept - 1.0).max() > 0.05, kept


@pytest.mark.parametrize("on", [True, False])
def test_rna_training_keeps_each_branchs_training_energy(on):
    s = tr.TrainSettings(size="tiny", epochs=2, batch=256, lr=1e-3, plane_lr=1e-3, device="cpu", energy_gain=on)
    r = tr.train(TRAIN, VAL, DOMAIN, s)
    y = np.maximum(tr.predict(r.model, tr._tensors(torch, TRAIN, *DOMAIN, "cpu")), 0.0)
    vis = TRAIN["vis"]
    kept = [y[vis, :3].sum(0) / TRAIN["rgb"][vis].sum(0), y[~vis, 3:].sum(0) / TRAIN["rgb"][~vis].sum(0)]
    if on:
        for branch, k in zip(("unshadowed", "shadowed"), kept, strict=True):
            assert all(r.energy_gain[branch]["applied"]) and np.allclose(k, 1.0, atol=1e-3), (branch, k)
    else:
        assert r.energy_gain is None and max(np.abs(k - 1.0).max() for k in kept) > 0.05, kept
