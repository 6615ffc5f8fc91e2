"""Plain ``BasisCurves`` and ``Points`` prims as triangles (spec/renderer.md#curves-and-points), in the prim's space:
the rules every renderer of this project reads them by (:func:`curves_or_points_mesh`).

Curves become closed prisms around the segments of their polylines (the tessellation of fiber assets, which each
renderer passes in as ``tessellate``; ``TUBE_SIDES`` sides), radius ``width / 2``; cubic curves (``bezier``,
``bspline``, ``catmullRom``; ``nonperiodic``, ``periodic`` or ``pinned``) are first evaluated at
:data:`SAMPLES_PER_SEGMENT` points per segment. Points become spheres of diameter ``width`` (an icosphere of 80
triangles). Corner normals are the tube's radial directions (its axis on the caps) and the spheres' radial ones.
"""

from __future__ import annotations

import numpy as np

from .errors import SceneError

#: sides of a tube's prisms (the fiber tessellation's, spec/renderer.md#fibers)
TUBE_SIDES = 8
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


def linear_segments(counts) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The segments (i, i + 1) inside linear curves of ``counts`` [C] points, in curve order: (first point of each
    segment [S], its curve [S], first segment of each curve [C+1]) (S = sum(max(counts - 1, 0)))."""
    c = np.asarray(counts, np.int64)
    n_seg = np.maximum(c - 1, 0)
    curve = np.repeat(np.arange(len(c)), n_seg)
    seg_first = np.concatenate([[0], np.cumsum(n_seg)])
    starts = np.cumsum(c) - c
    return np.arange(len(curve)) - seg_first[curve] + starts[curve], curve, seg_first


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


def tube_mesh(points, counts, widths, tessellate) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points [V,3], faces [F,3] wound outward, unit corner normals [F,3,3]) of prisms around the polylines.
    ``tessellate(points, counts, widths)``: the renderer's fiber tessellation (``TUBE_SIDES`` sides) as (vertices [V,3],
    faces [F,3], segment of each face [F], segment starts [S,3], segment ends [S,3])."""
    verts, tri_faces, seg, p0, p1 = tessellate(points, counts, widths)
    n = TUBE_SIDES
    local = np.arange(len(tri_faces)) % TUBE_TRIANGLES  # the face's place in its segment: 2n sides, then two caps
    axis = p1 - p0
    axis = axis / np.maximum(np.linalg.norm(axis, axis=1, keepdims=True), 1e-300)
    centre = np.where((tri_faces % (2 * n) < n)[..., None], p0[seg][:, None], p1[seg][:, None])  # [F,3,3]
    radial = verts[tri_faces] - centre
    radial = radial - (radial * axis[seg][:, None]).sum(-1, keepdims=True) * axis[seg][:, None]
    radial = radial / np.maximum(np.linalg.norm(radial, axis=-1, keepdims=True), 1e-300)
    cap0, cap1 = (local >= 2 * n) & (local < 3 * n - 2), local >= 3 * n - 2
    normals = np.where(cap0[:, None, None], -axis[seg][:, None], np.where(cap1[:, None, None], axis[seg][:, None], radial))
    return verts, tri_faces, normals


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


def curves_or_points_mesh(prim, tname: str, time, tessellate, warn, max_triangles: int):
    """(points [V,3] in the prim's space, faces [F,3] wound outward, unit corner normals [F,3,3]) of a ``BasisCurves``
    (``tname``) or ``Points`` prim by spec/renderer.md#curves-and-points, or None (warned) when it has no points or
    no triangles. ``tessellate``: see :func:`tube_mesh`; ``warn(message)``. SceneError naming the prim and attribute:
    SCENE_INVALID for counts that do not fit, non-finite points or widths, negative widths, more than ``max_triangles``
    triangles; SCENE_UNSUPPORTED for another type, basis or wrap."""
    from pxr import UsdGeom

    where = str(prim.GetPath())

    def fail(code, message, attribute):
        return SceneError(code, message, file=prim.GetStage().GetRootLayer().identifier, prim=where, attribute=attribute)

    geom = UsdGeom.BasisCurves(prim) if tname == "BasisCurves" else UsdGeom.Points(prim)
    pts = np.asarray(geom.GetPointsAttr().Get(time) or [], np.float64).reshape(-1, 3)
    counts = (np.asarray(geom.GetCurveVertexCountsAttr().Get(time) or [], np.int64)
              if tname == "BasisCurves" else np.ones(len(pts), np.int64))
    wv = geom.GetWidthsAttr().Get(time)
    wv = None if wv is None else np.asarray(wv, np.float64).ravel()
    if not len(pts) or not len(counts):
        warn(f"{tname} without points skipped")
        return None
    if not np.isfinite(pts).all() or (counts < 1).any() or counts.sum() != len(pts):
        raise fail("SCENE_INVALID", f"{tname} points and curveVertexCounts do not match (or are not finite)",
                   "curveVertexCounts" if tname == "BasisCurves" else "points")
    interp = geom.GetWidthsInterpolation()
    if wv is None or not len(wv):
        warn(f"{tname} without widths: width 1 (scene units)")
        widths = np.ones(len(pts))
    elif interp == "constant" and len(wv) == 1:
        widths = np.full(len(pts), wv[0])
    elif interp == "uniform" and len(wv) == len(counts):
        widths = np.repeat(wv, counts)
    elif len(wv) == len(pts):  # vertex (or varying of linear curves and points)
        widths = wv
    else:
        warn(f"{tname} widths ({interp}, {len(wv)} values) read as their mean")
        widths = np.full(len(pts), float(np.mean(wv)))
    if not (np.isfinite(widths).all() and (widths >= 0).all() and widths.max() <= 1e12):
        raise fail("SCENE_INVALID", "widths must be finite and >= 0", "widths")
    if tname == "Points":
        if len(pts) * SPHERE_TRIANGLES > max_triangles:
            raise fail("SCENE_INVALID", f"{len(pts)} points: their spheres would exceed {max_triangles} triangles", "points")
        local, faces, nrm = sphere_mesh(pts, widths)
    else:
        kind = str(geom.GetTypeAttr().Get(time) or "cubic")
        basis = str(geom.GetBasisAttr().Get(time) or "bezier")
        wrap = str(geom.GetWrapAttr().Get(time) or "nonperiodic")
        if kind not in ("linear", "cubic") or basis not in BASES or wrap not in ("nonperiodic", "periodic", "pinned"):
            raise fail("SCENE_UNSUPPORTED", f"BasisCurves type {kind!r}, basis {basis!r}, wrap {wrap!r}", "basis")
        if segment_count(counts, kind, basis, wrap) * TUBE_TRIANGLES > max_triangles:  # >= the exact count
            raise fail("SCENE_INVALID", f"{len(counts)} curves: their tubes would exceed {max_triangles} triangles",
                       "curveVertexCounts")
        try:
            p, c, w = polylines(pts, counts, widths, kind, basis, wrap)
        except CurveError as exc:
            raise fail("SCENE_INVALID", f"curveVertexCounts do not fit: {exc}", "curveVertexCounts") from None
        local, faces, nrm = tube_mesh(p, c, w, tessellate)
    if not len(faces):
        warn(f"{tname} of zero width or length skipped")
        return None
    return local, faces, nrm
