"""rna fiber assets (spec/renderer.md#fibers): curve tubes for the triangle scene and the fiber vertex.

Each linear segment of each curve becomes a closed prism of :data:`TUBE_SIDES` sides (two rings
of vertices on the circles of radius width/2 at the segment's end points, in planes perpendicular
to the segment, plus the two end caps). The prisms go into the renderer's single triangle scene
like any asset triangles. At a hit the fiber quantities come from the segment's axis, not from
the tessellation: the tangent t is the segment direction and h the signed offset of the ray from
the axis (:func:`fiber_h`), both in object space.

Rays leaving a fiber hit (shadow and continuation rays) start at the hit point and ignore the
instance like surface rays do, but the triangles of the hit's own segment and of its neighbours
in the same curve do not count as passing through the asset (the fiber's own cross-section is
part of its transport, not a shadow); any other triangle of the instance picks the shadowed
branch.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from nasset_sdk.curves import linear_segments
from nasset_sdk.embree import quads_of_pairs

from ..sampling import (
    INV_4PI,
    Z_AXIS,
    around,
    cross3,
    dot,
    normalize,
    sample_mixture,
    square_to_uniform_sphere,
    square_to_vmf,
    unit_or,
    vmf_pdf,
)
from .common import Frames
from .registry import register_shader
from .rna_surface import fetch_continuations, rna_sample_rows

#: sides of the prism built around each curve segment
TUBE_SIDES = 8

#: the fiber continuation's mixture weights: uniform sphere, forward lobe around -wo, specular-cone band
#: (:class:`FiberContinuation`). Chosen on the dense hair example (20 000 strands, 300 camera hits, T on 4096
#: directions each): the second moment of T / pdf is 2.8x lower than the uniform sphere's (1.16 against 3.24;
#: sampling proportional to T would give 0.62); 0.3-0.4 in each lobe are all within 5 %
CONT_MIX = (0.4, 0.4, 0.2)
#: the forward lobe's von Mises-Fisher concentration (about 25 degrees wide)
FORWARD_KAPPA = 6.0
#: half width, in sin(theta) about the tangent, of the specular-cone band sin(theta_i) = -sin(theta_o)
CONE_HALF_WIDTH = 0.2


@dataclass
class FiberTubes:
    """Tessellated curves of one fiber asset, object space."""

    points: np.ndarray  # [V,3] prism vertices
    faces: np.ndarray  # [F,3]
    tri_seg: np.ndarray  # [F] segment of each triangle
    p0: np.ndarray  # [S,3] segment start
    p1: np.ndarray  # [S,3] segment end
    r0: np.ndarray  # [S] radius at p0 (width / 2)
    r1: np.ndarray  # [S] radius at p1
    exempt: np.ndarray  # [S,2] triangle range [lo, hi) of the segment and its neighbours in its curve
    quads: np.ndarray | None = None  # [Q,4] uint32: the faces as Embree quads (embree.quads_of_pairs), or None
    quad_tri: np.ndarray | None = None  # [Q,2] uint32: the two triangles of each quad
    quad_corners: np.ndarray | None = None  # [Q,2,2] uint8: where each triangle's corners 1 and 2 are in its quad


def _unit_rows(v):
    n = np.linalg.norm(v, axis=1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def tessellate(points, counts, widths, sides: int = TUBE_SIDES) -> FiberTubes:
    """Closed ``sides``-gon prisms around every non-degenerate segment of linear curves."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    c = np.asarray(counts, np.int64)
    r = 0.5 * np.asarray(widths, np.float64)
    a, curve, seg_first = linear_segments(c)  # segments (a, a + 1) inside each curve, in curve order
    p0, p1, r0, r1 = p[a], p[a + 1], r[a], r[a + 1]
    seg_len = np.linalg.norm(p1 - p0, axis=1)
    tiny = 1e-9 * (1.0 + float(np.abs(p).max(initial=0.0)))
    live = seg_len > tiny  # zero-length segments get no triangles
    t = _unit_rows(p1 - p0)
    helper = np.where(np.abs(t[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    b1 = _unit_rows(cross3(t, helper))
    b2 = cross3(t, b1)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = np.cos(ang)[None, :, None] * b1[:, None] + np.sin(ang)[None, :, None] * b2[:, None]  # [S,N,3]
    verts = np.concatenate([p0[:, None] + r0[:, None, None] * ring, p1[:, None] + r1[:, None, None] * ring], 1)  # [S,2N,3]
    k = np.arange(sides)
    kn = (k + 1) % sides
    side = np.concatenate([np.stack([k, kn, sides + kn], 1), np.stack([k, sides + kn, sides + k], 1)])
    fan = np.arange(1, sides - 1)
    cap0 = np.stack([np.zeros_like(fan), fan + 1, fan], 1)  # wound to face -t
    cap1 = np.stack([np.full_like(fan, sides), sides + fan, sides + fan + 1], 1)  # wound to face +t
    local = np.concatenate([side, cap0, cap1])  # [4N-4, 3] into one segment's 2N vertices
    per = len(local)
    n_seg = len(a)
    live_ids = np.nonzero(live)[0]
    faces = (live_ids[:, None, None] * 2 * sides + local[None]).reshape(-1, 3)
    tri_seg = np.repeat(live_ids, per)
    n_tri = np.where(live, per, 0)
    first = np.concatenate([[0], np.cumsum(n_tri)])  # [S+1] first triangle of each segment
    seg = np.arange(n_seg)
    lo_seg = np.maximum(seg - 1, seg_first[curve])
    hi_seg = np.minimum(seg + 1, seg_first[curve + 1] - 1)
    exempt = np.stack([first[lo_seg], first[hi_seg + 1]], 1).astype(np.int64)
    # Embree holds a segment's coplanar triangle pairs as quads (reference_renderer/accel.py: half the primitives):
    # side triangle k with k + N, the cap fans' triangles 2m with 2m + 1
    fans = np.arange(0, sides - 3, 2)
    local_pairs = np.concatenate([np.stack([k, k + sides], 1), np.stack([2 * sides + fans, 2 * sides + fans + 1], 1),
                                  np.stack([3 * sides - 2 + fans, 3 * sides - 1 + fans], 1)])
    local_quads, local_tri, local_corners = quads_of_pairs(local, local_pairs)
    quads = quad_tri = corners = None
    # Embree's 32-bit indices: the points of every segment (dead ones too) and the triangles of the live ones (beyond
    # them Embree refuses the points anyway)
    if max(n_seg * 2 * sides, len(live_ids) * per) < 2**32 - 1:
        base = live_ids.astype(np.uint32)[:, None, None]
        quads = (base * np.uint32(2 * sides) + local_quads[None]).reshape(-1, 4)
        quad_tri = (np.arange(len(live_ids), dtype=np.uint32)[:, None, None] * np.uint32(per)
                    + local_tri[None].astype(np.uint32)).reshape(-1, 2)
        corners = np.ascontiguousarray(np.broadcast_to(local_corners, (len(live_ids), *local_corners.shape))).reshape(-1, 2, 2)
    return FiberTubes(verts.reshape(-1, 3), faces.astype(np.int64, copy=False), tri_seg.astype(np.int64, copy=False), p0, p1,
                      r0, r1, exempt, quads, quad_tri, corners)


def fiber_frame(tubes: FiberTubes, seg, x_obj, wo_obj):
    """(unit tangent t [n,3], h [n]) at object-space points x on segments ``seg``, seen along wo.

    h = ((x - p0) . (t x wo)) / (|t x wo| r(s)), clamped to [-1, 1]; 0 where t x wo vanishes (the ray
    runs along the axis). r(s) = r0 + s (r1 - r0), s = clamp((x - p0) . t / |p1 - p0|, 0, 1)."""
    p0, p1 = tubes.p0[seg], tubes.p1[seg]
    axis = p1 - p0
    ln = np.linalg.norm(axis, axis=1)
    t = axis / np.where(ln > 0, ln, 1.0)[:, None]
    rel = x_obj - p0
    s = np.clip((rel * t).sum(1) / np.where(ln > 0, ln, 1.0), 0.0, 1.0)
    r = tubes.r0[seg] + s * (tubes.r1[seg] - tubes.r0[seg])
    c = cross3(t, wo_obj)
    cl = np.linalg.norm(c, axis=1)
    ok = (cl > 1e-9) & (r > 0)
    h = np.where(ok, (rel * c).sum(1) / np.where(ok, cl * r, 1.0), 0.0)
    return t, np.clip(h, -1.0, 1.0)


class FiberContinuation:
    """Continuation directions of fiber hits (spec/renderer.md#fibers): a defensive mixture, per world
    steradian, of the uniform sphere, a von Mises-Fisher lobe around the forward direction -wo (light passing
    through and along the fibers) and the band |sin(theta_i) + sin(theta_o)| < :data:`CONE_HALF_WIDTH` about the
    tangent with uniform azimuth (the specular cone the R, TT and TRT lobes of a fiber scatter into).
    Every direction keeps density >= CONT_MIX[0] / 4pi, so the estimate stays unbiased and T / pdf is
    at most 4pi T / CONT_MIX[0].

    ``wo``, ``t`` [n,3]: unit world directions toward the viewer and along the fiber, one row per hit;
    ``sample`` and ``pdf`` take the hit rows they are for."""

    def __init__(self, wo: np.ndarray, t: np.ndarray) -> None:
        self.fwd = unit_or(-wo, Z_AXIS)
        self.t = unit_or(unit_or(t, wo), Z_AXIS)  # no tangent (a degenerate one): the band about wo, or +z without either
        s_o = np.clip(dot(wo, self.t), -1.0, 1.0)
        self.lo = np.maximum(-1.0, -s_o - CONE_HALF_WIDTH)
        self.hi = np.minimum(1.0, -s_o + CONE_HALF_WIDTH)  # hi - lo >= CONE_HALF_WIDTH

    def sample(self, rows: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Unit world directions [m,3] for hit rows ``rows`` from uniform numbers u [m,3] (u[:,2] picks the lobe)."""
        fwd, t, lo, hi = self.fwd[rows], self.t[rows], self.lo[rows], self.hi[rows]

        def band(m, u2):  # uniform in z = sin(theta_i) about the tangent over [lo, hi], and in azimuth
            z = lo[m] + u2[:, 0] * (hi[m] - lo[m])
            r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
            phi = 2.0 * np.pi * u2[:, 1]
            return around(t[m], np.stack([r * np.cos(phi), r * np.sin(phi), z], 1))

        return sample_mixture(CONT_MIX, u, (lambda m, u2: square_to_uniform_sphere(u2),
                                            lambda m, u2: around(fwd[m], square_to_vmf(u2, FORWARD_KAPPA)), band))

    def pdf(self, rows: np.ndarray, wi: np.ndarray) -> np.ndarray:
        """Density [m] per world steradian of unit directions wi [m,3] at hit rows ``rows``."""
        z = dot(wi, self.t[rows])
        lo, hi = self.lo[rows], self.hi[rows]
        band = np.where((z >= lo) & (z <= hi), 1.0 / (2.0 * np.pi * (hi - lo)), 0.0)
        return (CONT_MIX[0] * INV_4PI + CONT_MIX[1] * vmf_pdf(dot(wi, self.fwd[rows]), FORWARD_KAPPA)
                + CONT_MIX[2] * band)


class FiberShading:
    """The rna fiber vertex of :class:`nasset_reference_renderer.integrator.PathIntegrator` (a :class:`~.Shader`)."""

    def __init__(self, integ) -> None:
        self.integ = integ
        scene = integ.scene
        self.tubes = [data.fiber for data in scene.assets]
        self.inst_first_tri = np.array([i.first_tri for i in scene.instances], np.int64)
        self.lobes = integ.s.rna_continuation == "lobes"  # else the uniform sphere (RenderSettings)
        self.frames = Frames(scene)

    def hit_frame(self, x_obj, wo_obj, prim, asset_id):
        """(t, h, segment, exempt [n,2] world triangle ranges) of fiber hits on triangles ``prim``."""
        integ = self.integ
        n = len(prim)
        local = integ.scene.tri_local[prim]
        inst = integ.scene.tri_inst[prim]
        t = np.zeros((n, 3))
        h = np.zeros(n)
        seg = np.zeros(n, np.int64)
        exempt = np.zeros((n, 2), np.int64)
        for a in np.unique(asset_id):
            m = asset_id == a
            tubes = self.tubes[a]
            sg = tubes.tri_seg[local[m]]
            t[m], h[m] = fiber_frame(tubes, sg, x_obj[m], wo_obj[m])
            seg[m] = sg
            exempt[m] = tubes.exempt[sg] + self.inst_first_tri[inst[m]][:, None]
        return t, h, seg, exempt

    def vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset: int | None = None, mode: dict | None = None):
        integ = self.integ
        x, d, beta, prim, inst, ridx = x[r], d[r], beta[r], prim[r], inst[r], idx[r]
        x_obj = integ.to_object(x, inst, point=True)
        wo_obj = normalize(integ.to_object(-d, inst))
        asset_id = integ.inst_asset[inst]
        t_obj, h, _, exempt = self.hit_frame(x_obj, wo_obj, prim, asset_id)
        indirect = integ.indirect[inst]
        # rays leave a fiber hit from the hit point itself; its own and neighbouring segments are exempt
        continuation = None  # the uniform sphere
        if self.lobes and indirect.any():
            continuation = FiberContinuation(-d, self.frames.dir_to_world(t_obj, inst))
        fetch = integ.fetch_points(x, inst)  # None: every hit fetches its light at x (f = 0)
        ray, wi_all, w_all, self_all, is_cont, cont, wi_c, pdf_c = rna_sample_rows(
            integ, x, inst, indirect, rng, lambda s, wi_s, at: (at, exempt[s]), continuation, fetch)
        tu = np.zeros((len(ray), 3))
        ts = np.zeros((len(ray), 3))
        if len(ray):
            wi_obj = normalize(integ.to_object(wi_all, inst[ray]))
            ray_asset = asset_id[ray]
            x32, t32, wo32, h32 = (v.astype(np.float32) for v in (x_obj, t_obj, wo_obj, h))
            for a in np.unique(ray_asset):
                m = ray_asset == a
                rr = ray[m]
                t0 = time.perf_counter()
                u_, s_ = integ.scene.assets[a].evaluator.evaluate(x32[rr], t32[rr], wo32[rr], wi_obj[m].astype(np.float32), h32[rr])
                integ.stats.time["network"] += time.perf_counter() - t0
                integ.stats.network_evals += len(rr)
                tu[m], ts[m] = u_, s_
        light_rows = ~is_cont
        if light_rows.any():
            lr = ray[light_rows]
            tsel = np.where(self_all[light_rows][:, None], ts[light_rows], tu[light_rows])
            np.add.at(L, ridx[lr], beta[lr] * tsel * w_all[light_rows])
        if not len(cont):
            return None
        cu, cs = tu[is_cont] * w_all[is_cont], ts[is_cont] * w_all[is_cont]
        origin, beta_c, pend = fetch_continuations(integ, fetch, cont, x[cont], None, wi_c, inst[cont], beta[cont], cu,
                                                   cs, exempt[cont])
        return (ridx[cont], origin, wi_c, beta_c, pdf_c, inst[cont], pend,
                np.zeros(len(cont), bool), exempt[cont])


register_shader("rna", "fiber")(FiberShading)
