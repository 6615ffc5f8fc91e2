"""Embree reading the renderer's arrays in place (reference_renderer/embree.py) against embreex's own copy.

Both put the same float32 corners into the same Embree library, so every hit must be the same bit for
bit: distance, triangle and barycentrics, on closest-hit and shadow queries, in both of Embree's modes,
for triangle soups and for shared-vertex meshes.
"""

import gc

import numpy as np
import pytest

from nasset_reference_renderer import embree
from nasset_reference_renderer.accel import EmbreeBackend
from nasset_sdk.errors import NassetError


def _soup(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-1.0, 1.0, (n, 1, 3))
    return centres + rng.normal(0.0, 0.08, (n, 3, 3))


def _mesh(n_points=2000, n_faces=6000, seed=1):
    rng = np.random.default_rng(seed)
    points = rng.uniform(-1.0, 1.0, (n_points, 3))
    first = rng.integers(0, n_points, n_faces)
    faces = (first[:, None] + rng.integers(0, 40, (n_faces, 3))) % n_points  # nearby indices, shared corners
    return points, faces


def _rays(n=20000, seed=2):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-1.5, 1.5, (n, 3))
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.05, 2.0, n), np.inf)
    return o, d, tmax


def _copied(monkeypatch, *args, **kw):
    """An EmbreeBackend built through embreex's element-by-element copy."""
    with monkeypatch.context() as m:
        m.setattr(embree, "attach_triangles", lambda *a: False)
        backend = EmbreeBackend(*args, **kw)
    assert backend.shared is None
    return backend


@pytest.mark.parametrize("robust", [True, False])
@pytest.mark.parametrize("shape", ["soup", "mesh"])
def test_shared_arrays_give_embreex_hits_bit_for_bit(monkeypatch, robust, shape):
    if shape == "soup":
        tri, mesh = _soup(), None
    else:
        points, faces = _mesh()
        tri, mesh = points[faces], (points, faces)
    shared = EmbreeBackend(tri, robust=robust, mesh=mesh)
    assert shared.shared is not None, "the in-place path must be taken on this platform (Linux, embreex 4)"
    copied = _copied(monkeypatch, tri, robust=robust, mesh=mesh)
    o, d, tmax = _rays()
    got, ref = shared.closest(o, d, tmax), copied.closest(o, d, tmax)
    assert 0.3 < np.mean(ref[1] >= 0) < 0.99  # a mix of hits and misses
    for a, b in zip(got, ref, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(shared.occluded(o, d, tmax), copied.occluded(o, d, tmax))
    # and the hits are on the triangles they name: the corner the barycentrics give lies on the ray
    t, prim, u, v = got
    hit = prim >= 0
    c = tri[prim[hit]]
    p = c[:, 0] * (1 - u[hit] - v[hit])[:, None] + c[:, 1] * u[hit][:, None] + c[:, 2] * v[hit][:, None]
    np.testing.assert_allclose(p, o[hit] + t[hit][:, None] * d[hit], atol=2e-5)


def test_arrays_outlive_the_callers(monkeypatch):
    """Embree reads arrays the backend owns: the caller's may go."""
    o, d, tmax = _rays(5000, seed=5)
    ref = _copied(monkeypatch, _soup(seed=4)).closest(o, d, tmax)
    backend = EmbreeBackend(_soup(seed=4))
    gc.collect()
    _ = [np.full((1000, 3, 3), 7.0) for _ in range(50)]  # reuse of freed memory would move the triangles
    for a, b in zip(backend.closest(o, d, tmax), ref, strict=True):
        np.testing.assert_array_equal(a, b)


def test_scene_handle_refuses_what_it_cannot_confirm():
    from embreex import rtcore_scene

    scene = rtcore_scene.EmbreeScene()
    assert embree.scene_handle(scene) is not None
    scene.is_committed = 1  # a committed scene is not attached to
    assert embree.scene_handle(scene) is None

    class Other:
        is_committed = 0

    class SameSize:  # the size checked for, but Python objects in the slots: the read-back fails
        __slots__ = ("scene_i", "is_committed", "device")

        def __init__(self):
            self.scene_i, self.is_committed, self.device = None, 0, None

    assert type(SameSize()).__basicsize__ == type(scene).__basicsize__
    for other in (Other(), SameSize()):
        assert embree.scene_handle(other) is None


def test_bad_buffers_are_a_usage_error():
    from embreex import rtcore_scene

    points, faces = embree.shared_buffers(_soup(10), None)
    for bad in ((points.astype(np.float64), faces), (points, faces.astype(np.int64)), (points[:, :2].copy(), faces),
                (np.asfortranarray(points), faces)):
        with pytest.raises(NassetError) as exc:
            embree.attach_triangles(rtcore_scene.EmbreeScene(), *bad)
        assert exc.value.code == "USAGE"


def test_shared_buffers_layout():
    tri = _soup(5)
    points, faces = embree.shared_buffers(tri, None)
    assert points.shape == (16, 3) and points.dtype == np.float32 and not points[-1].any()  # spare row
    np.testing.assert_array_equal(points[faces], tri.astype(np.float32))
    p, f = _mesh(50, 80)
    points, faces = embree.shared_buffers(None, (p, f))
    np.testing.assert_array_equal(points[faces], p[f].astype(np.float32))


def test_the_library_is_embreexs_own_when_blender_maps_another(monkeypatch):
    """Blender's bpy maps its own Embree 4; a scene made by embreex's library must be handed to that one only."""
    import os

    pytest.importorskip("bpy")
    import bpy  # noqa: F401

    mapped = {line.split()[-1] for line in open("/proc/self/maps") if "/libembree4" in line}
    assert len(mapped) >= 2, mapped  # the case this guards: two Embree libraries in one process
    chosen = embree.loaded_embree_path()
    assert os.path.basename(os.path.dirname(chosen)) in ("embreex.libs", "embreex"), chosen
    o, d, tmax = _rays(3000, seed=9)
    tri = _soup(500, seed=8)
    shared = EmbreeBackend(tri)
    assert shared.shared is not None
    for a, b in zip(shared.closest(o, d, tmax), _copied(monkeypatch, tri).closest(o, d, tmax), strict=True):
        np.testing.assert_array_equal(a, b)
