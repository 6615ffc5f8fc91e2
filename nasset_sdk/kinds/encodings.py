"""Input encodings shared by the kinds, in numpy (spec/kinds/encodings.md).

All functions are vectorised over a leading batch axis N and return float32.
"""

from __future__ import annotations

import numpy as np


def to_unit_box(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Map object-space points [N,3] to the encoding box: 2 (x - lo) / (hi - lo) - 1, in [-1, 1]^3 inside."""
    lo = np.asarray(lo, np.float64)
    span = np.maximum(np.asarray(hi, np.float64) - lo, 1e-30)
    return (2.0 * (np.asarray(x, np.float64) - lo) / span - 1.0).astype(np.float32)


def grid_sample_2d(plane: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup in one feature plane [H, W, C] at u, v in [-1, 1] (texel centres, edge clamp).

    Continuous texel coordinate s = (u + 1) / 2 * W - 1/2, clamped to [0, W - 1]; the same for v.
    Returns [N, C].
    """
    h, w, _ = plane.shape
    fu = np.clip((np.asarray(u, np.float32) + 1.0) * 0.5 * w - 0.5, 0.0, w - 1)
    fv = np.clip((np.asarray(v, np.float32) + 1.0) * 0.5 * h - 0.5, 0.0, h - 1)
    fu = np.nan_to_num(fu, nan=0.0)
    fv = np.nan_to_num(fv, nan=0.0)
    u0 = np.minimum(fu.astype(np.int64), w - 1)
    v0 = np.minimum(fv.astype(np.int64), h - 1)
    u1 = np.minimum(u0 + 1, w - 1)
    v1 = np.minimum(v0 + 1, h - 1)
    au = (fu - u0)[:, None].astype(np.float32)
    av = (fv - v0)[:, None].astype(np.float32)
    p = plane.astype(np.float32, copy=False)
    top = p[v0, u0] * (1 - au) + p[v0, u1] * au
    bot = p[v1, u0] * (1 - au) + p[v1, u1] * au
    return top * (1 - av) + bot * av


#: plane index -> (u axis, v axis) of the unit-box coordinate: XY, YZ, ZX.
TRIPLANE_AXES = ((0, 1), (1, 2), (2, 0))


def triplane(planes: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """Sum of bilinear lookups in planes [3, R, R, C] (XY, YZ, ZX) at unit-box points xn [N,3] -> [N, C]."""
    out = None
    for k, (a, b) in enumerate(TRIPLANE_AXES):
        f = grid_sample_2d(planes[k], xn[:, a], xn[:, b])
        out = f if out is None else out + f
    return out


def safe_normalize(v: np.ndarray, fallback=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Unit vectors [N,3]; zero, non-finite or denormal input becomes ``fallback``."""
    v = np.asarray(v, np.float64)
    v = np.where(np.isfinite(v), v, 0.0)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    ok = n > 1e-20
    out = np.where(ok, v / np.where(ok, n, 1.0), np.asarray(fallback, np.float64))
    return out.astype(np.float32)
