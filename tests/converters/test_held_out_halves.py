"""Held-out views are unclamped and come in two independent halves; a training clamp's removed energy is
measured (spec/accuracy.md#held-out-figures-in-bakes)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")

from nasset_converters.mitsuba import dataset as ds  # noqa: E402
from tests.mitsuba_example import isolated_example  # noqa: E402


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    return isolated_example(tmp_path_factory.mktemp("scene"))


def test_defaults_keep_all_energy():
    assert ds.DataSettings().clamp == 0.0
    from nasset_bakers.train.rna import TrainSettings
    from nasset_converters.mitsuba.neupress_dataset import NeupressDataSettings

    assert NeupressDataSettings().clamp == 0.0
    assert TrainSettings().loss in ("l2", "rel")  # unbiased for noisy targets (spec/accuracy.md#loss)


def test_validation_view_is_two_unclamped_halves(setup):
    mi, iso, center, radius = setup
    # a clamp far below the ball's radiance: held-out views must ignore it
    r = ds.Renderer(mi, iso, ds.DataSettings(res=16, val_res=16, val_spp=32, clamp=0.01))
    v = ds.render_view(r, center, radius, 0, validation=True)
    a, b = v["rgb_a"], v["rgb_b"]
    assert a.shape == b.shape == v["rgb"].shape and len(a) > 20
    np.testing.assert_allclose(v["rgb"], 0.5 * (a + b), rtol=1e-5, atol=1e-7)
    assert max(a.max(), b.max()) > 0.05  # not clamped at 0.01
    assert not np.array_equal(a, b)  # independent seeds
    assert "clamp_removed" not in v


def test_training_clamp_removed_energy_is_measured(setup):
    mi, iso, center, radius = setup
    clamped = ds.Renderer(mi, iso, ds.DataSettings(res=16, spp=8, clamp=0.05))
    v = ds.render_view(clamped, center, radius, 1, validation=False)
    assert v["rgb"].max() <= 0.05 + 1e-6
    e, removed = v["energy"], v["clamp_removed"]
    assert (removed > 0).all() and (removed < e).all()
    # energy kept + energy removed = the unclamped pixel means' energy
    np.testing.assert_allclose(v["rgb"].astype(np.float64).sum(0) + removed, e, rtol=1e-4)
    free = ds.Renderer(mi, iso, ds.DataSettings(res=16, spp=8, clamp=0.0))
    w = ds.render_view(free, center, radius, 1, validation=False)
    assert (w["clamp_removed"] == 0).all()
    np.testing.assert_allclose(w["rgb"].astype(np.float64).sum(0), w["energy"], rtol=1e-4)
