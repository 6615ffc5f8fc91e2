"""Plain ``BasisCurves`` and ``Points`` prims as triangles (spec/renderer.md#curves-and-points), in the prim's space.

Curves become closed prisms around the segments of their polylines (the tessellation of fiber assets,
:func:`shaders.rna_fiber.tessellate`, ``TUBE_SIDES`` sides), radius ``width / 2``; cubic curves (``bezier``,
``bspline``, ``catmullRom``; ``nonperiodic``, ``periodic`` or ``pinned``) are first evaluated at
:data:`SAMPLES_PER_SEGMENT` points per segment. Points become spheres of diameter ``width`` (an icosphere of 80
triangles). Corner normals are the tube's radial directions (its axis on the caps) and the spheres' radial ones.
"""

from __future__ import annotations

import numpy as np

from .shaders.rna_fiber import TUBE_SIDES, tessellate

#: triangles of one segment's prism (the sides' 2 x TUBE_SIDES, two capping fans of TUBE_SIDES - 2) and of one point's
#: sphere (an icosphere subdivided once)
TUBE_TRIANGLES = 4 * TUBE_SIDES - 4
SPHERE_TRIANGLES = 80
#: evaluation points per cubic segment (its end shared with the next one)
SAMPLES_PER_SEGMENT = 4
#: cubic bases, row-vector form p(t) = [t^3, t^2, t, 1] @ M @ [P0, P1, P2, P3], and their vstep
BASES = {
    "bezier": (np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 3, 0, 0], [1, 0, 0, 0]], np.float64), 3),
    "bspline": (np.array([[-1, 3, -3, 1], [3, -6, 3, 0], [-3, 0, 3, 0], [1, 4, 1, 0]], np.float64) / 6.0, 1),
    "catmullRom": (np.array([[-1, 3, -3, 1], [2, -5, 4, -1], [-1, 0, 1, 0], [0, 2, 0, 0]], np.float64) / 2.0, 1),
}


class CurveError(ValueError):
    """Curves whose vertex counts do not fit their type, basis and wrap (the caller names the prim)."""


def _curve_cvs(p: np.ndarray, w: np.ndarray, basis: str, wrap: str) -> tuple[np.ndarray, np.ndarray, list]:
    """One cubic curve's control points [n,3], widths [n] -> (cvs, widths, segment start indices) after the wrap
    (periodic: the first vstep-aligned points appended; pinned bspline / catmullRom: mirrored end points)."""
    _, step = BASES[basis]
    if wrap == "periodic":
        extra = 3 if step == 1 else 1
        p, w = np.concatenate([p, p[:extra]]), np.concatenate([w, w[:extra]])
        n_seg = (len(p) - 4) // step + 1
    else:
        if wrap == "pinned" and basis != "bezier":
            p = np.concatenate([2 * p[:1] - p[1:2], p, 2 * p[-1:] - p[-2:-1]])
            w = np.concatenate([w[:1], w, w[-1:]])
        if len(p) < 4 or (len(p) - 4) % step:
            raise CurveError(f"a {basis} curve of {len(p)} vertices ({wrap})")
        n_seg = (len(p) - 4) // step + 1
    return p, w, [k * step for k in range(n_seg)]


def segment_count(counts, curve_type: str = "linear", basis: str = "bezier", wrap: str = "nonperiodic") -> int:
    """Segments of the polylines :func:`polylines` makes of curves with vertex ``counts`` (an upper bound for cubic
    curves whose counts do not fit), from the counts alone: a budget check before any evaluation."""
    c = np.asarray(counts, np.int64)
    if curve_type == "linear":
        return int(np.maximum(c - 1 + (wrap == "periodic"), 0).sum())
    step = BASES[basis][1] if basis in BASES else 1
    return int((np.maximum(c // step + 3, 0) * SAMPLES_PER_SEGMENT).sum())


def polylines(points, counts, widths, curve_type: str = "linear", basis: str = "bezier", wrap: str = "nonperiodic"):
    """(points [M,3], counts [C'], widths [M]) of linear polylines through the curves (``widths`` per vertex);
    a periodic linear curve is closed by repeating its first vertex."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    w = np.asarray(widths, np.float64).ravel()
    counts = np.asarray(counts, np.int64)
    if curve_type == "linear" and wrap != "periodic":  # the polylines are the curves (no loop over them)
        if (counts < 2).any():
            raise CurveError(f"a linear curve of {int(counts.min())} vertex")
        return p, counts, np.maximum(w, 0.0)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    out_p, out_c, out_w = [], [], []
    ts = np.linspace(0.0, 1.0, SAMPLES_PER_SEGMENT + 1)
    T = np.stack([ts ** 3, ts ** 2, ts, np.ones_like(ts)], 1)  # [K, 4]
    for s, n in zip(starts, counts, strict=True):
        cp, cw = p[s:s + n], w[s:s + n]
        if curve_type == "linear":
            if wrap == "periodic" and n > 2:
                cp, cw = np.concatenate([cp, cp[:1]]), np.concatenate([cw, cw[:1]])
            if len(cp) < 2:
                raise CurveError(f"a linear curve of {n} vertex")
            out_p.append(cp), out_w.append(cw), out_c.append(len(cp))
            continue
        M, _ = BASES[basis]
        cvs, cw, seg = _curve_cvs(cp, cw, basis, wrap)
        pts, wid = [], []
        for k, i in enumerate(seg):
            B = T @ M  # [K, 4] weights of the segment's four control points
            rows = slice(0, None) if k == 0 else slice(1, None)  # a segment's start is the previous one's end
            pts.append((B @ cvs[i:i + 4])[rows])
            wid.append((B @ cw[i:i + 4])[rows])
        cp, cw = np.concatenate(pts), np.concatenate(wid)
        out_p.append(cp), out_w.append(cw), out_c.append(len(cp))
    if not out_p:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0)
    return np.concatenate(out_p), np.asarray(out_c, np.int64), np.maximum(np.concatenate(out_w), 0.0)


def tube_mesh(points, counts, widths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points [V,3], faces [F,3] wound outward, unit corner normals [F,3,3]) of prisms around the polylines."""
    tubes = tessellate(points, counts, widths, TUBE_SIDES)
    n = TUBE_SIDES
    seg = tubes.tri_seg
    local = np.arange(len(tubes.faces)) % TUBE_TRIANGLES  # the face's place in its segment: 2n sides, then two caps
    axis = tubes.p1 - tubes.p0
    axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
    centre = np.where((tubes.faces % (2 * n) < n)[..., None], tubes.p0[seg][:, None], tubes.p1[seg][:, None])  # [F,3,3]
    radial = tubes.points[tubes.faces] - centre
    radial = radial - (radial * axis[seg][:, None]).sum(-1, keepdims=True) * axis[seg][:, None]
    radial = radial / np.maximum(np.linalg.norm(radial, axis=-1, keepdims=True), 1e-300)
    cap0, cap1 = (local >= 2 * n) & (local < 3 * n - 2), local >= 3 * n - 2
    normals = np.where(cap0[:, None, None], -axis[seg][:, None], np.where(cap1[:, None, None], axis[seg][:, None], radial))
    return tubes.points, tubes.faces, normals


def sphere_mesh(points, widths) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points [V,3], faces [F,3] wound outward, unit corner normals [F,3,3]) of spheres of diameter ``widths`` [P]
    at ``points`` [P,3] (80-triangle icospheres)."""
    import trimesh

    ico = trimesh.creation.icosphere(subdivisions=1, radius=1.0)
    unit, tri = np.asarray(ico.vertices, np.float64), np.asarray(ico.faces, np.int64)
    assert len(tri) == SPHERE_TRIANGLES
    p = np.asarray(points, np.float64).reshape(-1, 3)
    r = 0.5 * np.asarray(widths, np.float64).ravel()
    verts = (p[:, None] + r[:, None, None] * unit[None]).reshape(-1, 3)
    faces = (np.arange(len(p))[:, None, None] * len(unit) + tri[None]).reshape(-1, 3)
    normals = np.broadcast_to(unit[tri][None], (len(p), len(tri), 3, 3)).reshape(-1, 3, 3)
    return verts, faces, normals
