"""Encodings: 1D grid, cube map (orientation, seams, corners), Fourier features, frames, projections, SH."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_sdk.errors import UsageError
from nasset_sdk.kinds.encodings import (
    azimuthal_equidistant,
    azimuthal_equidistant_inverse,
    cube_face_dir,
    cube_face_uv,
    cube_table,
    cubemap,
    fourier_features,
    from_local,
    grid_1d,
    local_frame,
    sh9,
    spherical_coords,
    to_local,
    unit64,
)

POLES = np.array([[0, 0, 1.0], [0, 0, -1.0], [0, 0, -0.0], [1e-20, 0, -1.0], [0, 1e-30, 1.0], [0, 0, 0.0], [np.nan, 0, 1.0],
                  [1.0, 0, 0], [0, -1.0, 0]])


def test_grid_1d_texel_centres_and_clamp():
    g = np.arange(8, dtype=np.float32).reshape(4, 2)  # texel k holds (2k, 2k+1)
    centres = (np.arange(4) + 0.5) / 4 * 2 - 1
    np.testing.assert_allclose(grid_1d(g, centres), g)
    np.testing.assert_allclose(grid_1d(g, [-1.0, 1.0, -5.0, 5.0]), g[[0, 3, 0, 3]])
    mid = (centres[1] + centres[2]) / 2
    np.testing.assert_allclose(grid_1d(g, [mid]), [[3.0, 4.0]])
    assert np.isfinite(grid_1d(g, [np.nan, np.inf, -np.inf])).all()


def test_cube_face_orientation_table():
    face, s, t = cube_face_uv(np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1.0]]))
    np.testing.assert_array_equal(face, [0, 1, 2, 3, 4, 5])
    np.testing.assert_allclose(s, 0.5)
    np.testing.assert_allclose(t, 0.5)
    # +X: sc = -z, tc = -y ; +Y: sc = +x, tc = +z ; -Z: sc = -x, tc = -y
    f, s, t = cube_face_uv(np.array([[1.0, 0.5, -0.5], [0.5, 1.0, 0.5], [0.5, 0.5, -1.0]]))
    np.testing.assert_array_equal(f, [0, 2, 5])
    np.testing.assert_allclose(s, [0.75, 0.75, 0.25])
    np.testing.assert_allclose(t, [0.25, 0.75, 0.25])
    # ties go to the lower axis
    assert cube_face_uv(np.array([[1.0, 1.0, 1.0]]))[0][0] == 0


def test_cubemap_constant_and_texel_centres(rng):
    g = np.full((6, 4, 4, 3), 2.5, np.float32)
    assert np.allclose(cubemap(g, rng.normal(size=(200, 3))), 2.5)
    g = rng.normal(size=(6, 4, 4, 3)).astype(np.float32)
    # centre of texel (face +Z, row 1, col 2): s = 2.5/4, t = 1.5/4 -> x = 2s - 1, -y = 2t - 1
    d = np.array([[2 * 2.5 / 4 - 1, -(2 * 1.5 / 4 - 1), 1.0]])
    np.testing.assert_allclose(cubemap(g, d)[0], g[4, 1, 2], rtol=1e-6)


@pytest.mark.parametrize("res", [1, 2, 5])
def test_cubemap_continuous_across_edges_and_corners(rng, res):
    g = rng.normal(size=(6, res, res, 3)).astype(np.float32)
    n = 3000
    d = rng.uniform(-1, 1, (n, 3))
    ax = rng.integers(0, 3, n)  # free axis along the edge
    a = (ax + 1) % 3
    b = (ax + 2) % 3
    idx = np.arange(n)
    d[idx, a] = np.sign(d[idx, a])
    d[idx, b] = np.sign(d[idx, b])  # now on the edge between faces (a, b)
    e1, e2 = d.copy(), d.copy()
    e1[idx, a] *= 1 + 1e-9
    e2[idx, b] *= 1 + 1e-9
    assert np.abs(cubemap(g, e1) - cubemap(g, e2)).max() < 1e-5
    corner = np.array([[1.0, -1.0, 1.0]])
    vals = [cubemap(g, corner * (1 + 1e-9 * np.eye(3)[k]))[0] for k in range(3)]
    assert np.abs(vals[0] - vals[1]).max() < 1e-5 and np.abs(vals[0] - vals[2]).max() < 1e-5


def test_cubemap_finite_on_bad_directions(rng):
    g = rng.normal(size=(6, 3, 3, 2)).astype(np.float32)
    out = cubemap(g, np.array([[0, 0, 0.0], [np.nan, 1, 0], [np.inf, 0, 0], [1e-300, 0, 0]]))
    assert np.isfinite(out).all()


def test_fourier_features_formula(rng):
    G = rng.normal(18, 1, (5, 3))
    v = rng.random((7, 3))
    out = fourier_features(G, v)
    phase = 2 * np.pi * v @ G.T
    np.testing.assert_allclose(out, np.concatenate([np.cos(phase), np.sin(phase)], 1), atol=1e-6)
    with pytest.raises(UsageError):
        fourier_features(G, rng.random((7, 2)))


def test_local_frame_orthonormal_everywhere(rng):
    n = np.vstack([rng.normal(size=(500, 3)), POLES])
    t, b, nn = local_frame(n)
    for u in (t, b, nn):
        np.testing.assert_allclose(np.linalg.norm(u, axis=1), 1, atol=1e-12)
    assert np.abs((t * b).sum(1)).max() < 1e-12 and np.abs((t * nn).sum(1)).max() < 1e-12
    np.testing.assert_allclose(np.cross(t, b), nn, atol=1e-12)
    w = rng.normal(size=(len(n), 3))
    np.testing.assert_allclose(from_local(to_local(w, n), n), w, atol=1e-12)


def test_spherical_coords_ranges_and_poles():
    sc = spherical_coords(POLES)
    assert np.isfinite(sc).all() and (sc[:, 0] >= 0).all() and (sc[:, 0] <= 1).all() and (np.abs(sc[:, 1]) <= 0.5).all()
    np.testing.assert_allclose(sc[0], [0, 0])
    np.testing.assert_allclose(sc[1], [1, 0])
    np.testing.assert_allclose(spherical_coords(np.array([[0, 1.0, 0]]))[0], [0.5, 0.25])


def test_azimuthal_equidistant_round_trip(rng):
    n = np.vstack([rng.normal(size=(300, 3)), POLES[:5]])
    w = rng.normal(size=(len(n), 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    p = azimuthal_equidistant(w, n)
    assert (np.hypot(p[:, 0], p[:, 1]) <= np.pi + 1e-12).all()
    np.testing.assert_allclose(azimuthal_equidistant_inverse(p, n), w, atol=1e-9)
    t, b, nn = local_frame(n)
    np.testing.assert_allclose(azimuthal_equidistant(nn, n), 0, atol=1e-7)
    assert np.isfinite(azimuthal_equidistant(-nn, n)).all()


def test_sh9_orthonormal():
    from tests.stats import midpoints

    z = midpoints(-1, 1, 200)
    phi = midpoints(-np.pi, np.pi, 400)
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1 - zz ** 2)
    d = np.stack([r * np.cos(pp), r * np.sin(pp), zz], -1).reshape(-1, 3)
    y = sh9(d)
    gram = y.T @ y * (4 * np.pi / len(d))
    np.testing.assert_allclose(gram, np.eye(9), atol=2e-4)


def _cubemap_per_tap(g, d):
    """The spec's lookup written tap by tap (spec/kinds/encodings.md#cubemap): re-project each tap outside its face,
    then replace a tap beyond a cube corner by the mean of the other three (in tap order), bilinear in float64."""
    r = g.shape[1]
    out = np.empty((len(d), g.shape[-1]))
    face, s, t = cube_face_uv(d)
    for n in range(len(d)):
        fs, ft = s[n] * r - 0.5, t[n] * r - 0.5
        i0, j0 = int(np.floor(fs)), int(np.floor(ft))
        taps, corner = [], []
        for k in range(4):
            i, j = i0 + (k & 1), j0 + (k >> 1)
            out_i, out_j = not 0 <= i < r, not 0 <= j < r
            corner.append(out_i and out_j)
            f = face[n]
            if out_i or out_j:
                f2, s2, t2 = cube_face_uv(cube_face_dir(np.array([f]), np.array([2 * (i + 0.5) / r - 1]),
                                                        np.array([2 * (j + 0.5) / r - 1])))
                f, i, j = f2[0], min(int(np.floor(s2[0] * r)), r - 1), min(int(np.floor(t2[0] * r)), r - 1)
            taps.append(g[f, j, i].astype(np.float64))
        for k in range(4):
            if corner[k]:
                o = [taps[m] for m in range(4) if m != k]
                taps[k] = (o[0] + o[1] + o[2]) / 3.0
        a, b = fs - i0, ft - j0
        out[n] = taps[0] * (1 - a) * (1 - b) + taps[1] * a * (1 - b) + taps[2] * (1 - a) * b + taps[3] * a * b
    return out.astype(np.float32)


@pytest.mark.parametrize("res", [1, 2, 5, 16])
def test_cubemap_table_equals_the_per_tap_lookup(rng, res):
    """cubemap reads its taps from cube_table (built once per grid); the values are the spec's per-tap lookup bit for
    bit, on random directions and on ones near edges and corners (where taps are re-projected or averaged)."""
    g = rng.normal(size=(6, res, res, 3)).astype(np.float16).astype(np.float32)
    near_corner = np.sign(rng.normal(size=(300, 3))) + rng.normal(0, 0.05, (300, 3))
    near_edge = near_corner.copy()
    near_edge[:, 0] = rng.uniform(-1, 1, 300)
    d = np.concatenate([rng.normal(size=(300, 3)), near_corner, near_edge])
    want = _cubemap_per_tap(g, d)
    np.testing.assert_array_equal(cubemap(g, d), want)
    np.testing.assert_array_equal(cubemap(g, d, table=cube_table(g)), want)
    with pytest.raises(UsageError):
        cubemap(g, d, table=cube_table(g)[:, 1:])


def test_unit64_against_a_per_row_reference(rng):
    """unit64 (one fast pass when every row is finite and non-zero, the careful path otherwise) equals v / |v| in
    float64 row by row (norm from math.hypot), with the fallback for zero / non-finite rows and overflowing norms
    rescaled, however the rows are mixed."""
    import math

    v = rng.normal(size=(300, 3)) * 10.0 ** rng.uniform(-15, 300, (300, 1))
    v[::7] = 0.0
    v[3, 1], v[5, 0], v[8] = np.nan, -np.inf, 1e308
    for block in (v, v[v.any(axis=1) & np.isfinite(v).all(axis=1) & (np.abs(v).max(axis=1) < 1e150)]):
        got = unit64(block)
        for row, out in zip(block, got, strict=True):
            r = np.where(np.isfinite(row), row, 0.0)
            scale = np.abs(r).max()
            n = math.hypot(*(r / scale)) * scale if scale > 0 else 0.0
            want = r / n if n > 1e-20 else np.array([0.0, 0.0, 1.0])
            np.testing.assert_allclose(out, want, rtol=1e-15, atol=1e-300)


def test_dot3_is_the_row_sum_bit_for_bit(rng):
    """dot3 (three column products, summed left to right) equals numpy's (a * b).sum(1), special values included."""
    from nasset_sdk.kinds.encodings import dot3

    a = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-200, 200, (500, 3))
    b = rng.normal(size=(500, 3)) * 10.0 ** rng.uniform(-200, 200, (500, 3))
    a[:5] = [[np.nan, 0, 1], [np.inf, 1, 0], [-0.0, -0.0, -0.0], [1e308, 1e308, 0], [-np.inf, np.inf, 1]]
    with np.errstate(all="ignore"):
        np.testing.assert_array_equal(dot3(a, b), (a * b).sum(1))


def _cube_face_uv_per_row(d):
    """The spec's face selection one row at a time: major axis argmax |d_k| (first on ties), face 2 axis + (d < 0),
    (sc, tc) from the face table, s = (sc / |ma| + 1) / 2 and t likewise, clamped to [0, 1]."""
    from nasset_sdk.kinds.encodings import CUBE_FACES

    faces, ss, ts = [], [], []
    for row in unit64(d):
        ad = [abs(float(c)) for c in row]
        axis = ad.index(max(ad))
        face = 2 * axis + int(row[axis] < 0)
        _, _, (sa, sg), (ta, tg) = CUBE_FACES[face]
        ma = max(ad[axis], 1e-30)
        faces.append(face)
        ss.append(min(max((sg * row[sa] / ma + 1.0) * 0.5, 0.0), 1.0))
        ts.append(min(max((tg * row[ta] / ma + 1.0) * 0.5, 0.0), 1.0))
    return np.array(faces), np.array(ss), np.array(ts)


def test_cube_face_uv_equals_the_per_row_selection(rng):
    """Vectorised face selection (comparisons for the major axis, flat takes) equals the per-row rule bit for bit,
    on random directions and on ties between axes (first axis wins), signed zeros and poles."""
    ties = np.array([[1, 1, 1], [1, -1, 0], [0, 1, -1], [-1, 0, -1], [-1, -1, -1], [0.5, -0.5, 0.5], [-0.0, 0.0, 1],
                     [0, -0.0, -1], [1e-300, 1e-300, 0], [2, 2, -2]], np.float64)
    d = np.concatenate([rng.normal(size=(400, 3)), ties, POLES])
    want = _cube_face_uv_per_row(d)
    for got, exp in zip(cube_face_uv(d), want, strict=True):
        np.testing.assert_array_equal(got, exp)


def test_grid_1d_equals_the_formula_bit_for_bit(rng):
    """grid_1d (clamp by fmax / fmin, taps by take, accumulated in place) equals the spec's formula evaluated one
    value at a time in float64, for random t, texel centres and borders, the ends and NaN / +-inf."""
    g = rng.normal(size=(8, 3)).astype(np.float32)
    k = len(g)
    t = np.concatenate([rng.uniform(-1.2, 1.2, 300), (np.arange(k) + 0.5) / k * 2 - 1, np.arange(k + 1) / k * 2 - 1,
                        [-1.0, 1.0, np.nan, np.inf, -np.inf, -0.0]])
    want = np.empty((len(t), 3), np.float32)
    for n, v in enumerate(t):
        f = (v + 1.0) * 0.5 * k - 0.5
        f = 0.0 if np.isnan(f) else min(max(f, 0.0), k - 1.0)
        i0 = min(int(f), k - 1)
        i1 = min(i0 + 1, k - 1)
        a = f - i0
        want[n] = g[i0].astype(np.float64) * (1 - a) + g[i1].astype(np.float64) * a
    np.testing.assert_array_equal(grid_1d(g, t), want)
