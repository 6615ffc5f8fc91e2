"""Ray casting: Embree scenes (one per separately queried instance, one for the rest), plus a slow numpy reference.

Each triangle carries the id of the instance it belongs to (``tri_inst``). Instances that rays may
ignore (neural assets) get an acceleration structure of their own, so a ray leaving an asset finds
its closest hit on everything else by querying the other structures, and whether it passed through
the asset (the asset's self-occlusion, which picks the rna shadowed/unshadowed branch) by one
occlusion query on the asset's own structure: a ray costs a fixed number of Embree calls however
many of the asset's triangles (fibres) it crosses. Structures whose bounding box a ray misses are
not queried for it.

Instances listed in ``cutout`` (meshes whose material has an opacity, spec/renderer.md#cutouts) share one
structure of their own, queried hit by hit: a hit where ``Accel.presence`` says the surface is absent is stepped
over and the ray goes on (at most :data:`MAX_CUTOUT_STEPS` absent hits per ray; the next one then counts).

Embree structures are built in its robust mode (watertight at shared edges), except those of instances
listed in ``fast``: the prisms of fibre assets, where the robust mode costs 1.3-2x in ray rate (measured in
docs/benchmarks.md, *Dense hair*) and buys nothing, since a prism is closed and convex: a ray slipping
through an edge on its way in still meets the prism's far side.
"""

from __future__ import annotations

import copy

import numpy as np

from nasset_sdk import embree
from nasset_sdk.errors import UsageError

from .sampling import box3

#: bound on the exempt triangles a ray leaving a fiber hit steps over (three convex prisms: at most
#: six crossings, doubled for hits at shared edges and the ray's start on its own prism)
MAX_EXEMPT_STEPS = 16
#: bound on the absent (cut-out) hits one ray steps over
MAX_CUTOUT_STEPS = 64


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
    """Embree (through embreex) over ``triangles`` [F,3,3]; ``robust``: Embree's watertight mode. ``mesh``: the same
    triangles as (points [V,3], faces [F,3]) or (points, faces, quads) when the caller has them: Embree then holds
    shared vertices, less memory (a fibre prism's 28 triangles share 16 points); the hits are the same, the corners
    being the same float32 values. ``quads`` (quads [Q,4], tri [Q,2], corners [Q,2,2] of
    :func:`nasset_sdk.embree.quads_of_pairs`) or None: the triangles in pairs sharing an edge, which Embree then holds as
    quads: the same triangles in half the primitives, and on the long thin sides of fibre prisms, whose triangles
    each span their side's whole box, a faster structure (docs/benchmarks.md#hair-quads); hits are still reported as
    (triangle, barycentrics). Embree reads these arrays in place (:mod:`nasset_sdk.embree`), or, where that cannot be set up,
    embreex copies the triangles element by element."""

    def __init__(self, triangles: np.ndarray, robust: bool = True, mesh: tuple | None = None) -> None:
        from nasset_sdk.extras import require_extras

        require_extras("render", purpose="ray casting with Embree")
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        self.robust = robust
        self.scene = rtcore_scene.EmbreeScene(robust=robust)
        self.empty = len(triangles) == 0
        self.shared = None  # (points, faces or quads) Embree reads in place
        self.quads = None  # (tri [Q,2], corners [Q,2,2]) where Embree holds quads
        if not self.empty:
            quads = mesh[2] if mesh is not None and len(mesh) > 2 else None
            if quads is not None:
                points = embree.shared_points(mesh[0])
                if embree.attach_quads(self.scene, points, quads[0]):
                    self.shared, self.quads = (points, quads[0]), (quads[1], quads[2])
            if self.shared is None:
                buffers = embree.shared_buffers(triangles, mesh)
                if embree.attach_triangles(self.scene, *buffers):
                    self.shared = buffers
                elif mesh is not None:
                    TriangleMesh(self.scene, buffers[0][:-1], buffers[1])
                else:
                    TriangleMesh(self.scene, np.ascontiguousarray(triangles, np.float32))
            # Embree builds its BVH at the first query: build it now, with the scene setup
            self.scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=1)

    def closest(self, o, d, tmax):
        n = len(o)
        if self.empty or n == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int64), np.zeros(n), np.zeros(n)
        dist = np.ascontiguousarray(np.minimum(tmax, 3.0e38), np.float32)
        r = self.scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), dists=dist, output=1)
        prim = r["primID"].astype(np.int64)
        hit = prim >= 0
        t = np.where(hit, r["tfar"].astype(np.float64), np.inf)
        if self.quads is None:
            return t, prim, r["u"].astype(np.float64), r["v"].astype(np.float64)
        u, v = np.zeros(n), np.zeros(n)
        if hit.any():
            rows = np.nonzero(hit)[0]
            prim[rows], u[rows], v[rows] = embree.quad_hits_as_triangles(*self.quads, prim[rows], r["u"][rows], r["v"][rows])
        return t, prim, u, v

    def occluded(self, o, d, tmax):
        n = len(o)
        if self.empty or n == 0:
            return np.zeros(n, bool)
        dist = np.ascontiguousarray(np.minimum(tmax, 3.0e38), np.float32)
        r = self.scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32), dists=dist,
                           query="OCCLUDED")
        return r != -1


class NumpyBackend(_Backend):
    """Brute-force Moller-Trumbore over all triangles (tests and tiny scenes only); float64, so always
    robust (the argument is for the same signature as :class:`EmbreeBackend`)."""

    def __init__(self, triangles: np.ndarray, robust: bool = True, mesh: tuple | None = None, chunk: int = 1 << 20) -> None:
        self.robust = True
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


class _Part:
    """One acceleration structure: the triangles ``ids`` [k] (global indices) and their bounding box."""

    __slots__ = ("ids", "backend", "lo", "hi", "inst", "box", "cutout")

    def __init__(self, ids, triangles, inst, make, robust: bool = True, box=None, mesh=None, cutout: bool = False) -> None:
        self.ids = ids
        self.inst = inst  # the instance held alone, or -1 for the rest of the scene
        self.cutout = cutout  # triangles whose presence is tested hit by hit (Accel.presence)
        contiguous = len(ids) and ids[-1] - ids[0] + 1 == len(ids)  # a scene instance: a view, no copy
        tri = triangles[ids[0]:ids[-1] + 1] if contiguous else triangles[ids]
        self.backend = make(tri, robust, mesh if contiguous else None)
        if box is None:
            box = box3(tri.reshape(-1, 3)) if len(tri) else (np.zeros(3), -np.ones(3))
        self.lo, self.hi = box
        pad = 1e-6 * (1.0 + np.abs(self.hi).max() + np.abs(self.lo).max())
        self.box = [(float(a), float(b)) for a, b in zip(self.lo - pad, self.hi + pad, strict=True)]  # padded, per axis

    def rows_hitting_box(self, o, inv, tmax, rows):
        """Subset of ``rows`` (sorted) whose ray segment [0, tmax] meets the bounding box (slab test; padded).

        o [n,3] origins, inv [n,3] reciprocal directions (:func:`reciprocal`), tmax [n]. Per axis on
        columns, without [k,3] temporaries or NaN-aware reductions (``inv`` is finite: no 0 * inf)."""
        if not len(rows):
            return rows
        full = len(rows) == len(o)  # every row (rows is sorted and unique): no gathers
        oo, ii = (o, inv) if full else (o[rows], inv[rows])
        t_near = np.zeros(len(rows))
        t_far = np.array(tmax if full else tmax[rows], np.float64)
        for k, (lo, hi) in enumerate(self.box):
            a = lo - oo[:, k]
            a *= ii[:, k]
            b = hi - oo[:, k]
            b *= ii[:, k]
            np.maximum(t_near, np.minimum(a, b), out=t_near)
            np.minimum(t_far, np.maximum(a, b), out=t_far)
        return rows[t_near <= t_far]


def reciprocal(d: np.ndarray) -> np.ndarray:
    """1 / d [n,3], components below 1e-200 in magnitude read as 1e-200: finite, so the slab test never forms
    0 * inf, and its products (offsets below 1e100 times at most 1e200) do not overflow."""
    return 1.0 / np.where(np.abs(d) < 1e-200, 1e-200, d)


class Accel:
    """Closest-hit and shadow queries with per-ray 'ignore this instance'.

    ``separate`` [n_instances] bool: instances that rays may ignore (each gets its own structure);
    None: every instance. Ignoring an instance that is not separate is a ``USAGE`` error. ``fast``
    [n_instances] bool or None: separate instances made of closed convex pieces (fibre prisms) whose
    structure may use Embree's faster non-robust mode (see the module docstring). ``boxes``: per instance
    (lo [3], hi [3]) of its triangles (None for one without), when the caller has them; else computed here.
    ``meshes``: per instance its triangles as (points [V,3], faces [k,3]) or (points, faces, quads or None), or None
    (see :class:`EmbreeBackend`), used for separate instances. ``cutout`` [n_instances] bool or None: instances (not
    separate) whose hits are
    kept only where ``presence(triangles [k], u [k], v [k]) -> bool [k]`` says so (set :attr:`presence`; while it
    is None they are opaque).
    """

    def __init__(self, triangles: np.ndarray, tri_inst: np.ndarray, *, backend: str = "embree",
                 separate: np.ndarray | None = None, fast: np.ndarray | None = None, boxes: list | None = None,
                 meshes: list | None = None, cutout: np.ndarray | None = None) -> None:
        self.triangles = np.asarray(triangles, np.float64)
        self.tri_inst = np.asarray(tri_inst, np.int64)
        make = EmbreeBackend if backend == "embree" else NumpyBackend
        n_inst = int(self.tri_inst.max()) + 1 if len(self.tri_inst) else 0
        sep = np.ones(n_inst, bool) if separate is None else np.asarray(separate, bool)[:n_inst]
        quick, cut = np.zeros(n_inst, bool), np.zeros(n_inst, bool)
        if fast is not None:
            quick[:min(n_inst, len(fast))] = np.asarray(fast, bool)[:n_inst]
        if cutout is not None:
            cut[:min(n_inst, len(cutout))] = np.asarray(cutout, bool)[:n_inst]
        self.presence = None
        self.parts: list[_Part] = []
        self.inst_part = np.full(max(n_inst, len(sep)), -1, np.int64)
        order = np.argsort(self.tri_inst, kind="stable")
        bounds = np.searchsorted(self.tri_inst[order], np.arange(n_inst + 1))
        rest, cut_rest = [], []
        for i in range(n_inst):
            ids = order[bounds[i]:bounds[i + 1]]
            if not len(ids):
                continue
            box = boxes[i] if boxes is not None and i < len(boxes) else None
            if sep[i]:
                self.inst_part[i] = len(self.parts)
                mesh = meshes[i] if meshes is not None and i < len(meshes) else None
                self.parts.append(_Part(ids, self.triangles, i, make, robust=not quick[i], box=box, mesh=mesh))
            else:
                (cut_rest if cut[i] else rest).append((ids, box))
        for group, is_cut in ((rest, False), (cut_rest, True)):
            if group:
                known = all(b is not None for _, b in group)
                box = (np.min([b[0] for _, b in group], 0), np.max([b[1] for _, b in group], 0)) if known else None
                self.parts.append(_Part(np.concatenate([ids for ids, _ in group]), self.triangles, -1, make, box=box,
                                        cutout=is_cut))
        self.rays_cast = 0
        if len(self.triangles):  # from the parts' boxes (together: every triangle), not another pass over them
            lo = np.min([p.lo for p in self.parts], 0)
            hi = np.max([p.hi for p in self.parts], 0)
            self.scale = float(np.maximum(np.abs(lo), np.abs(hi)).max() + (hi - lo).max())
        else:
            self.scale = 1.0
        self.eps = 1e-5 * max(self.scale, 1e-6)

    def view(self) -> "Accel":
        """This accelerator for one render thread: the same acceleration structures (Embree's queries are
        thread-safe), its own ray counter and :attr:`presence` callback (None until set)."""
        v = copy.copy(self)
        v.rays_cast, v.presence = 0, None
        return v

    def _closest_in(self, part, o, d, inv, tmax, rows, hits) -> None:
        """Update ``hits`` rows with closer hits on ``part`` (rays limited to the current closest hit)."""
        lim = np.minimum(tmax, hits.t)
        rows = part.rows_hitting_box(o, inv, lim, rows)
        if not len(rows):
            return
        if part.cutout and self.presence is not None:
            t, prim, u, v = self._closest_present(part, o[rows], d[rows], lim[rows])
        else:
            self.rays_cast += len(rows)
            every = len(rows) == len(o)  # every ray: no gathers
            t, prim, u, v = part.backend.closest(o, d, lim) if every else part.backend.closest(o[rows], d[rows], lim[rows])
        better = (prim >= 0) & (t < (hits.t if len(rows) == len(o) else hits.t[rows]))
        r = rows[better]
        hits.t[r], hits.prim[r], hits.u[r], hits.v[r] = t[better], part.ids[prim[better]], u[better], v[better]

    def trace(self, o, d, tmax=None, ignore=None, exempt=None, self_rows=None) -> Hits:
        """Closest hit along each ray that is not on instance ``ignore[i]`` (-1: none).

        ``self_hit`` is set where the ray passed through the ignored instance before that hit (or
        before tmax). ``exempt`` ([n, 2] triangle index ranges [lo, hi), or None): ignored triangles in
        row i's range do not set ``self_hit`` (a fiber hit's own segment and its neighbours). ``self_rows``
        ([n] bool, or None: every row): the rows whose ``self_hit`` is wanted; the others are left False and
        cost no query on their instance's structure (rays whose branch was chosen elsewhere).
        """
        o, d, tmax, ignore, same, ids = self._rays(o, d, tmax, ignore)
        n = len(o)
        hits = Hits(n)
        all_rows = np.arange(n)
        inv = reciprocal(d)
        for part in self.parts:
            if part.inst < 0 or (same and ids[0] != part.inst):
                rows = all_rows
            else:
                rows = all_rows[:0] if same else np.nonzero(ignore != part.inst)[0]
            self._closest_in(part, o, d, inv, tmax, rows, hits)
        own = (all_rows if ids[0] >= 0 else all_rows[:0]) if same else np.nonzero(ignore >= 0)[0]
        if self_rows is not None:
            own = own[np.asarray(self_rows, bool)[own]]
        self._own_hits(o, d, inv, np.minimum(tmax, hits.t), ignore, exempt, own, same, ids, hits.self_hit)
        return hits

    def passes_own(self, o, d, tmax, inst, exempt=None) -> np.ndarray:
        """[n] bool: the ray segment [0, tmax] meets a triangle of instance ``inst[i]`` (outside row i's
        ``exempt`` range, as :meth:`trace`'s ``self_hit``), other objects not considered: the rna branch test
        alone (spec/kinds/rna.md#near-field-fetch)."""
        o, d, tmax, inst, same, ids = self._rays(o, d, tmax, inst)
        out = np.zeros(len(o), bool)
        own = np.arange(len(o)) if same else np.nonzero(inst >= 0)[0]
        if same and (not len(o) or ids[0] < 0):
            own = own[:0]
        self._own_hits(o, d, reciprocal(d), tmax, inst, exempt, own, same, ids, out)
        return out

    def _rays(self, o, d, tmax, ignore):
        """(o, d, tmax [n], ignore [n], same, ids) of a query: float64 rays, tmax and ignore filled in; ``same``:
        one ignored instance for every row (no searches), ``ids`` the ignored instances (the first row's when same)."""
        o = np.asarray(o, np.float64)
        d = np.asarray(d, np.float64)
        n = len(o)
        tmax = np.full(n, np.inf) if tmax is None else np.broadcast_to(np.asarray(tmax, np.float64), (n,))
        ignore = np.full(n, -1, np.int64) if ignore is None else np.asarray(ignore, np.int64)
        same = n > 0 and bool((ignore == ignore[0]).all())  # one value (all camera rays, one asset's rays): no searches
        ids = ignore[:1] if same else np.unique(ignore)
        if np.any(ids >= len(self.inst_part)) or np.any(self.inst_part[ids[ids >= 0]] < 0):
            raise UsageError("Accel.trace: an ignored instance has no acceleration structure of its own (Accel separate=...)")
        return o, d, tmax, ignore, same, ids

    def _own_hits(self, o, d, inv, lim, ignore, exempt, own, same, ids, out) -> None:
        """Set ``out[own]``: the ray segment [0, lim] of row i meets instance ``ignore[i]`` outside its exempt range."""
        if not len(own):
            return
        part_of = self.inst_part[ignore[own]]
        exempt = None if exempt is None else np.asarray(exempt, np.int64)
        stepping = None if exempt is None else exempt[own, 0] < exempt[own, 1]
        for p in (self.inst_part[ids[:1]] if same else np.unique(part_of)):
            mine = own if same else own[part_of == p]
            step = None if stepping is None else (stepping if same else stepping[part_of == p])
            rows = mine if step is None else mine[~step]  # nothing exempt: one occlusion query
            out[rows] = self._occluded_in(self.parts[p], o, d, inv, lim, rows)
            if step is not None and step.any():
                rows = mine[step]
                out[rows] = self._passes_outside(self.parts[p], o, d, inv, lim, rows, exempt)

    def _closest_present(self, part, o, d, tmax):
        """(t, prim, u, v) [n] of the closest hit on the cut-out ``part`` where the surface is present: absent hits
        are stepped over by eps (as :meth:`_passes_outside` steps over exempt ones); prim is part-local, -1: none."""
        n = len(o)
        t_out, prim_out = np.full(n, np.inf), np.full(n, -1, np.int64)
        u_out, v_out = np.zeros(n), np.zeros(n)
        idx, toff, oo = np.arange(n), np.zeros(n), o
        for step in range(MAX_CUTOUT_STEPS):
            if not len(idx):
                break
            self.rays_cast += len(idx)
            t, prim, u, v = part.backend.closest(oo, d[idx], np.maximum(tmax[idx] - toff, 0.0))
            hit = prim >= 0
            keep = hit.copy()
            if step < MAX_CUTOUT_STEPS - 1 and hit.any():
                keep[hit] = self.presence(part.ids[prim[hit]], u[hit], v[hit])
            r = idx[keep]
            t_out[r], prim_out[r], u_out[r], v_out[r] = t[keep] + toff[keep], prim[keep], u[keep], v[keep]
            go = hit & ~keep
            ahead = t[go] + self.eps
            idx, toff = idx[go], toff[go] + ahead
            oo = oo[go] + d[idx] * ahead[:, None]
        return t_out, prim_out, u_out, v_out

    def _occluded_in(self, part, o, d, inv, tmax, rows) -> np.ndarray:
        """[len(rows)] bool: any triangle of ``part`` on the ray segment [0, tmax] (a present one, on a cut-out part)."""
        if part.cutout and self.presence is not None:
            sel = part.rows_hitting_box(o, inv, tmax, rows)
            out = np.zeros(len(rows), bool)
            if len(sel):
                out[np.searchsorted(rows, sel)] = self._closest_present(part, o[sel], d[sel], tmax[sel])[1] >= 0
            return out
        sel = part.rows_hitting_box(o, inv, tmax, rows)
        if len(sel) == len(o):  # every ray (then rows holds every ray too): no gathers
            self.rays_cast += len(sel)
            return part.backend.occluded(o, d, tmax)
        out = np.zeros(len(rows), bool)
        if len(sel):
            self.rays_cast += len(sel)
            occ = part.backend.occluded(o[sel], d[sel], tmax[sel])
            out[np.searchsorted(rows, sel)] = occ
        return out

    def _passes_outside(self, part, o, d, inv, tmax, rows, exempt) -> np.ndarray:
        """[len(rows)] bool: a triangle of ``part`` outside row i's exempt range lies on [0, tmax].

        Exempt hits are stepped over by eps (at most :data:`MAX_EXEMPT_STEPS` per ray); only rays whose
        nearest hit was exempt are cast again. The search starts at eps too: a ray leaving a fibre hit
        would otherwise re-hit the (exempt) triangle it starts on about half the time, one more query
        (spec/renderer.md#fibers)."""
        out = np.zeros(len(rows), bool)
        sel = part.rows_hitting_box(o, inv, tmax, rows)
        pos = np.searchsorted(rows, sel)
        oo, toff = o[sel] + d[sel] * self.eps, np.full(len(sel), self.eps)
        for _ in range(MAX_EXEMPT_STEPS):
            if not len(sel):
                break
            self.rays_cast += len(sel)
            t, prim, _, _ = part.backend.closest(oo, d[sel], tmax[sel] - toff)
            hit = prim >= 0
            g = np.where(hit, part.ids[np.maximum(prim, 0)], -1)
            ex = hit & (g >= exempt[sel, 0]) & (g < exempt[sel, 1])
            out[pos[hit & ~ex]] = True
            step = t[ex] + self.eps
            sel, pos = sel[ex], pos[ex]
            toff = toff[ex] + step
            oo = oo[ex] + d[sel] * step[:, None]
        return out

    def occluded(self, o, d, tmax):
        """[n] bool: any triangle on the ray segment [0, tmax] (no instance ignored)."""
        o = np.asarray(o, np.float64)
        d = np.asarray(d, np.float64)
        tmax = np.broadcast_to(np.asarray(tmax, np.float64), (len(o),))
        out = np.zeros(len(o), bool)
        inv = reciprocal(d)
        for part in self.parts:
            rows = np.nonzero(~out)[0]
            if not len(rows):
                break
            out[rows] = self._occluded_in(part, o, d, inv, tmax, rows)
        return out
