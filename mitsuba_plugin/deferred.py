"""Deferred light-sample rows of ``nasset_path`` (``defer``): the asset transport of a vertex's light sample
only adds to L, so inside the path loop it is queued (a slot from an atomic counter, its inputs and weight
scattered into buffers), and evaluated after the loop on the dense queue, its contributions added to the
lanes' L. Inside the loop an asset vertex's networks run in every llvm packet / cuda warp holding one asset
lane (a symbolic ``if``); past the first bounce most of that work is masked out, and the queue runs it only
for the rows that need it. The estimator and its random numbers are unchanged; L sums its terms in another
order (float32 rounding; two queued rows of one lane are added atomically, in an order that may differ
between runs).

Rows past the queue's capacity (:data:`CAPACITY` per lane of the wavefront) are evaluated in the loop as before.
"""

from __future__ import annotations

import drjit as dr

#: queue rows per lane of the wavefront (asset light samples per sample are ~0.2 in the benchmark scenes;
#: a row takes 76 bytes, so the queue adds 38 bytes per lane)
CAPACITY = 0.5
#: queued per row: instance index, object-space x, frame, w_o, w_i (3 each), h, crossed-the-instance flag,
#: the lane, and the RGB weight beta * emitter weight * MIS weight
FIELDS = ("k", "x", "n", "wo", "wi", "h", "passed", "lane", "weight")


class LightQueue:
    """Buffers of :data:`CAPACITY` rows per lane of an n-lane wavefront (Dr.Jit arrays held outside the loop
    state: this object is not traversed)."""

    def __init__(self, mi, n: int) -> None:
        self.mi, self.cap = mi, max(1, int(n * CAPACITY))
        self.count = dr.zeros(mi.UInt32, 1)
        self.lanes = dr.arange(mi.UInt32, n)
        z = lambda t: dr.zeros(t, self.cap)  # noqa: E731
        self.buf = {"k": z(mi.UInt32), "x": z(mi.Point3f), "n": z(mi.Vector3f), "wo": z(mi.Vector3f), "wi": z(mi.Vector3f),
                    "h": z(mi.Float), "passed": z(mi.Bool), "lane": z(mi.UInt32), "weight": z(mi.Spectrum)}
        dr.make_opaque(self.count, *self.buf.values())

    def push(self, active, **row):
        """Queue the rows of lanes ``active`` (``row``: the :data:`FIELDS` but 'lane'); returns the lanes that did
        not fit (to evaluate in place)."""
        slot = dr.scatter_inc(self.count, self.mi.UInt32(0), active)
        ok = active & (slot < self.cap)
        row = dict(row, lane=self.lanes)
        for name in FIELDS:
            dr.scatter(self.buf[name], row[name], slot, ok)
        return active & ~ok

    def flush(self, assets, tab, L):
        """L [Spectrum] plus the queued rows' light: T(branch) * weight added to each row's lane. ``assets``: the
        (index, asset) of the transport kinds; ``tab``: the integrator's instance tables."""
        from .plugins import _of_asset

        mi = self.mi
        dr.eval(L, self.count)
        n = min(int(self.count[0]), self.cap)
        if n == 0:
            return L
        idx = dr.arange(mi.UInt32, n)
        r = {name: dr.gather(type(self.buf[name]), self.buf[name], idx) for name in FIELDS}
        t = mi.Spectrum(0)
        for a, asset in assets:
            mine = _of_asset(mi, tab, r["k"], a, mi.Bool(True))
            u, s = asset.transport(r["x"], r["n"], r["wo"], r["wi"], r["h"])
            t = dr.select(mine, dr.select(r["passed"], s, u), t)
        L = mi.Spectrum(L)
        dr.scatter_reduce(dr.ReduceOp.Add, L, t * r["weight"], r["lane"])
        return L
