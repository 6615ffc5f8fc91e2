"""Training data for the rna kind, rendered by Mitsuba (spec/bake.md#data).

Per view: a pinhole camera on a sphere around the asset looks at its centre; one primary ray per
pixel *centre* (rays are generated here, so there is no pixel-filter jitter). For every pixel
whose ray hits the asset we store the hit point x, the shading normal n, wo (towards the camera),
a light direction wi, the binary visibility V of the light from x against the asset alone, and
the transport T (radiance per unit irradiance, mean of ``spp`` path samples, each clamped at
``clamp``, default 0: none). Training views give every pixel its own random light direction (the paper's choice;
one Mitsuba call per view through the per-path emitter of ``scene.IsolatedAsset``), or, with
``lights_per_view = k > 0`` or when that emitter is unavailable (finite-angle light, scalar
variant), k random directions per view shared by random pixel groups. Validation views use one
fixed light per view, at ``val_res`` and ``val_spp``, **never clamped**, in two independent halves
(``rgb_a``, ``rgb_b``, each ``val_spp / 2`` paths; ``rgb`` is their mean) so the reference's own noise
is measured (spec/accuracy.md#metrics). Training views store the energy a clamp removed
(``clamp_removed`` and ``energy``, per channel, summed over the view's pixel means). Fiber assets (Mitsuba
curves, spec/bake.md#mitsuba-curves) take x, the tangent (in ``n``), h and V from the prisms the reference
renderer traces (:class:`nasset_converters.caster.Caster`) and record the pixels on which the two disagree.

A dataset lives in a folder: ``meta.json`` (settings; a resume must match them) and one
``train/NNNN.npz`` / ``val/NNNN.npz`` per view, each written atomically, so an interrupted
bake resumes at the first missing view.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from nasset_converters.caster import agree
from nasset_sdk.errors import error
from nasset_sdk.images import output_folder

from . import CONVERTER_VERSION, is_jit

FIELDS = ("x", "n", "wo", "wi", "vis", "rgb", "pix")
FIBER_FIELDS = FIELDS + ("h",)  # fibers: n holds the tangent t, h the offset across the fiber

#: lights per training view when per-pixel lights are unavailable (finite-angle light, scalar variant)
FALLBACK_LIGHT_GROUPS = 32


@dataclass(frozen=True)
class DataSettings:
    views: int = 48
    val_views: int = 8
    res: int = 96
    spp: int = 64
    val_spp: int = 128
    lights_per_view: int = 0  # 0: an independent random light per pixel; k > 0: k lights per view
    light_angle_deg: float = 0.0
    distance: float = 2.6  # camera distance in bounding-sphere radii
    upper_hemisphere: bool = False
    val_res: int = 0  # held-out image size; 0: res
    clamp: float = 0.0  # per-path-sample radiance clamp (1/sr) of training views; 0: none (spec/bake.md#clamp)
    max_depth: int = 24
    seed: int = 0
    chunk: int = 1 << 20  # rays (pixels x spp) per Mitsuba call


def unit_sphere(rng, n: int, upper: bool) -> np.ndarray:
    v = rng.normal(size=(n, 3))
    v /= np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
    if upper:
        v[:, 1] = np.abs(v[:, 1])
    return v


def camera_rays(eye: np.ndarray, target: np.ndarray, half_fov: float, res: int):
    """Pixel-centre rays [res*res,3] (row-major, row 0 at the top) of a square pinhole camera."""
    fwd = target - eye
    fwd /= max(float(np.linalg.norm(fwd)), 1e-12)
    up0 = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.95 else np.array([1.0, 0.0, 0.0])
    right = np.cross(fwd, up0)
    right /= max(float(np.linalg.norm(right)), 1e-12)
    up = np.cross(right, fwd)
    t = np.tan(half_fov)
    c = (np.arange(res) + 0.5) / res * 2.0 - 1.0
    sx, sy = np.meshgrid(c, -c)
    d = fwd[None] + (sx.reshape(-1, 1) * t) * right[None] + (sy.reshape(-1, 1) * t) * up[None]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(eye, d.shape).copy()
    return o, d


class Renderer:
    """Mitsuba queries on an IsolatedAsset: primary hits, light visibility, transport. ``caster``
    (:class:`nasset_converters.caster.Caster`, fiber assets): the geometric inputs and the visibility come from
    the fiber prisms the reference renderer traces, the transport from Mitsuba's own curves."""

    def __init__(self, mi, iso, settings: DataSettings, caster=None, shadows=None) -> None:
        self.mi, self.iso, self.s = mi, iso, settings
        self.jit = is_jit(mi)
        self.caster = caster
        self.shadows = shadows  # a surface Caster: V from Mitsuba's hit, offset as the renderer offsets it

    # -- helpers -------------------------------------------------------------------------------
    def _ray(self, o, d):
        """Rays from scene-frame origins ``o`` (moved into the isolated scenes' frame, IsolatedAsset.origin)."""
        mi = self.mi
        o = np.ascontiguousarray(self.iso.to_render(o), np.float32)
        d = np.ascontiguousarray(d, np.float32)
        return mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))

    @staticmethod
    def _np3(v) -> np.ndarray:
        import drjit as dr

        dr.eval(v)  # one kernel for all three components
        return np.stack([np.asarray(v.x), np.asarray(v.y), np.asarray(v.z)], axis=1).astype(np.float32)

    @staticmethod
    def _bucket(n: int) -> int:
        """Lane counts are padded to powers of two: Mitsuba bakes the wavefront size into its kernels,
        so a fixed set of sizes keeps the JIT kernel cache warm across views and lights."""
        b = 4096
        while b < n:
            b *= 2
        return b

    def _pad(self, a: np.ndarray, size: int) -> np.ndarray:
        if len(a) == size:
            return a
        pad = np.repeat(a[-1:], size - len(a), axis=0) if len(a) else np.zeros((size,) + a.shape[1:], a.dtype)
        return np.concatenate([a, pad])

    # -- queries -------------------------------------------------------------------------------
    def hits(self, o, d):
        """(mask [N], x [N,3], n [N,3]) of primary rays against the asset alone."""
        if not self.jit:
            return self._hits_scalar(o, d)
        import drjit as dr

        n = len(o)
        size = self._bucket(n)
        si = self.iso.geometry_scene.ray_intersect(self._ray(self._pad(o, size), self._pad(d, size)))
        valid = si.is_valid()
        dr.eval(valid, si.p, si.sh_frame.n)
        mask = np.asarray(valid, bool)[:n]
        return mask, self.iso.to_scene(self._np3(si.p)[:n]).astype(np.float32), self._np3(si.sh_frame.n)[:n]

    def visibility(self, o, d, wi) -> np.ndarray:
        """1 where the light direction wi is not blocked by the asset at the primary hit of (o, d)."""
        mi = self.mi
        if not self.jit:
            return self._vis_scalar(o, d, wi)
        n = len(o)
        size = self._bucket(n)
        si = self.iso.geometry_scene.ray_intersect(self._ray(self._pad(o, size), self._pad(d, size)))
        if self.shadows is not None:
            return self.shadows.shadow(self.iso.to_scene(self._np3(si.p)[:n]), self._np3(si.n)[:n], wi)
        w = np.ascontiguousarray(self._pad(np.asarray(wi, np.float32), size))
        shadow = si.spawn_ray(mi.Vector3f(w[:, 0], w[:, 1], w[:, 2]))
        blocked = np.asarray(self.iso.geometry_scene.ray_test(shadow), bool)[:n]
        return ~blocked

    def transport(self, o, d, spp: int, seed: int, wi=None, *, clamp: float | None = None, stats: dict | None = None,
                  scene=None) -> np.ndarray:
        """Mean radiance [N,3] over spp paths. ``wi`` [N,3]: each pixel's own light direction (needs
        ``iso.per_path_lights``); without it, the current light (set with iso.set_light), or ``scene``'s lights
        (the asset's shapes lit otherwise, e.g. :class:`near_field.SphereLight`). ``clamp``:
        per-path-sample clamp (default the settings'); ``stats``: a dict whose ``removed`` and
        ``energy`` [3] accumulate the pixel means' energy the clamp removed and the unclamped energy."""
        clamp = self.s.clamp if clamp is None else clamp
        if not self.jit:
            return self._transport_scalar(o, d, spp, seed, clamp, stats, scene)
        mi = self.mi
        lanes = wi is not None
        if lanes and not self.iso.per_path_lights:
            raise ValueError("per-pixel light directions need a delta light and a JIT variant")
        scene = self.iso.lane_scene if lanes else (self.iso.lit_scene if scene is None else scene)
        n = len(o)
        out = np.zeros((n, 3), np.float64)
        per = max(1, self.s.chunk // max(spp, 1))
        for s in range(0, n, per):
            e = min(n, s + per)
            oo = np.repeat(o[s:e], spp, axis=0)
            dd = np.repeat(d[s:e], spp, axis=0)
            size = self._bucket(len(oo))
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(int(seed * 7919 + s) & 0x7FFFFFFF, size)
            ray = mi.RayDifferential3f(self._ray(self._pad(oo, size), self._pad(dd, size)))
            if lanes:
                # the table is padded too: its size is part of the kernel (a new size recompiles, ~2 s)
                self.iso.set_light_table(self._pad(np.asarray(wi[s:e], np.float32), self._bucket(e - s)))
                idx = np.repeat(np.arange(e - s, dtype=np.float32), spp)  # ray time = row of the table
                ray.time = mi.Float(self._pad(idx, size))
            spec, _, _ = self.iso.integrator.sample(scene, sampler, ray, None, True)
            L = self._np3(spec)[: len(oo)].astype(np.float64).reshape(e - s, spp, 3)
            L = np.nan_to_num(L, nan=0.0, posinf=0.0, neginf=0.0)
            raw = L.mean(axis=1)
            if clamp > 0:
                L = np.minimum(L, clamp)
            out[s:e] = L.mean(axis=1)
            account_clamp(stats, raw, out[s:e])
        return out.astype(np.float32)

    # -- scalar fallback (slow: one ray per call) ----------------------------------------------
    def _sray(self, o, d):
        mi = self.mi
        return mi.Ray3f(mi.Point3f(*map(float, self.iso.to_render(o))), mi.Vector3f(*map(float, d)))

    def _hits_scalar(self, o, d):
        n = len(o)
        mask = np.zeros(n, bool)
        x = np.zeros((n, 3), np.float32)
        nn = np.zeros((n, 3), np.float32)
        for i in range(n):
            si = self.iso.geometry_scene.ray_intersect(self._sray(o[i], d[i]))
            if si.is_valid():
                mask[i] = True
                x[i] = self.iso.to_scene(list(si.p))
                nn[i] = list(si.sh_frame.n)
        return mask, x, nn

    def _vis_scalar(self, o, d, wi):
        mi = self.mi
        out = np.zeros(len(o), bool)
        x, ng = np.zeros((len(o), 3)), np.zeros((len(o), 3))
        for i in range(len(o)):
            si = self.iso.geometry_scene.ray_intersect(self._sray(o[i], d[i]))
            if self.shadows is not None:
                x[i], ng[i] = self.iso.to_scene(list(si.p)), list(si.n)
            else:
                out[i] = not self.iso.geometry_scene.ray_test(si.spawn_ray(mi.Vector3f(*map(float, wi[i]))))
        return self.shadows.shadow(x, ng, wi) if self.shadows is not None else out

    def _transport_scalar(self, o, d, spp, seed, clamp, stats=None, scene=None):
        mi = self.mi
        sampler = mi.load_dict({"type": "independent"})
        out = np.zeros((len(o), 3), np.float64)
        for i in range(len(o)):
            sampler.seed(int(seed * 7919 + i) & 0x7FFFFFFF)
            ray = mi.RayDifferential3f(self._sray(o[i], d[i]))
            acc, acc_raw = np.zeros(3), np.zeros(3)
            for _ in range(spp):
                spec, _, _ = self.iso.integrator.sample(self.iso.lit_scene if scene is None else scene, sampler, ray, None, True)
                v = np.nan_to_num(np.asarray(list(spec), np.float64))
                acc += np.minimum(v, clamp) if clamp > 0 else v
                acc_raw += v
                sampler.advance()
            out[i] = acc / max(spp, 1)
            account_clamp(stats, acc_raw[None] / max(spp, 1), out[i:i + 1])
        return out.astype(np.float32)


def account_clamp(stats: dict | None, raw: np.ndarray, kept: np.ndarray) -> None:
    """Accumulate the unclamped energy and the energy a clamp removed (pixel means, per channel)."""
    if stats is None:
        return
    stats["energy"] = stats.get("energy", np.zeros(3)) + raw.sum(0)
    stats["removed"] = stats.get("removed", np.zeros(3)) + (raw - kept).sum(0)


def concat_views(parts: list[dict], fields) -> dict:
    """Per-view arrays of one split joined: ``fields`` concatenated (all required), the held-out halves
    ``rgb_a``/``rgb_b`` concatenated and the per-view sums ``energy``/``clamp_removed`` added up where
    every view has them (spec/accuracy.md#metrics), plus 'view' [M] each sample's view index."""
    out = {f: np.concatenate([p[f] for p in parts]) for f in fields}
    for f in ("rgb_a", "rgb_b"):
        if parts and all(f in p for p in parts):
            out[f] = np.concatenate([p[f] for p in parts])
    for f in ("energy", "clamp_removed"):
        if parts and all(f in p for p in parts):
            out[f] = np.sum([p[f] for p in parts], axis=0)
    out["view"] = np.concatenate([np.full(len(p["pix"]), i, np.int32) for i, p in enumerate(parts)])
    return out


def half_seeds(seed: int) -> tuple[int, int]:
    """Seeds of a held-out view's two independent halves (disjoint sampler streams)."""
    return seed, seed ^ 0x800000  # seeds are < 2**24: bit 23 differs


def render_view(renderer: Renderer, center, radius, view_id: int, *, validation: bool) -> dict:
    """One view's samples (arrays of FIELDS) plus image size; deterministic in (seed, view, split)."""
    s = renderer.s
    split_seed = 1 if validation else 0
    rng = np.random.default_rng([s.seed, split_seed, view_id])
    cam_dir = unit_sphere(rng, 1, s.upper_hemisphere)[0]
    dist = s.distance * radius
    eye = np.asarray(center, np.float64) + dist * cam_dir
    half_fov = float(np.arcsin(min(1.0 / max(s.distance, 1.0 + 1e-6), 0.999))) * 1.04
    res = (s.val_res or s.res) if validation else s.res
    o, d = camera_rays(eye, np.asarray(center, np.float64), half_fov, res)
    mask, x, n = renderer.hits(o, d)
    fiber = None
    if renderer.caster is not None:  # fibers: pixels where Mitsuba's curves and our prisms both are hit
        fiber, disagree, covered = agree(renderer.caster.hits(o, d), len(o), mask, mask)
        fiber.update(disagree=disagree, covered=covered)
        pix = fiber["pix"]
        x, n = fiber["x"], fiber["frame"]
        o, d = o[pix], d[pix]
    else:
        pix = np.nonzero(mask)[0]
        o, d, x, n = o[pix], d[pix], x[pix], n[pix]
    visibility = ((lambda o_, d_, w: renderer.caster.visibility(fiber, w)) if fiber is not None
                  else renderer.visibility)
    spp = s.val_spp if validation else s.spp
    seed = hash((s.seed, split_seed, view_id)) & 0xFFFFFF
    per_pixel = not validation and s.lights_per_view == 0
    stats: dict = {}
    halves = None
    if per_pixel and renderer.iso.per_path_lights:
        wi = unit_sphere(rng, len(pix), s.upper_hemisphere).astype(np.float32)
        vis = visibility(o, d, wi) if len(pix) else np.zeros(0, bool)
        rgb = renderer.transport(o, d, spp, seed=seed, wi=wi, stats=stats) if len(pix) else np.zeros((0, 3), np.float32)
    else:
        k = 1 if validation else (s.lights_per_view or FALLBACK_LIGHT_GROUPS)
        lights = unit_sphere(rng, k, s.upper_hemisphere)
        group = rng.integers(0, k, len(pix)) if k > 1 else np.zeros(len(pix), np.int64)
        wi = lights[group].astype(np.float32)
        vis = visibility(o, d, wi) if len(pix) else np.zeros(0, bool)
        rgb = np.zeros((len(pix), 3), np.float32)
        halves = [np.zeros((len(pix), 3), np.float32), np.zeros((len(pix), 3), np.float32)] if validation else None
        for g in range(k):
            sel = np.nonzero(group == g)[0]
            if len(sel) == 0:
                continue
            renderer.iso.set_light(lights[g])
            gseed = hash((s.seed, split_seed, view_id, g)) & 0xFFFFFF
            if validation:  # unclamped, two independent halves (spec/accuracy.md#metrics)
                for h, hs in enumerate(half_seeds(gseed)):
                    halves[h][sel] = renderer.transport(o[sel], d[sel], max(1, spp // 2), seed=hs, clamp=0.0)
                rgb[sel] = 0.5 * (halves[0][sel] + halves[1][sel])
            else:
                rgb[sel] = renderer.transport(o[sel], d[sel], spp, seed=gseed, stats=stats)
    out = {
        "x": x.astype(np.float32), "n": n.astype(np.float32), "wo": (-d).astype(np.float32), "wi": wi,
        "vis": vis.astype(np.uint8), "rgb": rgb, "pix": pix.astype(np.int32), "res": np.int32(res),
    }
    if fiber is not None:
        out.update(h=fiber["h"].astype(np.float32), disagree=np.int32(fiber["disagree"]), covered=np.int32(fiber["covered"]))
    if halves is not None:
        out["rgb_a"], out["rgb_b"] = halves
    else:
        out["energy"] = np.asarray(stats.get("energy", np.zeros(3)), np.float64)
        out["clamp_removed"] = np.asarray(stats.get("removed", np.zeros(3)), np.float64)
    return out


def settings_digest(scene_path: Path, shape_ids, settings: DataSettings, variant: str) -> dict:
    """What a dataset folder must agree on to be resumed."""
    h = hashlib.sha256()
    try:
        h.update(Path(scene_path).read_bytes())
    except OSError:
        pass
    return {
        "converter": CONVERTER_VERSION,
        "scene": str(Path(scene_path).resolve()),
        "scene_sha256": h.hexdigest(),
        "shapes": list(shape_ids),
        "settings": asdict(settings),
        "variant": variant,
    }


class DatasetDir:
    """A dataset folder (see module docstring)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)

    def prepare(self, meta: dict) -> None:
        """:meth:`claim` the folder for ``meta`` and make its ``train`` and ``val`` folders."""
        self.claim(meta)
        output_folder(self.root / "train", "bake's dataset folder")
        output_folder(self.root / "val", "bake's dataset folder")

    def claim(self, meta: dict) -> None:
        """Create the folder and record ``meta`` in ``meta.json``, or check that the one there matches (the Mitsuba
        variant aside): ``CONVERT_DATASET`` naming the keys that differ (another scene, other shapes or settings,
        another kind's folder), before anything in it is used or overwritten."""
        meta = json.loads(json.dumps(meta))  # as it reads back (tuples as lists)
        output_folder(self.root, "bake's dataset folder")
        mp = self.root / "meta.json"
        if mp.exists():
            try:
                old = json.loads(mp.read_text())
            except (OSError, ValueError):
                raise error("CONVERT_DATASET", "meta.json is unreadable", file=str(mp)) from None
            # the Mitsuba variant may differ between runs (fallback); everything else must match
            a = {k: v for k, v in old.items() if k != "variant"}
            b = {k: v for k, v in meta.items() if k != "variant"}
            if a != b:
                diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
                raise error("CONVERT_DATASET", f"dataset was made with other settings ({', '.join(diff)}); "
                            "use a new folder or the same settings", file=str(self.root))
        else:
            tmp = mp.with_suffix(".tmp")
            tmp.write_text(json.dumps(meta, indent=2, sort_keys=True))
            os.replace(tmp, mp)

    def path(self, split: str, i: int) -> Path:
        return self.root / split / f"{i:04d}.npz"

    def has(self, split: str, i: int) -> bool:
        return self.path(split, i).exists()

    def save(self, split: str, i: int, data: dict) -> None:
        p = self.path(split, i)
        tmp = p.with_name(p.stem + ".part.npz")
        try:
            np.savez(tmp, **data)
            os.replace(tmp, p)
        except OSError as exc:  # disk full, read-only folder: earlier views stay for --resume
            tmp.unlink(missing_ok=True)
            raise error("CONVERT_DATASET", f"cannot write view {i} ({exc.strerror or exc}); the views already written "
                        "are kept, --resume continues after freeing space", file=str(p)) from None

    def load(self, split: str, i: int) -> dict:
        p = self.path(split, i)
        try:
            with np.load(p, allow_pickle=False) as z:
                return {k: z[k] for k in z.files}
        except Exception as exc:
            raise error("CONVERT_DATASET", f"view file unreadable ({type(exc).__name__})", file=str(p)) from None

    def load_split(self, split: str, count: int) -> dict:
        """All views of a split concatenated (FIELDS; fibers also 'h') plus 'view' [M] view index, and where the views
        have them the mask statistics 'disagree' and 'covered' (pixels, summed over the views)."""
        parts = [self.load(split, i) for i in range(count)]
        fiber = bool(parts) and all("h" in p for p in parts)
        out = concat_views(parts, FIBER_FIELDS if fiber else FIELDS)
        if parts and all("disagree" in p for p in parts):
            out["disagree"] = int(sum(int(p["disagree"]) for p in parts))
            out["covered"] = int(sum(int(p["covered"]) for p in parts))
        return out
