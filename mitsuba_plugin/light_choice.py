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
(``sample_emitter_direction``, ``pdf_emitter_direction``); with fewer emitters :func:`emitter_choice` returns the
scene itself, so images of such scenes do not change.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

#: with at least this many emitters the choice depends on the vertex (the reference renderer draws beyond 8 per kind)
SPATIAL_MIN = 9
#: share of the choice spread uniformly over the emitters (the reference renderer's light_selection.UNIFORM_SHARE)
UNIFORM_SHARE = 0.1


def emitter_choice(mi, scene):
    """An :class:`EmitterChoice` for ``scene``, or the scene itself (Mitsuba's choice) with fewer than SPATIAL_MIN
    emitters."""
    return EmitterChoice(mi, scene) if len(scene.emitters()) >= SPATIAL_MIN else scene


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
    """The emitter choice of the module docstring for ``scene`` (its emitters fixed at construction)."""

    def __init__(self, mi, scene) -> None:
        self.mi, self.scene = mi, scene
        centre, b, factor, const = emitter_terms(mi, scene)
        self.m = len(b)
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
        return (dr.gather(mi.Float, self.factor, j, active) / dr.maximum(d2, dr.gather(mi.Float, self.b, j, active))
                + dr.gather(mi.Float, self.const, j, active))

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
        prob = self._probability(it.p, j, self._total(it.p, active), active)
        return dr.select(active, ds.emitter.pdf_direction(it, ds, active) * prob, 0.0)
