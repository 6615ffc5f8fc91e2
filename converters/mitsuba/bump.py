"""Mitsuba's ``bumpmap`` written as the tangent-space normal map it amounts to on one shape.

UsdPreviewSurface has no bump input. Mitsuba's bump map perturbs the shading frame with the height texture's gradient
``(hu, hv)`` (``scale`` times its derivatives in the shape's uv, ``to_uv`` included): the normal becomes
``cross(dP/du + hu n, dP/dv + hv n)``, flipped to the geometric normal's side. With ``dP/du`` and ``dP/dv`` projected
onto the tangent plane, ``s = dP/du / |dP/du|``, ``t = n x s`` (the frame of Mitsuba's ``normalmap`` and of
spec/renderer.md#normal-maps), ``dP/dv = a s + b t``, that normal in (s, t, n) is

    normalize(-hu / |dP/du|,  hu a / (|dP/du| b) - hv / b,  1)

so a normal map reproduces it once the shape's ``K = (-1 / |dP/du|, a / (|dP/du| b), -1 / b)`` is known at each texel.
:func:`uv_metric` reads K off the shape's triangles in uv space (one value where the layout is uniform, the nearest
triangle's per texel where it is not: a sphere's rows); :func:`bump_normal_texels` evaluates Mitsuba's own gradient
(``eval_1_grad``: filter, wrap and ``to_uv`` as Mitsuba applies them), averaged over four points per texel, at twice
the height's resolution where that fits (:func:`normal_map_size`: a bilinear height's gradient steps at its texel
centres).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: relative spread (10th to 90th percentile, area-weighted) of K below which a shape's uv layout counts as uniform
UNIFORM_SPREAD = 0.02


@dataclass
class UvMetric:
    """How a height gradient in uv turns into a tangent-space normal on one shape.

    ``k`` [3]: K where the layout is uniform; else ``centroids`` [F, 2] (the triangles' centres in the shape's uv) and
    ``per_triangle`` [F, 3] give each texel the K of its nearest triangle. ``key``: equal keys give equal normal maps."""

    k: np.ndarray | None
    centroids: np.ndarray | None
    per_triangle: np.ndarray | None
    key: tuple

    def at(self, tex_uv: np.ndarray, to_uv: np.ndarray | None = None) -> np.ndarray:
        """K [N, 3] at points [N, 2] in the unit square of a texture's space (``to_uv`` [3, 3]: the texture's uv
        transform; the triangles are looked up there, modulo 1)."""
        if self.k is not None:
            return np.broadcast_to(self.k, (len(tex_uv), 3))
        from scipy.spatial import cKDTree

        c = self.centroids
        if to_uv is not None:
            c = c @ np.asarray(to_uv, np.float64)[:2, :2].T + np.asarray(to_uv, np.float64)[:2, 2]
        tree = cKDTree(np.mod(c, 1.0), boxsize=1.0 + 1e-12)  # periodic: a repeating texture's seams
        return self.per_triangle[tree.query(np.mod(tex_uv, 1.0))[1]]


def triangle_metric(pts: np.ndarray, faces: np.ndarray, uv: np.ndarray, normals: np.ndarray | None = None):
    """Per-triangle ``(K [F, 3], world area [F], usable [F])`` of a mesh: ``pts`` [V, 3] world space, ``faces`` [F, 3],
    ``uv`` [V, 2] Mitsuba's (v down the image), ``normals`` [V, 3] the vertex normals (they pick n's side, as
    Mitsuba's shading frame does). Degenerate triangles, and those whose uv span wraps round (a seam closed by
    index, whose uv area is far above its share), are not usable."""
    p0, p1, p2 = (pts[faces[:, k]] for k in range(3))
    t0, t1, t2 = (uv[faces[:, k]] for k in range(3))
    dp1, dp2, du1, du2 = p1 - p0, p2 - p0, t1 - t0, t2 - t0
    det = du1[:, 0] * du2[:, 1] - du1[:, 1] * du2[:, 0]
    cross = np.cross(dp1, dp2)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    ok = (np.abs(det) > 1e-12) & (area > 0.0)
    safe = np.where(ok, det, 1.0)[:, None]
    dpdu = (du2[:, 1:2] * dp1 - du1[:, 1:2] * dp2) / safe
    dpdv = (-du2[:, 0:1] * dp1 + du1[:, 0:1] * dp2) / safe
    n = cross / np.maximum(2.0 * area, 1e-300)[:, None]
    if normals is not None:
        side = np.einsum("ij,ij->i", n, normals[faces].sum(1))
        n = np.where((side < 0.0)[:, None], -n, n)
    du = dpdu - n * np.einsum("ij,ij->i", n, dpdu)[:, None]
    dv = dpdv - n * np.einsum("ij,ij->i", n, dpdv)[:, None]
    lu = np.linalg.norm(du, axis=1)
    s = du / np.maximum(lu, 1e-300)[:, None]
    t = np.cross(n, s)
    a, b = np.einsum("ij,ij->i", dv, s), np.einsum("ij,ij->i", dv, t)
    ok &= (lu > 1e-12) & (np.abs(b) > 1e-12)
    uv_area = 0.5 * np.abs(det)
    density = np.where(ok, area / np.where(ok, uv_area, 1.0), 0.0)
    if ok.any():  # a triangle spanning a seam covers far more uv than its world area's share
        ok &= density > 0.2 * np.median(density[ok])
    lu_s, b_s = np.where(ok, lu, 1.0), np.where(ok, b, 1.0)
    k = np.stack([-1.0 / lu_s, a / (lu_s * b_s), -1.0 / b_s], 1)
    return k, area, ok


def uv_metric(pts, faces, uv, normals=None) -> UvMetric | None:
    """The shape's :class:`UvMetric` (None when no triangle has a usable uv layout)."""
    k, area, ok = triangle_metric(np.asarray(pts, np.float64), np.asarray(faces, np.int64), np.asarray(uv, np.float64),
                                  None if normals is None else np.asarray(normals, np.float64))
    if not ok.any():
        return None
    k, area = k[ok], area[ok]
    order = np.argsort(k, axis=0)
    med, lo, hi = (np.array([_weighted_quantile(k[:, c], area, q, order[:, c]) for c in range(3)]) for q in (0.5, 0.1, 0.9))
    scale = np.abs(med).max()
    if np.abs(hi - lo).max() <= UNIFORM_SPREAD * scale:
        return UvMetric(med, None, None, ("uniform", *np.round(med / scale, 4), float(f"{scale:.4g}")))
    tri_uv = np.asarray(uv, np.float64)[np.asarray(faces, np.int64)[ok]].mean(1)
    key = ("per-triangle", len(k), float(f"{k.sum():.6g}"), float(f"{tri_uv.sum():.6g}"))
    return UvMetric(None, tri_uv, k, key)


def _weighted_quantile(x: np.ndarray, w: np.ndarray, q: float, order: np.ndarray) -> float:
    cw = np.cumsum(w[order])
    return float(x[order][min(np.searchsorted(cw, q * cw[-1]), len(x) - 1)])


#: points per call of Mitsuba's gradient (bounds the memory of one evaluation)
GRAD_CHUNK = 1 << 20


def normal_map_size(shape_hw: tuple[int, int], max_pixels: int) -> tuple[int, int]:
    """The normal map's resolution for a height of ``shape_hw``: twice it where that fits in ``max_pixels`` texels
    (each texel then lies inside one of the height's bilinear cells, where the gradient is what Mitsuba computes; at
    the same resolution a texel centre sits on the step between two cells and takes their mean: steep bumps lose
    contrast, measured 4-5x the squared error against Mitsuba's bump map on a sinusoidal height), else the largest
    size of the height's aspect within ``max_pixels`` (a larger height is resampled)."""
    h, w = int(shape_hw[0]), int(shape_hw[1])
    f = 2.0 if 4 * h * w <= max_pixels else min(1.0, float(np.sqrt(max_pixels / max(h * w, 1))))
    return max(1, int(h * f)), max(1, int(w * f))


def bump_normal_texels(mi, texture, out_hw: tuple[int, int], scale: float, metric: UvMetric,
                       to_uv: np.ndarray | None) -> np.ndarray:
    """Tangent-space normals [H, W, 3] (``out_hw``, :func:`normal_map_size`) encoded as ``(n + 1) / 2`` of a bump map
    with height ``texture`` (a Mitsuba texture; its gradient is evaluated by Mitsuba) times ``scale`` on a shape of uv
    ``metric``; the normal map covers the height's texture space (and takes its ``to_uv``)."""
    h, w = int(out_hw[0]), int(out_hw[1])
    y, x = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
    centres = np.stack([x.ravel(), y.ravel()], 1)
    inv = np.linalg.inv(np.asarray(to_uv, np.float64)) if to_uv is not None else np.eye(3)
    grad = np.zeros((len(centres), 2))
    for ox, oy in ((-0.25, -0.25), (0.25, -0.25), (-0.25, 0.25), (0.25, 0.25)):  # either side of the texel centre
        tex_pts = centres + [ox / w, oy / h]
        grad += _eval_grad(mi, texture, tex_pts @ inv[:2, :2].T + inv[:2, 2])
    grad *= 0.25 * float(scale)
    k = metric.at(centres, to_uv)
    n = np.stack([k[:, 0] * grad[:, 0], k[:, 1] * grad[:, 0] + k[:, 2] * grad[:, 1], np.ones(len(grad))], 1)
    n = np.nan_to_num(n, nan=0.0, posinf=0.0, neginf=0.0)
    n[:, 2] = 1.0
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return (0.5 * (n + 1.0)).reshape(h, w, 3)


def _eval_grad(mi, texture, uv: np.ndarray) -> np.ndarray:
    """Mitsuba's ``eval_1_grad`` [N, 2] of ``texture`` at shape uv points [N, 2] (in chunks of :data:`GRAD_CHUNK`)."""
    if len(uv) > GRAD_CHUNK:
        return np.concatenate([_eval_grad(mi, texture, uv[k:k + GRAD_CHUNK]) for k in range(0, len(uv), GRAD_CHUNK)])
    si = mi.SurfaceInteraction3f()
    if mi.variant().startswith("scalar"):
        out = []
        for u, v in uv:
            si.uv = mi.Point2f(float(u), float(v))
            g = texture.eval_1_grad(si)
            out.append((float(g[0]), float(g[1])))
        return np.array(out, np.float64)
    si.uv = mi.Point2f(*np.ascontiguousarray(uv.T, np.float32))
    g = texture.eval_1_grad(si)
    return np.stack([np.asarray(g[0], np.float64).ravel(), np.asarray(g[1], np.float64).ravel()], 1)
