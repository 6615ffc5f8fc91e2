"""Render threads (``RenderSettings.workers``): the image is a sum over jobs (one wavefront each) with their own random
numbers, added in job order, so every thread count gives the same image; statistics are summed over the threads.

"The same" is bit for bit in every measured render since ``np.arctan2`` takes contiguous columns (on strided ones its
last bits depended on where numpy's buffers landed; docs/benchmarks.md#render-threads); the test allows 1e-11 relative
for what else numpy's vectorised loops may do. A race between threads (a shared random stream, a shared accumulator)
changes values by the noise of the image, far above that."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.integrator import _in_order, check_settings, decoder_threads, render_workers
from nasset_reference_renderer.testscenes import SceneBuilder, constant_neupress_asset, dense_hair_curves, random_rna_asset, random_rna_fiber_asset
from nasset_sdk.errors import UsageError
from nasset_sdk.examples import example_builder


def _scene(tmp_path, kind: str):
    """A small scene for each path the integrator takes: plain meshes with a cut-out card (random draws per hit) and
    a rectangle light, and each neural kind."""
    from pxr import Sdf, UsdShade

    b = SceneBuilder()
    b.camera((0, 0.6, 3.0), (0, 0, 0), focal=40)
    b.distant("Sun", (0.3, 1.0, 0.4), 2.0)
    b.quad("Floor", (0, -0.6, 0), 4.0, diffuse=(0.6, 0.5, 0.4))
    if kind == "cutout":
        b.quad("Card", (0, 0, 0.3), 1.2, normal=(0, 0, 1), diffuse=(0.2, 0.7, 0.3))
        surf = UsdShade.Shader(b.stage.GetPrimAtPath("/World/Looks/CardMat/PreviewSurface"))
        surf.CreateInput("opacity", Sdf.ValueTypeNames.Float).Set(0.5)
        b.rect_light("Panel", (0.8, 0.8, 0.5), 0.5, 0.5, (-1, -1, -0.5), 4.0)
    elif kind == "rna":
        b.asset("Obj", random_rna_asset(tmp_path / "rna.usdc", seed=2))
    elif kind == "neupress":
        b.asset("Obj", constant_neupress_asset(tmp_path / "np.usdc"))
    elif kind == "8dna":
        b.sphere_light("Bulb", (0.9, 0.9, 0.8), 0.35, 8.0)
        b.asset("Obj", example_builder("8dna", size="tiny", seed=0).write(tmp_path / "e.usdc"))
    elif kind == "fiber":
        b.asset("Hair", random_rna_fiber_asset(tmp_path / "hair.usdc", dense_hair_curves(300, 3), seed=1))
    return load_scene(b.write(tmp_path / f"{kind}.usda"))


def _same(a, b, what, rtol=1e-11):
    """a == b but for last-bit rounding (module docstring)."""
    scale = max(float(np.abs(a).max()), 1e-30)
    assert np.all(np.abs(a - b) <= rtol * np.maximum(np.abs(a), 1e-3 * scale)), (what, float(np.abs(a - b).max()))


@pytest.mark.parametrize("kind", ["cutout", "rna", "neupress", "8dna", "fiber"])
def test_every_thread_count_renders_the_same_image(tmp_path, kind):
    scene = _scene(tmp_path, kind)
    # 12 tiles x 3 passes of 2 spp: 36 jobs
    base = dict(spp=6, width=24, height=20, tile=8, batch=128, seed=5)
    one = render(scene, RenderSettings(workers=1, **base))
    assert one.stats.workers == 1
    for workers in (2, 3):
        many = render(scene, RenderSettings(workers=workers, **base))
        assert many.stats.workers == workers
        _same(one.image, many.image, (kind, workers))
        _same(one.variance, many.variance, (kind, workers))
        assert (one.stats.camera_samples, one.stats.rays, one.stats.network_evals) == \
            (many.stats.camera_samples, many.stats.rays, many.stats.network_evals)
    assert one.image.mean() > 0
    # another seed is another image, far outside the tolerance: the equality above is not that of constant images
    other = render(scene, RenderSettings(workers=2, **dict(base, seed=6)))
    with pytest.raises(AssertionError):
        _same(one.image, other.image, "another seed")


def test_worker_counts_are_checked_and_bounded():
    for bad in (-1, True, 1.5, 10 ** 6):
        with pytest.raises(UsageError, match="workers"):
            check_settings(RenderSettings(workers=bad))
    assert render_workers(3, 100) == 3
    assert render_workers(8, 2) == 2  # never more threads than jobs
    assert 1 <= render_workers(0, 100) <= 16
    assert render_workers(0, 1) == 1
    assert decoder_threads(0, 2) == 1 and decoder_threads(4, 2) == 4  # several workers: one onnxruntime thread each


def test_jobs_come_back_in_order_and_at_most_two_per_thread_ahead():
    started, lock = [], threading.Lock()

    def job(i):
        with lock:
            started.append(i)
        time.sleep(0.002 * ((7 * i) % 5))  # finish out of order
        return i * i

    seen = []
    for k, value in enumerate(_in_order(job, list(range(40)), 3)):
        with lock:
            assert max(started) < k + 2 * 3  # the consumer's item plus at most 2 x workers submitted
        seen.append(value)
    assert seen == [i * i for i in range(40)]


def test_a_failing_job_raises_at_its_turn_and_the_rest_is_dropped():
    ran = []

    def job(i):
        ran.append(i)
        if i == 5:
            raise UsageError("job 5 failed")
        return i

    got = []
    with pytest.raises(UsageError, match="job 5"):
        for value in _in_order(job, list(range(200)), 2):
            got.append(value)
    assert got == [0, 1, 2, 3, 4]
    assert len(ran) < 20  # the jobs past the window were never started
