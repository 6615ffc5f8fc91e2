"""Input encodings shared by the kinds, in numpy (spec/kinds/encodings.md).

All functions are vectorised over a leading batch axis N and return float32.
"""

from __future__ import annotations

import numpy as np

from ..errors import UsageError


def to_unit_box(x: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Map object-space points [N,3] to the encoding box: 2 (x - lo) / (hi - lo) - 1, in [-1, 1]^3 inside."""
    lo = np.asarray(lo, np.float64)
    span = np.maximum(np.asarray(hi, np.float64) - lo, 1e-30)
    return (2.0 * (np.asarray(x, np.float64) - lo) / span - 1.0).astype(np.float32)


def grid_sample_2d(plane: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear lookup in one feature plane [H, W, C] at u, v in [-1, 1] (texel centres, edge clamp).

    Continuous texel coordinate s = (u + 1) / 2 * W - 1/2, clamped to [0, W - 1]; the same for v.
    NaN coordinates read texel 0. Returns [N, C] float32.
    """
    h, w, c = plane.shape

    def texel(x, n):  # (i0 intp, fraction float32) of the clamped coordinate; NaN -> 0
        f = np.asarray(x, np.float32) + np.float32(1.0)  # always a new array
        f *= np.float32(0.5)
        f *= np.float32(n)
        f -= np.float32(0.5)
        np.fmax(f, np.float32(0.0), out=f)  # fmax/fmin: NaN -> 0 (the lower bound), +-inf clamp
        np.fmin(f, np.float32(n - 1), out=f)
        i0 = f.astype(np.intp)  # f >= 0: truncation is floor, and i0 <= n - 1
        f -= i0  # the fraction of a float32 is exact in float32
        return i0, f

    u0, au = texel(u, w)
    v0, av = texel(v, h)
    # flat texel rows; np.take on axis 0 of a contiguous [H W, C] array is much faster than p[v, u]
    flat = np.ascontiguousarray(plane, np.float32).reshape(h * w, c)
    i00 = v0 * w + u0
    i01 = i00 + (u0 < w - 1)
    dv = (v0 < h - 1) * w
    i10 = i00 + dv
    i11 = i01 + dv
    au = au[:, None]
    av = av[:, None]
    bu = np.float32(1.0) - au
    # same operations and order as top = p00 (1 - au) + p01 au, bot likewise, top (1 - av) + bot av
    top = flat.take(i00, 0)
    top *= bu
    top += flat.take(i01, 0) * au
    bot = flat.take(i10, 0)
    bot *= bu
    bot += flat.take(i11, 0) * au
    top *= np.float32(1.0) - av
    bot *= av
    top += bot
    return top


#: plane index -> (u axis, v axis) of the unit-box coordinate: XY, YZ, ZX.
TRIPLANE_AXES = ((0, 1), (1, 2), (2, 0))


def triplane(planes: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """Sum of bilinear lookups in planes [3, R, R, C] (XY, YZ, ZX) at unit-box points xn [N,3] -> [N, C]."""
    xn = np.asarray(xn, np.float32)
    planes = np.asarray(planes, np.float32)  # convert once, not once per plane
    step = 8192  # rows per pass: keeps the [rows, C] temporaries in cache (2-4x faster on large N)
    if len(xn) > step:
        out = np.empty((len(xn), planes.shape[-1]), np.float32)
        for s in range(0, len(xn), step):
            out[s:s + step] = triplane(planes, xn[s:s + step])
        return out
    out = None
    for k, (a, b) in enumerate(TRIPLANE_AXES):
        f = grid_sample_2d(planes[k], xn[:, a], xn[:, b])
        if out is None:
            out = f
        else:
            out += f  # f is a fresh array: accumulate in place, same order (f0 + f1) + f2
    return out


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row dot products [N] of a, b [N, 3]: ``(a * b).sum(1)`` bit for bit (summed left to right), without numpy's
    reduction over rows of three (several times slower)."""
    out = a[:, 0] * b[:, 0]
    out += a[:, 1] * b[:, 1]
    out += a[:, 2] * b[:, 2]
    return out


def safe_normalize(v: np.ndarray, fallback=(0.0, 0.0, 1.0)) -> np.ndarray:
    """Unit vectors [N,3]; zero, non-finite or denormal input becomes ``fallback``."""
    v = np.asarray(v, np.float64)
    v = np.where(np.isfinite(v), v, 0.0)
    v, n = _norm_no_overflow(v)
    ok = n > 1e-20
    out = np.where(ok, v / np.where(ok, n, 1.0), np.asarray(fallback, np.float64))
    return out.astype(np.float32)


def _norm_no_overflow(v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(v, |v|) for finite v [..., 3]; rows whose norm overflows (|v_k| ~ 1e308) are first divided by max |v_k|."""
    with np.errstate(over="ignore"):  # an overflowing norm is expected here and rescaled below
        n = np.linalg.norm(v, axis=-1, keepdims=True)
    big = np.isinf(n)
    if big.any():
        v = np.where(big, v / np.where(big, np.abs(v).max(-1, keepdims=True), 1.0), v)
        n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v, n


# ----------------------------------------------------------------------------------------
# frames and direction parameterisations (spec/kinds/encodings.md#frames)


def atan2_columns(a: np.ndarray, i: int, j: int) -> np.ndarray:
    """atan2(a[:, i], a[:, j]) [N] of a [N, k], on contiguous copies of the columns: on strided ones numpy's arctan2
    goes through per-call buffers and its last bits depend on where they land, which concurrent render threads
    change (docs/benchmarks.md#render-threads)."""
    return np.arctan2(np.ascontiguousarray(a[:, i]), np.ascontiguousarray(a[:, j]))


def unit64(v: np.ndarray, fallback=(0.0, 0.0, 1.0)) -> np.ndarray:
    """float64 unit vectors [N,3]; zero / non-finite input becomes ``fallback``."""
    v = np.atleast_2d(np.asarray(v, np.float64))
    with np.errstate(over="ignore", invalid="ignore"):  # overflow / non-finite rows take the careful path below
        # np.linalg.norm's arithmetic (the same sum, left to right), without its checks or its reduction over rows of 3
        n = np.sqrt(dot3(v, v)[:, None] if v.ndim == 2 and v.shape[1] == 3 else np.add.reduce(v * v, axis=-1, keepdims=True))
    if not np.isfinite(n).all():  # a non-finite component or an overflowing norm: the careful path
        v = np.where(np.isfinite(v), v, 0.0)
        v, n = _norm_no_overflow(v)
    ok = n > 1e-20
    if ok.all():  # the common case: one division, no fallback rows
        return v / n
    return np.where(ok, v / np.where(ok, n, 1.0), np.asarray(fallback, np.float64))


def local_frame(n: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Right-handed orthonormal basis (t, b, n) [N,3] each, from normals [N,3] (branchless ONB).

    Duff et al. 2017: sign = copysign(1, n_z), a = -1 / (sign + n_z), c = n_x n_y a,
    t = (1 + sign n_x^2 a, sign c, -sign n_x), b = (c, sign + n_y^2 a, -n_y). No singularity:
    |sign + n_z| >= 1. Zero or non-finite normals become +Z. Returns float64.
    """
    n = unit64(n)
    x, y, z = n[:, 0], n[:, 1], n[:, 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    c = x * y * a
    t = np.stack([1.0 + sign * x * x * a, sign * c, -sign * x], axis=1)
    b = np.stack([c, sign + y * y * a, -y], axis=1)
    return t, b, n


def to_local(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Components of directions w [N,3] in the frame local_frame(n): (w.t, w.b, w.n), float64."""
    t, b, nn = local_frame(n)
    w = np.asarray(w, np.float64)
    return np.stack([dot3(w, t), dot3(w, b), dot3(w, nn)], axis=1)


def from_local(wl: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Inverse of :func:`to_local`: wl_x t + wl_y b + wl_z n, float64."""
    t, b, nn = local_frame(n)
    wl = np.asarray(wl, np.float64)
    return wl[:, :1] * t + wl[:, 1:2] * b + wl[:, 2:3] * nn


def spherical_coords(w: np.ndarray) -> np.ndarray:
    """Normalised spherical coordinates [N,2] of directions w [N,3] (normalised first; zero -> +Z):

    theta_hat = acos(clamp(w_z, -1, 1)) / pi in [0, 1], phi_hat = atan2(w_y, w_x) / (2 pi) in [-1/2, 1/2].
    At the poles atan2(0, 0) = 0. float32.
    """
    w = unit64(w)
    theta = np.arccos(np.clip(w[:, 2], -1.0, 1.0))
    phi = atan2_columns(w, 1, 0)
    return np.stack([theta / np.pi, phi / (2.0 * np.pi)], axis=1).astype(np.float32)


def azimuthal_equidistant(w: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Azimuthal equidistant projection of w [N,3] around n [N,3] -> p [N,2] (radians), float64.

    With (l_x, l_y, l_z) = to_local(w, n): r = acos(clamp(l_z, -1, 1)) in [0, pi], phi = atan2(l_y, l_x),
    p = r (cos phi, sin phi). The antipode -n maps to the circle r = pi (phi = 0 there).
    """
    loc = to_local(unit64(w), n)
    r = np.arccos(np.clip(loc[:, 2], -1.0, 1.0))
    phi = atan2_columns(loc, 1, 0)
    return np.stack([r * np.cos(phi), r * np.sin(phi)], axis=1)


def azimuthal_equidistant_inverse(p: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Inverse projection: p [N,2] with |p| <= pi -> unit w [N,3] = cos r n + sin r (cos phi t + sin phi b), float64.

    |p| is clamped to pi; p = 0 gives n.
    """
    p = np.nan_to_num(np.asarray(p, np.float64))
    r = np.minimum(np.hypot(p[:, 0], p[:, 1]), np.pi)
    phi = atan2_columns(p, 1, 0)
    sr = np.sin(r)
    loc = np.stack([sr * np.cos(phi), sr * np.sin(phi), np.cos(r)], axis=1)
    return from_local(loc, n)


def sh9(w: np.ndarray) -> np.ndarray:
    """Real spherical harmonics Y_l^m, l <= 2, of unit directions [N,3] -> [N,9] in the order
    (0,0), (1,-1), (1,0), (1,1), (2,-2), (2,-1), (2,0), (2,1), (2,2) (spec/kinds/encodings.md#sh)."""
    w = unit64(w)
    x, y, z = w[:, 0], w[:, 1], w[:, 2]
    return np.stack([
        np.full_like(x, 0.282094791773878),
        0.488602511902920 * y, 0.488602511902920 * z, 0.488602511902920 * x,
        1.092548430592079 * x * y, 1.092548430592079 * y * z, 0.315391565252520 * (3 * z * z - 1),
        1.092548430592079 * x * z, 0.546274215296040 * (x * x - y * y),
    ], axis=1)


# ----------------------------------------------------------------------------------------
# Fourier features (spec/kinds/encodings.md#fourier)


def fourier_features(G: np.ndarray, v: np.ndarray) -> np.ndarray:
    """gamma(v) = [cos(2 pi G v), sin(2 pi G v)]: G [M, n], v [N, n] -> [N, 2M] float32 (phase in float64)."""
    G = np.asarray(G, np.float64)
    v = np.nan_to_num(np.asarray(v, np.float64))
    if v.ndim != 2 or G.ndim != 2 or v.shape[1] != G.shape[1]:
        from ..errors import UsageError

        raise UsageError(f"fourier_features: G {G.shape} and v {v.shape} must be [M, n] and [N, n]")
    phase = 2.0 * np.pi * (v @ G.T)
    phase[~np.isfinite(phase)] = 0.0  # v = +-inf or an overflowing product: no meaningful phase (as NaN: 0)
    return np.concatenate([np.cos(phase), np.sin(phase)], axis=1).astype(np.float32)


# ----------------------------------------------------------------------------------------
# 1D grid and cubemap (spec/kinds/encodings.md#grid1d, #cubemap)


def grid_1d(grid: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Linear interpolation in a feature line [K, C] at t in [-1, 1] (texel centres, edge clamp) -> [N, C].

    f = clamp((t + 1) / 2 K - 1/2, 0, K - 1); i0 = floor(f), i1 = min(i0 + 1, K - 1), a = f - i0;
    result = (1 - a) grid[i0] + a grid[i1]. NaN t reads texel 0.
    """
    k = grid.shape[0]
    f = (np.asarray(t, np.float64).reshape(-1) + 1.0) * 0.5 * k - 0.5
    np.fmax(f, 0.0, out=f)  # fmax / fmin: the clamp, and NaN -> 0 (the lower bound)
    np.fmin(f, k - 1, out=f)
    i0 = np.minimum(f.astype(np.int64), k - 1)
    i1 = np.minimum(i0 + 1, k - 1)
    a = (f - i0)[:, None]
    g = np.asarray(grid, np.float32)
    out = g.take(i0, 0) * (1 - a)
    out += g.take(i1, 0) * a
    return out.astype(np.float32)


#: face -> (major axis, sign, (axis, sign) of s_c, (axis, sign) of t_c); OpenGL cube-map table.
CUBE_FACES = (
    (0, +1, (2, -1), (1, -1)),  # +X: sc = -z, tc = -y
    (0, -1, (2, +1), (1, -1)),  # -X: sc = +z, tc = -y
    (1, +1, (0, +1), (2, +1)),  # +Y: sc = +x, tc = +z
    (1, -1, (0, +1), (2, -1)),  # -Y: sc = +x, tc = -z
    (2, +1, (0, +1), (1, -1)),  # +Z: sc = +x, tc = -y
    (2, -1, (0, -1), (1, -1)),  # -Z: sc = -x, tc = -y
)


#: face -> (axis of s_c, its sign, axis of t_c, its sign), from :data:`CUBE_FACES`
_CUBE_TAPS = np.array([[f[2][0], f[2][1], f[3][0], f[3][1]] for f in CUBE_FACES])


def cube_face_uv(d: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Direction [N,3] (any length; zero/non-finite -> +Z) -> (face [N] int, s [N], t [N]) with s, t in [0, 1].

    The major axis is argmax |d_k| (ties go to the lower axis index), face = 2 axis + (d_axis < 0);
    s = (sc / |ma| + 1) / 2, t = (tc / |ma| + 1) / 2 with sc, tc from :data:`CUBE_FACES`.
    """
    d = unit64(d)
    ad = np.abs(d)
    a0, a1, a2 = ad[:, 0], ad[:, 1], ad[:, 2]
    axis = np.where((a0 >= a1) & (a0 >= a2), 0, np.where(a1 >= a2, 1, 2))  # np.argmax: ties to the lower axis
    base = 3 * np.arange(len(d))  # flat index of each row's first component
    flat = d.reshape(-1)
    face = 2 * axis + (flat.take(base + axis) < 0)
    tab = _CUBE_TAPS[face]
    ma = np.maximum(ad.reshape(-1).take(base + axis), 1e-30)
    sc = tab[:, 1] * flat.take(base + tab[:, 0])
    tc = tab[:, 3] * flat.take(base + tab[:, 2])
    s = np.clip((sc / ma + 1.0) * 0.5, 0.0, 1.0)
    t = np.clip((tc / ma + 1.0) * 0.5, 0.0, 1.0)
    return face, s, t


def cube_face_dir(face: np.ndarray, sc: np.ndarray, tc: np.ndarray) -> np.ndarray:
    """Point on the plane of ``face`` at face coordinates (sc, tc) in [-1-, 1+] -> 3D direction (not unit)."""
    d = np.zeros((len(face), 3), np.float64)
    for f, (ax, sg, (sa, ss), (ta, ts)) in enumerate(CUBE_FACES):
        m = face == f
        if not m.any():
            continue
        d[m, ax] = sg
        d[m, sa] = ss * sc[m]
        d[m, ta] = ts * tc[m]
    return d


def cube_table(grid: np.ndarray) -> np.ndarray:
    """[6, R+2, R+2, C] float64: entry (f, j + 1, i + 1) is the value :func:`cubemap` reads for tap (i, j) of
    face f, i, j in [-1, R]: the texel inside the face, the re-projected texel across an edge, and beyond a
    cube corner the mean of the lookup's other three taps (summed in tap order, as below). Depends on the
    grid only: compute it once per grid and pass it to :func:`cubemap` (``table``)."""
    g = np.asarray(grid, np.float32)
    r = g.shape[1]
    e = r + 2
    ext = np.zeros((6, e, e, g.shape[-1]), np.float64)
    ext[:, 1:-1, 1:-1] = g
    idx = np.arange(-1, r + 1)
    jj, ii = np.meshgrid(idx, idx, indexing="ij")
    edge = ((ii < 0) | (ii >= r)) ^ ((jj < 0) | (jj >= r))  # exactly one index outside
    i, j = ii[edge], jj[edge]
    for f in range(6):  # re-projected taps: the centre (sc, tc) on the extended face plane, looked up by direction
        f2, s2, t2 = cube_face_uv(cube_face_dir(np.full(len(i), f), 2.0 * (i + 0.5) / r - 1.0, 2.0 * (j + 0.5) / r - 1.0))
        ext[f, j + 1, i + 1] = g[f2, np.minimum(np.floor(t2 * r).astype(np.int64), r - 1),
                                 np.minimum(np.floor(s2 * r).astype(np.int64), r - 1)]
    for k in range(4):  # the corner that is tap k of its lookups: the mean of taps m != k, in the order of m
        ci, cj = (r if k & 1 else -1), (r if k >> 1 else -1)
        i0, j0 = ci - (k & 1), cj - (k >> 1)
        o = [ext[:, j0 + (m >> 1) + 1, i0 + (m & 1) + 1] for m in range(4) if m != k]
        ext[:, cj + 1, ci + 1] = (o[0] + o[1] + o[2]) / 3.0
    return ext


def cubemap(grid: np.ndarray, d: np.ndarray, *, table: np.ndarray | None = None) -> np.ndarray:
    """Seam-safe bilinear lookup in a cube-map feature grid [6, R, R, C] (face, row t, column s, channel).

    Texel (face, j, i) has its centre at s = (i + 1/2) / R, t = (j + 1/2) / R. Within a face:
    fs = s R - 1/2, ft = t R - 1/2, i0 = floor(fs), j0 = floor(ft), bilinear weights from the fractions.
    A tap with i or j outside [0, R-1] is re-projected: its centre (sc, tc) = (2 (i + 1/2) / R - 1, ...)
    on the extended plane of its face gives a 3D direction, which is looked up with :func:`cube_face_uv`
    and read at the texel containing it (min(floor(s R), R - 1), min(floor(t R), R - 1)). A tap with
    both i and j outside (beyond a cube corner) takes the mean of the other three taps. This makes the
    lookup continuous across face edges and corners. The taps come from :func:`cube_table` (``table``,
    built here if not given). Returns [N, C] float32.
    """
    g = np.asarray(grid, np.float32)
    r = g.shape[1]
    if table is None:
        table = cube_table(g)
    e = r + 2
    if table.shape != (6, e, e, g.shape[-1]):
        raise UsageError(f"cube table {table.shape} does not belong to a cube map {g.shape}")
    face, s, t = cube_face_uv(d)
    fs = s * r - 0.5
    ft = t * r - 0.5
    i0 = np.floor(fs).astype(np.int64)  # in [-1, R-1]
    j0 = np.floor(ft).astype(np.int64)
    a_s = (fs - i0)[:, None]
    a_t = (ft - j0)[:, None]
    rows = table.reshape(-1, table.shape[-1])
    row = (face * e + j0 + 1) * e + i0 + 1  # tap (i0, j0) in the [6 (R+2)^2, C] table
    b_s, b_t = 1 - a_s, 1 - a_t
    # taps[0] (1 - a_s) (1 - a_t) + taps[1] a_s (1 - a_t) + taps[2] (1 - a_s) a_t + taps[3] a_s a_t, in this
    # order, accumulated in place
    out = rows.take(row, 0)
    out *= b_s
    out *= b_t
    for off, ws, wt in ((1, a_s, b_t), (e, b_s, a_t), (e + 1, a_s, a_t)):
        tap = rows.take(row + off, 0)
        tap *= ws
        tap *= wt
        out += tap
    return out.astype(np.float32)
