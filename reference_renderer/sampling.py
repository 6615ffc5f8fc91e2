"""Warping functions, frames, discrete distributions and MIS weights (vectorised over rows).

Every ``square_to_*`` maps uniform numbers in [0,1)^2 to directions and has a matching
``*_pdf`` in solid angle; ``tests/renderer/test_render_samplers.py`` checks each pair with a chi² test.
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.kinds.encodings import dot3

INV_PI = 1.0 / np.pi
INV_4PI = 0.25 / np.pi


def dot(a, b):
    """Row dot products [N] of a, b [N,3] (on columns: several times faster than einsum for 3 columns)."""
    if a.ndim == 2 and a.shape[1] == 3 and b.ndim == 2 and b.shape[1] == 3:
        return dot3(a, b)
    return np.einsum("ij,ij->i", a, b)


def cross3(a, b):
    """Row cross products [N,3] of a, b [N,3]: ``np.cross(a, b)`` bit for bit, on columns (np.cross is ~20x
    slower here: it moves axes and promotes through temporaries)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape), np.result_type(a, b))
    a0, a1, a2 = a[:, 0], a[:, 1], a[:, 2]
    b0, b1, b2 = b[:, 0], b[:, 1], b[:, 2]
    np.subtract(a1 * b2, a2 * b1, out=out[:, 0])
    np.subtract(a2 * b0, a0 * b2, out=out[:, 1])
    np.subtract(a0 * b1, a1 * b0, out=out[:, 2])
    return out


def box3(p):
    """(lo [3], hi [3]) of points p [N,3] (N >= 1): ``p.min(0), p.max(0)`` per column (10x faster than a
    reduction over rows of three)."""
    return (np.array([p[:, k].min() for k in range(3)]), np.array([p[:, k].max() for k in range(3)]))


def face_normals(tris):
    """Unit geometric normals [F,3] of triangles [F,3,3] (zero for degenerate ones): the cross product of the
    edges from corner 0, normalised as :func:`normalize` does."""
    return normalize(cross3(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]))


def barycentric(corners, b1, b2):
    """Values [n,k] at barycentrics (b1, b2) [n] of triangle corner values ``corners`` [n,3,k]: corner 0 weighs
    1 - b1 - b2, corner 1 b1, corner 2 b2 (Embree's u, v)."""
    return corners[:, 0] * (1 - b1 - b2)[:, None] + corners[:, 1] * b1[:, None] + corners[:, 2] * b2[:, None]


def normalize(v):
    if v.ndim == 2 and v.shape[1] == 3:
        # same sum in the same order as np.linalg.norm over the last axis, without its temporaries
        x, y, z = v[:, 0], v[:, 1], v[:, 2]
        n = x * x
        n += y * y
        n += z * z
        np.sqrt(n, out=n)
        n[~(n > 0)] = 1.0
        return v / n[:, None]
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def unit_or(v, alt):
    """Rows [N,3]: ``v``'s unit rows, ``alt`` (a row [3] or rows [N,3]) where a row of ``v`` is not a unit vector (a zero
    or degenerate one): the axis a lobe turns about must be a direction."""
    return np.where((dot(v, v) > 0.5)[:, None], v, alt)


#: an axis for rows that have none (a degenerate normal, tangent and viewing direction together)
Z_AXIS = np.array([0.0, 0.0, 1.0])


def frame(n):
    """Orthonormal tangent frame (t, b) for unit normals n [N,3] (Duff et al. 2017)."""
    sign = np.where(n[:, 2] >= 0, 1.0, -1.0)
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], axis=1)
    bb = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], axis=1)
    return t, bb


def to_local(v, t, b, n):
    return np.stack([dot(v, t), dot(v, b), dot(v, n)], axis=1)


def to_world(v, t, b, n):
    return v[:, 0:1] * t + v[:, 1:2] * b + v[:, 2:3] * n


def around(axis, local):
    """Local directions [m,3] (z along the axis) turned about unit axes [m,3] into world directions."""
    t, b = frame(axis)
    return to_world(local, t, b, axis)


# -- disk / hemisphere / sphere / cone --------------------------------------------------------
def square_to_uniform_disk(u):
    """Points [m,2] uniform on the unit disk (polar map; density 1/pi) from u [m,2] in [0,1)^2."""
    rho, phi = np.sqrt(u[:, 0]), 2.0 * np.pi * u[:, 1]
    return np.stack([rho * np.cos(phi), rho * np.sin(phi)], axis=1)


def square_to_cosine_hemisphere(u):
    r = np.sqrt(u[:, 0])
    phi = 2.0 * np.pi * u[:, 1]
    z = np.sqrt(np.maximum(0.0, 1.0 - u[:, 0]))
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def cosine_hemisphere_pdf(v):
    return np.maximum(v[:, 2], 0.0) * INV_PI


def square_to_uniform_sphere(u):
    z = 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def uniform_sphere_pdf(v):
    return np.full(len(v), INV_4PI)


def square_to_uniform_cone(u, cos_max):
    """Directions within ``acos(cos_max)`` of +Z, uniform in solid angle."""
    cos_max = np.broadcast_to(np.asarray(cos_max, np.float64), (len(u),))
    z = 1.0 - u[:, 0] * (1.0 - cos_max)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def uniform_cone_pdf(v, cos_max):
    cos_max = np.broadcast_to(np.asarray(cos_max, np.float64), (len(v),))
    return np.where(v[:, 2] >= cos_max, 1.0 / (2.0 * np.pi * np.maximum(1.0 - cos_max, 1e-300)), 0.0)


def square_to_vmf(u, kappa):
    """Directions [n,3] from a von Mises-Fisher lobe around +Z with concentration ``kappa`` > 0 (scalar):
    density kappa exp(kappa (z - 1)) / (2 pi (1 - exp(-2 kappa))) per steradian (:func:`vmf_pdf`).
    Inverse CDF in z written without cancellation: z = 1 + log(u0 + (1 - u0) exp(-2 kappa)) / kappa."""
    z = 1.0 + np.log(np.maximum(u[:, 0] + (1.0 - u[:, 0]) * np.exp(-2.0 * kappa), 1e-300)) / kappa
    z = np.clip(z, -1.0, 1.0)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    phi = 2.0 * np.pi * u[:, 1]
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def vmf_pdf(cos, kappa):
    """Density [1/sr] of :func:`square_to_vmf` at directions whose cosine to the lobe axis is ``cos``."""
    return kappa / (2.0 * np.pi * -np.expm1(-2.0 * kappa)) * np.exp(kappa * (np.clip(cos, -1.0, 1.0) - 1.0))


def sample_mixture(weights, u, lobes) -> np.ndarray:
    """Unit directions [m,3] from the mixture whose component k (picked by u[:,2] against ``weights``) maps
    u[:,:2] of its rows through ``lobes[k](rows_mask, u2)`` -> [r,3]; lobe 0 is the uniform sphere."""
    wi = np.empty((len(u), 3))
    pick = np.searchsorted(np.cumsum(weights)[:-1], u[:, 2], side="right")
    for k, lobe in enumerate(lobes):
        m = pick == k
        if m.any():
            wi[m] = lobe(m, u[m, :2])
    return normalize(wi)


# -- MIS --------------------------------------------------------------------------------------
def power_heuristic(a, b):
    """w = a² / (a² + b²); a is the pdf of the strategy that produced the sample."""
    a2 = np.square(a)
    den = a2 + np.square(b)
    return np.where(den > 0, a2 / np.where(den > 0, den, 1.0), 0.0)


# -- discrete distributions -------------------------------------------------------------------
class Distribution2D:
    """Piecewise-constant distribution over an [H, W] grid on [0,1)^2 (rows = v, columns = u).

    ``sample(u)`` -> (uv in [0,1)^2, pdf with respect to area on the unit square).
    """

    def __init__(self, weights: np.ndarray) -> None:
        w = np.asarray(weights, np.float64)
        if w.ndim != 2 or (w < 0).any() or not np.isfinite(w).all():
            raise ValueError("weights must be a finite, non-negative [H, W] array")
        self.h, self.w = w.shape
        row = w.sum(1)
        self.total = float(row.sum())
        if self.total <= 0:
            w = np.ones_like(w)
            row = w.sum(1)
            self.total = float(row.sum())
        self.func = w
        self.row_cdf = np.concatenate([[0.0], np.cumsum(row)]) / self.total
        safe = np.where(row > 0, row, 1.0)
        self.cond_cdf = np.concatenate([np.zeros((self.h, 1)), np.cumsum(w, 1)], 1) / safe[:, None]
        self._flat = (self.cond_cdf + 2.0 * np.arange(self.h)[:, None]).ravel()
        self.pdf_grid = w / self.total * (self.h * self.w)  # density on the unit square

    def sample(self, u: np.ndarray):
        u0 = np.clip(u[:, 0], 0.0, np.nextafter(1.0, 0))
        u1 = np.clip(u[:, 1], 0.0, np.nextafter(1.0, 0))
        r = np.clip(np.searchsorted(self.row_cdf, u0, side="right") - 1, 0, self.h - 1)
        lo, hi = self.row_cdf[r], self.row_cdf[r + 1]
        dv = np.where(hi > lo, (u0 - lo) / np.where(hi > lo, hi - lo, 1.0), 0.5)
        k = np.searchsorted(self._flat, u1 + 2.0 * r, side="right") - 1 - r * (self.w + 1)
        c = np.clip(k, 0, self.w - 1)
        lo2 = self.cond_cdf[r, c]
        hi2 = self.cond_cdf[r, c + 1]
        du = np.where(hi2 > lo2, (u1 - lo2) / np.where(hi2 > lo2, hi2 - lo2, 1.0), 0.5)
        uv = np.stack([(c + np.clip(du, 0, 1 - 1e-9)) / self.w, (r + np.clip(dv, 0, 1 - 1e-9)) / self.h], 1)
        return uv, self.pdf_grid[r, c]

    def pdf(self, uv: np.ndarray) -> np.ndarray:
        c = np.clip((uv[:, 0] * self.w).astype(np.int64), 0, self.w - 1)
        r = np.clip((uv[:, 1] * self.h).astype(np.int64), 0, self.h - 1)
        return self.pdf_grid[r, c]


def luminance(rgb):
    return rgb[..., 0] * 0.2126 + rgb[..., 1] * 0.7152 + rgb[..., 2] * 0.0722
