"""Embree intersector vs the numpy reference intersector (reference_renderer/accel.py) on random rays.

Embree works in float32 and the reference in float64, so the two may disagree on rays that graze a
triangle edge or hit two surfaces at (nearly) the same distance; every disagreement must be such a
case, checked against the exact float64 intersection, and there may only be a few of them.
"""

import numpy as np
import pytest
import trimesh

from nasset_reference_renderer.accel import Accel, EmbreeBackend, NumpyBackend

EDGE = 1e-4  # barycentric margin below which float32 and float64 may legitimately disagree
T_REL = 1e-4  # relative distance agreement for the same hit


def _scene():
    rng = np.random.default_rng(7)
    parts = []
    s = trimesh.creation.icosphere(subdivisions=2, radius=0.6)
    parts.append(s.vertices[s.faces] + [-0.7, 0.0, 0.0])
    s = trimesh.creation.icosphere(subdivisions=1, radius=0.4)
    parts.append(s.vertices[s.faces] + [0.8, 0.3, -0.2])
    floor = np.array([[[-2, -1, -2], [2, -1, -2], [2, -1, 2]], [[-2, -1, -2], [2, -1, 2], [-2, -1, 2]]], float)
    parts.append(floor)
    c = rng.uniform(-1.5, 1.5, (40, 1, 3))
    parts.append(c + rng.normal(0, 0.3, (40, 3, 3)))  # loose random triangles, some intersecting the rest
    tri = np.concatenate(parts)
    tri_inst = np.concatenate([np.full(len(p), i) for i, p in enumerate(parts)])
    return tri, tri_inst


def _rays(n, seed):
    rng = np.random.default_rng(seed)
    o = rng.uniform(-2.5, 2.5, (n, 3))
    aim = rng.uniform(-1.0, 1.0, (n, 3))  # toward the middle: most rays hit something
    d = np.where(rng.random((n, 1)) < 0.8, aim - o, rng.normal(size=(n, 3)))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tmax = np.where(rng.random(n) < 0.3, rng.uniform(0.2, 4.0, n), np.inf)
    return o, d, tmax


def _exact(tri, o, d, prim):
    """float64 (t, u, v, edge margin) of each ray against triangle prim[i] (prim >= 0)."""
    p0, p1, p2 = tri[prim, 0], tri[prim, 1], tri[prim, 2]
    e1, e2 = p1 - p0, p2 - p0
    pv = np.cross(d, e2)
    det = (e1 * pv).sum(1)
    inv = 1.0 / det
    tv = o - p0
    u = (tv * pv).sum(1) * inv
    qv = np.cross(tv, e1)
    v = (d * qv).sum(1) * inv
    t = (e2 * qv).sum(1) * inv
    return t, u, v, np.minimum(np.minimum(u, v), 1 - u - v)


def _check_closest(tri, o, d, tmax, got, ref):
    t_e, p_e, u_e, v_e = got
    t_n, p_n, u_n, v_n = ref
    hit_n, hit_e = p_n >= 0, p_e >= 0
    assert hit_n.mean() > 0.4 and (~hit_n).mean() > 0.05  # both cases well represented
    same = p_e == p_n
    both = same & hit_n
    assert np.all(np.isinf(t_e[~hit_e])) and np.all(np.isinf(t_n[~hit_n]))
    np.testing.assert_allclose(t_e[both], t_n[both], rtol=T_REL, atol=T_REL)
    np.testing.assert_allclose(u_e[both], u_n[both], atol=1e-3)
    np.testing.assert_allclose(v_e[both], v_n[both], atol=1e-3)
    bad = np.nonzero(~same)[0]
    assert len(bad) <= 0.01 * len(o), f"{len(bad)} of {len(o)} rays disagree"
    for i in bad:
        why = []
        for p in (p_e[i], p_n[i]):
            if p >= 0:
                t, _, _, margin = _exact(tri, o[i:i + 1], d[i:i + 1], np.array([p]))
                why.append(margin[0] < EDGE or abs(t[0] - tmax[i]) < T_REL * (1 + t[0]))
        tie = hit_n[i] and hit_e[i] and abs(t_e[i] - t_n[i]) < T_REL * (1 + t_n[i])
        assert tie or any(why), f"ray {i}: embree prim {p_e[i]} t {t_e[i]}, numpy prim {p_n[i]} t {t_n[i]}"


@pytest.mark.parametrize("seed", [0, 1])
def test_closest_matches_numpy(seed):
    tri, _ = _scene()
    o, d, tmax = _rays(3000, seed)
    got = EmbreeBackend(tri).closest(o, d, tmax)
    ref = NumpyBackend(tri).closest(o, d, tmax)
    assert got[1].dtype == ref[1].dtype == np.int64
    _check_closest(tri, o, d, tmax, got, ref)


def test_occluded_matches_numpy():
    tri, _ = _scene()
    o, d, tmax = _rays(3000, 2)
    occ = EmbreeBackend(tri).occluded(o, d, tmax)
    ref_t, ref_p, _, _ = NumpyBackend(tri).closest(o, d, tmax)
    bad = np.nonzero(occ != (ref_p >= 0))[0]
    assert len(bad) <= 0.01 * len(o)
    # a disagreement is a graze: the nearest float64 candidate is at an edge or at tmax
    all_t, all_p, _, _ = NumpyBackend(tri).closest(o[bad], d[bad], np.full(len(bad), np.inf))
    for k, i in enumerate(bad):
        p = EmbreeBackend(tri).closest(o[i:i + 1], d[i:i + 1], tmax[i:i + 1])[1][0] if occ[i] else ref_p[i]
        p = p if p >= 0 else all_p[k]  # Embree's closest misses too: judge the nearest triangle along the whole ray
        assert p >= 0, f"ray {i}: reported occluded but no triangle lies anywhere along it"
        t, _, _, margin = _exact(tri, o[i:i + 1], d[i:i + 1], np.array([p]))
        near_tmax = abs(all_t[k] - tmax[i]) < T_REL * (1 + tmax[i]) or abs(t[0] - tmax[i]) < T_REL * (1 + tmax[i])
        assert margin[0] < EDGE or near_tmax, f"ray {i}"


def test_empty_scene():
    tri = np.zeros((0, 3, 3))
    o, d, tmax = _rays(10, 3)
    for be in (EmbreeBackend(tri), NumpyBackend(tri)):
        t, p, _, _ = be.closest(o, d, tmax)
        assert np.all(p == -1) and np.all(np.isinf(t))
    assert not EmbreeBackend(tri).occluded(o, d, tmax).any()


def test_trace_with_ignore_matches_numpy():
    """Accel.trace (skip an instance, report self-occlusion) gives the same answers on both backends."""
    tri, tri_inst = _scene()
    o, d, tmax = _rays(2000, 4)
    ignore = np.random.default_rng(5).integers(-1, 3, len(o))
    a_e = Accel(tri, tri_inst, backend="embree")
    a_n = Accel(tri, tri_inst, backend="numpy")
    h_e, h_n = a_e.trace(o, d, tmax, ignore), a_n.trace(o, d, tmax, ignore)
    same = (h_e.prim == h_n.prim) & (h_e.self_hit == h_n.self_hit)
    assert same.mean() > 0.99
    assert h_e.self_hit.any() and (h_e.prim >= 0).any()
    both = same & (h_n.prim >= 0)
    np.testing.assert_allclose(h_e.t[both], h_n.t[both], rtol=T_REL, atol=T_REL)
    assert not np.any(tri_inst[h_e.prim[h_e.prim >= 0]] == ignore[h_e.prim >= 0])  # never reports the ignored instance
    h0 = a_e.trace(o, d, tmax)  # without ignore: plain closest hits
    np.testing.assert_array_equal(h0.prim, EmbreeBackend(tri).closest(o, d, tmax)[1])
    assert not h0.self_hit.any()


# -- queries whose cost does not grow with the asset triangles a ray crosses ----------------------------------
def _brute_trace(tri, tri_inst, o, d, tmax, ignore, exempt=None, chunk=1 << 21):
    """float64 brute force of Accel.trace's contract: (t, prim, self_hit, crossed) where crossed counts the
    ignored instance's triangles along the whole ray (how much of the asset the ray passes through)."""
    n, m = len(o), len(tri)
    p0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    t_out, p_out = np.full(n, np.inf), np.full(n, -1, np.int64)
    self_out, crossed = np.zeros(n, bool), np.zeros(n, np.int64)
    step = max(1, chunk // m)
    for s in range(0, n, step):
        sl = slice(s, s + step)
        dd, tv = d[sl, None, :], o[sl, None, :] - p0[None]
        pv = np.cross(dd, e2[None])
        det = np.einsum("rmk,mk->rm", pv, e1)
        inv = 1.0 / np.where(det == 0, np.inf, det)
        u = np.einsum("rmk,rmk->rm", tv, pv) * inv
        qv = np.cross(tv, e1[None])
        v = np.einsum("rmk,rmk->rm", dd, qv) * inv
        t = np.einsum("rmk,mk->rm", qv, e2) * inv
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        own = tri_inst[None, :] == ignore[sl, None]
        t_other = np.where(hit & ~own & (t <= tmax[sl, None]), t, np.inf)
        k = np.argmin(t_other, 1)
        tb = t_other[np.arange(len(k)), k]
        t_out[sl], p_out[sl] = tb, np.where(np.isfinite(tb), k, -1)
        counted = own & hit
        crossed[sl] = counted.sum(1)
        if exempt is not None:
            ids = np.arange(m)[None, :]
            counted &= (ids < exempt[sl, 0:1]) | (ids >= exempt[sl, 1:2])
        self_out[sl] = (counted & (t < np.minimum(tmax[sl], tb)[:, None])).any(1)
    return t_out, p_out, self_out, crossed


def _hair_scene():
    """A dense tuft (400 strands x 3 segments as fiber prisms, instance 0) over a floor (instance 1)."""
    from nasset_reference_renderer.shaders.rna_fiber import tessellate
    from nasset_reference_renderer.testscenes import dense_hair_curves

    g = dense_hair_curves(400, 3, seed=2, radius=0.1, length=0.2, width=0.02)
    tubes = tessellate(g.points, g.counts, g.widths)
    floor = np.array([[[-1, -0.5, -1], [1, -0.5, -1], [1, -0.5, 1]], [[-1, -0.5, -1], [1, -0.5, 1], [-1, -0.5, 1]]], float)
    tri = np.concatenate([tubes.points[tubes.faces], floor])
    tri_inst = np.concatenate([np.zeros(len(tubes.faces), np.int64), np.ones(2, np.int64)])
    return tri, tri_inst, tubes


def test_trace_matches_brute_force_on_random_scene():
    """closest hit past the ignored instance and self_hit, against an independent float64 brute force."""
    tri, tri_inst = _scene()
    o, d, tmax = _rays(1500, 8)
    ignore = np.random.default_rng(9).integers(-1, 4, len(o))
    t_b, p_b, s_b, _ = _brute_trace(tri, tri_inst, o, d, tmax, ignore)
    assert s_b.mean() > 0.05 and (p_b >= 0).mean() > 0.3  # both answers well represented
    for backend in ("embree", "numpy"):
        h = Accel(tri, tri_inst, backend=backend).trace(o, d, tmax, ignore)
        same = (h.prim == p_b) & (h.self_hit == s_b)
        assert same.mean() > 0.99, backend
        both = same & (p_b >= 0)
        np.testing.assert_allclose(h.t[both], t_b[both], rtol=T_REL, atol=T_REL)


def _first_fiber_hits(acc, tri_inst, tubes, rng, n=600):
    """Camera-like rays at the tuft of :func:`_hair_scene` and their first fiber hits: (x [M,3], the rays'
    directions [M,3], the hit segments [M]); more than half of the rays hit a fibre."""
    o = rng.normal(0, 0.05, (n, 3)) + [0.0, 0.1, 2.0]
    d = rng.normal(0, 0.03, (n, 3)) + [0.0, 0.0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = acc.trace(o, d)
    m = (h.prim >= 0) & (tri_inst[np.maximum(h.prim, 0)] == 0)
    assert m.mean() > 0.5
    return o[m] + d[m] * h.t[m][:, None], d[m], tubes.tri_seg[h.prim[m]]


def _tuft_meshes(tubes, held):
    """``Accel``'s meshes for :func:`_hair_scene`: the tuft as a triangle soup (None), as shared points and faces,
    or as those in quads (what the renderer gives Embree)."""
    if held == "soup":
        return None
    quads = (tubes.quads, tubes.quad_tri, tubes.quad_corners) if held == "quads" else None
    return [(tubes.points, tubes.faces, quads), None]


@pytest.mark.parametrize("fast,held", [(False, "soup"), (True, "soup"), (True, "quads"), (False, "quads")])
def test_fiber_rays_cost_constant_embree_calls(fast, held):
    """Rays leaving fiber hits (exempt ranges of their segment and neighbours) through a dense tuft: the same
    hits and self_hit flags as brute force, at a fixed number of Embree rays each although they cross many
    fibre triangles; also with the tuft's structure in Embree's non-robust mode (``fast``, as the renderer
    builds fibre assets), and with its triangles held as quads (``held``, as the renderer holds them)."""
    tri, tri_inst, tubes = _hair_scene()
    rng = np.random.default_rng(4)
    acc = Accel(tri, tri_inst, separate=np.array([True, False]), fast=np.array([fast, False]),
                meshes=_tuft_meshes(tubes, held))
    assert [p.backend.robust for p in acc.parts] == [not fast, True]
    assert (acc.parts[0].backend.quads is not None) == (held == "quads")
    x, _, seg = _first_fiber_hits(acc, tri_inst, tubes, rng)  # then random directions from there
    exempt = tubes.exempt[seg].copy()
    exempt[::7] = -1  # rows with nothing exempt (surface rows in a batch of mixed kinds)
    wi = rng.normal(size=(len(x), 3))
    wi[: len(x) // 2, 2] = -np.abs(wi[: len(x) // 2, 2])  # half of them straight through the tuft
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    tmax = np.full(len(x), np.inf)
    ignore = np.zeros(len(x), np.int64)
    t_b, p_b, s_b, crossed = _brute_trace(tri, tri_inst, x, wi, tmax, ignore, exempt)
    assert s_b.mean() > 0.3 and (~s_b).mean() > 0.05 and (p_b >= 0).any()
    heavy = crossed >= 20  # rays crossing at least 10 fibres (20 triangles)
    assert heavy.sum() >= 50
    h = acc.trace(x, wi, tmax, ignore, exempt)
    acc.rays_cast = 0
    acc.trace(x[heavy], wi[heavy], tmax[heavy], ignore[heavy], exempt[heavy])
    assert acc.rays_cast / heavy.sum() <= 3.0  # floor (closest) + tuft (occlusion, exempt steps)
    same = (h.prim == p_b) & (h.self_hit == s_b)
    assert same.mean() > 0.98, np.nonzero(~same)[0][:10]
    # shadow-ray form: limited by tmax, the floor never hit
    tmax2 = np.full(len(x), 0.2)
    _, p_b2, s_b2, _ = _brute_trace(tri, tri_inst, x, wi, tmax2, ignore, exempt)
    h2 = acc.trace(x, wi, tmax2, ignore, exempt)
    assert ((h2.self_hit == s_b2) & (h2.prim == p_b2)).mean() > 0.98


@pytest.mark.parametrize("held", ["soup", "quads"])
def test_fiber_rays_leaving_outward_cost_one_query(held):
    """Rays leaving fiber hits back toward the side the fibre was seen from do not re-hit the triangle they
    start on (the branch test starts at eps from x): one Embree query each, with the brute force's answers."""
    tri, tri_inst, tubes = _hair_scene()
    rng = np.random.default_rng(5)
    acc = Accel(tri, tri_inst, separate=np.array([True, False]), fast=np.array([True, False]),
                meshes=_tuft_meshes(tubes, held))
    x, d, seg = _first_fiber_hits(acc, tri_inst, tubes, rng)
    exempt = tubes.exempt[seg]
    wi = -d + rng.normal(0, 0.2, (len(x), 3))  # back out, spread: some rays cross other fibres of the tuft
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    tmax = np.full(len(x), 0.2)
    ignore = np.zeros(len(x), np.int64)
    _, p_b, s_b, _ = _brute_trace(tri, tri_inst, x, wi, tmax, ignore, exempt)
    assert s_b.any() and (~s_b).mean() > 0.5
    acc.rays_cast = 0
    h = acc.trace(x, wi, tmax, ignore, exempt)
    assert acc.rays_cast <= 1.1 * len(x)  # re-hitting the start triangle would cost a second query for about half
    assert ((h.self_hit == s_b) & (h.prim == p_b)).mean() > 0.98


def test_ignoring_a_merged_instance_is_a_usage_error():
    from nasset_sdk.errors import UsageError

    tri, tri_inst = _scene()
    acc = Accel(tri, tri_inst, separate=np.array([True, False, False, False]))
    o, d, tmax = _rays(4, 5)
    acc.trace(o, d, tmax, np.array([0, -1, 0, -1]))  # instance 0 has its own structure
    with pytest.raises(UsageError, match="acceleration structure"):
        acc.trace(o, d, tmax, np.array([0, 1, -1, -1]))
    with pytest.raises(UsageError, match="acceleration structure"):
        acc.trace(o, d, tmax, np.full(4, 1))  # one value for every ray (the path without searches)


@pytest.mark.parametrize("inst", [-1, 0, 3])
def test_trace_with_one_ignored_value_matches_brute_force(inst):
    """Every ray ignoring the same instance (camera rays: none; one asset's rays) takes a path without searches;
    it must give the brute force's hits and self_hit flags like mixed ignore arrays do."""
    tri, tri_inst = _scene()
    o, d, tmax = _rays(1500, 13)
    ignore = np.full(len(o), inst)
    t_b, p_b, s_b, _ = _brute_trace(tri, tri_inst, o, d, tmax, ignore)
    assert (p_b >= 0).mean() > 0.3 and (inst < 0 or s_b.mean() > 0.02)
    h = Accel(tri, tri_inst).trace(o, d, tmax, ignore)
    same = (h.prim == p_b) & (h.self_hit == s_b)
    assert same.mean() > 0.99
    np.testing.assert_allclose(h.t[same & (p_b >= 0)], t_b[same & (p_b >= 0)], rtol=T_REL, atol=T_REL)


def test_box_test_keeps_every_hit_and_drops_clear_misses():
    """_Part.rows_hitting_box (the per-structure cull before Embree): never drops a ray whose segment hits one of
    the structure's triangles (float64 brute force), also with zero direction components and origins on a box
    face; drops rays that provably miss the box (constructed: parallel to a face outside it, pointing away,
    or stopping short)."""
    from nasset_reference_renderer.accel import _Part, reciprocal

    s = trimesh.creation.box(extents=(1.0, 1.0, 1.0))  # the box [-0.5, 0.5]^3: its triangles span the whole box
    tri = np.asarray(s.vertices[s.faces], np.float64)
    part = _Part(np.arange(len(tri)), tri, 0, NumpyBackend)
    o, d, tmax = _rays(4000, 11)
    rng = np.random.default_rng(12)
    axis = rng.integers(0, 3, len(o))
    flat = rng.random(len(o)) < 0.3  # a zero direction component, some origins exactly on a face plane
    d[flat, axis[flat]] = 0.0
    on_face = flat & (rng.random(len(o)) < 0.5)
    o[on_face, axis[on_face]] = rng.choice([-0.5, 0.5], on_face.sum())
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    rows = np.arange(len(o))
    kept = part.rows_hitting_box(o, reciprocal(d), tmax, rows)
    _, prim, _, _ = NumpyBackend(tri).closest(o, d, tmax)
    assert (prim >= 0).sum() > 500 and len(kept) < len(o)
    assert np.isin(np.nonzero(prim >= 0)[0], kept).all()  # conservative
    sub = rows[::3]  # a subset: the same answers for its rows
    np.testing.assert_array_equal(part.rows_hitting_box(o, reciprocal(d), tmax, sub), np.intersect1d(kept, sub))
    # constructed misses: parallel to the x faces outside the slab; pointing away; stopping short of the box
    o2 = np.array([[0.6, 0.0, -3.0], [0.0, 0.0, 2.0], [0.0, 0.0, 2.0], [0.0, 0.0, 2.0]])
    d2 = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    t2 = np.array([np.inf, np.inf, 1.4, 1.6])
    np.testing.assert_array_equal(part.rows_hitting_box(o2, reciprocal(d2), t2, np.arange(4)), [3])


def test_scale_is_the_scenes_extent():
    """Accel.scale (the ray-offset scale S of spec/renderer.md#ray-offsets): the largest absolute coordinate plus
    the largest edge of the bounding box of all triangles, however the instances are split into structures."""
    rng = np.random.default_rng(3)
    tri = np.concatenate([rng.uniform(-1, 1, (20, 3, 3)), rng.uniform(4, 9, (5, 3, 3)) * [1, -1, 1]])
    tri_inst = np.repeat([0, 1], [20, 5])
    ext = tri.reshape(-1, 3)
    want = np.abs(ext).max() + (ext.max(0) - ext.min(0)).max()
    for sep in (None, [True, False], [False, True], [False, False]):
        acc = Accel(tri, tri_inst, backend="numpy", separate=None if sep is None else np.array(sep))
        assert acc.scale == pytest.approx(want, rel=1e-15)


@pytest.mark.parametrize("fast", [False, True])
def test_shared_vertex_structure_gives_the_same_hits(fast):
    """A fibre instance handed to Embree as shared points and faces (``meshes``, what the renderer does) and as
    a flat triangle soup: the same closest hits, barycentrics, distances and self_hit flags, bit for bit, and
    the same part boxes whether given (``boxes``) or computed."""
    from nasset_reference_renderer.sampling import box3

    tri, tri_inst, tubes = _hair_scene()
    sep, quick = np.array([True, False]), np.array([fast, False])
    boxes = [box3(tri[tri_inst == i].reshape(-1, 3)) for i in (0, 1)]
    flat = Accel(tri, tri_inst, separate=sep, fast=quick)
    shared = Accel(tri, tri_inst, separate=sep, fast=quick, boxes=boxes, meshes=[(tubes.points, tubes.faces), None])
    for a, b in zip(flat.parts, shared.parts, strict=True):
        np.testing.assert_array_equal(a.lo, b.lo)
        np.testing.assert_array_equal(a.hi, b.hi)
    assert shared.scale == flat.scale
    rng = np.random.default_rng(5)
    x, _, seg = _first_fiber_hits(flat, tri_inst, tubes, rng)
    wi = rng.normal(size=(len(x), 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    o = rng.normal(0, 0.05, (600, 3)) + [0.0, 0.1, 2.0]  # camera-like rays: closest hits on the tuft itself
    d = rng.normal(0, 0.03, (600, 3)) + [0.0, 0.0, -1.0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    leaving = (x, wi, np.full(len(x), np.inf), np.zeros(len(x), np.int64), tubes.exempt[seg])  # branch tests
    for args in ((o, d), leaving):
        h1, h2 = flat.trace(*args), shared.trace(*args)
        for k in ("prim", "t", "u", "v", "self_hit"):
            np.testing.assert_array_equal(getattr(h1, k), getattr(h2, k), err_msg=k)
    assert (tri_inst[flat.trace(o, d).prim] == 0).mean() > 0.5 and 0.1 < h1.self_hit.mean() < 0.9


def test_branch_query_alone_and_self_rows():
    """``passes_own`` (the rna branch test of the near-field fetch, spec/kinds/rna.md#near-field-fetch) answers
    whether a ray meets its instance's own triangles outside the exempt range, other objects not considered: where
    the floor is not in the way it is ``trace``'s self_hit. ``trace`` with
    ``self_rows`` leaves self_hit False elsewhere, computes the same flags on those rows, and casts no ray on the
    instance's structure for the others."""
    tri, tri_inst, tubes = _hair_scene()
    rng = np.random.default_rng(6)
    acc = Accel(tri, tri_inst, separate=np.array([True, False]), fast=np.array([True, False]))
    x, _, seg = _first_fiber_hits(acc, tri_inst, tubes, rng)
    exempt = tubes.exempt[seg].copy()
    exempt[::5] = -1
    wi = rng.normal(size=(len(x), 3))
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    tmax = np.full(len(x), np.inf)
    ignore = np.zeros(len(x), np.int64)
    h = acc.trace(x, wi, tmax, ignore, exempt)
    own = acc.passes_own(x, wi, tmax, ignore, exempt)
    assert h.self_hit.any() and (h.prim >= 0).any()
    assert np.array_equal(own[h.prim < 0], h.self_hit[h.prim < 0])
    assert (own >= h.self_hit).all()
    rows = rng.random(len(x)) < 0.5
    acc.rays_cast = 0
    hr = acc.trace(x, wi, tmax, ignore, exempt, rows)
    partial = acc.rays_cast
    acc.rays_cast = 0
    acc.trace(x, wi, tmax, ignore, exempt)
    assert np.array_equal(hr.self_hit[rows], h.self_hit[rows]) and not hr.self_hit[~rows].any()
    assert np.array_equal(hr.prim, h.prim) and partial < acc.rays_cast
    assert not acc.passes_own(x, wi, tmax, np.full(len(x), -1), None).any()  # no instance: nothing to meet
