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
    np.testing.assert_array_equal(h0.prim, a_e.backend.closest(o, d, tmax)[1])
    assert not h0.self_hit.any()
