"""Ray casting: one Embree scene over every triangle, plus a slow numpy reference.

Each triangle carries the id of the instance it belongs to (``tri_inst``), so rays leaving a
neural asset can skip that asset (:meth:`Accel.trace`) and report whether they passed through
it (the asset's self-occlusion, which picks the rna shadowed/unshadowed branch).
"""

from __future__ import annotations

import numpy as np

MAX_SKIPS = 64


class Hits:
    __slots__ = ("t", "prim", "u", "v", "self_hit")

    def __init__(self, n: int) -> None:
        self.t = np.full(n, np.inf)
        self.prim = np.full(n, -1, np.int64)
        self.u = np.zeros(n)
        self.v = np.zeros(n)
        self.self_hit = np.zeros(n, bool)


class _Backend:
    def closest(self, o, d, tmax):
        """(t, prim, u, v) arrays; prim -1 on a miss."""
        raise NotImplementedError

    def occluded(self, o, d, tmax):
        t, prim, _, _ = self.closest(o, d, tmax)
        return prim >= 0


class EmbreeBackend(_Backend):
    def __init__(self, triangles: np.ndarray) -> None:
        from nasset_sdk.extras import require_extras

        require_extras("render", purpose="ray casting with Embree")
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.scene = rtcore_scene.EmbreeScene()
        if len(triangles):
            TriangleMesh(self.scene, np.ascontiguousarray(triangles, np.float32))
        self.empty = len(triangles) == 0

    def closest(self, o, d, tmax):
        n = len(o)
        if self.empty or n == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n)
        dist = np.ascontiguousarray(np.minimum(tmax, 3.0e38), np.float32)
        r = self.scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), dists=dist, output=1)
        prim = r["primID"].astype(np.int64)
        t = np.where(prim >= 0, r["tfar"].astype(np.float64), np.inf)
        return t, prim, r["u"].astype(np.float64), r["v"].astype(np.float64)

    def occluded(self, o, d, tmax):
        n = len(o)
        if self.empty or n == 0:
            return np.zeros(n, bool)
        dist = np.ascontiguousarray(np.minimum(tmax, 3.0e38), np.float32)
        r = self.scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), dists=dist,
                           query="OCCLUDED")
        return r != -1


class NumpyBackend(_Backend):
    """Brute-force Moller-Trumbore over all triangles (tests and tiny scenes only)."""

    def __init__(self, triangles: np.ndarray, chunk: int = 1 << 20) -> None:
        tri = np.asarray(triangles, np.float64)
        self.p0 = tri[:, 0]
        self.e1 = tri[:, 1] - tri[:, 0]
        self.e2 = tri[:, 2] - tri[:, 0]
        self.chunk = chunk

    def closest(self, o, d, tmax):
        n, m = len(o), len(self.p0)
        t_best = np.full(n, np.inf)
        prim = np.full(n, -1, np.int64)
        ub = np.zeros(n)
        vb = np.zeros(n)
        if m == 0:
            return t_best, prim, ub, vb
        step = max(1, self.chunk // max(m, 1))
        for s in range(0, n, step):
            oo, dd = o[s:s + step, None, :], d[s:s + step, None, :]
            pv = np.cross(dd, self.e2[None])
            det = np.einsum("rmk,mk->rm", pv, self.e1)
            inv = 1.0 / np.where(np.abs(det) > 1e-300, det, np.inf)
            tv = oo - self.p0[None]
            u = np.einsum("rmk,rmk->rm", tv, pv) * inv
            qv = np.cross(tv, self.e1[None])
            v = np.einsum("rmk,rmk->rm", dd, qv) * inv
            t = np.einsum("rmk,mk->rm", qv, self.e2) * inv
            ok = (np.abs(det) > 1e-300) & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t <= tmax[s:s + step, None])
            t = np.where(ok, t, np.inf)
            k = np.argmin(t, 1)
            rows = np.arange(len(k))
            tb = t[rows, k]
            hit = np.isfinite(tb)
            t_best[s:s + step] = tb
            prim[s:s + step] = np.where(hit, k, -1)
            ub[s:s + step] = u[rows, k]
            vb[s:s + step] = v[rows, k]
        return t_best, prim, ub, vb


class Accel:
    """Closest-hit and shadow queries with per-ray 'ignore this instance'."""

    def __init__(self, triangles: np.ndarray, tri_inst: np.ndarray, *, backend: str = "embree") -> None:
        self.triangles = np.asarray(triangles, np.float64)
        self.tri_inst = np.asarray(tri_inst, np.int64)
        self.backend = EmbreeBackend(self.triangles) if backend == "embree" else NumpyBackend(self.triangles)
        self.rays_cast = 0
        if len(self.triangles):
            ext = self.triangles.reshape(-1, 3)
            self.scale = float(np.max(np.abs(ext)) + np.max(ext.max(0) - ext.min(0)))
        else:
            self.scale = 1.0
        self.eps = 1e-5 * max(self.scale, 1e-6)

    def trace(self, o, d, tmax=None, ignore=None, exempt=None) -> Hits:
        """Closest hit along each ray that is not on instance ``ignore[i]`` (-1: none).

        ``self_hit`` is set where the ray passed through the ignored instance first. ``exempt``
        ([n, 2] triangle index ranges [lo, hi), or None): ignored triangles in row i's range are
        stepped over without setting ``self_hit`` (a fiber hit's own segment and its neighbours).
        """
        n = len(o)
        tmax = np.full(n, np.inf) if tmax is None else np.asarray(tmax, np.float64)
        if exempt is not None:
            return self._trace_exempt(o, d, tmax, ignore, np.asarray(exempt, np.int64))
        self.rays_cast += n
        t, prim, u, v = self.backend.closest(o, d, tmax)
        skip = None
        if ignore is not None:
            skip = (prim >= 0) & (ignore >= 0)
            skip[skip] = self.tri_inst[prim[skip]] == ignore[skip]
        hits = Hits.__new__(Hits)
        hits.t, hits.prim, hits.u, hits.v = t, prim, u, v
        hits.self_hit = np.zeros(n, bool) if skip is None else skip.copy()
        if skip is None or not hits.self_hit.any():
            return hits
        # rays that hit the ignored instance: step past it and cast again (hits keep the
        # first-round values elsewhere; the skipped rows are reset to a miss, then filled)
        idx = np.nonzero(skip)[0]
        t_s = t[idx]
        t[idx], prim[idx], u[idx], v[idx] = np.inf, -1, 0.0, 0.0
        step = t_s + self.eps
        toff = step
        oo = o[idx] + d[idx] * step[:, None]
        for _ in range(MAX_SKIPS - 1):
            self.rays_cast += len(idx)
            t2, prim2, u2, v2 = self.backend.closest(oo, d[idx], tmax[idx] - toff)
            ig = ignore[idx]
            skip = (prim2 >= 0) & (ig >= 0) & (self.tri_inst[np.maximum(prim2, 0)] == ig)
            keep = ~skip
            k = idx[keep]
            hits.t[k] = t2[keep] + toff[keep]
            hits.prim[k] = prim2[keep]
            hits.u[k] = u2[keep]
            hits.v[k] = v2[keep]
            if not skip.any():
                break
            step = t2[skip] + self.eps
            toff = toff[skip] + step
            oo = oo[skip] + d[idx[skip]] * step[:, None]
            idx = idx[skip]
        return hits

    def _trace_exempt(self, o, d, tmax, ignore, exempt) -> Hits:
        """:meth:`trace` with per-row exempt triangle ranges (every ignored hit is stepped over;
        only those outside the row's range set ``self_hit``)."""
        n = len(o)
        hits = Hits(n)
        ignore = np.full(n, -1, np.int64) if ignore is None else np.asarray(ignore, np.int64)
        idx = np.arange(n)
        oo = np.asarray(o, np.float64)
        toff = np.zeros(n)
        for _ in range(MAX_SKIPS):
            if not len(idx):
                break
            self.rays_cast += len(idx)
            t, prim, u, v = self.backend.closest(oo, d[idx], tmax[idx] - toff)
            ig = ignore[idx]
            skip = (prim >= 0) & (ig >= 0) & (self.tri_inst[np.maximum(prim, 0)] == ig)
            keep = ~skip
            k = idx[keep]
            hits.t[k] = t[keep] + toff[keep]
            hits.prim[k] = prim[keep]
            hits.u[k] = u[keep]
            hits.v[k] = v[keep]
            rows, ps = idx[skip], prim[skip]
            counted = (ps < exempt[rows, 0]) | (ps >= exempt[rows, 1])
            hits.self_hit[rows[counted]] = True
            step = t[skip] + self.eps
            toff = toff[skip] + step
            oo = oo[skip] + d[rows] * step[:, None]
            idx = rows
        return hits

    def occluded(self, o, d, tmax):
        self.rays_cast += len(o)
        return self.backend.occluded(o, d, tmax)
