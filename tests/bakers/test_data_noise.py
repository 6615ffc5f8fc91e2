"""The data-noise rule of bakes (spec/bake.md#data-noise): the training set's relative noise measured from the held-out
halves, the views it asks for, and the bakes (Mitsuba rna and neupress, Blender rna) that render them."""

from __future__ import annotations

import math

import numpy as np
import pytest

from nasset_bakers.stages import data_noise, data_noise_line, views_for_noise


def _halves(rng, mean: np.ndarray, val_spp: int, sigma_rel: float):
    """Two independent halves of val_spp // 2 heavy-tailed (lognormal) path samples per pixel and channel, each
    path with mean ``mean`` and standard deviation ``sigma_rel * mean``."""
    s2 = math.log(1 + sigma_rel ** 2)  # lognormal with the given mean and relative standard deviation
    mu = np.log(mean) - s2 / 2
    half = val_spp // 2
    draw = lambda: np.exp(rng.normal(mu[..., None], math.sqrt(s2), mean.shape + (half,))).mean(-1)  # noqa: E731
    return draw(), draw()


def test_recovers_a_known_path_variance():
    rng = np.random.default_rng(3)
    mean = rng.uniform(0.05, 0.3, (20000, 3))
    a, b = _halves(rng, mean, 64, 2.0)  # heavy-tailed; the estimate is within ~3 % at this size (seeds 0-7)
    got = data_noise(1000, 32, {"rgb_a": a, "rgb_b": b}, 64)
    # the true relative variance of one path: mean of (2 m)^2 over pixels and channels, over (mean of m)^2
    truth = float(np.mean((2.0 * mean) ** 2)) / float(np.mean(mean)) ** 2
    assert got["path_relative_variance"] == pytest.approx(truth, rel=0.1)
    assert got["noise"] == pytest.approx(got["path_relative_variance"] / (1000 * 32))
    # the noise of the training mean falls as 1 / (samples x spp)
    assert data_noise(4000, 64, {"rgb_a": a, "rgb_b": b}, 64)["noise"] == pytest.approx(got["noise"] / 8)


def test_noiseless_halves_and_missing_data():
    m = np.full((100, 3), 0.2)
    assert data_noise(10, 8, {"rgb_a": m, "rgb_b": m}, 128)["noise"] == 0.0
    assert data_noise(10, 8, {"rgb": m}, 128) is None  # no halves
    assert data_noise(0, 8, {"rgb_a": m, "rgb_b": m}, 128) is None
    assert data_noise(10, 8, {"rgb_a": 0 * m, "rgb_b": 0 * m}, 128) is None  # no signal
    assert data_noise(10, 8, {"rgb_a": m + np.nan, "rgb_b": m}, 128) is None


@pytest.mark.parametrize("noise,expected", [
    (1e-6, 640),  # within the target
    (4.5e-6, 640),  # at it
    (6.75e-6, 960),  # 1.5x the target: 1.5x the views
    (8.82e-6, 1255),  # ceil(640 x 1.96)
    (1e-4, 1280),  # capped at 2x
    (float("nan"), 640),
    (float("inf"), 640),
])
def test_views_for_noise(noise, expected):
    assert views_for_noise(640, noise, 4.5e-6, 2.0) == expected


def test_summary_line():
    base = {"noise": 8.8e-6, "views": 640, "path_relative_variance": 282.0}
    assert "within" in data_noise_line({**base, "target": 1e-5, "views_used": 640, "noise_used": 8.8e-6, "capped": False})
    line = data_noise_line({**base, "target": 4.5e-6, "views_used": 1255, "noise_used": 4.5e-6, "capped": False})
    assert "1255 views" in line and "target 4.5e-06" in line
    assert data_noise_line(None) is None


BAKERS = {  # kind -> (baker module, example, data presets, data-noise rules, resume and --views checked too)
    "neupress": ("nasset_bakers.mitsuba.neupress", "default", "NEUPRESS_MITSUBA_DATA", "NEUPRESS_MITSUBA_DATA_NOISE", True),
    "rna": ("nasset_bakers.mitsuba.rna", "default", "RNA_MITSUBA_DATA", "RNA_MITSUBA_DATA_NOISE", True),
    "blender": ("nasset_bakers.blender.rna", "blender-surface", "RNA_BLENDER_DATA", "RNA_BLENDER_DATA_NOISE", False),
}


@pytest.mark.parametrize("kind", sorted(BAKERS))
def test_bake_renders_the_views_the_noise_asks_for(kind, tmp_path, monkeypatch):
    """A tiny bake with a target no dataset meets: 1.5x the preset's views, recorded; a bake with --views keeps its
    count; resuming the first folder renders nothing new (the last two shared by the bakers: checked on Mitsuba's)."""
    pytest.importorskip("torch")
    pytest.importorskip("bpy" if kind == "blender" else "mitsuba")
    import importlib

    from nasset_bakers import presets
    from nasset_sdk.asset import Asset
    from tests.bakers.bake_counting import count_rendered_views

    module, example, data, rules, full = BAKERS[kind]
    bake = importlib.import_module(module).bake
    monkeypatch.setitem(getattr(presets, rules), "tiny", dict(target=1e-12, max_factor=1.5))
    views = getattr(presets, data)["tiny"]["views"]
    # Cycles views at 16^2 and 4 spp, two suns each: the rule reads whatever noise there is
    opts = dict(size="tiny", example=example, quiet=True) | (
        dict(res=16, spp=4, lights_per_view=2) if kind == "blender" else dict(near_field_fetch=0.0))
    s = bake(None, None, tmp_path / "a.usdc", **opts)
    noise = s["data_noise"]
    if kind == "blender":  # two suns share a render's 4 paths: each target is about as noisy as 2 paths of one sun
        assert noise["spp"] == 2.0
    assert noise["noise"] == pytest.approx(noise["path_relative_variance"] / (noise["train_samples"] * noise["spp"]))
    assert noise["views"] == views and noise["views_used"] == math.floor(1.5 * views) == s["views"] and noise["capped"]
    assert noise["noise_used"] < noise["noise"] and noise["target"] == 1e-12
    assert len(list((tmp_path / "a.usdc.bake" / "train").glob("*.npz"))) == noise["views_used"]
    assert Asset.open(s["asset"], load="none").provenance["data"]["noise"] == noise
    if not full:
        return

    rendered = count_rendered_views(monkeypatch)
    again = bake(None, None, tmp_path / "b.usdc", resume=s["dataset_dir"], **opts)
    assert rendered == [] and again["data_noise"] == noise and again["train_samples"] == s["train_samples"]

    fixed = bake(None, None, tmp_path / "c.usdc", views=views, **opts)
    assert fixed["views"] == views and fixed["data_noise"]["target"] is None and fixed["data_noise"]["views_used"] == views
