"""Subsurface-only ground truth for the ``neupress`` kind, rendered by Mitsuba (spec/bake-neupress.md#data).

Per view: a pinhole camera on a sphere around the asset looks at its centre; one primary ray per pixel
centre. For every pixel whose ray hits the asset boundary at x_o (shading normal n, w_o towards the
camera) we estimate

    S(x_o, w_o, w_i) = radiance leaving x_o towards w_o per unit irradiance of a distant light from w_i,
                       **without** the light reflected at x_o itself

with ``scene.IsolatedAsset``'s ``volpath`` integrator (``volpathmis`` for a chromatic medium): the first
boundary interaction samples the boundary BSDF's
**transmission lobe only** (``BSDFContext.type_mask = Transmission``, so the path weight is the
transmitted part (1 - F) G ... of the rough dielectric), and the refracted ray continues inside the
boundary's interior medium (``integrator.sample(..., medium=interior)``): volume scattering, the inner
objects, internal reflections and refraction out (with next-event estimation through the rough
boundary) are all ordinary path tracing. The excluded external reflection is the analytic GGX term the
asset stores (``core/boundary``). Light directions are uniform over the **full sphere**, an independent
one per pixel (the per-path directional emitter of ``scene.IsolatedAsset``). Held-out views use one
light per view at more samples per pixel, **unclamped**, in two independent halves (``rgb_a``,
``rgb_b``; ``rgb`` their mean; spec/accuracy.md#metrics). Training targets are unclamped by default;
with a clamp, each training view records the energy it removed (``energy``, ``clamp_removed``).

Storage: ``DatasetDir`` folders (``meta.json`` + one atomic ``.npz`` per view), so an interrupted bake
resumes at the first missing view.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nasset_sdk.errors import error

from .dataset import account_clamp, camera_rays, concat_views, half_seeds, unit_sphere
from .scene import ggx_dielectric

FIELDS = ("x", "n", "wo", "wi", "rgb", "pix")


@dataclass(frozen=True)
class NeupressDataSettings:
    views: int = 64
    val_views: int = 4
    res: int = 64
    spp: int = 16
    val_res: int = 48
    val_spp: int = 512
    distance: float = 2.6  # camera distance in bounding-sphere radii
    clamp: float = 0.0  # per-path-sample radiance clamp (1/sr) of training views; 0: none (spec/accuracy.md)
    max_depth: int = 64
    seed: int = 0
    chunk: int = 1 << 19  # rays (pixels x spp) per Mitsuba call


def boundary_of(mi, shapes, file: str = "") -> tuple[list, float, float]:
    """(boundary shapes, eta, alpha) of an asset: its rough-dielectric shapes, which must hold an interior medium.

    Raises CONVERT_SHAPE_UNSUPPORTED when no shape has a rough dielectric BSDF (a smooth dielectric cannot be
    reached by the delta lights of the training data: spec/bake-neupress.md#inputs)."""
    out, params = [], []
    for s in shapes:
        text = str(s.bsdf())
        if text.startswith("RoughDielectric"):
            eta, alpha = ggx_dielectric(mi, s, kind="neupress", file=file)
            if s.interior_medium() is None:
                raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {s.id()!r}: a neupress boundary needs an interior medium",
                            file=file)
            out.append(s)
            params.append((eta, alpha))
        elif text.startswith(("SmoothDielectric", "Dielectric", "ThinDielectric")):
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {s.id()!r}: smooth dielectric boundary; neupress bakes need a "
                        "roughdielectric (GGX) boundary, which distant delta lights reach", file=file)
    if not out:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"no asset shape among {[s.id() for s in shapes]} has a roughdielectric "
                    "BSDF with an interior medium: neupress needs a refractive boundary", file=file)
    if len({id(s.interior_medium()) for s in out}) > 1:
        raise error("CONVERT_SHAPE_UNSUPPORTED", "boundary shapes have different interior media; bake them as separate assets",
                    file=file)
    if len({p for p in params}) > 1:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"boundary shapes have different (eta, alpha) {params}; the format stores one",
                    file=file)
    return out, params[0][0], params[0][1]


class SubsurfaceRenderer:
    """Mitsuba queries on an IsolatedAsset: primary hits and subsurface-only transport (see module doc)."""

    def __init__(self, mi, iso, settings: NeupressDataSettings, medium) -> None:
        """``medium``: the boundary's interior medium (where every refracted first ray starts)."""
        self.medium = medium
        if not iso.per_path_lights:
            raise error("CONVERT_BACKEND", "neupress bakes need a JIT Mitsuba variant (llvm_ad_rgb) for per-path lights")
        self.mi, self.iso, self.s = mi, iso, settings

    @staticmethod
    def _bucket(n: int) -> int:
        b = 4096
        while b < n:
            b *= 2
        return b

    @staticmethod
    def _pad(a: np.ndarray, size: int) -> np.ndarray:
        if len(a) == size:
            return a
        pad = np.repeat(a[-1:], size - len(a), axis=0) if len(a) else np.zeros((size,) + a.shape[1:], a.dtype)
        return np.concatenate([a, pad])

    def _ray(self, o, d):
        """Rays from scene-frame origins ``o`` (moved into the isolated scenes' frame, IsolatedAsset.origin)."""
        mi = self.mi
        o = np.ascontiguousarray(self.iso.to_render(o), np.float32)
        d = np.ascontiguousarray(d, np.float32)
        return mi.Ray3f(mi.Point3f(o[:, 0], o[:, 1], o[:, 2]), mi.Vector3f(d[:, 0], d[:, 1], d[:, 2]))

    @staticmethod
    def _np3(v) -> np.ndarray:
        import drjit as dr

        dr.eval(v)
        return np.stack([np.asarray(v.x), np.asarray(v.y), np.asarray(v.z)], axis=1)

    def hits(self, o, d):
        """(mask [N], x [N,3], n [N,3]) of primary rays against the asset's shapes."""
        import drjit as dr

        n = len(o)
        size = self._bucket(n)
        si = self.iso.geometry_scene.ray_intersect(self._ray(self._pad(o, size), self._pad(d, size)))
        valid = si.is_valid()
        dr.eval(valid, si.p, si.sh_frame.n)
        x = self.iso.to_scene(self._np3(si.p)[:n]).astype(np.float32)
        return np.asarray(valid, bool)[:n], x, self._np3(si.sh_frame.n)[:n].astype(np.float32)

    def transport(self, o, d, wi, spp: int, seed: int, *, clamp: float | None = None, stats: dict | None = None) -> np.ndarray:
        """Mean subsurface-only radiance [N,3] over ``spp`` paths per pixel; ``wi`` [N,3] each pixel's light.
        ``clamp``: per-path-sample clamp (default the settings'); ``stats`` accumulates the energy it removed."""
        mi = self.mi
        clamp = self.s.clamp if clamp is None else clamp
        scene = self.iso.lane_scene
        n = len(o)
        out = np.zeros((n, 3), np.float64)
        per = max(1, self.s.chunk // max(spp, 1))
        ctx = mi.BSDFContext()
        ctx.type_mask = mi.BSDFFlags.Transmission
        for s in range(0, n, per):
            e = min(n, s + per)
            m = (e - s) * spp
            size = self._bucket(m)
            oo = self._pad(np.repeat(o[s:e], spp, axis=0), size)
            dd = self._pad(np.repeat(d[s:e], spp, axis=0), size)
            self.iso.set_light_table(self._pad(np.asarray(wi[s:e], np.float32), self._bucket(e - s)))
            sampler = mi.load_dict({"type": "independent"})
            sampler.seed(int(seed * 7919 + s) & 0x7FFFFFFF, size)
            ray = self._ray(oo, dd)
            ray.time = mi.Float(self._pad(np.repeat(np.arange(e - s, dtype=np.float32), spp), size))
            si = scene.ray_intersect(ray)
            active = si.is_valid()
            bsdf = si.bsdf(mi.RayDifferential3f(ray))
            bs, weight = bsdf.sample(ctx, si, sampler.next_1d(active), sampler.next_2d(active), active)
            active &= (bs.pdf > 0) & (mi.Frame3f.cos_theta(bs.wo) < 0)  # refracted into the interior
            inner = si.spawn_ray(si.to_world(bs.wo))
            spec, _, _ = self.iso.integrator.sample(scene, sampler, mi.RayDifferential3f(inner), self.medium, active)
            L = self._np3(spec * weight)[:m].astype(np.float64).reshape(e - s, spp, 3)
            L = np.maximum(np.nan_to_num(L, nan=0.0, posinf=0.0, neginf=0.0), 0.0)
            raw = L.mean(axis=1)
            if clamp > 0:
                L = np.minimum(L, clamp)
            out[s:e] = L.mean(axis=1)
            account_clamp(stats, raw, out[s:e])
        return out.astype(np.float32)


def render_view(renderer: SubsurfaceRenderer, center, radius, view_id: int, *, validation: bool) -> dict:
    """One view's samples (arrays of FIELDS) plus image size; deterministic in (seed, view, split)."""
    s = renderer.s
    split_seed = 1 if validation else 0
    rng = np.random.default_rng([s.seed, split_seed, view_id, 77])
    cam_dir = unit_sphere(rng, 1, False)[0]
    eye = np.asarray(center, np.float64) + s.distance * radius * cam_dir
    half_fov = float(np.arcsin(min(1.0 / max(s.distance, 1.0 + 1e-6), 0.999))) * 1.04
    res = s.val_res if validation else s.res
    o, d = camera_rays(eye, np.asarray(center, np.float64), half_fov, res)
    mask, x, n = renderer.hits(o, d)
    pix = np.nonzero(mask)[0]
    o, d, x, n = o[pix], d[pix], x[pix], n[pix]
    if validation:  # one light for the whole view
        wi = np.repeat(unit_sphere(rng, 1, False), len(pix), axis=0).astype(np.float32)
    else:  # the full sphere, an independent direction per pixel
        wi = unit_sphere(rng, len(pix), False).astype(np.float32)
    spp = s.val_spp if validation else s.spp
    seed = (s.seed * 1_000_003 + split_seed * 10_007 + view_id) & 0xFFFFFF
    extra: dict = {}
    if not len(pix):
        rgb = np.zeros((0, 3), np.float32)
        extra = {"rgb_a": rgb, "rgb_b": rgb} if validation else {"energy": np.zeros(3), "clamp_removed": np.zeros(3)}
    elif validation:  # unclamped, two independent halves (spec/accuracy.md#metrics)
        a, b = (renderer.transport(o, d, wi, max(1, spp // 2), hs, clamp=0.0) for hs in half_seeds(seed))
        rgb, extra = 0.5 * (a + b), {"rgb_a": a, "rgb_b": b}
    else:
        stats: dict = {}
        rgb = renderer.transport(o, d, wi, spp, seed, stats=stats)
        extra = {"energy": np.asarray(stats.get("energy", np.zeros(3))), "clamp_removed": np.asarray(stats.get("removed", np.zeros(3)))}
    return {"x": x, "n": n, "wo": (-d).astype(np.float32), "wi": wi, "rgb": rgb, "pix": pix.astype(np.int32),
            "res": np.int32(res), **extra}


def load_split(store, split: str, count: int) -> dict:
    """All views of a split of a ``DatasetDir`` concatenated (FIELDS) plus 'view' [M] view index."""
    parts = [store.load(split, i) for i in range(count)]
    missing = [f for f in FIELDS if parts and f not in parts[0]]
    if missing:
        raise error("CONVERT_DATASET", f"view files lack {missing}: not a neupress dataset", file=str(store.root))
    return concat_views(parts, FIELDS)
