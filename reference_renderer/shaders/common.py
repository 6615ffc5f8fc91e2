"""Shared helpers of the shading vertices (and the integrator's ``max3``, ``unique``) (spec/renderer.md#neural-assets).

A :class:`Hit` gathers, for the rows of one wavefront that hit instances of one asset file, the
world hit point, the object-space point, outgoing direction and shading normal, the geometric
normal and the ray-offset scale, exactly as the rna vertex computes them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..sampling import normalize


@dataclass
class Hit:
    ridx: np.ndarray  # pixel-sample index of each row (into L)
    x: np.ndarray  # world hit point
    d: np.ndarray  # world ray direction
    beta: np.ndarray  # path throughput [n,3]
    prim: np.ndarray
    bu: np.ndarray
    bv: np.ndarray
    inst: np.ndarray
    ng: np.ndarray  # world geometric normal (unflipped)
    scale: np.ndarray  # [n,1] ray offset
    x_obj: np.ndarray
    wo_obj: np.ndarray
    n_obj: np.ndarray  # object-space shading normal (interpolated vertex normals)
    asset: int

    def __len__(self) -> int:
        return len(self.x)


def max3(a: np.ndarray) -> np.ndarray:
    """a.max(1) for [n, 3] rows (elementwise maxima: much faster than a reduction over 3 items)."""
    return np.maximum(np.maximum(a[:, 0], a[:, 1]), a[:, 2])


def unique(a: np.ndarray) -> np.ndarray:
    """np.unique, with a quick path for the common single-value array."""
    if len(a) and (a == a[0]).all():
        return a[:1].copy()
    return np.unique(a)


def gather_hit(integ, r, idx, x, d, beta, prim, bu, bv, inst, asset: int) -> Hit:
    x, d, beta, prim, bu, bv, inst, ridx = x[r], d[r], beta[r], prim[r], bu[r], bv[r], inst[r], idx[r]
    ng = integ.tri_ng[prim]
    scale = (integ.eps * (1.0 + max3(np.abs(x)) / integ.accel.scale))[:, None]
    x_obj = integ.to_object(x, inst, point=True)
    wo_obj = normalize(integ.to_object(-d, inst))
    local = integ.scene.tri_local[prim]
    cn = integ.asset_corner_n[asset][local]
    w0 = 1 - bu - bv
    n_obj = normalize(cn[:, 0] * w0[:, None] + cn[:, 1] * bu[:, None] + cn[:, 2] * bv[:, None])
    return Hit(ridx, x, d, beta, prim, bu, bv, inst, ng, scale, x_obj, wo_obj, n_obj, asset)


class Frames:
    """Per-instance linear maps between world and object space, and the solid-angle Jacobian."""

    def __init__(self, scene) -> None:
        insts = scene.instances
        self.to_world = np.array([i.to_world for i in insts]) if insts else np.zeros((0, 4, 4))
        self.to_obj = np.array([i.to_object for i in insts]) if insts else np.zeros((0, 4, 4))
        self.det_obj = np.abs(np.linalg.det(self.to_obj[:, :3, :3])) if insts else np.zeros(0)
        self.to_obj_t = self.to_obj.transpose(0, 2, 1)  # normals map by the inverse transpose

    def _apply(self, mats, v, inst, point):
        if len(inst) and (inst == inst[0]).all():  # one instance (the common case): no row masks
            o = v @ mats[inst[0], :3, :3]
            return o + mats[inst[0], 3, :3] if point else o
        out = np.empty((len(v), 3))
        for i in np.unique(inst):
            m = inst == i
            o = v[m] @ mats[i, :3, :3]
            out[m] = o + mats[i, 3, :3] if point else o
        return out

    def point_to_world(self, p, inst):
        return self._apply(self.to_world, p, inst, True)

    def dir_to_world(self, v, inst):
        return normalize(self._apply(self.to_world, v, inst, False))

    def normal_to_world(self, n_obj, inst):
        """Unit world normals of object-space normals (rows times to_object's transpose)."""
        return normalize(self._apply(self.to_obj_t, n_obj, inst, False))

    def dir_to_object(self, w_world, inst):
        """(unit object-space direction, J = d omega_obj / d omega_world) of unit world directions.

        For the linear map B (row vectors, w_obj ~ w_world B): J = |det B| / |w_world B|^3 (1 for
        rigid motions and uniform scales)."""
        v = self._apply(self.to_obj, w_world, inst, False)
        ln = np.sqrt((v * v).sum(1))
        ln = np.where(ln > 0, ln, 1.0)
        return v / ln[:, None], self.det_obj[inst] / ln ** 3
