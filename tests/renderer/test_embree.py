"""Embree reading the renderer's arrays in place (nasset_sdk/embree.py) against embreex's own copy.

Both put the same float32 corners into the same Embree library, so every hit must be the same bit for
bit: distance, triangle and barycentrics, on closest-hit and shadow queries, in both of Embree's modes,
for triangle soups and for shared-vertex meshes.
"""

import gc

import numpy as np
import pytest

from nasset_reference_renderer.accel import EmbreeBackend
from nasset_sdk import embree
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


def _quad_soup(n=3000, seed=6):
    """Pairs of triangles sharing an edge, bent out of plane (the quad's two triangles need not be coplanar), and
    every third pair's second triangle alone (no pair given), as (points [V,3], faces [F,3], pairs [P,2])."""
    rng = np.random.default_rng(seed)
    centre = rng.uniform(-1.0, 1.0, (n, 1, 3))
    corners = centre + rng.normal(0.0, 0.08, (n, 4, 3))  # a, s0, b, s1 of each would-be quad
    points = corners.reshape(-1, 3)
    base = 4 * np.arange(n)[:, None]
    first = base + [0, 1, 3]  # (a, s0, s1)
    second = base + [2, 3, 1]  # (b, s1, s0)
    rot = rng.integers(0, 3, n)  # the triangles' corners start anywhere
    first = np.stack([np.roll(f, r) for f, r in zip(first, rot, strict=True)])
    second = np.stack([np.roll(f, -r) for f, r in zip(second, rot, strict=True)])
    faces = np.concatenate([first, second])
    pairs = np.stack([np.arange(n), n + np.arange(n)], 1)
    return points, faces, pairs[np.arange(n) % 3 != 0]


def test_quads_of_pairs_layout():
    """Every triangle is in exactly one quad; Embree's two triangles of a quad, (v0, v1, v3) and (v2, v3, v1), are
    the named triangles' corners; ``corners`` points at each named triangle's corners 1 and 2."""
    points, faces, pairs = _quad_soup(60)
    quads, tri, corners = embree.quads_of_pairs(faces, pairs)
    assert len(quads) == len(faces) - len(pairs)
    assert sorted(np.unique(tri).tolist()) == list(range(len(faces)))
    for h, at in ((0, [0, 1, 3]), (1, [2, 3, 1])):
        paired = tri[:, 0] != tri[:, 1]
        np.testing.assert_array_equal(np.sort(quads[paired][:, at], 1), np.sort(faces[tri[paired, h]], 1))
        for k in (1, 2):
            np.testing.assert_array_equal(np.take_along_axis(quads, corners[:, h, k - 1:k].astype(np.int64), 1)[:, 0],
                                          faces[tri[:, h], k])
    alone = tri[:, 0] == tri[:, 1]
    np.testing.assert_array_equal(quads[alone], faces[tri[alone, 0]][:, [0, 1, 2, 2]])
    # pairs that share no edge, or a triangle with itself, stay apart; a triangle in two pairs is an error
    q2, t2, _ = embree.quads_of_pairs(faces[:4], [[0, 1], [2, 2]])
    assert len(q2) == 4 and (t2[:, 0] == t2[:, 1]).all()
    with pytest.raises(NassetError) as exc:
        embree.quads_of_pairs(faces, [[0, 60], [60, 1]])
    assert exc.value.code == "USAGE"


@pytest.mark.parametrize("robust", [True, False])
def test_quads_give_the_triangles_hits(robust):
    """The same triangles held by Embree as quads (non-planar ones too, and triangles alone) and as triangles: the
    same rays hit, on the same triangle away from the shared edge, at the same distance; the barycentrics reported
    for the named triangle give the point on the ray; shadow queries agree."""
    points, faces, pairs = _quad_soup()
    tri = points[faces]
    quads = embree.quads_of_pairs(faces, pairs)
    held = EmbreeBackend(tri, robust=robust, mesh=(points, faces, quads))
    assert held.quads is not None, "the in-place path must be taken on this platform (Linux, embreex 4)"
    plain = EmbreeBackend(tri, robust=robust, mesh=(points, faces))
    o, d, tmax = _rays(seed=7)
    (t, prim, u, v), (t0, prim0, _, _) = held.closest(o, d, tmax), plain.closest(o, d, tmax)
    hit = prim >= 0
    assert 0.3 < hit.mean() < 0.99 and (prim0[~hit] < 0).all()
    np.testing.assert_array_equal(hit, prim0 >= 0)
    assert (prim[hit] == prim0[hit]).mean() > 0.999  # only where a ray meets the shared edge may the two differ
    np.testing.assert_allclose(t[hit], t0[hit], rtol=1e-5, atol=1e-6)
    assert (u[hit] >= -1e-6).all() and (v[hit] >= -1e-6).all() and (u[hit] + v[hit] <= 1 + 1e-6).all()
    c = tri[prim[hit]]
    p = c[:, 0] * (1 - u[hit] - v[hit])[:, None] + c[:, 1] * u[hit][:, None] + c[:, 2] * v[hit][:, None]
    np.testing.assert_allclose(p, o[hit] + t[hit][:, None] * d[hit], atol=2e-5)
    np.testing.assert_array_equal(held.occluded(o, d, tmax), plain.occluded(o, d, tmax))


def test_fibre_prisms_pair_into_quads():
    """The fibre tessellation's pairs: each prism side's two triangles and the cap fans' triangles two by two (14
    quads for 28 triangles at 8 sides), each pair in one plane, every triangle once."""
    from nasset_reference_renderer.shaders.rna_fiber import tessellate
    from nasset_reference_renderer.testscenes import dense_hair_curves

    g = dense_hair_curves(50, 4, seed=1)
    tubes = tessellate(g.points, g.counts, g.widths)
    assert len(tubes.quads) * 2 == len(tubes.faces) and (tubes.quad_tri[:, 0] != tubes.quad_tri[:, 1]).all()
    assert sorted(tubes.quad_tri.ravel().tolist()) == list(range(len(tubes.faces)))
    p = tubes.points[tubes.quads.astype(np.int64)]  # [Q,4,3]: coplanar corners
    n = np.cross(p[:, 1] - p[:, 0], p[:, 3] - p[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    assert np.abs(((p[:, 2] - p[:, 0]) * n).sum(1)).max() < 1e-9
    np.testing.assert_array_equal(tubes.tri_seg[tubes.quad_tri[:, 0]], tubes.tri_seg[tubes.quad_tri[:, 1]])


def test_quads_fall_back_to_triangles(monkeypatch):
    """Where Embree cannot take the quads in place, the backend holds the same faces as triangles: the triangle hits."""
    points, faces, pairs = _quad_soup(500, seed=8)
    tri = points[faces]
    with monkeypatch.context() as m:
        m.setattr(embree, "attach_quads", lambda *a: False)
        fallback = EmbreeBackend(tri, robust=False, mesh=(points, faces, embree.quads_of_pairs(faces, pairs)))
    assert fallback.quads is None and fallback.shared is not None and fallback.shared[1].shape == faces.shape
    plain = EmbreeBackend(tri, robust=False, mesh=(points, faces))
    o, d, tmax = _rays(5000, seed=10)
    for a, b in zip(fallback.closest(o, d, tmax), plain.closest(o, d, tmax), strict=True):
        np.testing.assert_array_equal(a, b)
