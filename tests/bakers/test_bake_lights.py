"""Per-pixel lights of the bake's ground truth (spec/bake.md#data): the per-path directional
emitter must give the same transport as Mitsuba's own directional emitter."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")

from nasset_converters.mitsuba import dataset as ds  # noqa: E402
from tests.mitsuba_example import isolated_example  # noqa: E402


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    mi, iso, center, radius = isolated_example(tmp_path_factory.mktemp("scene"))
    assert iso.per_path_lights
    r = ds.Renderer(mi, iso, ds.DataSettings(res=32, clamp=0.0))
    eye = center + 2.6 * radius * np.array([0.4, 0.6, 0.7]) / np.linalg.norm([0.4, 0.6, 0.7])
    o, d = ds.camera_rays(eye, center, np.arcsin(1 / 2.6) * 1.04, 32)
    mask, x, _ = r.hits(o, d)
    shell = np.linalg.norm(x - np.array([0.0, 0.21, 0.0]), axis=1) > 0.2  # the ball is noisy: shell only
    return r, iso, o[mask & shell], d[mask & shell]


def test_per_pixel_light_matches_directional_emitter(setup):
    r, iso, o, d = setup
    lights = np.array([[0.2, 0.9, 0.3], [-0.7, 0.5, 0.5]])
    lights /= np.linalg.norm(lights, axis=1, keepdims=True)
    group = np.arange(len(o)) % 2
    lane = r.transport(o, d, 64, seed=1, wi=lights[group].astype(np.float32))
    for g in range(2):
        iso.set_light(lights[g])
        ref = r.transport(o[group == g], d[group == g], 64, seed=2)
        got = lane[group == g]
        assert ref.mean() > 1e-3
        assert abs(got.mean() / ref.mean() - 1.0) < 0.05, (g, got.mean(), ref.mean())
        assert np.corrcoef(got.ravel(), ref.ravel())[0, 1] > 0.95


def test_clamp_bounds_samples(setup):
    r, iso, o, d = setup
    iso.set_light([0.0, 1.0, 0.0])
    low = ds.Renderer(r.mi, iso, ds.DataSettings(clamp=0.01)).transport(o, d, 8, seed=3)
    assert low.max() <= 0.01 + 1e-6
