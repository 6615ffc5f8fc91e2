"""Rays leaving an asset instance in the plugin: the split structures (one query on the other shapes, one
branch query on the instance's own) give the hits and branch flags of re-tracing past every surface of
the instance, and the same images."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

import drjit as dr  # noqa: E402

import nasset_mitsuba_plugin.plugins as plugins  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.shaders.rna_fiber import tessellate  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from tests.mitsuba_plugin.test_neupress import _vec  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    return jit_mitsuba()


@pytest.fixture(scope="module")
def hair_scene(mi, tmp_path_factory):
    """Two instances of a fiber asset (rays cross many prisms) beside a surface asset, a sphere and a floor."""
    d = tmp_path_factory.mktemp("split")
    example_builder("rna", variant="fiber", size="small", seed=3).write(d / "hair.usdc")
    example_builder("rna", size="tiny", seed=4).write(d / "blob.usdc")
    t = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "hair_a": {**asset_shape(d / "hair.usdc", t().translate([-0.3, 0, 0]), mi=mi), "id": "hair_a"},
        "hair_b": {**asset_shape(d / "hair.usdc", t().translate([0.35, 0.1, 0.2]).rotate([0, 1, 0], 70), mi=mi), "id": "hair_b"},
        "blob": asset_shape(d / "blob.usdc", t().translate([0, 0.2, -0.8]).scale(0.5), mi=mi),
        "ball": {"type": "sphere", "center": [0.1, -0.1, 0.9], "radius": 0.3},
        "floor": {"type": "rectangle", "to_world": t().translate([0, -0.7, 0]).rotate([1, 0, 0], -90).scale(3)},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    })
    return scene, d


def _rid(mi, shape) -> int:
    return int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(shape))[0])


def _numpy(mi, si, passed):
    return (np.asarray(si.is_valid().numpy()), np.asarray(si.p.numpy()).T,
            np.asarray(dr.reinterpret_array(mi.UInt32, si.shape).numpy()), np.asarray(passed.numpy()))


def test_split_queries_equal_retracing(mi, hair_scene, rng):
    """Rays from points on the instances' prisms (ignoring their own instance, with random exempt ranges) and
    from outside (ignoring nothing): same hit, hit point, shape and branch flag both ways."""
    scene, d = hair_scene
    split = plugins.split_scenes(mi, scene)
    assert split is not None and len(split) == 2  # the fiber instances; the surface asset keeps the whole scene
    shapes = {s.id(): s for s in scene.shapes()}
    g = Asset.open(d / "hair.usdc").geometry()
    tubes = tessellate(g.points, g.counts, g.widths)
    n = 6000
    prim = rng.integers(0, len(tubes.faces), n)
    x = np.einsum("nk,nkj->nj", rng.dirichlet(np.ones(3), n), tubes.points[tubes.faces[prim]])
    which = rng.integers(0, 2, n)  # hair_a or hair_b: their to_world applied to the object-space points
    m_a = np.array(shapes["hair_a"].bsdf().to_world)
    m_b = np.array(shapes["hair_b"].bsdf().to_world)
    world = np.where(which[:, None] == 0, x @ m_a[:3, :3].T + m_a[:3, 3], x @ m_b[:3, :3].T + m_b[:3, 3])
    origin = np.concatenate([world, rng.uniform(-2, 2, (n, 3))])
    direction = rng.normal(size=(2 * n, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    ids = np.array([_rid(mi, shapes["hair_a"]), _rid(mi, shapes["hair_b"])], np.uint32)
    ignore = np.concatenate([ids[which], np.zeros(n, np.uint32)])
    lo = np.concatenate([rng.integers(0, len(tubes.faces), n), np.zeros(n, int)]).astype(np.uint32)
    hi = (lo + np.concatenate([rng.integers(0, 200, n), np.zeros(n, int)])).astype(np.uint32)
    origin[:n] += 1e-4 * direction[:n]  # off the prism it starts on
    ray = mi.Ray3f(mi.Point3f(_vec(mi, origin)), _vec(mi, direction))
    args = (mi.UInt32(ignore), mi.UInt32(lo), mi.UInt32(hi), mi.Bool(True))
    new = _numpy(mi, *plugins._trace(mi, scene, ray, *args))
    old = _numpy(mi, *plugins._trace_skipping(mi, scene, ray, *args))
    np.testing.assert_array_equal(new[0], old[0])
    hit = new[0]
    np.testing.assert_array_equal(new[2][hit], old[2][hit])
    # hit points (not t: the old way counts it from its last re-trace), equal but for the drift of the old way's
    # re-spawned float32 origins over tens of crossings (< 1e-3 in a scene of size 3)
    gap = np.abs(new[1][hit] - old[1][hit]).max(1)
    assert np.median(gap) < 1e-6 and gap.max() < 1e-3
    # the branch flags: equal but for rays grazing an edge between the two ways of stepping (at most 0.2 %)
    assert new[3][:n].mean() > 0.2 and not new[3][n:].any()
    assert np.mean(new[3] != old[3]) <= 2e-3


def test_split_structures_leave_images_unchanged(mi, hair_scene):
    """The same render (same seed) with and without the split structures: the paths are the same but where a
    hit point's float32 drift or an edge case sends one elsewhere, so the two images differ far less than two
    seeds of one way do, and their means agree to 1e-3."""
    scene, _ = hair_scene
    integ = mi.load_dict({"type": "nasset_path", "max_depth": 4})
    sensor = mi.load_dict({"type": "perspective", "fov": 40, "film": {"type": "hdrfilm", "width": 48, "height": 48},
                           "to_world": mi.ScalarTransform4f().look_at([0.5, 0.8, 2.8], [0, 0, 0], [0, 1, 0])})
    saved = plugins.MAX_SPLIT_INSTANCES

    def render(limit, seed):
        plugins.MAX_SPLIT_INSTANCES = limit
        plugins._SPLIT.clear()
        return np.asarray(mi.render(scene, sensor=sensor, integrator=integ, spp=16, seed=seed), np.float64)

    try:
        old, new, new_other_seed = render(0, 5), render(saved, 5), render(saved, 6)
    finally:
        plugins.MAX_SPLIT_INSTANCES = saved
        plugins._SPLIT.clear()
    assert old.mean() > 0.05
    assert abs(old.mean() - new.mean()) < 1e-3 * old.mean()
    rms = lambda d: float(np.sqrt(np.mean(d ** 2)))  # noqa: E731
    assert rms(old - new) < 0.05 * rms(new - new_other_seed)  # measured 0.003
