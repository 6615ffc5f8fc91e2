"""Mitsuba plugins of the nasset package, registered from Python (:func:`register`):

- BSDF ``nasset`` (``filename``, ``to_world``): marks a shape as an instance of a neural asset
  (its fallback mesh, in world space). It reflects nothing by itself: the integrator shades it.
- Integrator ``nasset_path`` (``max_depth``, ``rr_depth``, counted like Mitsuba's ``path``: 2 = direct
  lighting, i.e. spec/renderer.md's max_depth + 1; ``lobe``; ``defer``: the light samples' asset transports
  queued and evaluated densely after the path loop, :mod:`.deferred`): Mitsuba's unidirectional path tracer
  (BSDF sampling + emitter sampling with power-heuristic MIS, Russian roulette) that, at a hit on an
  asset instance, applies spec/renderer.md#neural-assets: object-space inputs, a light sample whose
  shadow ray ignores the instance and picks the shadowed branch when the instance lies on it,
  ``w_light = power(p_light, p_A)``, and a continuation of weight T / p_A that ignores the instance, drawn
  by the asset technique: the kind's object-space sampler mapped to world, p_A = pdf_obj J (rna: the
  continuation mixture of :mod:`.lobes`; neupress: its Gaussian lobe, spec/renderer.md#neupress), or the
  uniform world sphere (p_A = 1/4pi; neupress without ``sampling``, and every asset with ``lobe`` false).
  An rna or neupress asset with a near-field fetch f > 0 (spec/kinds/rna.md#near-field-fetch) takes its light sample at
  the fetch point p (the shadow ray from p, the branch a second ray from x) and its continuation's radiance
  from p (the branch traced from x at the vertex); scenes without one trace the kernel they always did.
  Fiber assets (spec/renderer.md#fibers): tangent and h inputs from the hit's segment, and the triangles
  of that segment and its neighbours do not count as crossing the instance; a ray leaving a fiber
  instance costs O(1) queries on split structures (:func:`_trace`), not one per prism surface it crosses. 8dna assets
  (spec/renderer.md#8dna) take their own light samples (at x_o and at u_i) and continuation from
  :func:`.eightdna.vertex`. ``prt`` (default false): neupress instances are shaded by their PRT
  component under the scene's domes and end the path there (:mod:`.prt`; spec/renderer.md#neupress).
  Every per-sample step is Dr.Jit (one kernel per render on llvm and cuda).
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

from nasset_sdk.errors import error

from . import eightdna
from . import prt as prt_mode
from .deferred import LightQueue
from .eightdna import EightDnaJit
from .light_choice import emitter_choice
from .neupress import NeupressJit
from .rna import RnaJit

INTEGRATOR = "nasset_path"
BSDF = "nasset"
FOUR_PI = 4.0 * math.pi
#: how many surfaces of the ignored instance one ray may pass through before it is cut: only a guard
#: against rays that make no progress (spec/renderer.md#fibers: no crossing limit; in rna_fiber_dense
#: rays cross more than 16 prism faces of their own asset)
MAX_SKIPS = 1 << 16
#: shape id prefixes of a USD scene's light surfaces (spec/renderer.md#light-surfaces: the sphere of a SphereLight, the
#: rectangle of a RectLight, the ellipse of a DiskLight, the side of a CylinderLight): every ray passes through them
#: (Mitsuba's own lights block rays, as in an XML scene), but for an opaque one (:data:`OPAQUE_MARK`); those hidden
#: from camera rays (``nasset:cameraVisibility`` false) show camera rays nothing
LIGHT_SURFACE_PREFIX = "nasset_lightsurface_"
HIDDEN_PREFIX = LIGHT_SURFACE_PREFIX + "hidden_"
#: in a light surface's id after its prefix: an opaque one (``nasset:opaqueSurface``: rays end on its emitting side)
OPAQUE_MARK = "opaque_"
#: scenes with at most this many fiber instances trace rays leaving one on split structures (:func:`split_scenes`)
MAX_SPLIT_INSTANCES = 8

#: kind -> its Dr.Jit evaluator class (each has ``kind``, ``fiber``, ``geometry``). rna and neupress:
#: ``transport(x, n, wo, wi, h) -> (unshadowed, shadowed)`` Color3f (1/sr) and ``technique(x, n, wo) -> None``
#: (uniform world sphere) or an object-space sampler with ``sample(u)`` and ``pdf(w)``; 8dna: its own vertex
#: estimator (:func:`.eightdna.vertex`)
JIT_KINDS = {"rna": RnaJit, "neupress": NeupressJit, "8dna": EightDnaJit}
_ASSETS: dict[tuple, object] = {}  # (variant, file, its identity) -> asset read once per process and file version
_REGISTERED: set[str] = set()


def asset_for(mi, filename: str):
    """The asset of ``filename`` read once per process and variant, by its kind (:data:`JIT_KINDS`; typed
    errors from the SDK, SCENE_UNSUPPORTED for other kinds; NEAR_FIELD_INVALID for a bad ``nasset:nearFieldFetch``, or
    a non-zero one on kind 8dna)."""
    from nasset_sdk.asset import Asset
    from nasset_sdk.safeopen import file_identity

    key = (mi.variant(), str(filename), file_identity(filename))  # a file rewritten in place is read again
    if key not in _ASSETS:
        asset = Asset.open(filename)
        kind = asset.kind
        asset.near_field_fetch  # noqa: B018 (read for its check: spec/kinds/rna.md#near-field-fetch)
        if kind not in JIT_KINDS:
            raise error("SCENE_UNSUPPORTED", f"the Mitsuba plugin renders kinds {', '.join(JIT_KINDS)}, not {kind!r}",
                        file=str(filename))
        for old in [k for k in _ASSETS if k[:2] == key[:2]]:  # an earlier version of the file
            del _ASSETS[old]
        _ASSETS[key] = JIT_KINDS[kind](mi, filename)
    return _ASSETS[key]


def _mis(a, b):
    """Power heuristic a^2 / (a^2 + b^2), 0 where both are 0."""
    import drjit as dr

    a2, b2 = dr.square(a), dr.square(b)
    return dr.select(a2 + b2 > 0, a2 / dr.select(a2 + b2 > 0, a2 + b2, 1.0), 0.0)


def register(mi) -> None:
    """Register the ``nasset`` BSDF and the ``nasset_path`` integrator for the active variant (idempotent)."""
    import drjit as dr

    if mi.variant() in _REGISTERED:
        return

    class NassetBSDF(mi.BSDF):
        """Marker BSDF of an asset instance: ``filename`` (the asset), ``to_world`` (its instance transform)."""

        def __init__(self, props):
            super().__init__(props)
            self.filename = str(props.get("filename", ""))
            if not self.filename:
                raise error("SCENE_INVALID", "bsdf 'nasset' needs a 'filename' property")
            self.to_world = np.array(props.get("to_world", mi.ScalarTransform4f()).matrix, np.float64).reshape(4, 4)
            self.asset = asset_for(mi, self.filename)
            self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
            self.m_components = [self.m_flags]

        def sample(self, ctx, si, sample1, sample2, active=True):
            return dr.zeros(mi.BSDFSample3f), mi.Spectrum(0)

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return mi.Spectrum(0), mi.Float(0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"NassetBSDF[filename={self.filename}]"

    class NassetPathIntegrator(mi.SamplingIntegrator):
        def __init__(self, props):
            super().__init__(props)
            self.max_depth = int(props.get("max_depth", 5))
            self.rr_depth = int(props.get("rr_depth", 5))
            self.lobe = bool(props.get("lobe", True))  # False: the uniform world sphere for every asset
            self.prt = bool(props.get("prt", False))  # True: neupress assets shaded by PRT (.prt)
            # True: the light samples' asset transports run after the path loop on a dense queue (.deferred)
            self.defer = bool(props.get("defer", True))
            if self.max_depth < 1:
                raise error("SCENE_INVALID", f"nasset_path: max_depth must be >= 1 (got {self.max_depth})")

        def instances(self, scene):
            """(assets, instance-of-shape LUT UInt32 [max registry id + 1], per-instance Float tables); built at
            every trace of :meth:`sample` (once per render call: a Python loop over the scene's shapes)."""
            return _instance_tables(mi, scene)

        @dr.syntax
        def sample(self, scene, sampler, ray, medium=None, active=True):
            import mitsuba as mi  # dr.syntax recompiles this method without register()'s closure
            assets, lut, tab = self.instances(scene)
            split_scenes(mi, scene)  # built here, outside the symbolic loop whose rays use them
            hidden = shapes_named(mi, scene, HIDDEN_PREFIX)  # light surfaces camera rays pass through (None: none)
            lights = PassThrough.of(mi, scene)  # light surfaces and absent cut-outs rays pass through (None: none)
            emitters = emitter_choice(mi, scene)  # the scene itself (Mitsuba's choice) unless many emitters or cone lights
            env = scene.environment()
            env_hidden = env is not None and not getattr(env, "camera_visible", True)  # its camera view: eval_camera
            prt = prt_mode.tables(mi, scene, assets, tab) if self.prt else None  # PRT mode: neupress by .prt
            shaded = _by_kind(assets, "rna") + ([] if self.prt else _by_kind(assets, "neupress"))  # transport + technique
            eight = _by_kind(assets, "8dna")
            ctx = mi.BSDFContext()
            ray = mi.Ray3f(ray)
            L = mi.Spectrum(0)
            beta = mi.Spectrum(1)
            depth = mi.UInt32(0)
            active = mi.Bool(active)
            prev_si = dr.zeros(mi.SurfaceInteraction3f)
            prev_pdf = mi.Float(1.0)
            prev_delta = mi.Bool(True)
            ignore = mi.UInt32(0)  # registry id of the instance the ray leaves (0: none)
            ign_lo = mi.UInt32(0)  # its exempt triangle range (a fiber hit's segment and neighbours)
            ign_hi = mi.UInt32(0)
            pending = mi.Bool(False)  # the ray leaves an asset: its weight waits for the branch
            t_un = mi.Spectrum(0)
            t_sh = mi.Spectrum(0)
            valid = mi.Bool(False)
            # spec/kinds/rna.md#near-field-fetch: with an instance that fetches its light off the hit, a continuation
            # leaving its fetch point (c_moved) takes its branch from the ray traced from x (c_passed)
            near = any(getattr(a, "fetch", 0.0) > 0 for a in assets)
            c_moved = mi.Bool(False)
            c_passed = mi.Bool(False)
            # held out of the loop state (not a Dr.Jit tree): the queue's buffers are written, never carried
            queue = LightQueue(mi, dr.width(ray)) if self.defer and shaded else None

            while dr.hint(active, max_iterations=self.max_depth + 1, label="nasset_path"):
                emission = _light_emission(mi, scene, emitters, prev_si, prev_pdf, prev_delta)  # MIS-weighted, from prev_si
                si, passed, via_lights = _trace_onward(mi, scene, ray, ignore, ign_lo, ign_hi, active, lights, hidden,
                                                       depth == 0, emission)
                if dr.hint(near, mode="scalar"):
                    passed = dr.select(c_moved, c_passed, passed)
                beta[pending] *= dr.select(passed, t_sh, t_un)
                valid |= active & si.is_valid()
                L += beta * via_lights

                # emission reached by the previous vertex's continuation
                seen = emission(si, active)
                if dr.hint(env_hidden, mode="scalar"):  # an escaping camera ray sees only the lights shown to the camera
                    seen = dr.select((depth == 0) & ~si.is_valid(), env.eval_camera(si, active), seen)  # (MIS weight 1)
                L += beta * seen

                active_next = active & (depth + 1 < self.max_depth) & si.is_valid()
                sid = dr.reinterpret_array(mi.UInt32, si.shape)
                # shapes registered after the last asset have ids past the table: not assets (a masked gather
                # reads 0; clamping the id onto the last entry would make them that asset)
                inst = dr.gather(mi.UInt32, lut, sid, active_next & (sid < len(lut)))
                on_asset = active_next & (inst > 0)
                on_plain = active_next & (inst == 0)
                bsdf = si.bsdf(ray)
                k = inst - 1
                x_o, n_o, wo_o, h_o, ex_lo, ex_hi = _asset_inputs(mi, assets, tab, k, si, -ray.d, on_asset)
                on_8 = mi.Bool(False)  # 8dna hits: their own light samples and continuation (eightdna.vertex)
                if dr.hint(len(eight) > 0, mode="scalar"):
                    on_8 = on_asset & (dr.gather(mi.UInt32, tab["kind8"], k, on_asset) > 0)
                on_shaded = on_asset & ~on_8
                if dr.hint(prt is not None, mode="scalar"):  # PRT vertices end their path here
                    on_prt = _prt_lanes(mi, prt, tab, k, on_shaded)
                    on_shaded &= ~on_prt
                    active_next &= ~on_prt
                    if on_prt:  # symbolic: the gathers run only in packets with a lane on a PRT asset
                        L = _prt_vertex(mi, prt, tab, k, si, wo_o, on_prt, L, beta)

                # light sample; at an asset the shadow ray ignores the instance and records crossing it. An instance
                # with a near-field fetch: the light is sampled at the fetch point p and the shadow ray leaves p, the
                # branch is a second ray from x along the sample's direction
                si_l, moved = si, mi.Bool(False)
                if dr.hint(near, mode="scalar"):
                    moved, p_f = _fetch_point(mi, tab, k, si, on_asset & ~on_8)
                    si_l = mi.SurfaceInteraction3f(si)
                    si_l.p = p_f
                ds_em, em_weight = emitters.sample_emitter_direction(si_l, sampler.next_2d(), False, active_next)
                active_em = active_next & (ds_em.pdf != 0.0) & ~on_8
                ray_em = si.spawn_ray_to(ds_em.p)
                if dr.hint(near, mode="scalar"):
                    ray_em = dr.select(moved, _ray_to_from(mi, si, p_f, ds_em.p), ray_em)
                si_sh, passed_sh = _occluder(mi, scene, ray_em, dr.select(on_asset, sid, 0), ex_lo, ex_hi, active_em, lights)
                active_em &= ~si_sh.is_valid()
                if dr.hint(near, mode="scalar"):
                    ray_x = si.spawn_ray(ds_em.d)
                    ray_x.maxt = ds_em.dist * (1.0 - mi.math.ShadowEpsilon)
                    passed_sh = dr.select(moved, _crosses(mi, scene, ray_x, sid, ex_lo, ex_hi, active_em & moved), passed_sh)
                val, pdf = bsdf.eval_pdf(ctx, si, si.to_local(ds_em.d), on_plain & active_em)
                L[on_plain & active_em] += beta * dr.select(ds_em.delta, 1.0, _mis(ds_em.pdf, pdf)) * val * em_weight

                # asset vertex: object-space inputs, both light sample and continuation transports; the
                # continuation from the asset technique (uniform world sphere unless the kind has a sampler)
                u_c = sampler.next_2d()
                wi_c = mi.warp.square_to_uniform_sphere(u_c)
                p_c = mi.Float(1.0 / FOUR_PI)
                if dr.hint(len(shaded) > 0, mode="scalar"):
                    if on_shaded:  # symbolic: the networks run only in llvm packets / cuda warps with a lane on an asset
                        L, t_un, t_sh, wi_c, p_c = _asset_vertex(mi, shaded, tab, k, x_o, n_o, wo_o, h_o, ds_em, em_weight, passed_sh,
                                                                 active_em, on_shaded, u_c, self.lobe, L, beta, wi_c, p_c, queue)
                if dr.hint(len(eight) > 0, mode="scalar"):
                    rnd8 = eightdna.draw(sampler)  # on every lane, outside the symbolic if: the same sample sequence
                    d8, pdf8, alive8, from_u8, origin8 = mi.Vector3f(0), mi.Float(0), mi.Bool(False), mi.Bool(False), mi.Point3f(0)
                    if on_8:  # symbolic, like the transport kinds: the flows run only in packets with an 8dna lane
                        L, t_un, t_sh, d8, pdf8, alive8, from_u8, origin8 = _eightdna_vertex(
                            mi, scene, rnd8, si, -ray.d, sid, eight, tab, k, x_o, n_o, wo_o, on_8, L, beta, t_un, t_sh, lights,
                            emitters)

                # continuation
                bs, bsdf_weight = bsdf.sample(ctx, si, sampler.next_1d(), sampler.next_2d(), on_plain)
                d_next = dr.select(on_asset, wi_c, si.to_world(bs.wo))
                prev_si = dr.detach(si, True)
                prev_pdf = dr.select(on_asset, p_c, bs.pdf)
                if dr.hint(len(eight) > 0, mode="scalar"):
                    d_next = dr.select(on_8, d8, d_next)
                    prev_pdf = dr.select(on_8, pdf8, prev_pdf)
                    active_next &= ~on_8 | alive8
                ray = si.spawn_ray(d_next)
                if dr.hint(near, mode="scalar"):  # the branch from x now, the radiance from p at the next trace
                    c_moved = moved & active_next
                    c_passed = _crosses(mi, scene, ray, sid, ex_lo, ex_hi, c_moved)
                    ray.o = dr.select(c_moved, p_f + _offset(mi, si, d_next), ray.o)
                    prev_si.p = dr.select(c_moved, p_f, prev_si.p)  # light pdfs of MIS seen from p
                if dr.hint(len(eight) > 0, mode="scalar"):
                    from_u = on_8 & from_u8  # a flow continuation leaves u_i M itself (no offset)
                    ray.o = dr.select(from_u, origin8, ray.o)
                    prev_si.p = dr.select(from_u, origin8, prev_si.p)
                beta[on_plain] *= bsdf_weight
                prev_delta = on_plain & mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
                pending = mi.Bool(on_asset)
                ignore = dr.select(on_asset, sid, 0)
                ign_lo = dr.select(on_asset, ex_lo, 0)
                ign_hi = dr.select(on_asset, ex_hi, 0)
                active_next &= on_asset | (dr.max(beta) != 0)

                # Russian roulette on the throughput before the pending asset weight (any q keeps it unbiased)
                q = dr.minimum(dr.max(beta), 0.95)
                rr = depth + 1 >= self.rr_depth
                survive = sampler.next_1d() < q
                beta[rr & on_plain] *= dr.rcp(dr.select(q > 0, q, 1.0))
                active_next &= ~(rr & on_plain) | survive
                depth[active] += 1
                active = active_next
            if dr.hint(queue is not None, mode="scalar"):
                L = queue.flush(shaded, tab, L)
            return dr.select(dr.isfinite(L), L, 0.0), valid, []

        def aov_names(self):
            return []

        def to_string(self):
            return f"NassetPathIntegrator[max_depth={self.max_depth}, rr_depth={self.rr_depth}, lobe={self.lobe}, prt={self.prt}]"

    mi.register_bsdf(BSDF, lambda props: NassetBSDF(props))
    mi.register_integrator(INTEGRATOR, lambda props: NassetPathIntegrator(props))
    _REGISTERED.add(mi.variant())


def _by_kind(assets, kind):
    """(index, asset) of the assets of ``kind``."""
    return [(a, asset) for a, asset in enumerate(assets) if asset.kind == kind]


def _trace(mi, scene, ray, ignore, lo, hi, active):
    """(first intersection of ``ray`` not on shape ``ignore`` [registry id, 0: none], whether the ray crossed
    a triangle of that shape outside its exempt range [lo, hi) of primitive indices (a fiber hit's own
    and neighbouring segments, spec/renderer.md#fibers; lo = hi: none exempt)).

    A ray leaving a fiber instance (rays through hair cross tens of its prisms) costs O(1) queries on the
    scene's split structures (:func:`split_scenes`), as in the reference renderer (spec/renderer.md#fibers):
    its closest hit is a query on the scene of every other shape, its branch a query on the instance's own
    scene up to that hit, stepping only over exempt triangles. Every other ray is traced on the whole scene,
    re-tracing past each surface of the instance it leaves (a surface asset's rays cross it once or twice:
    measured 5 % faster on the high-albedo pebble than two structures)."""
    import drjit as dr

    split = split_scenes(mi, scene) or []
    on_split = mi.Bool(False)
    for rid, _, _ in split:
        on_split |= ignore == rid
    si, passed = _trace_skipping(mi, scene, ray, ignore, lo, hi, active & ~on_split)
    for rid, others, own in split:
        mine = active & (ignore == rid)
        si_j = others.ray_intersect(ray, mine)
        si = dr.select(mine, si_j, si)
        passed |= _branch(mi, own, ray, dr.select(si_j.is_valid(), si_j.t, ray.maxt), lo, hi, mine)
    return si, passed


def _crosses(mi, scene, ray, own, lo, hi, active):
    """Whether ``ray`` meets a triangle of shape ``own`` (registry id) outside its exempt range [lo, hi) before its
    maxt, every other surface passed through: the branch ray from x of a hit whose light is fetched elsewhere
    (spec/kinds/rna.md#near-field-fetch: only the asset's own triangles count on it). On the instance's own
    structure where the scene has split structures for it (:func:`split_scenes`), else stepping over the others."""
    split = split_scenes(mi, scene) or []
    on_split = mi.Bool(False)
    passed = mi.Bool(False)
    for rid, _, own_scene in split:
        mine = active & (own == rid)
        on_split |= mine
        passed |= _branch(mi, own_scene, ray, ray.maxt, lo, hi, mine)
    return passed | _crosses_skipping(mi, scene, ray, own, lo, hi, active & ~on_split)


@dr.syntax
def _crosses_skipping(mi, scene, ray, own, lo, hi, active):
    """:func:`_crosses` on the whole scene: re-trace past every hit that is not an own triangle outside [lo, hi)."""
    si = scene.ray_intersect(ray, active)
    mine = (dr.reinterpret_array(mi.UInt32, si.shape) == own) & ((si.prim_index < lo) | (si.prim_index >= hi))
    passed = active & si.is_valid() & mine
    go = active & si.is_valid() & ~mine
    r = mi.Ray3f(ray)
    i = mi.UInt32(0)
    while dr.hint(go & (i < MAX_SKIPS), max_iterations=-1, label="nasset_crosses"):
        r = _beyond(r, si)
        si = scene.ray_intersect(r, go)
        mine = (dr.reinterpret_array(mi.UInt32, si.shape) == own) & ((si.prim_index < lo) | (si.prim_index >= hi))
        passed |= go & si.is_valid() & mine
        go = go & si.is_valid() & ~mine
        i += 1
    return passed


def _beyond(ray, si):
    """The rest of ``ray`` past its hit ``si`` (from Mitsuba's offset origin at the hit, up to the same end)."""
    left = ray.maxt - si.t
    r = si.spawn_ray(ray.d)
    r.maxt = left
    return r


@dr.syntax
def _branch(mi, own, ray, tmax, lo, hi, active):
    """Whether ``ray`` crosses a triangle of the instance's own scene ``own`` outside [lo, hi) before ``tmax``."""
    r = mi.Ray3f(ray)
    r.maxt = tmax
    s = own.ray_intersect(r, active)
    exempt = active & s.is_valid() & (s.prim_index >= lo) & (s.prim_index < hi)
    passed = active & s.is_valid() & ~exempt
    i = mi.UInt32(0)
    while dr.hint(exempt & (i < MAX_SKIPS), max_iterations=-1, label="nasset_branch"):
        r = _beyond(r, s)
        s = own.ray_intersect(r, exempt)
        hit = exempt & s.is_valid()
        is_exempt = (s.prim_index >= lo) & (s.prim_index < hi)
        passed |= hit & ~is_exempt
        exempt = hit & is_exempt
        i += 1
    return passed


def shapes_named(mi, scene, prefix: str, mark: str = ""):
    """UInt32 [max registry id + 1]: 1 for the scene's shapes whose id starts with ``prefix`` (and holds ``mark``);
    None when there are none."""
    ids = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh))[0]) for sh in scene.shapes()
           if sh.id().startswith(prefix) and mark in sh.id()]
    if not ids:
        return None
    lut = np.zeros(max(ids) + 1, np.uint32)
    lut[ids] = 1
    return mi.UInt32(lut)


def _on(mi, si, lut):
    """Whether ``si`` hit a shape marked in ``lut`` (:func:`shapes_named`)."""
    sid = dr.reinterpret_array(mi.UInt32, si.shape)
    return si.is_valid() & (dr.gather(mi.UInt32, lut, sid, si.is_valid() & (sid < dr.width(lut))) > 0)


class PassThrough:
    """What rays of a USD scene pass through: light surfaces (spec/renderer.md#light-surfaces; shadow rays every one,
    camera and continuation rays every one but an opaque one met on its emitting side, adding the emission of those
    they see on the way) and cut-outs where they are absent (spec/renderer.md#cutouts: the ``presence`` of their
    ``nasset_preview`` BSDF, every ray alike)."""

    def __init__(self, mi, lights, opaque, cutouts: list) -> None:
        self.mi, self.lights, self.opaque, self.cutouts = mi, lights, opaque, cutouts

    @classmethod
    def of(cls, mi, scene):
        """The scene's light surfaces (:data:`LIGHT_SURFACE_PREFIX`; the opaque ones, :data:`OPAQUE_MARK`) and cut-outs;
        None when it has neither."""
        lights = shapes_named(mi, scene, LIGHT_SURFACE_PREFIX)
        opaque = shapes_named(mi, scene, LIGHT_SURFACE_PREFIX, OPAQUE_MARK)
        cutouts = [(int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh))[0]), sh.bsdf().presence) for sh in scene.shapes()
                   if sh.bsdf() is not None and getattr(sh.bsdf(), "presence", None) is not None]
        return None if lights is None and not cutouts else cls(mi, lights, opaque, cutouts)

    def absent(self, si):
        """[Bool] ``si`` hit a cut-out where it is absent. The uniform number of a fractional opacity is a hash of the
        hit (its point and distance): one per hit, as the spec draws it."""
        mi = self.mi
        out = mi.Bool(False)
        if not self.cutouts:
            return out
        sid = dr.reinterpret_array(mi.UInt32, si.shape)
        bits = [dr.reinterpret_array(mi.UInt32, v) for v in (si.p.x, si.p.y, si.p.z, si.t)]
        u = mi.sample_tea_float32(bits[0] ^ (bits[1] * 0x9E3779B1), bits[2] ^ (bits[3] * 0x85EBCA77), 4)
        for shape_id, presence in self.cutouts:
            on = si.is_valid() & (sid == shape_id)
            out |= on & ~presence.present(si, u, on)
        return out

    def shadow(self, si):
        """[Bool] a shadow ray goes on past hit ``si``."""
        through = self.absent(si)
        return through if self.lights is None else through | _on(self.mi, si, self.lights)

    def onward(self, si, hidden, camera):
        """[Bool] a camera (``camera``) or continuation ray goes on past hit ``si``: a light surface (met on its emitting
        side it adds its emission on the way, :meth:`seen`), but for an opaque one met on its emitting side and not
        hidden from this camera ray (``hidden``: :func:`shapes_named`, None: none), where it ends; an absent cut-out."""
        through = self.absent(si)
        if self.lights is None:
            return through
        passes = _on(self.mi, si, self.lights)
        if self.opaque is not None:
            stop = _on(self.mi, si, self.opaque) & (self.mi.Frame3f.cos_theta(si.wi) > 0.0)
            if hidden is not None:
                stop &= ~(camera & _on(self.mi, si, hidden))
            passes &= ~stop
        return through | passes

    def seen(self, si, hidden, camera):
        """[Bool] hit ``si`` is a light surface whose emission a camera (``camera``) or continuation ray takes on its
        way: not one hidden from camera rays (``hidden``: :func:`shapes_named`, None: none). Its back emits nothing."""
        if self.lights is None:
            return self.mi.Bool(False)
        seen = _on(self.mi, si, self.lights)
        return seen if hidden is None else seen & ~(camera & _on(self.mi, si, hidden))


def _light_emission(mi, scene, emitters, prev_si, prev_pdf, prev_delta):
    """``emission(si, mask)``: the radiance of the emitter hit at ``si`` toward the previous vertex ``prev_si``, times
    the MIS weight of a continuation of pdf ``prev_pdf`` (1 after a delta or camera vertex, ``prev_delta``) against
    the light samples of ``emitters`` (the scene, or a light_choice.EmitterChoice)."""
    def emission(si, m):
        ds = mi.DirectionSample3f(scene, si=si, ref=prev_si)
        pdf = emitters.pdf_emitter_direction(prev_si, ds, m & ~prev_delta)
        return _mis(prev_pdf, dr.select(prev_delta, 0.0, pdf)) * ds.emitter.eval(si, m)

    return emission


def _trace_onward(mi, scene, ray, ignore, lo, hi, active, lights, hidden, camera, emission):
    """:func:`_trace` of a camera or continuation ray among light surfaces and cut-outs (spec/renderer.md#light-surfaces,
    #cutouts): it passes what ``lights`` (a :class:`PassThrough`, None: nothing) says, and returns (si, passed, the sum
    of ``emission(si, mask)`` over the light surfaces it passed and saw); ``hidden``: :func:`shapes_named`."""
    if lights is None:
        si, passed = _trace(mi, scene, ray, ignore, lo, hi, active)
        return si, passed, mi.Spectrum(0.0)
    return _trace_past(mi, scene, ray, ignore, lo, hi, active, lambda si: lights.onward(si, hidden, camera),
                       lambda si, m: emission(si, m & lights.seen(si, hidden, camera)))


def _occluder(mi, scene, ray, ignore, lo, hi, active, lights):
    """:func:`_trace` of a shadow ray, passing what ``lights`` (a :class:`PassThrough`, None: nothing) says: its first
    occluder (invalid: the light is reached) and whether it crossed instance ``ignore`` on the way."""
    if lights is None:
        return _trace(mi, scene, ray, ignore, lo, hi, active)
    return _trace_past(mi, scene, ray, ignore, lo, hi, active, lights.shadow)[:2]


@dr.syntax
def _trace_past(mi, scene, ray, ignore, lo, hi, active, through, collect=None):
    """:func:`_trace`, traced on past every hit where ``through(si)`` holds; the crossings of ``ignore`` accumulate.
    Returns (si, passed, the sum of ``collect(si, mask)`` over the hits passed; 0 without ``collect``)."""
    si, passed = _trace(mi, scene, ray, ignore, lo, hi, active)
    skip = active & through(si)
    acc = mi.Spectrum(0.0)
    if dr.hint(collect is not None, mode="scalar"):
        acc += collect(si, skip)
    r = mi.Ray3f(ray)
    i = mi.UInt32(0)
    while dr.hint(skip & (i < MAX_SKIPS), max_iterations=-1, label="nasset_past_lights"):
        r = _beyond(r, si)
        si_next, passed_next = _trace(mi, scene, r, ignore, lo, hi, skip)
        si[skip] = si_next
        passed |= skip & passed_next
        skip &= through(si)
        if dr.hint(collect is not None, mode="scalar"):
            acc += collect(si, skip)
        i += 1
    return si, passed, acc


@dr.syntax
def _trace_skipping(mi, scene, ray, ignore, lo, hi, active):
    """:func:`_trace` on the whole scene: re-trace past every hit on shape ``ignore``. No limit on the number
    of crossings other than :data:`MAX_SKIPS` against rays that make no progress."""
    si = scene.ray_intersect(ray, active)
    skip = active & si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == ignore) & (ignore != 0)
    passed = skip & ((si.prim_index < lo) | (si.prim_index >= hi))
    r = mi.Ray3f(ray)
    i = mi.UInt32(0)
    while dr.hint(skip & (i < MAX_SKIPS), max_iterations=-1, label="nasset_skip"):
        r = _beyond(r, si)
        si = scene.ray_intersect(r, skip)
        skip = si.is_valid() & (dr.reinterpret_array(mi.UInt32, si.shape) == ignore)
        passed |= skip & ((si.prim_index < lo) | (si.prim_index >= hi))
        i += 1
    return si, passed


#: per scene with fiber instances (keyed by id, checked against its shapes): its shapes' registry ids and
#: [(registry id, scene without instance j, instance j alone)]; at most MAX_SPLIT_SCENES scenes are kept
_SPLIT: dict[tuple, tuple] = {}
MAX_SPLIT_SCENES = 2


def split_scenes(mi, scene):
    """Per fiber-asset instance j of ``scene``: (its registry id, a Mitsuba scene of every other shape, a scene
    of instance j alone), built at the first render of the scene and kept (the shapes are shared, the
    acceleration structures are new: the instances' triangles are in two structures). None for a scene
    without fiber instances or with more than :data:`MAX_SPLIT_INSTANCES` (the structures grow with their square)."""
    shapes = list(scene.shapes())
    rid = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh))[0]) for sh in shapes]
    key = (id(scene), mi.variant())
    hit = _SPLIT.get(key)
    if hit is not None and hit[0] == rid:
        return hit[1]
    fibers = [j for j, sh in enumerate(shapes)
              if type(sh.bsdf()).__name__ == "NassetBSDF" and getattr(sh.bsdf().asset, "fiber", False)]
    split = None
    if 0 < len(fibers) <= MAX_SPLIT_INSTANCES:
        # keyed by their own ids: Mitsuba renames an object after the key it is loaded under
        keys = [sh.id() or f"_nasset_shape_{i}" for i, sh in enumerate(shapes)]
        split = []
        for j in fibers:
            others = mi.load_dict({"type": "scene", **{keys[i]: sh for i, sh in enumerate(shapes) if i != j}})
            own = mi.load_dict({"type": "scene", keys[j]: shapes[j]})
            split.append((rid[j], others, own))
    if split is not None:
        while len(_SPLIT) >= MAX_SPLIT_SCENES:  # the oldest scene's structures go (a hair's are hundreds of MB)
            _SPLIT.pop(next(iter(_SPLIT)))
        _SPLIT[key] = (rid, split)
    return split


def _asset_vertex(mi, assets, tab, k, x_o, n_o, wo_o, h_o, ds_em, em_weight, passed_sh, active_em, on_asset, u_c, use_lobe, L, beta, wi_c, p_c,
                  queue=None):
    """spec/renderer.md#neural-assets at the lanes ``on_asset`` of instances k (object-space inputs x_o, n_o,
    wo_o, h_o from :func:`_asset_inputs`): the light sample's
    contribution added to L (its branch from ``passed_sh``, MIS ``power(p_light, p_A)``), and the
    continuation of the asset technique: returns (L, T_unshadowed / p_A, T_shadowed / p_A, its world
    direction wi_c, its world pdf p_A); ``wi_c``, ``p_c`` come in as the uniform world-sphere sample."""
    import drjit as dr

    wi_o = _object_dir(mi, tab, k, ds_em.d, on_asset)
    wc_o = _object_dir(mi, tab, k, wi_c, on_asset)
    wi_c, p_c = mi.Vector3f(wi_c), mi.Float(p_c)
    p_l = mi.Float(1.0 / FOUR_PI)
    ta_un, ta_sh, tc_un, tc_sh = (mi.Spectrum(0) for _ in range(4))
    for a, asset in assets:
        mine = _of_asset(mi, tab, k, a, on_asset)
        lobe = asset.technique(x_o, n_o, wo_o) if use_lobe else None
        wc_a = wc_o
        if lobe is not None:
            wc_a, p_obj = lobe.sample(u_c)
            wc_w = _world_dir(mi, tab, k, wc_a, mine)
            wi_c[mine] = wc_w
            p_c[mine] = p_obj * _jacobian(mi, tab, k, wc_w, mine)
            p_l[mine] = lobe.pdf(wi_o) * _jacobian(mi, tab, k, ds_em.d, mine)
        u, s = asset.transport(x_o, n_o, wo_o, wc_a, h_o)
        tc_un[mine] = u
        tc_sh[mine] = s
    w_light = dr.select(ds_em.delta, 1.0, _mis(ds_em.pdf, p_l))
    here = on_asset & active_em  # light samples whose transport runs here
    if queue is not None:  # queued for the dense evaluation after the loop; what does not fit stays here
        here = queue.push(here, k=k, x=x_o, n=n_o, wo=wo_o, wi=wi_o, h=h_o, passed=passed_sh, weight=beta * em_weight * w_light)
    for a, asset in assets:
        mine = _of_asset(mi, tab, k, a, here)
        if queue is None:
            u, s = asset.transport(x_o, n_o, wo_o, wi_o, h_o)
        else:  # symbolic: packets without such a lane skip it
            u, s = dr.if_stmt((x_o, n_o, wo_o, wi_o, h_o), mine, lambda *v, asset=asset: asset.transport(*v),
                              lambda *_: (mi.Spectrum(0), mi.Spectrum(0)))
        ta_un[mine] = u
        ta_sh[mine] = s
    L = mi.Spectrum(L)
    L[here] += beta * dr.select(passed_sh, ta_sh, ta_un) * em_weight * w_light
    inv_p = dr.select(p_c > 0, dr.rcp(dr.select(p_c > 0, p_c, 1.0)), 0.0)  # T / p_A; a zero pdf carries nothing
    return L, tc_un * inv_p, tc_sh * inv_p, wi_c, p_c


def _fetch_point(mi, tab, k, si, active):
    """(lanes whose light is fetched off the hit, the fetch point p = x + f (c_w - x), x elsewhere) of hits si on
    instances k (spec/kinds/rna.md#near-field-fetch)."""
    f = dr.gather(mi.Float, tab["fetch"], k, active)
    c_w = dr.gather(mi.Point3f, tab["centre"], k, active)
    moved = active & (f > 0)
    return moved, dr.select(moved, dr.fma(f, c_w - si.p, si.p), si.p)


def _offset(mi, si, d):
    """The offset Mitsuba gives a ray leaving the hit si along d (``Interaction::offset_p(d) - p``)."""
    mag = (1.0 + dr.max(dr.abs(si.p))) * mi.math.RayEpsilon
    return dr.mulsign(mag, dr.dot(si.n, d)) * si.n


def _ray_to_from(mi, si, p, target):
    """The shadow ray from p toward ``target`` with the offset a ray from the hit si in that direction gets
    (``si.spawn_ray_to(target)`` moved to p: spec/kinds/rna.md#near-field-fetch)."""
    o = p + _offset(mi, si, target - p)
    d = target - o
    dist = dr.norm(d)
    return mi.Ray3f(o, d / dist, dist * (1.0 - mi.math.ShadowEpsilon), si.time, si.wavelengths)


def _prt_lanes(mi, prt, tab, k, active):
    """Lanes of ``active`` whose instance k is an instance of a PRT-shaded (neupress) asset."""
    mine = mi.Bool(False)
    for a, _ in prt.assets:
        mine |= _of_asset(mi, tab, k, a, active)
    return mine


def _prt_vertex(mi, prt, tab, k, si, wo_o, on_prt, L, beta):
    """L plus beta times the PRT radiance (:func:`.prt.radiance`) at the lanes ``on_prt`` of instances k."""
    val = mi.Color3f(0)
    for a, asset in prt.assets:
        mine = _of_asset(mi, tab, k, a, on_prt)
        val[mine] = prt_mode.radiance(mi, prt, a, asset, k, si.prim_index, si.uv, wo_o, mine)
    L = mi.Spectrum(L)
    L[on_prt] += beta * val
    return L


def _eightdna_vertex(mi, scene, rnd, si, wo_world, sid, assets, tab, k, x_o, n_o, wo_o, on_8, L, beta, t_un, t_sh, lights,
                     emitters):
    """:func:`.eightdna.vertex` at the lanes ``on_8`` as the state of the integrator's symbolic ``if``:
    returns (L plus beta times the vertex's light, t_un and t_sh with its continuation weights, the
    continuation's world direction, its world pdf, whether it lives, whether it leaves u_i M, u_i M)."""
    import drjit as dr

    v = eightdna.vertex(mi, scene, rnd, si, wo_world, sid, assets, tab, k, x_o, n_o, wo_o, on_8, lights, emitters)
    L = dr.select(on_8, L + beta * v["L"], L)
    t_un = dr.select(on_8, v["weight"], t_un)
    t_sh = dr.select(on_8, v["weight_passed"], t_sh)
    return L, t_un, t_sh, v["d"], v["pdf"], v["alive"], v["from_u"], v["origin"]


def _instance_tables(mi, scene):
    """Assets and per-instance transforms of the scene's shapes carrying the ``nasset`` BSDF.

    Returns (assets [JIT_KINDS instances], lut UInt32 [max registry id + 1] -> instance index + 1, tables dict of
    Float / UInt32 arrays per instance: 'inv' 12 (world -> object affine, row-major 3x4), 'nt' 9
    (object normal = normalize(M3^T n_world) times sign(det M3) when the asset has no normals), 'fwd' 12
    (the object -> world affine map M, 3 x 4 row-major), 'kind8' (1 for 8dna instances), 'jdet' 1 (|det M3^-1|), 'asset',
    'fetch' 1 (the near-field fetch f, 0 but for rna and neupress assets that author one) and 'centre' 3 (the encoding box's centre c_w
    in world space, spec/kinds/rna.md#near-field-fetch))."""
    import drjit as dr

    assets: list = []
    ids, inv, nt, fwd, jdet, which, fetch, centre = [], [], [], [], [], [], [], []
    for sh in scene.shapes():
        b = sh.bsdf()
        filename = getattr(b, "filename", None)
        if filename is None or type(b).__name__ != "NassetBSDF":
            continue
        if b.asset not in assets:
            assets.append(b.asset)
        m = b.to_world
        m3 = m[:3, :3]
        det = float(np.linalg.det(m3))
        if not np.isfinite(det) or abs(det) < 1e-30:
            raise error("SCENE_INVALID", f"asset instance {sh.id()!r} has a singular to_world", file=filename)
        minv = np.linalg.inv(m)
        sign = 1.0 if b.asset.geometry.normals is not None or det > 0 else -1.0
        ids.append(int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(sh))[0]))
        inv.append(minv[:3, :].ravel())
        nt.append((sign * m3.T).ravel())
        fwd.append(m[:3, :].ravel())
        jdet.append(1.0 / abs(det))
        which.append(assets.index(b.asset))
        fetch.append(float(getattr(b.asset, "fetch", 0.0)))
        centre.append(m3 @ np.asarray(getattr(b.asset, "centre", np.zeros(3)), np.float64) + m[:3, 3])
    lut = np.zeros(max(ids, default=0) + 1, np.uint32)
    for j, rid in enumerate(ids):
        lut[rid] = j + 1
    tab = {"inv": mi.Float(np.asarray(inv, np.float32).ravel()) if ids else mi.Float(0),
           "nt": mi.Float(np.asarray(nt, np.float32).ravel()) if ids else mi.Float(0),
           "fwd": mi.Float(np.asarray(fwd, np.float32).ravel()) if ids else mi.Float(0),
           "jdet": mi.Float(np.asarray(jdet, np.float32)) if ids else mi.Float(0),
           "kind8": mi.UInt32(np.asarray([assets[w].kind == "8dna" for w in which], np.uint32)) if ids else mi.UInt32(0),
           "asset": mi.UInt32(np.asarray(which, np.uint32)) if ids else mi.UInt32(0),
           "fetch": mi.Float(np.asarray(fetch, np.float32)) if ids else mi.Float(0),
           "centre": mi.Float(np.asarray(centre, np.float32).ravel()) if ids else mi.Float(0)}
    return assets, mi.UInt32(lut), tab


def _rows(mi, arr, k, width, first, active):
    import drjit as dr

    return [dr.gather(mi.Float, arr, k * width + first + j, active) for j in range(3)]


def _object_dir(mi, tab, k, v, active):
    """normalize(M3^-1 v) of world directions v for instance k (spec/renderer.md#neural-assets item 1)."""
    import drjit as dr

    rows = [_rows(mi, tab["inv"], k, 12, 4 * r, active) for r in range(3)]
    out = mi.Vector3f(*[r[0] * v.x + r[1] * v.y + r[2] * v.z for r in rows])
    return dr.normalize(out)


def _world_dir(mi, tab, k, v, active):
    """normalize(M3 v) of object directions v for instance k (spec/renderer.md#neupress: the lobe mapped to world)."""
    import drjit as dr

    rows = [_rows(mi, tab["fwd"], k, 12, 4 * r, active) for r in range(3)]
    return dr.normalize(mi.Vector3f(*[r[0] * v.x + r[1] * v.y + r[2] * v.z for r in rows]))


def _jacobian(mi, tab, k, w, active):
    """J = d omega_obj / d omega_world = |det B| / |B w|^3 at unit world directions w (B = M3^-1; 1 for rigid motions)."""
    import drjit as dr

    rows = [_rows(mi, tab["inv"], k, 12, 4 * r, active) for r in range(3)]
    bw = mi.Vector3f(*[r[0] * w.x + r[1] * w.y + r[2] * w.z for r in rows])
    return dr.gather(mi.Float, tab["jdet"], k, active) * dr.rcp(dr.maximum(dr.norm(bw), 1e-10) ** 3)  # |B w| >= the least singular value of B


def _object_inputs(mi, tab, k, si, wo, active):
    """(x, n, wo) in the object space of instance k: x = M^-1 x_w, n the asset's own normal, wo mapped by M3^-1."""
    import drjit as dr

    rows = [_rows(mi, tab["inv"], k, 12, 4 * r, active) + [dr.gather(mi.Float, tab["inv"], k * 12 + 4 * r + 3, active)]
            for r in range(3)]
    p = si.p
    x = mi.Point3f(*[r[0] * p.x + r[1] * p.y + r[2] * p.z + r[3] for r in rows])
    nrows = [_rows(mi, tab["nt"], k, 9, 3 * r, active) for r in range(3)]
    n_w = si.sh_frame.n
    n = dr.normalize(mi.Vector3f(*[r[0] * n_w.x + r[1] * n_w.y + r[2] * n_w.z for r in nrows]))
    return x, n, _object_dir(mi, tab, k, wo, active)


def _of_asset(mi, tab, k, a, active):
    """Lanes of ``active`` whose instance k is an instance of asset a."""
    import drjit as dr

    return active & (dr.gather(mi.UInt32, tab["asset"], k, active) == a)


def _asset_inputs(mi, assets, tab, k, si, wo, active):
    """(x, frame, wo, h, exempt lo, exempt hi) of asset hits in the object space of instance k: frame the
    asset's normal (surface) or the curve tangent (fiber, with h and the hit segment's exempt triangle
    range [lo, hi), spec/renderer.md#fibers); h, lo, hi are 0 elsewhere."""
    import drjit as dr

    h, lo, hi = mi.Float(0), mi.UInt32(0), mi.UInt32(0)
    if not assets:
        return mi.Point3f(0), mi.Vector3f(0), mi.Vector3f(0), h, lo, hi
    x, n, wo_o = _object_inputs(mi, tab, k, si, wo, active)
    for a, asset in enumerate(assets):
        if asset.fiber:
            mine = _of_asset(mi, tab, k, a, active)
            t, hh, l_, h_ = asset.fiber_frame(si.prim_index, x, wo_o, mine)
            n, h = dr.select(mine, t, n), dr.select(mine, hh, h)
            lo, hi = dr.select(mine, l_, lo), dr.select(mine, h_, hi)
    return x, n, wo_o, h, lo, hi
