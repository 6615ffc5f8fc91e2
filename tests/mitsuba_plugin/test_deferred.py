"""``nasset_path``'s deferred light-sample rows (``defer``, mitsuba_plugin/deferred.py) against the in-loop
evaluation: the same estimator and random numbers, so the same image to float32 rounding."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import deferred  # noqa: E402
from nasset_mitsuba_plugin.plugins import register  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A floor, an rna and a neupress asset (one scaled and mirrored), a sun and a constant sky."""
    mi = jit_mitsuba()
    register(mi)
    d = tmp_path_factory.mktemp("deferred")
    example_builder("rna", size="tiny", seed=5).write(d / "rna.usdc")
    example_builder("neupress", size="tiny", seed=6).write(d / "np.usdc")
    t = mi.ScalarTransform4f
    return mi, mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 45, "to_world": t().look_at(origin=[0, 2.5, 4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 40, "height": 28, "rfilter": {"type": "box"}}},
        "floor": {"type": "rectangle", "to_world": t().translate([0, -0.5, 0]).rotate([1, 0, 0], -90).scale(4),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
        "left": asset_shape(d / "rna.usdc", t().translate([-0.9, 0, 0]), mi=mi),
        "right": asset_shape(d / "np.usdc", t().translate([0.9, 0.1, 0]).scale([-1.2, 0.8, 1.0]), mi=mi),
        "sun": {"type": "directional", "direction": [0.3, -1, 0.2], "irradiance": {"type": "rgb", "value": 3.0}},
        "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.3}},
    })


def _render(mi, scene, defer, spp=8):
    integ = mi.load_dict({"type": "nasset_path", "max_depth": 5, "defer": defer})
    return np.asarray(mi.render(scene, integrator=integ, spp=spp, seed=3), np.float64)


@pytest.mark.parametrize("capacity", [1.0, 1e-9])
def test_deferred_light_rows_equal_in_loop(scene, monkeypatch, capacity):
    """Deferred and in-loop light rows give the same image (float32 rounding: the terms of L are summed in
    another order), also when the queue overflows (capacity 1 row: every other row is evaluated in the loop)."""
    mi, sc = scene
    monkeypatch.setattr(deferred, "CAPACITY", capacity)
    ref = _render(mi, sc, False)
    img = _render(mi, sc, True)
    assert np.isfinite(img).all() and ref.mean() > 0.05
    np.testing.assert_allclose(img, ref, rtol=1e-5, atol=1e-6)
