"""Which side of a converted Mitsuba shape is its front (spec/bake.md#scene-conversion, spec/renderer.md#sidedness).

Mitsuba shades and emits on the side of a shape's shading normal: the interpolated vertex normals (transformed
by ``to_world``) or the face normal, turned over by ``flip_normals``; a mirroring ``to_world`` turns an analytic
shape's normal over too. USD's front is the right-hand side of the winding (the left-hand side for a prim
whose transform mirrors). Only a one-sided surface, a surface with a back material and an emitter show the
difference. A loaded shape does not say whether ``flip_normals`` was set, so the sign is read off the shape:
Mitsuba's normal at one sampled surface position against the normal the geometry gives there.
"""

from __future__ import annotations

import numpy as np

from nasset_reference_renderer.sampling import cross3


def sampled_normal(mi, shape) -> tuple[np.ndarray, np.ndarray]:
    """(position [3], unit normal [3]) of one surface position Mitsuba samples on ``shape`` (world space; the
    normal as Mitsuba shades and emits with it, ``flip_normals`` included)."""
    ps = shape.sample_position(0.0, mi.Point2f(0.37, 0.61))
    p = np.asarray(ps.p, np.float64).reshape(3, -1)[:, 0]
    n = np.asarray(ps.n, np.float64).reshape(3, -1)[:, 0]
    return p, n / max(float(np.linalg.norm(n)), 1e-300)


def front_sign(mi, shape, pts: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None) -> float:
    """-1 when Mitsuba's normal at a sampled position of ``shape`` is the opposite of the geometry's own normal
    there, else +1. The geometry: world points ``pts`` [V, 3], triangles ``faces`` [F, 3] and unit vertex normals
    ``normals`` [V, 3] (interpolated), or the face normal where there are none."""
    pts, faces = np.asarray(pts, np.float64), np.asarray(faces, np.int64).reshape(-1, 3)
    if not len(faces):
        return 1.0
    p, n = sampled_normal(mi, shape)
    t = pts[faces]
    e1, e2, v = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0], p - t[:, 0]
    d00, d01, d11 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    d20, d21 = (v * e1).sum(1), (v * e2).sum(1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-30 * np.maximum(d00 * d11, 1e-300)
    den = np.where(ok, den, 1.0)
    b1, b2 = (d11 * d20 - d01 * d21) / den, (d00 * d21 - d01 * d20) / den
    b = np.stack([1.0 - b1 - b2, b1, b2], 1)
    cr = cross3(e1, e2)
    area2 = np.maximum(np.linalg.norm(cr, axis=1), 1e-300)
    off_plane = np.abs((v * cr).sum(1)) / area2
    outside = np.maximum(-b.min(1), 0.0) * np.sqrt(area2)
    score = np.where(ok, off_plane + outside, np.inf)
    k = int(np.argmin(score))
    if not np.isfinite(score[k]):
        return 1.0
    own = cr[k] if normals is None else (b[k, :, None] * np.asarray(normals, np.float64)[faces[k]]).sum(0)
    return -1.0 if float(own @ n) < 0.0 else 1.0


def faces_facing_as_mitsuba(mi, shape, pts: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None, *,
                            mirrored: bool = False) -> np.ndarray:
    """``faces`` [F, k] (convex polygons of k corners) with the winding of each face turned where needed so that
    its USD front is Mitsuba's front (:func:`turned_faces`)."""
    faces = np.asarray(faces, np.int64)
    turn = turned_faces(mi, shape, pts, faces, normals, mirrored=mirrored)
    out = faces.copy()
    out[turn] = out[turn][:, ::-1]
    return out


def turned_faces(mi, shape, pts: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None, *,
                 mirrored: bool = False) -> np.ndarray:
    """Which of ``faces`` [F, k] (convex polygons of k corners) must have their winding reversed ([F] bool) so that
    their USD front is Mitsuba's front: the side of the vertex normals summed over the face's corners (of the face
    normal without ``normals``), times :func:`front_sign`. ``pts`` [V, 3] and ``normals`` [V, 3] are in world space;
    ``mirrored``: the prim is written with a transform of negative determinant (its USD front is the left-hand side
    of the world winding)."""
    pts, faces = np.asarray(pts, np.float64), np.asarray(faces, np.int64)
    fan = np.concatenate([faces[:, [0, j, j + 1]] for j in range(1, faces.shape[1] - 1)])
    t = pts[faces]
    cr = cross3(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    mitsuba = cr if normals is None else np.asarray(normals, np.float64)[faces].sum(1)
    mitsuba = mitsuba * front_sign(mi, shape, pts, fan, normals)
    usd = -cr if mirrored else cr
    return (mitsuba * usd).sum(1) < 0.0
