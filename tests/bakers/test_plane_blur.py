"""The final plane blur (spec/bake.md#plane-blur): after training, the rna bake blurs its feature planes as widely as
the held-out views show to help. Planes fitted to noisy targets of a smooth object get a wider blur, and it brings
them closer to the noiseless truth; planes fitted to clean targets of a finely textured object keep the schedule's."""

from __future__ import annotations

import numpy as np
import pytest

torch = pytest.importorskip("torch", reason="training tests need torch (pip install torch==2.13.0)")

from nasset_bakers.train import rna as tr  # noqa: E402

DOMAIN = (np.full(3, -1.0), np.full(3, 1.0))
RES = 32


def _smooth(x):
    return 0.5 + 0.25 * np.sin(2.0 * x[:, :1] + 1.0) * np.cos(1.5 * x[:, 1:2])


def _checker(x):
    # a texture at the scale of 2 texels of the 32-texel planes, on the plane of x and y
    c = (np.floor((x[:, :1] + 1) * RES / 4) + np.floor((x[:, 1:2] + 1) * RES / 4)) % 2
    return 0.2 + 0.6 * c


def _samples(n: int, seed: int, truth, noise: float, views: int) -> tuple[dict, np.ndarray]:
    """Samples whose radiance depends on position only ([N, 3]); targets = truth x lognormal noise of mean 1 and log-sd
    ``noise`` (heavy-tailed, like path-traced pixels); also returns the noiseless truth."""
    rng = np.random.default_rng(seed)
    unit = lambda a: a / np.linalg.norm(a, axis=1, keepdims=True)  # noqa: E731
    x = rng.uniform(-0.95, 0.95, (n, 3))
    x[:, 2] = 0.0  # a flat object in z = 0: only the xy plane carries it
    t = np.repeat(truth(x), 3, 1) * np.array([1.0, 0.8, 0.6])
    y = t * rng.lognormal(-0.5 * noise ** 2, noise, (n, 1)) if noise > 0 else t
    d = {"x": x, "n": np.tile([0.0, 0.0, 1.0], (n, 1)), "wo": unit(rng.normal(size=(n, 3)) + [0, 0, 2]),
         "wi": unit(rng.normal(size=(n, 3)) + [0, 0, 2]), "vis": np.ones(n, bool), "rgb": y, "view": np.arange(n) % views}
    return d, t


def _fit(truth, noise: float, val_noise: float):
    train, _ = _samples(40000, 0, truth, noise, 80)
    val, val_truth = _samples(6000, 1, truth, val_noise, 24)
    s = tr.TrainSettings(size="tiny", epochs=6, batch=512, lr=3e-3, plane_lr=3e-2, plane_res=RES, plane_channels=4,
                         hidden=32, device="cpu", energy_gain=False)
    r = tr.train(train, val, DOMAIN, s)
    return r, val, val_truth


def _error_against_truth(model, val, truth) -> float:
    p = np.maximum(tr.predict(model, tr._tensors(torch, val, *DOMAIN, "cpu")), 0.0)[:, :3]
    return float(np.mean((p - truth) ** 2))




def test_noisy_targets_of_a_smooth_object_get_a_wider_blur_that_brings_the_planes_closer_to_the_truth():
    r, val, truth = _fit(_smooth, noise=1.2, val_noise=0.1)
    b = r.plane_blur
    assert b is not None and b["schedule"] == pytest.approx(1.0)
    assert b["chosen"] > b["schedule"], b
    # the stored (chosen) planes predict the noiseless truth better than the schedule's blur of the same planes
    chosen_err = _error_against_truth(r.model, val, truth)
    s = tr.TrainSettings(size="tiny", epochs=6, batch=512, lr=3e-3, plane_lr=3e-2, plane_res=RES, plane_channels=4,
                         hidden=32, device="cpu", energy_gain=False, plane_blur="schedule")
    train, _ = _samples(40000, 0, _smooth, 1.2, 80)
    r0 = tr.train(train, val, DOMAIN, s)
    assert r0.plane_blur is None
    schedule_err = _error_against_truth(r0.model, val, truth)
    assert chosen_err < 0.8 * schedule_err, (chosen_err, schedule_err)


def test_clean_targets_of_a_fine_texture_keep_the_schedules_blur():
    r, val, truth = _fit(_checker, noise=0.0, val_noise=0.0)
    b = r.plane_blur
    assert b is not None and b["chosen"] == b["schedule"], b
    # every wider footprint was worse on the held-out views
    assert all(m > b["mse"][0] for m in b["mse"][1:]), b


def test_no_choice_without_two_held_out_views():
    r = tr.train(*(_samples(2000, s, _smooth, 0.5, v)[0] for s, v in ((0, 8), (1, 1))), DOMAIN,
                 tr.TrainSettings(size="tiny", epochs=1, batch=512, device="cpu", energy_gain=False))
    assert r.plane_blur is None


def test_unknown_plane_blur_setting_is_a_typed_error():
    from nasset_sdk.errors import NassetError

    with pytest.raises(NassetError, match="plane_blur"):
        tr.train(_samples(500, 0, _smooth, 0.5, 4)[0], _samples(200, 1, _smooth, 0.5, 4)[0], DOMAIN,
                 tr.TrainSettings(size="tiny", epochs=1, batch=256, device="cpu", plane_blur="wide"))
