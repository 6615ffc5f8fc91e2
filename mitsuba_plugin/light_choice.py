"""Which emitter a light sample goes to, by where the vertex is (spec/renderer.md#light-selection).

Mitsuba picks the emitter of a light sample by its ``sampling_weight`` alone (the plugin sets it half by power, half
uniform: lights.selection_weights), whatever the vertex: among many lights most samples go to lights far from it.
With more than :data:`SPATIAL_MIN` - 1 emitters, :class:`EmitterChoice` picks emitter j at the vertex x with probability

    P_j(x) = a / m + (1 - a) I_j(x) / sum_i I_i(x),    a = UNIFORM_SHARE,

the importance I_j(x) = w_j / (4 pi max(|x - c_j|^2, b_j)) of an emitter with a position (w_j its sampling weight, c_j
the centre of its shape's bounding box or its position, b_j the square of half that box's diagonal) and
w_j / (pi R^2) at infinity (R: the radius of the scene's bounding sphere): the weight stands for the power that
reaches x, as in the reference renderer's choice. A light sample's pdf is the emitter's own times P_j(x), as is the
pdf a continuation that meets the emitter is weighed with. It offers the two scene methods the integrator calls
(``sample_emitter_direction``, ``pdf_emitter_direction``).

**Emitters that light a cone only.** A spot (``nasset_spot``), a RectLight or DiskLight with a spread below 180 degrees
(half-angle below 90) and a SphereLight with a spot cone below 90 degrees (``nasset_profiled``) send no light outside a
cone (the reference renderer's emission_cone, spec/renderer.md#light-selection): apex a_j, axis
n_j, half-angle theta_j, the apex a point light's position, or for a light surface of bounding radius rho moved back
along the axis until the cone holds the surface (rho / tan(theta) behind a planar light's centre, rho / sin(theta)
behind a sphere's): every ray the light emits leaves a point inside that cone in a direction within theta of n_j, so
it stays inside. I_j(x) is 0 outside the cone, where the light gives x nothing. Such emitters make the choice depend
on the vertex however few there are: under two soft boxes and a faint dome, Mitsuba's choice by weight had 6.7x the
reference renderer's variance (each vertex drew one emitter, often one that lights little of it); with this choice
2.4x, at equal error 3.1x faster (docs/bench-mitsuba-jit.md#cone-lights). With fewer than :data:`SPATIAL_MIN`
emitters and none of these, :func:`emitter_choice` returns the scene itself, so images of such scenes do not change
(there the choice by the vertex had 1.1-1.3x more variance than Mitsuba's).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

#: with at least this many emitters the choice depends on the vertex (the reference renderer draws beyond 8 per kind)
SPATIAL_MIN = 9
#: share of the choice spread uniformly over the emitters (the reference renderer's light_selection.UNIFORM_SHARE)
UNIFORM_SHARE = 0.1
#: up to this many emitters the choice is straight-line code, each emitter's terms literals in the kernel; beyond it, a
#: Dr.Jit loop over arrays of the terms (docs/bench-mitsuba-jit.md#cone-lights: a render under 5 emitters 0.7x the CPU
#: time of the loop's, under 16 about 0.5x)
UNROLLED_MAX = 16


def emitter_choice(mi, scene):
    """An :class:`EmitterChoice` for ``scene``, or the scene itself (Mitsuba's choice) with fewer than SPATIAL_MIN
    emitters none of which lights a cone only (:func:`emitter_cone`)."""
    ems = scene.emitters()
    if len(ems) >= SPATIAL_MIN:
        return EmitterChoice(mi, scene)
    cones = [emitter_cone(mi, e) for e in ems]
    if len(ems) > 1 and any(cone is not None for cone in cones):
        return EmitterChoice(mi, scene, cones=cones)
    return scene


def emitter_cone(mi, e):
    """(apex [3], unit axis [3], cos theta) of the cone outside which emitter ``e`` sends no light (module docstring),
    or None (it may light any point in front of it)."""
    if hasattr(e, "falloff") and hasattr(e, "position"):  # nasset_spot: a point light
        axis = np.asarray(e.axis, np.float64).reshape(3)
        return np.asarray(e.position, np.float64).reshape(3), axis, math.cos(min(e.cone, math.pi))
    if not hasattr(e, "tan_h") or e.get_shape() is None:  # not nasset_profiled
        return None
    box = e.get_shape().bbox()
    lo, hi = np.asarray(box.min, np.float64).reshape(3), np.asarray(box.max, np.float64).reshape(3)
    centre, rho = 0.5 * (lo + hi), 0.5 * float(np.linalg.norm(hi - lo))
    if e.axis is not None and e.cone < 0.5 * math.pi:  # a SphereLight's spot cone: the sphere inside it
        axis = np.asarray(e.axis, np.float64).reshape(3)
        return centre - axis * rho / math.sin(max(e.cone, 1e-6)), axis, math.cos(e.cone)
    if math.isfinite(e.tan_h):  # a half-spread below 90 degrees on a planar light (RectLight, DiskLight)
        normal = _plane_normal(mi, e.get_shape())
        if normal is not None:
            h = math.atan(e.tan_h)
            return centre - normal * rho / max(e.tan_h, 1e-6), normal, math.cos(h)
    return None


def _plane_normal(mi, shape):
    """The unit normal [3] of a planar light surface (the same normal at five sample points, all in its plane), else
    None."""
    ps = shape.sample_position(0.0, mi.Point2f([0.5, 0.1, 0.9, 0.1, 0.9], [0.5, 0.1, 0.1, 0.9, 0.9]))
    n = np.broadcast_to(np.asarray(ps.n, np.float64).reshape(3, -1), (3, 5)).T  # [5,3] (a constant is one column)
    p = np.broadcast_to(np.asarray(ps.p, np.float64).reshape(3, -1), (3, 5)).T
    if not (np.isfinite(n).all() and np.isfinite(p).all()):
        return None
    n0 = n[0] / max(float(np.linalg.norm(n[0])), 1e-300)
    size = max(float(np.ptp(p, 0).max()), 1e-300)
    if np.abs(n @ n0 - 1.0).max() > 1e-4 or np.abs((p - p[0]) @ n0).max() > 1e-4 * size:
        return None
    return n0


def emitter_terms(mi, scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per emitter of ``scene.emitters()``: centre [m,3], b [m] (squared half diagonal of its shape's box, a tiny
    floor for a point), the factor of 1 / max(d^2, b) [m] (0 at infinity) and the constant term [m] (0 with a
    position): the importance is ``factor / max(d^2, b) + constant``."""
    box = scene.bbox()
    radius = 0.5 * float(np.linalg.norm(np.asarray(box.max, np.float64) - np.asarray(box.min, np.float64))) if box.valid() else 1.0
    radius = radius if math.isfinite(radius) and radius > 0 else 1.0
    ems = scene.emitters()
    centre, b, factor, const = np.zeros((len(ems), 3)), np.ones(len(ems)), np.zeros(len(ems)), np.zeros(len(ems))
    for j, e in enumerate(ems):
        w = float(e.sampling_weight())
        w = w if math.isfinite(w) and w > 0 else 0.0
        shape, params = e.get_shape(), mi.traverse(e)
        pos = None
        if shape is not None:
            sb = shape.bbox()
            lo, hi = np.asarray(sb.min, np.float64).reshape(3), np.asarray(sb.max, np.float64).reshape(3)
            pos, b[j] = 0.5 * (lo + hi), max(float(0.25 * np.sum((hi - lo) ** 2)), 1e-30)
        elif "position" in params:
            pos, b[j] = np.asarray(params["position"], np.float64).reshape(3), 1e-30
        elif hasattr(e, "position"):  # the plugin's nasset_spot
            pos, b[j] = np.asarray(e.position, np.float64).reshape(3), 1e-30
        if pos is not None and np.isfinite(pos).all():
            centre[j], factor[j] = pos, w / (4.0 * math.pi)
        else:  # at infinity (or nowhere known): no distance term
            const[j] = w / (math.pi * radius * radius)
    return centre, b, factor, const


class EmitterChoice:
    """The emitter choice of the module docstring for ``scene`` (its emitters fixed at construction); ``unrolled``:
    straight-line code over the emitters (default: up to :data:`UNROLLED_MAX` of them) or a Dr.Jit loop; ``cones``:
    :func:`emitter_cone` of each emitter where the caller has them (else found here)."""

    def __init__(self, mi, scene, unrolled: bool | None = None, cones: list | None = None) -> None:
        self.mi, self.scene = mi, scene
        centre, b, factor, const = emitter_terms(mi, scene)
        self.m = len(b)
        apex, axis, cos_cone = np.zeros((self.m, 3)), np.tile([0.0, 0.0, 1.0], (self.m, 1)), np.full(self.m, -2.0)
        if cones is None:
            cones = [emitter_cone(mi, e) for e in scene.emitters()]
        for j, cone in enumerate(cones):
            if cone is not None:
                apex[j], axis[j], cos_cone[j] = cone
        self.unrolled = self.m <= UNROLLED_MAX if unrolled is None else bool(unrolled)
        # per emitter, Python floats: centre, b, factor, const, apex, axis, cos theta (None: no cone)
        self.terms = [(centre[j].tolist(), float(b[j]), float(factor[j]), float(const[j]),
                       None if cos_cone[j] < -1.5 else (apex[j].tolist(), axis[j].tolist(), float(cos_cone[j])))
                      for j in range(self.m)]
        self.apex = mi.Point3f(*(apex[:, i].tolist() for i in range(3)))
        self.axis = mi.Vector3f(*(axis[:, i].tolist() for i in range(3)))
        self.cos_cone = mi.Float(cos_cone.tolist())  # -2: no cone
        self.centre = mi.Point3f(*(centre[:, i].tolist() for i in range(3)))
        self.b, self.factor, self.const = mi.Float(b.tolist()), mi.Float(factor.tolist()), mi.Float(const.tolist())
        self.ptrs = scene.emitters_dr()
        ids = np.asarray(dr.reinterpret_array(mi.UInt32, self.ptrs), np.int64)
        lut = np.zeros(int(ids.max()) + 1 if len(ids) else 1, np.int64)
        lut[ids] = np.arange(len(ids))
        self.lut = mi.UInt32(lut.tolist())  # emitter registry id -> index j

    def _importance(self, p, j, active):
        mi = self.mi
        c = dr.gather(mi.Point3f, self.centre, j, active)
        d2 = dr.squared_norm(p - c)
        imp = (dr.gather(mi.Float, self.factor, j, active) / dr.maximum(d2, dr.gather(mi.Float, self.b, j, active))
               + dr.gather(mi.Float, self.const, j, active))
        v = p - dr.gather(mi.Point3f, self.apex, j, active)
        lit = dr.dot(v, dr.gather(mi.Vector3f, self.axis, j, active)) >= dr.gather(mi.Float, self.cos_cone, j, active) * dr.norm(v)
        return dr.select(lit, imp, 0.0)

    def _importances(self, p):
        """[m] Float: every emitter's importance at p, straight-line (the unrolled path)."""
        mi = self.mi
        out = []
        for c, b, factor, const, cone in self.terms:
            imp = mi.Float(const)
            if factor > 0:
                imp = imp + factor / dr.maximum(dr.squared_norm(p - mi.Point3f(*c)), b)
            if cone is not None:
                v = p - mi.Point3f(*cone[0])
                imp = dr.select(dr.dot(v, mi.Vector3f(*cone[1])) >= cone[2] * dr.norm(v), imp, 0.0)
            out.append(imp)
        return out

    def _shares(self, imps):
        """[m] Float: P_j from the importances [m] (module docstring)."""
        total = sum(imps[1:], imps[0])
        ok = total > 0
        inv = dr.select(ok, dr.rcp(dr.select(ok, total, 1.0)), 0.0)
        return [UNIFORM_SHARE / self.m + (1.0 - UNIFORM_SHARE) * dr.select(ok, imp * inv, 1.0 / self.m) for imp in imps]

    def probability(self, p, j, active=True):
        """P_j(p) [Float] of emitter indices j [UInt32] at points p."""
        if not self.unrolled:
            return self._probability(p, j, self._total(p, active), active)
        prob = self.mi.Float(0.0)
        for k, pk in enumerate(self._shares(self._importances(p))):
            prob = dr.select(j == k, pk, prob)
        return prob

    def _total(self, p, active):
        mi = self.mi

        def body(j, total):
            return j + 1, total + self._importance(p, j, active)

        _, total = dr.while_loop((mi.UInt32(0), mi.Float(0.0)), lambda j, total: j < self.m, body,
                                 labels=("j", "total"), label="emitter importance")
        return total

    def _probability(self, p, j, total, active):
        share = dr.select(total > 0, self._importance(p, j, active) / dr.select(total > 0, total, 1.0), 1.0 / self.m)
        return UNIFORM_SHARE / self.m + (1.0 - UNIFORM_SHARE) * share

    def choose(self, p, u, active):
        """(index j [UInt32], P_j(p), u rescaled to [0, 1) inside j's slice of the cumulative P(p)) for a uniform u."""
        mi = self.mi
        if self.unrolled:
            chosen, lo, prob, acc = mi.UInt32(self.m - 1), mi.Float(0.0), mi.Float(1.0), mi.Float(0.0)
            done = mi.Bool(False)
            for k, pk in enumerate(self._shares(self._importances(p))):
                take = ~done & ((u < acc + pk) | (k + 1 == self.m))
                chosen, lo, prob = dr.select(take, k, chosen), dr.select(take, acc, lo), dr.select(take, pk, prob)
                done, acc = done | take, acc + pk
            return chosen, prob, dr.clip((u - lo) / dr.maximum(prob, 1e-30), 0.0, 0.99999994)
        total = self._total(p, active)

        def cond(j, acc, chosen, lo, prob, done):
            return ~done & (j < self.m)

        def body(j, acc, chosen, lo, prob, done):
            pj = self._probability(p, j, total, active)
            take = (u < acc + pj) | (j + 1 == self.m)
            return (j + 1, acc + pj, dr.select(take, j, chosen), dr.select(take, acc, lo), dr.select(take, pj, prob),
                    done | take)

        _, _, chosen, lo, prob, _ = dr.while_loop(
            (mi.UInt32(0), mi.Float(0.0), mi.UInt32(0), mi.Float(0.0), mi.Float(1.0), ~mi.Bool(active)), cond, body,
            labels=("j", "acc", "chosen", "lo", "prob", "done"), label="emitter choice")
        return chosen, prob, dr.clip((u - lo) / dr.maximum(prob, 1e-30), 0.0, 0.99999994)

    def sample_emitter_direction(self, it, sample, test_visibility, active=True):
        """Mitsuba's ``Scene.sample_emitter_direction`` with the emitter chosen by :meth:`choose` at ``it.p``."""
        mi = self.mi
        active = mi.Bool(active)
        j, prob, ux = self.choose(it.p, sample.x, active)
        emitter = dr.gather(mi.EmitterPtr, self.ptrs, j, active)
        ds, spec = emitter.sample_direction(it, mi.Point2f(ux, sample.y), active)
        ds.pdf *= prob
        spec = spec / prob
        if test_visibility:
            spec = dr.select(self.scene.ray_test(it.spawn_ray_to(ds.p), active & (ds.pdf != 0)), 0.0, spec)
        return ds, spec

    def pdf_emitter_direction(self, it, ds, active=True):
        """Mitsuba's ``Scene.pdf_emitter_direction`` with the choice's probability of ``ds.emitter`` at ``it.p``."""
        mi = self.mi
        active = mi.Bool(active) & (ds.emitter != None)  # noqa: E711 (a Dr.Jit pointer array)
        j = dr.gather(mi.UInt32, self.lut, dr.reinterpret_array(mi.UInt32, ds.emitter), active)
        prob = self.probability(it.p, j, active)
        return dr.select(active, ds.emitter.pdf_direction(it, ds, active) * prob, 0.0)
