"""Path-traced training tuples of the ``8dna`` kind on Mitsuba's Python API (spec/bake-8dna.md#sampler).

Paper §3.3 "Training data generation": a point is drawn uniformly on the asset's bounding sphere
(centre c, radius 1.01 r) and a cosine-weighted direction d about the inward normal; the ray is
traced into the asset (alone: no other shape, no emitter) and continued as a path through the
asset's own BSDFs (Mitsuba ``bsdf.sample``, radiance transport mode) and interior media
(free-flight sampling against the medium's majorant, history-aware spectral tracking with coefficients looked up per
collision -- constants for homogeneous media, Mitsuba's ``get_scattering_coefficients`` for grid
media -- and the medium's phase function), with
throughput Russian roulette, until it leaves the asset. Camera-side / light-side convention
(spec/kinds/8dna.md): the first hit is x_o and w_o = -d (towards the viewer); the last boundary
vertex is x_i and w_i the direction the path leaves along (from the asset towards the light);
u_i is where the ray x_i + t w_i leaves the encoding box. Paths whose first ray misses the asset are
dropped; paths ending by roulette or at the depth cap carry beta = 0; with the direct lobe separated
(the default), paths that leave after a single (boundary) event carry beta = 0 too (paper §3.1).

beta (RGB) is the path throughput: E[beta | x_o, w_o] = alpha(x_o, w_o), the radiance leaving x_o
towards w_o under unit incident radiance (paper Eq. 7), and beta-weighted (u_i, w_i) follow p.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nasset_sdk.errors import error

from .scene import scene_of

FIELDS = ("xo", "wo", "xi", "wi", "ui", "beta")


@dataclass
class MediumParams:
    """A homogeneous medium: sigma_t, sigma_s RGB (1/m, scale applied) and the Henyey-Greenstein g (0: isotropic)."""

    sigma_t: np.ndarray
    sigma_s: np.ndarray
    g: float = 0.0

    @property
    def majorant(self) -> float:
        return float(self.sigma_t.max())

    def coefficients(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(sigma_s, sigma_t) [N,3] at points p [N,3]."""
        n = len(p)
        return np.tile(self.sigma_s, (n, 1)), np.tile(self.sigma_t, (n, 1))

    def key(self):
        return ("homogeneous", tuple(self.sigma_t), tuple(self.sigma_s), self.g)


class GridMedium:
    """A heterogeneous Mitsuba medium: coefficients looked up through Mitsuba at each tentative collision,
    against its global majorant (spectral tracking)."""

    def __init__(self, mi, medium, g: float) -> None:
        import drjit as dr

        self.mi, self.medium, self.g = mi, medium, float(g)
        mei = dr.zeros(mi.MediumInteraction3f, 1)
        self.majorant = float(np.max(np.asarray(medium.get_majorant(mei), np.float64)))

    def coefficients(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        import drjit as dr

        mi = self.mi
        mei = dr.zeros(mi.MediumInteraction3f, len(p))
        mei.p = mi.Point3f(np.ascontiguousarray(p.T, np.float32))
        sigma_s, _, sigma_t = self.medium.get_scattering_coefficients(mei)
        dr.eval(sigma_s, sigma_t)
        ss = np.broadcast_to(np.asarray(sigma_s, np.float64).reshape(-1, len(p)).T, (len(p), 3))
        st = np.broadcast_to(np.asarray(sigma_t, np.float64).reshape(-1, len(p)).T, (len(p), 3))
        return np.nan_to_num(np.clip(ss, 0, None)), np.nan_to_num(np.clip(st, 0, self.majorant))

    def key(self):
        return ("grid", id(self.medium))


def _phase_g(mi, medium, shape_id: str) -> float:
    phase = medium.phase_function()
    name = str(phase).split("[")[0]
    if "HG" in name or "Henyey" in name:
        pp = mi.traverse(phase)
        return float(np.asarray(pp["g"]).ravel()[0]) if "g" in pp.keys() else 0.0
    if "Isotropic" not in name:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape_id!r}: phase function {name} (isotropic and hg are supported)")
    return 0.0


def medium_params(mi, medium, shape_id: str):
    """The interior medium of a shape: :class:`MediumParams` (homogeneous) or :class:`GridMedium` (heterogeneous)."""
    g = _phase_g(mi, medium, shape_id)
    if not medium.is_homogeneous():
        return GridMedium(mi, medium, g)
    p = mi.traverse(medium)
    keys = {k: p[k] for k in p.keys()}
    scale = float(np.asarray(keys.get("scale", 1.0)).ravel()[0])
    st = next((np.asarray(v, np.float64).ravel() for k, v in keys.items() if k.startswith("sigma_t")), None)
    al = next((np.asarray(v, np.float64).ravel() for k, v in keys.items() if k.startswith("albedo")), None)
    if st is None or al is None:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape_id!r}: cannot read sigma_t/albedo of {str(medium).split('[')[0]}")
    st = np.broadcast_to(st, 3) * scale if st.size in (1, 3) else None
    al = np.broadcast_to(al, 3) if al.size in (1, 3) else None
    if st is None or al is None or not (np.isfinite(st).all() and (st >= 0).all() and np.isfinite(al).all()):
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape_id!r}: medium coefficients must be finite RGB values")
    return MediumParams(np.array(st, np.float64), np.array(st * np.clip(al, 0, 1), np.float64), g)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-30)


def _frame(n: np.ndarray):
    sign = np.copysign(1.0, n[:, 2])
    a = -1.0 / (sign + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + sign * n[:, 0] ** 2 * a, sign * b, -sign * n[:, 0]], 1)
    s = np.stack([b, sign + n[:, 1] ** 2 * a, -n[:, 1]], 1)
    return t, s


def real_collision_probability(beta: np.ndarray, sigma_t: np.ndarray, majorant: float) -> np.ndarray:
    """Probability [N] that a tentative collision at coefficients ``sigma_t`` [N,3] (1/m, each <= ``majorant``) is
    real, for paths of throughput ``beta`` [N,3]: history-aware spectral tracking (Kutz et al. 2017, Sec. 5), the
    throughput-weighted mean of sigma_t / majorant.

    With the weights sigma_s / (majorant p) on a real collision and (1 - sigma_t / majorant) / (1 - p) on a null one,
    every channel stays unbiased for any p in (0, 1), and this p keeps the channel sum of beta from growing: a
    chromatic medium's thin channel is not multiplied up at each null collision (with the plain mean of the channels,
    a channel at a third of the majorant gained x3 per null collision and a long path's weights grew without bound).
    Paths with zero throughput use the plain mean."""
    w = np.clip(beta, 0.0, None)
    total = w.sum(1, keepdims=True)
    w = np.where(total > 0, w / np.maximum(total, 1e-300), 1.0 / 3.0)
    return np.clip((w * sigma_t).sum(1) / majorant, 0.0, 1.0)


def sample_hg(rng, d: np.ndarray, g: float) -> np.ndarray:
    """New directions [N,3] from the Henyey-Greenstein phase function around the travel direction d (g = 0: uniform)."""
    n = len(d)
    u1, u2 = rng.random(n), rng.random(n)
    if abs(g) < 1e-4:
        cos_t = 1.0 - 2.0 * u1
    else:
        sq = (1.0 - g * g) / (1.0 - g + 2.0 * g * u1)
        cos_t = (1.0 + g * g - sq * sq) / (2.0 * g)
    cos_t = np.clip(cos_t, -1.0, 1.0)
    sin_t = np.sqrt(np.maximum(1.0 - cos_t ** 2, 0.0))
    phi = 2.0 * np.pi * u2
    t, s = _frame(d)
    return _unit(sin_t[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * s) + cos_t[:, None] * d)


def box_exit(x: np.ndarray, w: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Point where the ray x + t w (x inside the box lo..hi) leaves it [N,3]."""
    with np.errstate(divide="ignore", invalid="ignore"):
        tk = np.where(w > 0, (hi - x) / w, np.where(w < 0, (lo - x) / w, np.inf))
    t = np.maximum(np.min(tk, axis=1), 0.0)
    return np.clip(x + t[:, None] * w, lo, hi)


class PathSampler:
    """Forward path sampler over the asset's shapes (see module docstring); object space = scene space."""

    def __init__(self, mi, shapes, lo, hi, *, separate_direct: bool = True, rr_depth: int = 4, max_depth: int = 512,
                 seed: int = 0) -> None:
        self.mi = mi
        self.shapes = list(shapes)
        self.scene = scene_of(mi, self.shapes)
        self.lo = np.asarray(lo, np.float64)
        self.hi = np.asarray(hi, np.float64)
        bb = self.scene.bbox()
        bmin, bmax = np.array(bb.min, np.float64), np.array(bb.max, np.float64)
        self.center = 0.5 * (bmin + bmax)
        self.radius = 1.01 * 0.5 * float(np.linalg.norm(bmax - bmin))
        self.eps = 1e-5 * max(self.radius, 1e-3)
        self.separate_direct = bool(separate_direct)
        self.rr_depth = int(rr_depth)
        self.max_depth = int(max_depth)
        self.rng = np.random.default_rng(seed)
        media = {s.id(): s.interior_medium() for s in self.shapes}
        found = {k: medium_params(mi, m, k) for k, m in media.items() if m is not None}
        if len({p.key() for p in found.values()}) > 1:
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"asset shapes {sorted(found)} have different interior media; "
                        "the 8dna sampler supports one medium per asset")
        self.medium = next(iter(found.values()), None)
        self.stats = {"started": 0, "hits": 0, "exits": 0, "roulette": 0, "capped": 0, "direct": 0, "events": 0}

    # -- Mitsuba calls ----------------------------------------------------------------------
    def _intersect(self, o: np.ndarray, d: np.ndarray):
        mi = self.mi
        ray = mi.Ray3f(mi.Point3f(np.ascontiguousarray(o.T, np.float32)), mi.Vector3f(np.ascontiguousarray(d.T, np.float32)))
        si = self.scene.ray_intersect(ray)
        valid = si.is_valid()
        import drjit as dr

        dr.eval(si, valid)  # one kernel for all outputs
        return si, np.asarray(valid, bool), np.asarray(si.t, np.float64)

    def backtrace_hits(self, u: np.ndarray, w: np.ndarray) -> np.ndarray:
        """bool [N]: the ray from box points u [N,3] along -w [N,3] hits the asset (a renderer lights (u, w) only then)."""
        if not len(u):
            return np.zeros(0, bool)
        return self._intersect(u + w * self.eps, -w)[1]

    def _bsdf_sample(self, si, active: np.ndarray):
        mi = self.mi
        n = len(active)
        s1 = mi.Float(self.rng.random(n).astype(np.float32))
        s2 = mi.Point2f(self.rng.random((2, n)).astype(np.float32))
        bs, w = si.bsdf().sample(mi.BSDFContext(), si, s1, s2, mi.Bool(active))
        wo_w = si.to_world(bs.wo)
        import drjit as dr

        dr.eval(wo_w, w, bs.pdf)  # one kernel for all outputs
        wo = np.asarray(wo_w, np.float64).T
        w = np.asarray(w, np.float64).T
        ok = active & (np.asarray(bs.pdf, np.float64) > 0) & np.isfinite(w).all(1) & np.isfinite(wo).all(1)
        return _unit(wo), np.where(ok[:, None], w, 0.0), ok

    # -- sampling ----------------------------------------------------------------------------
    def start_rays(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        """n rays: uniform points on the bounding sphere, cosine-weighted directions about the inward normal."""
        nrm = _unit(self.rng.normal(size=(n, 3)))
        o = self.center + self.radius * nrm
        r, phi = np.sqrt(self.rng.random(n)), 2 * np.pi * self.rng.random(n)
        z = np.sqrt(np.maximum(1 - r * r, 0))
        inward = -nrm
        t, s = _frame(inward)
        d = _unit((r * np.cos(phi))[:, None] * t + (r * np.sin(phi))[:, None] * s + z[:, None] * inward)
        return o, d

    def sample_shard(self, key: tuple[int, ...], rays: int) -> tuple[dict, dict]:
        """One shard: ``rays`` starting rays drawn from the random stream ``key`` (seed, stream, shard)
        alone, so the shard's tuples are the same in any process. Returns (FIELDS arrays, the shard's
        counts: the keys of ``stats``)."""
        before = dict(self.stats)
        self.rng = np.random.default_rng([int(k) for k in key])
        out = self.sample(int(rays))
        return out, {k: self.stats[k] - before[k] for k in self.stats}

    def sample(self, n: int) -> dict:
        """Trace n starting rays; returns the FIELDS arrays [M, 3] (float32) for the M rays that hit the asset."""
        o, d = self.start_rays(n)
        si, hit, t = self._intersect(o, d)
        self.stats["started"] += n
        idx = np.nonzero(hit)[0]
        self.stats["hits"] += len(idx)
        m = len(idx)
        xo = o[idx] + t[idx, None] * d[idx]
        out = {"xo": xo, "wo": -d[idx], "xi": xo.copy(), "wi": d[idx].copy(), "beta": np.zeros((m, 3))}
        # path state (rows of `out`): position, direction, throughput, inside flag, events so far
        rows = np.arange(m)
        pos, dirv, beta = o[idx].copy(), d[idx].copy(), np.ones((m, 3))
        inside = np.zeros(m, bool)
        events = np.zeros(m, np.int64)
        med = self.medium
        majorant = med.majorant if med is not None else 0.0
        while len(rows):
            si, hit, t = self._intersect(pos, dirv)
            t = np.where(hit, t, np.inf)
            # medium events (inside only): spectral tracking with one majorant for the three channels
            mev = np.zeros(len(rows), bool)
            if med is not None and majorant > 0:
                tm = -np.log1p(-self.rng.random(len(rows))) / majorant
                mev = inside & (tm < t)
                if mev.any():
                    k = np.nonzero(mev)[0]
                    pos[k] += tm[k, None] * dirv[k]
                    sig_s, sig_t = med.coefficients(pos[k])
                    p_real = real_collision_probability(beta[k], sig_t, majorant)
                    real = self.rng.random(len(k)) < p_real
                    kr, kn = k[real], k[~real]
                    beta[kr] *= sig_s[real] / np.maximum(majorant * p_real[real, None], 1e-300)
                    if len(kn):
                        beta[kn] *= (1.0 - sig_t[~real] / majorant) / np.maximum(1.0 - p_real[~real, None], 1e-12)
                    dirv[kr] = sample_hg(self.rng, dirv[kr], med.g)
                    events[kr] += 1
            done = np.zeros(len(rows), bool)
            # leaving: no surface ahead and not inside
            esc = ~mev & ~hit
            leak = esc & inside  # open mesh: a path inside that finds no boundary is lost
            beta[leak] = 0.0
            exits = esc & ~inside
            if exits.any():
                e = np.nonzero(exits)[0]
                out["wi"][rows[e]] = dirv[e]
                single = events[e] <= 1
                b = beta[e].copy()
                if self.separate_direct:
                    b[single] = 0.0
                    self.stats["direct"] += int(single.sum())
                out["beta"][rows[e]] = b
                self.stats["exits"] += len(e)
            done |= esc
            # boundary events
            surf = ~mev & hit
            if surf.any():
                hp = pos + np.where(np.isfinite(t), t, 0.0)[:, None] * dirv
                wnew, w, ok = self._bsdf_sample(si, surf)
                ng = np.asarray(si.n, np.float64).T
                k = np.nonzero(surf)[0]
                beta[k] *= w[k]
                dirv[k] = wnew[k]
                going_in = (wnew[k] * ng[k]).sum(1) < 0
                inside[k] = going_in
                pos[k] = hp[k] + np.where(going_in, -1.0, 1.0)[:, None] * ng[k] * self.eps
                out["xi"][rows[k]] = hp[k]
                events[k] += 1
                bad = surf & ~ok
                beta[bad] = 0.0
                done |= bad
            # Russian roulette and depth cap
            live = ~done
            rr = live & (events >= self.rr_depth)
            if rr.any():
                k = np.nonzero(rr)[0]
                q = np.minimum(beta[k].max(1), 0.95)
                die = self.rng.random(len(k)) >= q
                beta[k[~die]] /= q[~die, None]
                kill = k[die]
                beta[kill] = 0.0
                done[kill] = True
                self.stats["roulette"] += len(kill)
            cap = ~done & (events >= self.max_depth)
            beta[cap] = 0.0
            done |= cap
            self.stats["capped"] += int(cap.sum())
            self.stats["events"] += int(mev.sum() + surf.sum())
            keep = ~done
            rows, pos, dirv, beta, inside, events = rows[keep], pos[keep], dirv[keep], beta[keep], inside[keep], events[keep]
        out["ui"] = box_exit(out["xi"], out["wi"], self.lo, self.hi)
        out["beta"] = np.nan_to_num(out["beta"], nan=0.0, posinf=0.0, neginf=0.0)
        return {k: np.asarray(out[k], np.float32) for k in FIELDS}


#: most starting rays of one shard (a unit of work a cluster worker runs; spec/bake.md#cluster)
SHARD_RAYS = 1 << 15
#: shard streams: 0 the held-out tuples, 1 + k the k-th fill of the online buffer
HELDOUT_STREAM = 0


def shard_rays(n: int) -> int:
    """Starting rays per shard for a fill of ``n`` tuples: a function of ``n`` alone (never of the
    worker count), so the shards, and the tuples, are the same however they are spread."""
    return int(min(SHARD_RAYS, max(2048, int(n) // 8)))


def local_runner(sample_shard):
    """``run(jobs, on_result)`` that runs each shard job ``(key, rays)`` in this process through
    ``sample_shard`` (:meth:`PathSampler.sample_shard`)."""

    def run(jobs, on_result) -> None:
        for job in jobs:
            on_result(job, sample_shard(*job))

    return run


class ShardedTuples:
    """Tuples drawn in deterministic shards: ``fill(n, stream)`` is the first ``n`` tuples of the
    concatenated shards (seed, stream, 0), (seed, stream, 1), ... of ``shard_rays(n)`` rays each.

    ``run(jobs, on_result)`` runs shard jobs ``(key, rays)`` anywhere (:func:`local_runner`, or a
    cluster's worker pool) and hands back ``(tuples, counts)`` per job in any order; ``batch``: the
    fewest shards handed out at once (the worker count). Shards beyond the ``n``-th tuple that ran
    (handed out together with the needed ones) are traced but not used."""

    def __init__(self, seed: int, run, *, batch: int = 1) -> None:
        self.seed, self.run, self.batch = int(seed), run, max(1, int(batch))
        self.stats = {"started": 0, "hits": 0, "shards": 0}

    def fill(self, n: int, stream: int, progress=None) -> dict:
        """The FIELDS arrays [n, 3] (float32) of stream ``stream``; ``progress(have, n)`` after each shard."""
        rays, n = shard_rays(n), int(n)
        done: dict = {}  # shard index -> its tuples
        arrived = [0]  # tuples of this fill so far, used or not

        def on_result(job, result) -> None:
            tuples, counts = result
            done[job[0][2]] = tuples
            self.stats["started"] += counts["started"]
            self.stats["hits"] += counts["hits"]
            self.stats["shards"] += 1
            arrived[0] += len(tuples["beta"])
            if progress is not None:
                progress(min(arrived[0], n), n)

        first, have = 0, 0
        while have < n:
            hit_rate = max(self.stats["hits"] / self.stats["started"], 0.05) if self.stats["started"] else 0.5
            k = max(self.batch, math.ceil(1.1 * (n - have) / (rays * hit_rate)))
            self.run([((self.seed, int(stream), first + j), rays) for j in range(k)], on_result)
            first += k
            have = sum(len(done[i]["beta"]) for i in range(first))
        return {f: np.concatenate([done[i][f] for i in range(first)])[:n] for f in FIELDS}


class OnlineBuffer:
    """A buffer of ``size`` tuples served in shuffled batches and regenerated once fully consumed
    (paper §3.3); fill k is stream 1 + k of ``source`` (:class:`ShardedTuples`), shuffled by ``seed``."""

    def __init__(self, source: ShardedTuples, size: int, *, reuse: int = 1, seed: int = 0, progress=None) -> None:
        self.source = source
        self.size = int(size)
        self.reuse = max(1, int(reuse))
        self.passes = 0
        self.progress = progress
        self.rng = np.random.default_rng([int(seed), 1])
        self.data: dict | None = None
        self.order = np.zeros(0, np.int64)
        self.pos = 0
        self.refreshes = 0

    def refill(self) -> None:
        self.data = self.source.fill(self.size, HELDOUT_STREAM + 1 + self.refreshes, progress=self.progress)
        self.order = self.rng.permutation(self.size)
        self.pos = 0
        self.passes = 1
        self.refreshes += 1

    def next(self, batch: int) -> dict:
        """The next ``batch`` tuples (a new shuffled pass, or a regenerated buffer after ``reuse`` passes)."""
        if self.data is None or self.pos + batch > self.size:
            if self.data is not None and self.passes < self.reuse:
                self.order = self.rng.permutation(self.size)
                self.pos = 0
                self.passes += 1
            else:
                self.refill()
        idx = self.order[self.pos:self.pos + batch]
        self.pos += batch
        return {k: v[idx] for k, v in self.data.items()}
