"""Wavefront unidirectional path tracer with next-event estimation and MIS (power heuristic).

All rays of a batch advance together as arrays, one bounce per loop iteration. Hits on neural
assets are shaded by :mod:`nasset_reference_renderer.shaders` (spec/renderer.md#neural-assets).
"""

from __future__ import annotations

import copy
import os
import queue
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from nasset_sdk.errors import UsageError
from nasset_sdk.process import single_threaded_blas

from .accel import Accel
from .bsdf import bsdf_eval, bsdf_sample
from .film import MAX_SPP, Film, check_image_size, pixel_offsets
from .light_selection import DRAWS as LIGHT_DRAWS
from .light_selection import MAX_DRAWS, LightSelection
from .lights import MeshLight, rays_near_shapes
from .plan import RenderPlan, make_plan
from .sampling import barycentric, cross3, dot, face_normals, frame, normalize, power_heuristic, to_local, to_world
from .shaders import NeuralShading, shader_class, variant_of
from .shaders.common import max3, unique
from .shadow import aim_shadow

#: with more light shapes than this, a ray batch tests each shape only on the rays passing near it (lights.rays_near_shapes)
CULLED_LIGHT_SHAPES = 8


@dataclass
class RenderSettings:
    spp: int = 16
    seed: int = 0
    width: int | None = None
    height: int | None = None
    max_depth: int | None = None  # None: the scene's nasset:maxDepth (-1: MAX_DEPTH), else DEFAULT_MAX_DEPTH
    batch: int = 65536
    tile: int = 64
    threads: int = 0
    workers: int = 0  # render threads, each tracing whole jobs (wavefronts); 0: one per usable core, at most MAX_AUTO_WORKERS
    rr_depth: int = 3
    progress: bool = False
    backend: str = "embree"
    neupress_sampling: str = "auto"  # auto | dome | lobe | mis (spec/renderer.md#neupress)
    prt: bool = False  # neupress PRT mode
    eightdna_sampling: str = "mis"  # light | flow | mis (spec/renderer.md#8dna)
    rna_continuation: str = "lobes"  # uniform | lobes (spec/renderer.md#neural-assets, #fibers)
    light_draws: int = LIGHT_DRAWS  # light samples per vertex of a kind with more lights (0: every light; #light-selection)


@dataclass
class RenderStats:
    camera_samples: int = 0
    rays: int = 0
    network_evals: int = 0
    time_total: float = 0.0  # wall seconds of the render loop (after the plan, integrator and Embree setup)
    cpu_total: float = 0.0  # CPU seconds of this process over the same loop
    # seconds summed over the render threads (with one thread they add up to time_total)
    time: dict = field(default_factory=lambda: {"trace": 0.0, "network": 0.0, "other": 0.0})
    workers: int = 1  # render threads used


@dataclass
class RenderResult:
    film: Film
    plan: RenderPlan
    stats: RenderStats

    @property
    def image(self):
        return self.film.image()

    @property
    def variance(self):
        return self.film.variance()


class _Timer:
    def __init__(self, stats, key):
        self.stats, self.key = stats, key

    def __enter__(self):
        self.t = time.perf_counter()

    def __exit__(self, *a):
        self.stats.time[self.key] += time.perf_counter() - self.t


def scene_accel(scene, backend: str, neural: np.ndarray):
    """(Accel, unit geometric normals [F,3]) of ``scene``, built at the first render and kept in
    ``scene.accel_cache`` for later ones (on dense hair Embree's build is most of a render's setup).

    ``neural`` [n_instances] bool: rays ignore neural instances only, so those get acceleration
    structures of their own; fibre assets' structures use Embree's fast mode (accel.py).
    """
    fiber = np.array([i.kind == "neural" and scene.assets[i.asset].fiber is not None for i in scene.instances], bool)
    cutout = np.array([i.kind == "mesh" and scene.materials.opacity_of(max(i.material, 0)) is not None
                       for i in scene.instances], bool)
    key = (backend, np.asarray(neural, bool).tobytes(), fiber.tobytes(), cutout.tobytes(), id(scene.triangles),
           len(scene.triangles))
    hit = scene.accel_cache.get(key)
    if hit is None:
        scene.accel_cache.clear()  # one set of structures per scene at a time (their memory)
        tri = scene.triangles
        ng = scene.tri_ng if scene.tri_ng is not None else face_normals(tri)
        hit = scene.accel_cache[key] = (Accel(tri, scene.tri_inst, backend=backend, separate=neural, fast=fiber,
                                              cutout=cutout, boxes=[i.box for i in scene.instances],
                                              meshes=[scene.world_mesh(i) for i in range(len(scene.instances))]), ng)
    return hit


def bump_terminator(smooth, mapped, wi):
    """[n] Estevez et al.'s bump-terminator shadowing (Mitsuba's normalmap, Cycles' diffuse closures): a GGX masking
    term with alpha^2 = min(tan^2(theta_d) / 8, 1), theta_d the angle between the interpolated normal ``smooth`` and
    the ``mapped`` one, at the angle of ``wi`` to ``smooth`` (0 at or below its horizon). Where the normals agree it
    is 1 (spec/renderer.md#normal-maps)."""
    cos_d = np.minimum(np.abs(dot(smooth, mapped)), 1.0)
    alpha2 = np.minimum(0.125 * (1.0 - cos_d * cos_d) / np.maximum(cos_d * cos_d, 1e-300), 1.0)
    cos_i = dot(smooth, wi)
    c2 = np.maximum(cos_i * cos_i, 1e-300)
    g = 2.0 / (1.0 + np.sqrt(1.0 + alpha2 * (1.0 - c2) / c2))
    return np.where(cos_i > 1e-6, g, 0.0)


class PathIntegrator:
    def __init__(self, scene, plan: RenderPlan, settings: RenderSettings) -> None:
        self.scene, self.plan, self.s = scene, plan, settings
        insts = scene.instances
        self.inst_neural = np.array([i.kind == "neural" for i in insts], bool)
        accel, self.tri_ng = scene_accel(scene, settings.backend, self.inst_neural)
        self._bind_accel(accel)
        self.presence_rng = np.random.default_rng(settings.seed)  # replaced by each wavefront's generator
        self.eps = self.accel.eps
        self.stats = RenderStats()
        self.inst_mat = np.array([max(i.material, 0) for i in insts], np.int64)
        self.inst_one_sided = np.array([i.one_sided for i in insts], bool)
        self.inst_back_mat = np.array([i.back_material for i in insts], np.int64)
        self.inst_asset = np.array([i.asset for i in insts], np.int64)
        self.inst_to_obj = np.array([i.to_object for i in insts]) if insts else np.zeros((0, 4, 4))
        self.indirect = plan.instance_indirect
        self.mt = scene.materials
        self.normal_maps = [(m, t.normal) for m, t in enumerate(self.mt.textures) if t is not None and t.normal is not None]
        self.emissive = self.mt.emission.max(1) > 0
        self.inst_light = np.full(len(insts), -1, np.int64)  # instance -> index of its MeshLight
        for k, light in enumerate(scene.lights):
            if isinstance(light, MeshLight):
                self.inst_light[light.instance] = k
        self.nee = plan.nee
        self.light_choice = LightSelection(scene.lights, self.nee, settings.light_draws)
        # light shapes camera rays / other rays meet, with their bounding spheres where there are many (light_surfaces)
        self.light_shapes = {}
        for camera in (True, False):
            shapes = [(k, light) for k, light in enumerate(scene.lights) if light.area and (not camera or light.camera_visible)]
            spheres = [light.bounding_sphere() for _, light in shapes] if len(shapes) > CULLED_LIGHT_SHAPES else None
            self.light_shapes[camera] = shapes, spheres
        # object-space corner normals of each asset's triangles (None for fibers: shaded from the curve axis)
        self.asset_corner_n = []
        for data in scene.assets:
            if data.fiber is not None:
                cn = None
            elif data.normals is not None:
                cn = data.normals[data.faces]
            else:
                n = face_normals(data.points[data.faces])
                cn = np.repeat(n[:, None], 3, 1)
            self.asset_corner_n.append(cn)
        # near-field fetch (spec/kinds/rna.md#near-field-fetch, kinds/neupress.md): per instance f (0 but on rna and
        # neupress instances whose asset has one) and the world centre c_w of its asset's encoding box; ``fetching``: some instance has f > 0
        self.inst_fetch = np.zeros(len(insts))
        self.inst_centre = np.zeros((len(insts), 3))
        for i, inst in enumerate(insts):
            if inst.kind == "neural" and scene.assets[inst.asset].near_field_fetch > 0:
                lo, hi = scene.assets[inst.asset].asset.domain
                self.inst_fetch[i] = scene.assets[inst.asset].near_field_fetch
                self.inst_centre[i] = np.append(0.5 * (lo + hi), 1.0) @ inst.to_world[:, :3]
        self.fetching = bool((self.inst_fetch > 0).any())
        self.shading = NeuralShading(self)  # the shaders of the scene's neural assets

    def worker_copy(self) -> "PathIntegrator":
        """Another integrator of the same scene and plan for a render thread: it shares the read-only arrays and
        the acceleration structures, and has its own accelerator view, statistics and shaders (their caches)."""
        twin = copy.copy(self)
        twin._bind_accel(self.accel)
        twin.stats = RenderStats()
        twin.shading = NeuralShading(twin)
        return twin

    def _bind_accel(self, accel) -> None:
        """Trace with a view of ``accel``: its own ray counter (this integrator's rays) and this integrator's
        cut-out test (spec/renderer.md#cutouts)."""
        self.accel = accel.view()
        self.accel.presence = self._present

    # -- helpers ---------------------------------------------------------------------------
    def _present(self, tri, u, v) -> np.ndarray:
        """[k] bool: the surface is there at hits on cut-out mesh triangles ``tri`` [k] (global ids) with
        barycentrics (u, v) [k] (spec/renderer.md#cutouts)."""
        inst = self.scene.tri_inst[tri]
        mat = self.inst_mat[inst]
        out = np.ones(len(tri), bool)
        draws = self.presence_rng.random(len(tri))
        for m in np.unique(mat):
            op = self.mt.opacity_of(m)
            if op is None:
                continue
            sel = np.nonzero(mat == m)[0]
            st = None
            if op.texture is not None:
                cst = self.scene.tri_st[self.scene.corner_rows(tri[sel], inst[sel])]
                bu, bv = u[sel], v[sel]
                st = barycentric(cst, bu, bv)
            out[sel] = op.present(st, draws[sel])
        return out

    def trace(self, o, d, tmax=None, ignore=None, exempt=None, self_rows=None):
        with _Timer(self.stats, "trace"):
            return self.accel.trace(o, d, tmax, ignore, exempt, self_rows)

    def passes_own(self, o, d, tmax, inst, exempt=None):
        """[n] bool: the ray meets instance inst[i] itself before tmax (the rna branch test alone)."""
        with _Timer(self.stats, "trace"):
            return self.accel.passes_own(o, d, tmax, inst, exempt)

    def fetch_points(self, x, inst):
        """(p [n,3], far [n] bool) of rna or neupress hits x [n,3] on instances ``inst``: the points their incident light is
        fetched at, x + f (c_w - x), and where f > 0 (spec/kinds/rna.md#near-field-fetch); None where no instance
        of the scene has f > 0 (every p is x: the rule of format 0.2, on its code path)."""
        if not self.fetching:
            return None
        f = self.inst_fetch[inst]
        far = f > 0
        if not far.any():
            return None
        p = x.copy()
        p[far] = x[far] + f[far, None] * (self.inst_centre[inst[far]] - x[far])
        return p, far

    def occluded(self, o, d, tmax):
        with _Timer(self.stats, "trace"):
            return self.accel.occluded(o, d, tmax)

    def _mis_light(self, k, prev_pdf, specular, o, d, no_mis, count=None):
        """Weight of radiance from light k reached by a BSDF / continuation sample from ``o``; ``count``: the light's
        expected samples per vertex at ``o`` (light_selection), computed when not given."""
        light = self.scene.lights[k]
        if not self.plan.light_nee[k]:
            return np.ones(len(d))
        if count is None:
            count = self.light_choice.count(k, o)
        w = power_heuristic(prev_pdf, count * light.pdf(o, d))
        return np.where(specular | no_mis, 1.0, w)

    def light_surfaces(self, L, idx, beta, o, d, t_geometry, prev_pdf, specular, no_mis, camera: bool) -> np.ndarray:
        """Every light surface the rays (``o``, ``d`` [n, 3], throughput ``beta``, of image rows ``idx``) meet on its
        emitting side before ``t_geometry`` [n] adds its emission, MIS-weighted, to ``L``; the rays go on: light surfaces
        occlude nothing (spec/renderer.md#light-surfaces), but for an opaque one (``nasset:opaqueSurface``), where the
        ray ends: only the surfaces up to the nearest opaque one count. ``camera`` rays do not see the lights hidden from
        them. Returns [n] bool: the rays that ended on an opaque light surface."""
        met = []  # (light, opaque, rays tested (None: all), their t, their Le)
        t_end = np.array(t_geometry, np.float64)
        shapes, spheres = self.light_shapes[camera]
        near = [None] * len(shapes)
        if spheres is not None:  # many lights: each tests only the rays that pass near it
            near = rays_near_shapes(spheres, o, d, t_end)
        for (k, light), r in zip(shapes, near, strict=True):
            if r is not None and not len(r):
                continue
            tl, le = light.intersect(o, d) if r is None else light.intersect(o[r], d[r])
            met.append((k, light.opaque, r, tl, le))
            if light.opaque:
                if r is None:
                    t_end = np.minimum(t_end, tl)
                else:
                    t_end[r] = np.minimum(t_end[r], tl)
        hits = []
        for k, opaque, r, tl, le in met:
            te, tg = (t_end, t_geometry) if r is None else (t_end[r], t_geometry[r])
            sel = np.nonzero((tl <= te) & (tl < tg) if opaque else tl < te)[0]
            if len(sel):
                hits.append((k, le[sel], sel if r is None else r[sel]))
        counts = self.light_choice.counts([(k, m) for k, _, m in hits], o)
        for (k, le, m), count in zip(hits, counts, strict=True):
            w = self._mis_light(k, prev_pdf[m], specular[m], o[m], d[m], no_mis[m], count)
            L[idx[m]] += beta[m] * le * w[:, None]
        return t_end < t_geometry

    def _mesh_light_mis(self, inst, prev_pdf, specular, o, d):
        """MIS weights [n] of emission reached on mesh instances ``inst`` [n] (1 where the mesh is no light)."""
        w = np.ones(len(inst))
        k_of = self.inst_light[inst]
        pairs = [(k, np.nonzero(k_of == k)[0]) for k in unique(k_of[k_of >= 0])]
        for (k, m), count in zip(pairs, self.light_choice.counts(pairs, o), strict=True):
            w[m] = self._mis_light(k, prev_pdf[m], specular[m], o[m], d[m], np.zeros(len(m), bool), count)
        return w

    # -- main loop -------------------------------------------------------------------------
    def radiance(self, o, d, rng) -> np.ndarray:
        self.presence_rng = rng  # draws only where a ray meets a cut-out surface
        n0 = len(o)
        L = np.zeros((n0, 3))
        idx = np.arange(n0)
        beta = np.ones((n0, 3))
        prev_pdf = np.zeros(n0)
        specular = np.ones(n0, bool)  # camera rays: emitters seen directly, weight 1
        ignore = np.full(n0, -1, np.int64)
        pend = None  # (mask, T_unshadowed/pdf, T_shadowed/pdf of the rows in mask) of neural continuations
        exempt = None  # [n,2] triangle ranges that do not count as self hits (fiber continuations), or None
        lights = self.scene.lights
        has_area = any(light.area for light in lights)
        depth = 0
        while len(idx):
            # rows whose continuation branch is still to choose (pend's mask); all rows unless an instance fetches
            # its light elsewhere (those rays start inside the asset, their branch was chosen at the hit)
            need = pend[0] if pend is not None and self.fetching else None
            hits = self.trace(o, d, None, ignore, exempt, need)
            if pend is not None:
                m, tu, ts = pend
                beta[m] *= np.where(hits.self_hit[m][:, None], ts, tu)
            pend = None
            if depth >= self.s.rr_depth:
                q = np.clip(max3(beta), 0.05, 1.0)
                live = rng.random(len(idx)) < q
                beta = beta / q[:, None]
                sel = np.nonzero(live)[0]
                idx, o, d, beta, prev_pdf, specular, ignore = idx[sel], o[sel], d[sel], beta[sel], prev_pdf[sel], \
                    specular[sel], ignore[sel]
                hits.t, hits.prim, hits.u, hits.v = hits.t[sel], hits.prim[sel], hits.u[sel], hits.v[sel]
                if not len(idx):
                    break
            no_mis = np.zeros(len(idx), bool)
            ended = np.zeros(len(idx), bool)
            if has_area:
                ended = self.light_surfaces(L, idx, beta, o, d, hits.t, prev_pdf, specular, no_mis, depth == 0)
            esc = (hits.prim < 0) & ~ended
            surf = (hits.prim >= 0) & ~ended
            if esc.any():
                for k, light in enumerate(lights):
                    # a delta light is never reached by a ray; a dome hidden from the camera is not seen by camera rays
                    if light.infinite and not light.delta and (depth > 0 or light.camera_visible):
                        le = light.le_escaped(d[esc])
                        if le.any():
                            w = self._mis_light(k, prev_pdf[esc], specular[esc], o[esc], d[esc], no_mis[esc])
                            L[idx[esc]] += beta[esc] * le * w[:, None]
            sel = np.nonzero(surf)[0]
            if not len(sel):
                break
            hit_pdf, hit_specular = prev_pdf[sel], specular[sel]
            idx, o, d, beta = idx[sel], o[sel], d[sel], beta[sel]
            prim = hits.prim[sel]
            bu, bv = hits.u[sel], hits.v[sel]
            tri = self.scene.triangles[prim]
            x = barycentric(tri, bu, bv)
            inst = self.scene.tri_inst[prim]
            neural = self.inst_neural[inst]
            mesh = ~neural
            if mesh.any():
                seen_front = dot(self.tri_ng[prim], d) < 0
                side_mat = np.where(~seen_front & (self.inst_back_mat[inst] >= 0), self.inst_back_mat[inst], self.inst_mat[inst])
                em = mesh & self.emissive[side_mat] & (~self.inst_one_sided[inst] | seen_front)
                if em.any():
                    w = self._mesh_light_mis(inst[em], hit_pdf[em], hit_specular[em], o[em], d[em])
                    L[idx[em]] += beta[em] * self._emission(side_mat[em], prim[em], inst[em], bu[em], bv[em]) * w[:, None]
            if depth >= self.s.max_depth:
                break
            new = []
            if mesh.any():
                new.append(self._mesh_vertex(np.nonzero(mesh)[0], idx, x, d, beta, prim, bu, bv, inst, L, rng))
            if neural.any():
                new += self.shading.vertices(neural, idx, x, d, beta, prim, bu, bv, inst, L, rng)
            new = [n for n in new if n is not None and len(n[0])]
            if not new:
                break
            idx = np.concatenate([n[0] for n in new])
            o = np.concatenate([n[1] for n in new])
            d = np.concatenate([n[2] for n in new])
            beta = np.concatenate([n[3] for n in new])
            prev_pdf = np.concatenate([n[4] for n in new])
            ignore = np.concatenate([n[5] for n in new])
            specular = np.zeros(len(idx), bool)
            exempt = None
            if any(len(n) > 8 for n in new):  # fiber continuations: their own segments are not self hits
                exempt = np.concatenate([n[8] if len(n) > 8 else np.full((len(n[0]), 2), -1, np.int64) for n in new])
            if any(len(n) > 7 for n in new):  # neupress / 8dna continuations may carry MIS weight 1
                specular = np.concatenate([n[7] if len(n) > 7 else np.zeros(len(n[0]), bool) for n in new])
            pm = [n[6] for n in new]
            if any(p is not None for p in pm):
                mask = np.concatenate([np.zeros(len(n[0]), bool) if p is None else p[0] for n, p in zip(new, pm, strict=True)])
                tu = np.concatenate([p[1] for p in pm if p is not None])
                ts = np.concatenate([p[2] for p in pm if p is not None])
                pend = (mask, tu, ts)
            depth += 1
        return L

    # -- ordinary surfaces -----------------------------------------------------------------
    def _emission(self, mat, prim, inst, bu, bv):
        """Emitted radiance [n,3] of hits on mesh triangles ``prim`` with materials ``mat`` (textured emission read at
        the hit's st, spec/renderer.md#textures)."""
        if not any(t is not None for t in self.mt.emission_textures):
            return self.mt.emission[mat]
        cst = self.scene.tri_st[self.scene.corner_rows(prim, inst)]
        st = barycentric(cst, bu, bv)
        return self.mt.emission_at(mat, st)

    def _normal_mapped(self, ns, mat, prim, cst, st):
        """Shading normals [n,3] turned by the materials' tangent-space normal maps (spec/renderer.md#normal-maps):
        the texel (x, y, z) (scale and bias applied) in the frame T = dP/ds made orthogonal to the interpolated normal
        N, B = N x T, N. Where the triangle's st are degenerate T is any tangent; a mapped normal that is not finite
        or zero keeps N. Returns (normals [n,3], [n] bool: the row's material has a map)."""
        out, mapped = ns.copy(), np.zeros(len(ns), bool)
        for m, tex in self.normal_maps:
            sel = np.nonzero(mat == m)[0]
            if not len(sel):
                continue
            mapped[sel] = True
            v = tex.sample(st[sel])
            tri = self.scene.triangles[prim[sel]]
            e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
            c = cst[sel]
            d1, d2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
            det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
            ok = np.abs(det) > 1e-300
            dpds = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) / np.where(ok, det, 1.0)[:, None]
            n = ns[sel]
            tan = dpds - n * dot(n, dpds)[:, None]
            length = np.sqrt(dot(tan, tan))
            ok &= np.isfinite(length) & (length > 1e-12 * np.sqrt(np.maximum(dot(dpds, dpds), 1e-300)))
            tan = np.where(ok[:, None], tan / np.where(ok, length, 1.0)[:, None], frame(n)[0])
            turned = tan * v[:, 0:1] + cross3(n, tan) * v[:, 1:2] + n * v[:, 2:3]
            size = np.sqrt(dot(turned, turned))
            good = np.isfinite(size) & (size > 1e-12)
            out[sel] = np.where(good[:, None], turned / np.where(good, size, 1.0)[:, None], n)
        return out, mapped

    def _mesh_vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng):
        x, d, beta, prim, bu, bv, inst, ridx = x[r], d[r], beta[r], prim[r], bu[r], bv[r], inst[r], idx[r]
        wo = -d
        ng = self.tri_ng[prim]
        seen_front = dot(ng, wo) > 0
        front = ~self.inst_one_sided[inst] | seen_front  # one-sided surfaces are black from the back
        if not front.all():
            x, d, beta, prim, bu, bv, inst, ridx, wo, ng, seen_front = (
                a[front] for a in (x, d, beta, prim, bu, bv, inst, ridx, wo, ng, seen_front))
        rows = self.scene.corner_rows(prim, inst)
        mat = self.inst_mat[inst]
        back_mat = self.inst_back_mat[inst]
        mat = np.where(~seen_front & (back_mat >= 0), back_mat, mat)  # a two-sided material's back side
        looked_up = None  # (kd, f0, alpha) per hit of textured materials
        cn = self.scene.tri_normals[rows]
        ns = normalize(barycentric(cn, bu, bv))
        if self.mt.textured:
            cst = self.scene.tri_st[rows]
            st = barycentric(cst, bu, bv)
            colors = None
            if self.scene.tri_color is not None:
                cc = self.scene.tri_color[rows]
                colors = barycentric(cc, bu, bv)
            looked_up = self.mt.lookup(mat, st, colors)
        smooth = None  # the interpolated normal under a normal map (the terminator term's reference)
        if looked_up is not None and self.normal_maps:
            smooth = ns
            ns, mapped = self._normal_mapped(ns, mat, prim, cst, st)
        flip = dot(ng, wo) < 0
        ng = np.where(flip[:, None], -ng, ng)
        ns = np.where(flip[:, None], -ns, ns)
        ns = np.where((dot(ns, wo) <= 1e-6)[:, None], ng, ns)
        if smooth is not None:  # rows without a map: the shading normal itself (a term of 1)
            smooth = np.where(mapped[:, None], np.where(flip[:, None], -smooth, smooth), ns)
        t, b = frame(ns)
        wo_l = to_local(wo, t, b, ns)
        indirect = self.indirect[inst]
        offset = ng * (self.eps * (1.0 + max3(np.abs(x)) / self.accel.scale))[:, None]
        xo = x + offset
        # glass (spec/renderer.md#transmission): directions below the surface count too, their rays start below it
        glass = self.mt.glass(mat, seen_front)
        transmits = None if glass is None else glass[0] > 0

        def sub(rows):
            """The per-row material arguments of bsdf_eval / bsdf_sample for ``rows``."""
            args = () if looked_up is None else tuple(a[rows] for a in looked_up)
            if glass is not None:
                args = (args or (None, None, None)) + (tuple(a[rows] for a in glass),)
            return args

        for delta, wi, dist, li, pdf in self.light_choice.samples(x, rng):
            cos = dot(wi, ns)
            ok = (pdf > 0) & (cos > 0) & (dot(wi, ng) > 0) & (max3(li) > 0)
            if transmits is not None:
                ok |= transmits & (pdf > 0) & (cos < 0) & (dot(wi, ng) < 0) & (max3(li) > 0)
            s = np.nonzero(ok)[0]
            if not len(s):
                continue
            f, bpdf = bsdf_eval(self.mt, mat[s], wo_l[s], to_local(wi[s], t[s], b[s], ns[s]), *sub(s))
            below = cos[s] < 0
            if smooth is not None:
                f = f * np.where(below, 1.0, bump_terminator(smooth[s], ns[s], wi[s]))[:, None]
            w = np.ones(len(s)) if delta else np.where(indirect[s], power_heuristic(pdf[s], bpdf), 1.0)
            c = beta[s] * f * (np.abs(cos[s]) * w / pdf[s])[:, None] * li[s]
            nz = max3(c) > 0
            s, c, below = s[nz], c[nz], below[nz]
            if not len(s):
                continue
            start = np.where(below[:, None], x[s] - offset[s], xo[s])
            d_shadow, tmax = aim_shadow(x[s], start, wi[s], dist[s], self.eps)
            vis = ~self.occluded(start, d_shadow, tmax)
            L[ridx[s[vis]]] += c[vis]  # s holds each ray once: no repeated indices
        cont = np.nonzero(indirect)[0]
        if not len(cont):
            return None
        wi_l, f, pdf = bsdf_sample(self.mt, mat[cont], wo_l[cont], rng.random(len(cont)), rng.random((len(cont), 2)),
                                   *sub(cont))
        wi = to_world(wi_l, t[cont], b[cont], ns[cont])
        side = dot(wi, ng[cont])
        ok = (pdf > 0) & (wi_l[:, 2] > 0) & (side > 0)
        if transmits is not None:
            ok |= transmits[cont] & (pdf > 0) & (wi_l[:, 2] < 0) & (side < 0)
        c = cont[ok]
        nb = beta[c] * f[ok] * (np.abs(wi_l[ok, 2]) / pdf[ok])[:, None]
        below = side[ok] < 0
        if smooth is not None:
            nb *= np.where(below, 1.0, bump_terminator(smooth[c], ns[c], wi[ok]))[:, None]
        start = np.where(below[:, None], x[c] - offset[c], xo[c])
        return ridx[c], start, wi[ok], nb, pdf[ok], np.full(len(c), -1, np.int64), None

    # -- neural assets ---------------------------------------------------------------------
    def to_object(self, v, inst, point=False):
        """Rows of v [n,3] in the object space of instance inst[i] (row vectors times to_object).

        The same per-row product as einsum("ij,ijk->ik", v, M[inst]) but one matrix per instance
        present instead of a gathered [n,4,4] array (a matrix product: einsum is ~30x slower here).
        """
        ids = unique(inst)
        if len(ids) == 1:
            M = self.inst_to_obj[ids[0]]
            out = v @ M[:3, :3]
            if point:
                out += M[3, :3]
            return out
        out = np.empty((len(v), 3))
        for i in ids:
            m = inst == i
            M = self.inst_to_obj[i]
            o = v[m] @ M[:3, :3]
            out[m] = o + M[3, :3] if point else o
        return out


#: camera rays per wavefront (per :meth:`PathIntegrator.radiance` call): a pass over a tile is split into
#: bands of rows of at most this many rays. Small enough that a wavefront's per-ray arrays stay in a
#: core's L2 cache, large enough that per-call overhead stays small: measured
#: (``python -m nasset_benchmarks.renderer_throughput``) 1.2-1.3x faster than 32768-ray wavefronts on the
#: rna scene and on the 8dna near field. Images depend on it only through the order of random numbers.
WAVEFRONT = 8192


def render(scene, settings: RenderSettings | None = None, *, plan: RenderPlan | None = None,
           load_components: bool = True) -> RenderResult:
    """Render ``scene`` (from :func:`nasset_reference_renderer.scene.load_scene`).

    The image is a sum over jobs, one per wavefront (a band of a tile's rows, for the samples of one pass) with its
    own random numbers; ``settings.workers`` threads trace them (numpy, onnxruntime and Embree release the
    interpreter lock) and the film adds their results in job order, so the image does not depend on the number of
    threads (spec/renderer.md#film). numpy's BLAS runs on one thread meanwhile
    (:func:`nasset_sdk.process.single_threaded_blas`)."""
    with single_threaded_blas():
        return _render(scene, settings, plan, load_components)


def _render(scene, settings: RenderSettings | None, plan: RenderPlan | None, load_components: bool) -> RenderResult:
    from .scene import Scene

    if not isinstance(scene, Scene):
        raise UsageError(f"render: scene must be a Scene (nasset_reference_renderer.load_scene), got {type(scene).__name__}")
    check_settings(settings or RenderSettings())
    s = resolve_settings(settings or RenderSettings(), scene)
    check_settings(s)
    width, height = check_image_size(*scene.camera.default_resolution(s.width, s.height), s.spp)
    if plan is None:
        plan = make_plan(scene, width=width, height=height, spp=s.spp, max_depth=s.max_depth, tile=s.tile, batch=s.batch,
                         neupress_sampling=s.neupress_sampling, prt=s.prt, eightdna_sampling=s.eightdna_sampling,
                         rna_continuation=s.rna_continuation)
    tile = max(1, s.tile)
    tiles = [(x0, y0) for y0 in range(0, height, tile) for x0 in range(0, width, tile)]
    passes = [(p0, min(s.spp, p0 + plan.spp_per_pass)) for p0 in range(0, s.spp, plan.spp_per_pass)]
    n_jobs = sum(1 for _ in _jobs(tiles, passes, width, height, tile))  # the bands' pixel slices are views: cheap
    n_workers = render_workers(s.workers, n_jobs)
    if load_components:
        prepare_assets(scene, plan, s, workers=n_workers)
    integ = PathIntegrator(scene, plan, s)
    integs = [integ] + [integ.worker_copy() for _ in range(n_workers - 1)]
    free = queue.SimpleQueue()  # the integrators not tracing a job now
    for it in integs:
        free.put(it)
    rs = scene.render_settings
    filt = (rs.get("pixel_filter", "box"), rs.get("pixel_filter_stddev", 0.5))

    def run(job):
        it = free.get()
        try:
            return _render_job(it, scene, s, job, width, height, filt)
        finally:
            free.put(it)

    film = Film(width, height)
    bar = None
    if s.progress:
        from tqdm import tqdm

        bar = tqdm(total=n_jobs, unit="wavefront", desc="render", leave=False)
    t_start, c_start = time.perf_counter(), time.process_time()
    camera_samples, busy = 0, 0.0
    for pix_band, L, seconds in _in_order(run, _jobs(tiles, passes, width, height, tile), n_workers):
        film.add_passes(pix_band, L)  # L: pix_band's samples, the band repeated once per spp of the pass
        camera_samples += len(L)
        busy += seconds
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    st = integ.stats
    for other in integs[1:]:
        st.network_evals += other.stats.network_evals
        for key in ("trace", "network"):
            st.time[key] += other.stats.time[key]
    st.camera_samples, st.workers = camera_samples, n_workers
    st.time_total = time.perf_counter() - t_start
    st.cpu_total = time.process_time() - c_start
    st.rays = sum(it.accel.rays_cast for it in integs)
    st.time["other"] = max(0.0, (st.time_total if n_workers == 1 else busy) - st.time["trace"] - st.time["network"])
    return RenderResult(film, plan, st)


def _band(p0: int, p1: int) -> int:
    """Pixels per wavefront of a pass of spp p1 - p0: at most WAVEFRONT camera rays."""
    return max(1, WAVEFRONT // (p1 - p0))


def _jobs(tiles, passes, width: int, height: int, tile: int):
    """The render's jobs in film order: (tile index, pass index, band index, pixels of the band [m], p0, p1), tile by
    tile, each tile's passes in turn, each pass in bands of the tile's rows (one wavefront each)."""
    for ti, (x0, y0) in enumerate(tiles):
        x1, y1 = min(width, x0 + tile), min(height, y0 + tile)
        ys, xs = np.mgrid[y0:y1, x0:x1]
        pix_tile = (ys * width + xs).ravel()
        for pi, (p0, p1) in enumerate(passes):
            band = _band(p0, p1)
            for bi, b0 in enumerate(range(0, len(pix_tile), band)):
                yield ti, pi, bi, pix_tile[b0:b0 + band], p0, p1


def _render_job(integ: PathIntegrator, scene, s: RenderSettings, job, width: int, height: int, filt):
    """(pixels [m], radiance [m * (p1 - p0), 3]: the band repeated once per spp of the pass, seconds) of one job of
    :func:`_jobs`: one wavefront, its random numbers seeded by (seed, tile, pass, band)."""
    t0 = time.perf_counter()
    ti, pi, bi, pix_band, p0, p1 = job
    rng = np.random.default_rng([s.seed, ti, pi, bi])
    pix = np.tile(pix_band, p1 - p0)
    jit = pixel_offsets(rng, len(pix), *filt)
    px = (pix % width) + jit[:, 0]
    py = (pix // width) + jit[:, 1]
    cam = scene.camera
    lens = rng.random((len(pix), 2)) if cam.needs_lens_samples else None
    o, d = cam.generate_rays(px, py, width, height, lens)
    L = integ.radiance(o, d, rng)
    if cam.exposure_scale != 1.0:
        L *= cam.exposure_scale
    return pix_band, L, time.perf_counter() - t0


def _in_order(fn, items, workers: int):
    """fn(item) for each item, yielded in the items' order; with several workers computed on that many threads, at
    most 2 * workers ahead of the consumer (their results' memory). An exception is raised when its item's turn comes,
    and the items not started by then are dropped."""
    if workers <= 1:
        for item in items:
            yield fn(item)
        return
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="nasset-render") as pool:
        pending = deque()
        try:
            for item in items:
                pending.append(pool.submit(fn, item))
                if len(pending) >= 2 * workers:
                    yield pending.popleft().result()
            while pending:
                yield pending.popleft().result()
        finally:
            for f in pending:
                f.cancel()


DEFAULT_MAX_DEPTH = 5


def resolve_settings(s: RenderSettings, scene) -> RenderSettings:
    """``s`` with ``max_depth`` filled in when it is None: the scene's ``nasset:maxDepth`` (-1: unbounded, i.e.
    MAX_DEPTH with Russian roulette; 0: only what the camera sees emitting), else DEFAULT_MAX_DEPTH."""
    import dataclasses

    if s.max_depth is not None:
        return s
    md = getattr(scene, "render_settings", {}).get("max_depth")
    return dataclasses.replace(s, max_depth=DEFAULT_MAX_DEPTH if md is None else (MAX_DEPTH if md < 0 else int(md)))


#: Bounds of the other render settings (spec/renderer.md#limits); image size and spp: film.check_image_size.
MAX_DEPTH = 1024
MAX_BATCH = 1 << 24
MAX_TILE = 1 << 16
MAX_THREADS = 1024


#: ``RenderSettings.backend`` values: Embree, or the brute-force numpy ray caster (tests and tiny scenes only)
BACKENDS = ("embree", "numpy")


def check_settings(s: RenderSettings) -> None:
    """``USAGE`` error unless ``s`` is a RenderSettings whose spp, seed, max_depth, rr_depth, batch, tile,
    threads, workers and light_draws are integers within their bounds, width and height integers or None (their bounds:
    film.check_image_size) and backend one of :data:`BACKENDS`."""
    if not isinstance(s, RenderSettings):
        raise UsageError(f"render settings must be a RenderSettings, got {type(s).__name__}")
    for name, value, lo, hi in (("spp", s.spp, 1, MAX_SPP), ("seed", s.seed, 0, (1 << 64) - 1),
                                ("max_depth", s.max_depth, 0, MAX_DEPTH), ("rr_depth", s.rr_depth, 0, MAX_DEPTH),
                                ("batch", s.batch, 1, MAX_BATCH), ("tile", s.tile, 1, MAX_TILE),
                                ("threads", s.threads, 0, MAX_THREADS), ("workers", s.workers, 0, MAX_THREADS),
                                ("light_draws", s.light_draws, 0, MAX_DRAWS),
                                ("width", s.width, 1, None), ("height", s.height, 1, None)):
        if value is None and name in ("max_depth", "width", "height"):
            continue  # filled in from the scene (resolve_settings, the camera's own resolution)
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < lo or (hi is not None and value > hi):
            bound = f"{lo} .." if hi is None else f"{lo} .. {hi}"
            raise UsageError(f"{name} = {value!r} is not an integer in {bound} (--{name.replace('_', '-')})")
    if s.backend not in BACKENDS:
        raise UsageError(f"backend must be one of {BACKENDS}, got {s.backend!r}")


def usable_cores() -> int:
    """The CPU cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on every platform
        return os.cpu_count() or 1


#: the most render threads ``RenderSettings.workers = 0`` picks
MAX_AUTO_WORKERS = 16


def render_workers(workers: int, jobs: int) -> int:
    """Render threads for ``RenderSettings.workers`` (0: one per usable core, at most MAX_AUTO_WORKERS), never more
    than the render's jobs (wavefronts)."""
    n = int(workers) if workers > 0 else min(usable_cores(), MAX_AUTO_WORKERS)
    return max(1, min(n, jobs))


def decoder_threads(threads: int, workers: int = 1) -> int:
    """onnxruntime intra-op threads for ``RenderSettings.threads`` (0: automatic) with ``workers`` render threads.

    Automatic is onnxruntime's own default (one per core) for a single render thread, except on machines with at
    most two usable cores: there one thread is faster, because the render's numpy work between decoder runs
    shares the cores with onnxruntime's spinning worker threads (measured with
    ``python -m nasset_benchmarks.renderer_throughput --threads 1,2``: about 2x slower renders with 2 threads).
    With several render threads it is one: the threads already keep the cores busy.
    """
    if threads > 0:
        return int(threads)
    return 1 if workers > 1 or usable_cores() <= 2 else 0


def prepare_assets(scene, plan: RenderPlan, settings: RenderSettings, workers: int = 1) -> None:
    """Load what the plan needs of each asset and build its evaluator (once per file; ``workers``: the render
    threads that will share it, for its onnxruntime thread count)."""
    from nasset_sdk.errors import NassetError, SceneError

    for data in scene.assets:
        if data.evaluator is not None:
            continue
        loaded, _ = plan.components[str(data.path)]
        options = getattr(shader_class(data.asset.kind, variant_of(data)), "evaluator_options", {})
        try:
            data.asset.load(loaded)
            data.evaluator = data.asset.evaluator(intra_threads=decoder_threads(settings.threads, workers), batch=max(1024, settings.batch),
                                                  **options)
        except NassetError as exc:
            raise SceneError("SCENE_INVALID", f"referenced asset {data.path} is invalid: {exc}", file=scene.file,
                             prim=data.prims[0] if data.prims else None) from None
