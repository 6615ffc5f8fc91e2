"""Render settings: those read from the stage (the Gaussian pixel filter's sample offsets, chi² against the filter), and
the Python API's RenderSettings and scene arguments checked before any work."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer.film import pixel_offsets
from tests.stats import chi2_test, stat_seed


@pytest.mark.parametrize("stddev", [0.5, 0.7])
def test_gaussian_offsets_follow_mitsubas_truncated_gaussian(stddev):
    # Mitsuba's gaussian: exp(-x^2 / 2s^2) - exp(-r^2 / 2s^2) on |x| < r = 4 s around the pixel centre, per axis
    r, n, bins = 4 * stddev, 200_000, 40
    off = pixel_offsets(np.random.default_rng(stat_seed(11)), n, "gaussian", stddev) - 0.5
    assert np.abs(off).max() <= r
    edges = np.linspace(-r, r, bins + 1)
    x = np.linspace(-r, r, bins * 512 + 1)  # fine midpoint quadrature of the density per bin
    mid = 0.5 * (x[1:] + x[:-1])
    f = np.exp(-mid ** 2 / (2 * stddev ** 2)) - np.exp(-r ** 2 / (2 * stddev ** 2))
    prob = f.reshape(bins, -1).sum(1)
    for axis in (0, 1):
        counts, _ = np.histogram(off[:, axis], edges)
        _, _, p = chi2_test(counts, prob)
        assert p > 1e-4, (axis, p)
    assert abs(np.corrcoef(off[:, 0], off[:, 1])[0, 1]) < 0.01  # separable: independent axes


def test_box_offsets_are_uniform_over_the_pixel():
    off = pixel_offsets(np.random.default_rng(stat_seed(12)), 100_000, "box")
    assert off.min() >= 0 and off.max() < 1
    counts, _ = np.histogram(off[:, 0], np.linspace(0, 1, 21))
    assert chi2_test(counts, np.full(20, 0.05))[2] > 1e-4


@pytest.mark.parametrize("change,name", [
    (dict(spp=1.5), "spp"), (dict(spp="4"), "spp"), (dict(spp=None), "spp"), (dict(spp=0), "spp"),
    (dict(seed=-1), "seed"), (dict(seed=1 << 70), "seed"), (dict(rr_depth=-1), "rr_depth"), (dict(width=2.5), "width"),
    (dict(height="8"), "height"), (dict(width=True), "width"), (dict(backend="optix"), "backend"),
])
def test_render_settings_of_the_wrong_type_or_range_are_usage_errors(change, name):
    """The Python API's settings are checked like the CLI's before any work: a float or string spp, a negative or
    oversized seed, a negative Russian-roulette depth, a non-integer size or an unknown backend used to fail as a bare
    TypeError / ValueError in the render loop, or (backend) to switch silently to the brute-force ray caster."""
    from nasset_reference_renderer import RenderSettings
    from nasset_reference_renderer.integrator import check_settings
    from nasset_sdk.errors import UsageError

    with pytest.raises(UsageError, match=name):
        check_settings(RenderSettings(**{"spp": 1, "width": 8, "height": 8, **change}))
    check_settings(RenderSettings(spp=1, width=8, height=8, seed=(1 << 64) - 1, rr_depth=0, backend="numpy"))


def test_render_and_load_scene_refuse_what_is_not_a_scene(tmp_path):
    from nasset_reference_renderer import RenderSettings, load_scene, render
    from nasset_reference_renderer.testscenes import SceneBuilder
    from nasset_sdk.errors import UsageError

    for bad in (None, 5, {"scene": 1}):
        with pytest.raises(UsageError, match="load_scene: source must be a path or a Usd.Stage"):
            load_scene(bad)
        with pytest.raises(UsageError, match="render: scene must be a Scene"):
            render(bad, RenderSettings(spp=1, width=4, height=4))
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    scene = load_scene(b.write(tmp_path / "s.usda"))
    with pytest.raises(UsageError, match="render settings must be a RenderSettings"):
        render(scene, {"spp": 1})
    assert render(scene, RenderSettings(spp=1, width=4, height=4)).image.shape == (4, 4, 3)
