"""``nasset bench 8dna``: near-field light, 8D flow vs 6D far-field baseline vs path tracing (8DNA paper Tables 1-2).

Scene: the built-in translucent example (:mod:`.eightdna_example`), the asset lit by a small sphere
light 0.16 m from its surface, black background. One run produces:

* **reference**: Mitsuba ``volpath`` (``llvm_ad_rgb``) of the original scene at ``--gt-spp``, in
  independent chunks (its own noise, estimated from the disagreement of two halves, is subtracted
  from every MSE);
* **path tracing**: Mitsuba at ``--spp`` (128), timed after a warm-up render at the same spp;
* **8dna**: the baked 8D asset, and **far-field**: the 6D baseline baked from the same sampler and
  settings (spec/bake-8dna.md#far-field), both rendered by :class:`NearFieldRenderer` at ``--spp``.

Table 1 is the MSE of each against the reference (and, with ``--converged-spp N``, the neural
renders' MSE and bias² = MSE - own variance at N spp: the model error); Table 2 the mean per-pixel
variance of the ``--spp`` estimate and the render time. ``--example heterogeneous`` runs the
grid-medium variant of the example. Variance: Mitsuba's from two independent renders
(var = mean((a - b)^2) / 2); the neural renders' from their per-sample second moments.

:class:`NearFieldRenderer` is a bench-only single-vertex renderer for this scene type (one asset, one
sphere light, nothing else): camera ray -> asset hit x_o -> analytic direct lobe (light sample + GGX
sample, power heuristic) + the neural transport. 8D: one channel c uniform, (u_i, w_i) ~ p^c from the
flow, then at u_i the power heuristic between a light sample and the flow direction, against the
channel-mixture densities (as reference_renderer/shaders/eightdna.py). Far-field: the incident radiance
of every entry point is taken as the radiance arriving at x_o (the 6D assumption): light sample at
x_o and flow direction w_i ~ p6^c(w_i | x_o, w_o), power heuristic, no self-occlusion test (the 6D
transport already integrates the asset's self-shadowing over entry points). Both models run through
the same code, so their times compare; the 8D path also renders through ``nasset_reference_renderer``
(``--reference-renderer``) as a cross-check of the asset in the project's renderer.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from nasset_benchmarks.common import machine, open_given_asset, require_kind, save_figure
from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg, seed_arg
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import atomic_output, output_folder, write_text_atomic

QUICK = {"res": 32, "gt_spp": 512, "spp": 32, "size": "tiny", "converged_spp": 0}
PAPER = ("8DNA paper (Table 1): under near-field light the far-field baseline's MSE is several times 8DNA's; Table 2: "
         "8DNA at 128 spp has lower variance than path tracing on volumetric assets at 2-20x lower time.")


# ----------------------------------------------------------------------------------------
# camera and light geometry


def _unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-30)


def camera_rays(res: int, rng, camera: dict, pix: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jittered primary rays for pixels ``pix`` (default: every pixel once; row-major, y down): (origin, dir [N,3], pix [N])."""
    o = np.asarray(camera["origin"], np.float64)
    fwd = _unit((np.asarray(camera["target"], np.float64) - o)[None])[0]
    right = _unit(np.cross(fwd, np.asarray(camera["up"], np.float64))[None])[0]
    up = np.cross(right, fwd)
    tan = math.tan(math.radians(camera["fov"]) / 2)
    pix = np.arange(res * res) if pix is None else np.asarray(pix)
    py, px = np.divmod(pix, res)
    u = (px + rng.random(len(px))) / res
    v = (py + rng.random(len(py))) / res
    d = fwd[None] + ((2 * u - 1) * tan)[:, None] * right[None] + ((1 - 2 * v) * tan)[:, None] * up[None]
    return np.tile(o, (len(d), 1)), _unit(d), pix


class SphereLight:
    """Uniform sphere emitter: centre C, radius r, RGB radiance; sampled by the cone it subtends."""

    def __init__(self, center, radius, radiance) -> None:
        self.c = np.asarray(center, np.float64)
        self.r = float(radius)
        self.le = np.asarray(radiance, np.float64)

    def _cone(self, p):
        dc = self.c[None] - p
        dist = np.linalg.norm(dc, axis=1)
        sin2 = np.minimum((self.r / np.maximum(dist, 1e-12)) ** 2, 1.0)
        cos_max = np.sqrt(1 - sin2)
        return dc / np.maximum(dist, 1e-12)[:, None], dist, cos_max

    def sample(self, p, u2):
        """(w [N,3], distance to the surface [N], pdf per steradian [N]) from points p [N,3]."""
        axis, dist, cos_max = self._cone(p)
        cos_t = 1 - u2[:, 0] * (1 - cos_max)
        sin_t = np.sqrt(np.maximum(1 - cos_t ** 2, 0))
        phi = 2 * np.pi * u2[:, 1]
        from nasset_sdk.kinds.encodings import from_local

        w = _unit(from_local(np.stack([sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t], 1), axis))
        t = self.hit(p, w)
        return w, t, 1.0 / (2 * np.pi * np.maximum(1 - cos_max, 1e-12))

    def pdf(self, p, w):
        axis, _, cos_max = self._cone(p)
        inside = (w * axis).sum(1) >= cos_max
        return np.where(inside, 1.0 / (2 * np.pi * np.maximum(1 - cos_max, 1e-12)), 0.0)

    def hit(self, p, w):
        """Distance along w to the sphere (inf where missed)."""
        oc = p - self.c[None]
        b = (oc * w).sum(1)
        cc = (oc * oc).sum(1) - self.r ** 2
        disc = b * b - cc
        t = -b - np.sqrt(np.maximum(disc, 0))
        t = np.where(t > 0, t, -b + np.sqrt(np.maximum(disc, 0)))
        return np.where((disc >= 0) & (t > 0), t, np.inf)


def _power(a, b):
    a2, b2 = a * a, b * b
    s = a2 + b2
    return np.where(s > 0, a2 / np.where(s > 0, s, 1.0), 0.0)


class NearFieldRenderer:
    """The bench renderer (module docstring): one asset (8D or far-field evaluator) + one sphere light."""

    def __init__(self, mi, shapes, ev, light: SphereLight, *, far_field: bool) -> None:
        from nasset_converters.mitsuba.scene import scene_of

        self.mi = mi
        self.scene = scene_of(mi, list(shapes))
        self.ev = ev
        self.light = light
        self.far = bool(far_field)
        bb = self.scene.bbox()
        self.eps = 1e-5 * float(np.linalg.norm(np.array(bb.max) - np.array(bb.min)))
        self.network_s = 0.0

    def _rays(self, o, d):
        mi = self.mi
        return mi.Ray3f(mi.Point3f(np.ascontiguousarray(o.T, np.float32)), mi.Vector3f(np.ascontiguousarray(d.T, np.float32)))

    def intersect(self, o, d):
        import drjit as dr

        if not len(o):
            z = np.zeros((0, 3))
            return np.zeros(0, bool), np.zeros(0), z, z, z
        si = self.scene.ray_intersect(self._rays(o, d))
        valid = si.is_valid()
        dr.eval(si, valid)
        return (np.asarray(valid, bool), np.asarray(si.t, np.float64), np.asarray(si.p, np.float64).T,
                np.asarray(si.n, np.float64).T, np.asarray(si.sh_frame.n, np.float64).T)

    def occluded(self, o, d, tmax):
        t = self.intersect(o, d)[1]
        return t < tmax

    def _net(self, fn, *a):
        t = time.perf_counter()
        out = fn(*a)
        self.network_s += time.perf_counter() - t
        return out

    def shade(self, x, n, ng, wo, rng) -> np.ndarray:
        """Radiance [N,3] leaving asset points x towards wo (direct lobe + neural transport)."""
        ev, light = self.ev, self.light
        m = len(x)
        L = np.zeros((m, 3))
        ngf = np.where(((ng * wo).sum(1) < 0)[:, None], -ng, ng)
        xo = x + ngf * self.eps * 10
        # -- direct lobe: light sample + GGX sample, power heuristic
        wl, tl, pl = light.sample(xo, rng.random((m, 2)))
        f = ev.direct_eval(n, wo, wl)[:, 0].astype(np.float64)
        ok = (f > 0) & ((wl * ngf).sum(1) > 0) & np.isfinite(tl)
        k = np.nonzero(ok)[0]
        vis = ~self.occluded(xo[k], wl[k], tl[k])
        k = k[vis]
        w = _power(pl[k], ev.direct_pdf(n[k], wo[k], wl[k]))
        L[k] += light.le[None] * (f[k] * w / pl[k])[:, None]
        wd, pd = ev.direct_sample(n, wo, rng.random((m, 2)))
        fd = ev.direct_eval(n, wo, wd)[:, 0].astype(np.float64)
        td = light.hit(xo, wd)
        ok = (pd > 0) & (fd > 0) & np.isfinite(td) & ((wd * ngf).sum(1) > 0)
        k = np.nonzero(ok)[0]
        k = k[~self.occluded(xo[k], wd[k], td[k])]
        w = _power(pd[k], light.pdf(xo[k], wd[k]))
        L[k] += light.le[None] * (fd[k] * w / pd[k])[:, None]
        # -- neural transport
        alpha = self._net(ev.albedo, x, wo).astype(np.float64)
        if self.far:
            L += self._far_field(x, wo, alpha, rng)
        else:
            L += self._near_field(x, wo, alpha, rng)
        return L

    def _pdf_rgb_dir(self, x, wo, u, w):
        n = len(x)
        if not n:
            return np.zeros((0, 3))
        ch = np.repeat(np.arange(3), n)
        t3 = lambda a: np.concatenate([a, a, a])  # noqa: E731
        return self._net(self.ev.pdf_direction, t3(x), t3(wo), t3(u), t3(w), ch).reshape(3, n).T

    def _far_field(self, x, wo, alpha, rng):
        ev, light = self.ev, self.light
        m = len(x)
        L = np.zeros((m, 3))
        u_dummy = np.tile(ev.box.center + np.array([ev.box.half[0], 0.0, 0.0]), (m, 1))  # d12 = +X: flows 3-4 ignore it
        # light sample at x_o, no self-occlusion (6D assumption)
        wl, tl, pl = light.sample(x, rng.random((m, 2)))
        P = self._pdf_rgb_dir(x, wo, u_dummy, wl)
        q = P.mean(1)
        w = _power(pl, q)
        L += alpha * P * light.le[None] * (w / pl)[:, None]
        # flow direction
        ch = rng.integers(0, 3, m)
        wf, _ = self._net(lambda: ev.sample_direction(x, wo, u_dummy, ch, u=rng.random((m, 2))))
        tf = light.hit(x, wf)
        k = np.nonzero(np.isfinite(tf))[0]
        if len(k):
            P = self._pdf_rgb_dir(x[k], wo[k], u_dummy[k], wf[k])
            q = P.mean(1)
            w = _power(q, light.pdf(x[k], wf[k]))
            good = q > 0
            k, P, q, w = k[good], P[good], q[good], w[good]
            L[k] += alpha[k] * P * light.le[None] * (w / q)[:, None]
        return L

    def _near_field(self, x, wo, alpha, rng):
        ev, light = self.ev, self.light
        m = len(x)
        L = np.zeros((m, 3))
        ch = rng.integers(0, 3, m)
        u, wf, _ = self._net(lambda: ev.sample(x, wo, ch, u=rng.random((m, 4))))
        t3 = lambda a: np.concatenate([a, a, a])  # noqa: E731
        p_u = self._net(ev.pdf_position, t3(x), t3(wo), t3(u), np.repeat(np.arange(3), m)).reshape(3, m).mean(0)
        n_u = ev.box.face_normal(u)

        def backtrace_ok(k, w):
            hit, *_ = self.intersect(u[k] + w * self.eps, -w)
            return hit

        def pdf_rgb(k, w):
            if not len(k):
                return np.zeros((0, 3))
            ch3 = np.repeat(np.arange(3), len(k))
            return self._net(ev.pdf, t3(x[k]), t3(wo[k]), t3(u[k]), t3(w), ch3).reshape(3, len(k)).T

        # light sample at u_i
        wl, tl, pl = light.sample(u, rng.random((m, 2)))
        k = np.nonzero((p_u > 0) & ((n_u * wl).sum(1) > 0) & np.isfinite(tl))[0]
        k = k[~self.occluded(u[k] + wl[k] * self.eps, wl[k], tl[k])]
        k = k[backtrace_ok(k, wl[k])]
        P = pdf_rgb(k, wl[k])
        q = P.mean(1)
        w = _power(pl[k], q / p_u[k])
        L[k] += alpha[k] * P * light.le[None] * (w / (p_u[k] * pl[k]))[:, None]
        # flow direction at u_i
        tf = light.hit(u, wf)
        k = np.nonzero((p_u > 0) & ((n_u * wf).sum(1) > 0) & np.isfinite(tf))[0]
        k = k[~self.occluded(u[k] + wf[k] * self.eps, wf[k], tf[k])]
        k = k[backtrace_ok(k, wf[k])]
        P = pdf_rgb(k, wf[k])
        q = P.mean(1)
        good = q > 0
        k, P, q = k[good], P[good], q[good]
        w = _power(q / p_u[k], light.pdf(u[k], wf[k]))
        L[k] += alpha[k] * P * light.le[None] * (w / q)[:, None]
        return L

    def render(self, res: int, spp: int, camera: dict, seed: int = 0, batch: int = 1 << 16):
        """(image [res,res,3], per-pixel variance of the mean [res,res,3]) at spp samples per pixel.

        All res^2 x spp camera samples are processed in batches of ``batch`` rays (wavefront style)."""
        rng = np.random.default_rng(seed)
        s1 = np.zeros((res * res, 3))
        s2 = np.zeros((res * res, 3))
        allpix = np.repeat(np.arange(res * res), spp)
        for start in range(0, len(allpix), batch):
            o, d, pix = camera_rays(res, rng, camera, allpix[start:start + batch])
            hit, t, p, ng, ns = self.intersect(o, d)
            tl = self.light.hit(o, d)
            val = np.zeros((len(o), 3))
            on_light = tl < np.where(hit, t, np.inf)
            val[on_light] = self.light.le
            k = np.nonzero(hit & ~on_light)[0]
            if len(k):
                val[k] = self.shade(p[k], ns[k], ng[k], -d[k], rng)
            val = np.nan_to_num(val, nan=0.0, posinf=0.0, neginf=0.0)
            for c in range(3):
                s1[:, c] += np.bincount(pix, weights=val[:, c], minlength=res * res)
                s2[:, c] += np.bincount(pix, weights=val[:, c] ** 2, minlength=res * res)
        mean = s1 / spp
        var = np.maximum(s2 / spp - mean * mean, 0) / max(spp - 1, 1)
        return mean.reshape(res, res, 3), var.reshape(res, res, 3)


# ----------------------------------------------------------------------------------------
# the benchmark


def _mi_sensor(mi, res: int, camera: dict):
    return mi.load_dict({
        "type": "perspective", "fov": float(camera["fov"]), "fov_axis": "x",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(camera["origin"]), target=list(camera["target"]), up=list(camera["up"])),
        "film": {"type": "hdrfilm", "width": res, "height": res, "rfilter": {"type": "box"}, "pixel_format": "rgb"},
        "sampler": {"type": "independent"},
    })


def _mi_render(mi, scene, sensor, spp: int, seed: int) -> np.ndarray:
    return np.nan_to_num(np.asarray(mi.render(scene, sensor=sensor, spp=int(spp), seed=int(seed)), np.float64)[..., :3])


def _open(path):
    from nasset_sdk.asset import Asset

    a = Asset.open(path)
    a.load("all")
    return a


def check_given_asset(path, *, far_field: bool):
    """``--asset`` (far_field False) or ``--farfield``, checked before any bake or render: an existing, readable 8dna
    surface asset (CONVERT_ASSET_REFERENCE, BENCH_ASSET_KIND), and not the other model of the pair where its provenance
    says which it is (BENCH_ASSET_KIND: the 6D baseline given as the 8D asset, or the reverse). Its bounds are checked
    against the example's blob once the scene is loaded (:func:`nasset_benchmarks.accuracy.check_asset_fits`).
    Returns the asset, opened without its payloads, for that check."""
    flag = "--farfield" if far_field else "--asset"
    asset = open_given_asset(path, flag)
    require_kind(asset, path, ("8dna",), flag)
    model = str((asset.provenance or {}).get("model", ""))
    if model and model.startswith("6D") != far_field:
        want = "the 6D far-field baseline" if far_field else "an 8D asset"
        raise error("BENCH_ASSET_KIND", f"{flag}: {Path(path).name} holds the model '{model.split(' (')[0]}', not {want}",
                    file=str(path))
    return asset


def _reference_npz(path, res: int, light_center, example: str) -> tuple:
    """(reference [res, res, 3], its noise variance, its spp, its per-pixel noise [res, res, 3] or None for a file from
    before it was stored) of an earlier run (``--reference-npz``), made under the same light and example (a file from
    before they were stored holds the default light and example)."""
    from nasset_converters.mitsuba.eightdna_example import LIGHT_CENTER

    file = Path(path)
    try:
        with np.load(file, allow_pickle=False) as z:
            gt, var_gt, gt_spp = z["reference"].astype(np.float64), float(z["reference_noise_variance"]), int(z["reference_spp"])
            noise_map = z["reference_noise_map"].astype(np.float64) if "reference_noise_map" in z.files else None
            its_light = tuple(float(v) for v in z["light_center"]) if "light_center" in z.files else tuple(LIGHT_CENTER)
            its_example = str(z["example"]) if "example" in z.files else "default"
    except (OSError, KeyError, ValueError, TypeError) as exc:
        raise UsageError(f"--reference-npz {file}: not the images file of an earlier run ({exc})") from None
    if gt.shape != (res, res, 3):
        raise UsageError(f"--reference-npz {file} holds a {'x'.join(map(str, gt.shape[:2]))} image, not {res}x{res}")
    if not np.isfinite(gt).all() or not math.isfinite(var_gt) or gt_spp < 1:
        raise UsageError(f"--reference-npz {file}: its reference is not finite")
    if noise_map is not None and (noise_map.shape != gt.shape or not np.isfinite(noise_map).all()):
        raise UsageError(f"--reference-npz {file}: its noise map is not finite or not {res}x{res}")
    if len(its_light) != 3 or not np.allclose(its_light, light_center, rtol=0, atol=1e-6) or its_example != example:
        raise UsageError(f"--reference-npz {file} is a reference of the {its_example} example under the light at "
                         f"{','.join(f'{v:g}' for v in its_light)}, not of the {example} example at "
                         f"{','.join(f'{v:g}' for v in light_center)}")
    return gt, var_gt, gt_spp, noise_map


def light_arg(text: str) -> tuple:
    """argparse type of ``--light X,Y,Z``: :func:`check_light` of the comma-separated numbers, refused as argparse's
    usage error (exit 2) before any work."""
    import argparse

    try:
        return check_light(text.split(","))
    except UsageError as exc:
        raise argparse.ArgumentTypeError(exc.message) from None


def check_light(center) -> tuple:
    """``center`` as three finite floats (m), outside the blob's box by more than the lamp's radius (USAGE otherwise:
    the near-field renderer and the bench assume the lamp outside the object)."""
    from nasset_converters.mitsuba.eightdna_example import LIGHT_RADIUS, blob_mesh

    try:
        c = tuple(float(v) for v in center)
    except (TypeError, ValueError):
        raise UsageError(f"--light must be three numbers X,Y,Z, got {center!r}") from None
    if len(c) != 3 or not all(math.isfinite(v) for v in c):
        raise UsageError(f"--light must be three finite numbers X,Y,Z, got {center!r}")
    lo, hi = blob_mesh().bounds
    gap = float(np.linalg.norm(np.maximum(np.maximum(lo - c, np.asarray(c) - hi), 0.0)))
    if gap <= LIGHT_RADIUS:
        raise UsageError(f"--light {','.join(f'{v:g}' for v in c)}: the lamp (radius {LIGHT_RADIUS} m) must lie outside "
                         f"the blob's box {np.round(lo, 3).tolist()} .. {np.round(hi, 3).tolist()}")
    return c


def blob_pixels(mi, mscene, sensor, res: int, sub: int = 4) -> np.ndarray:
    """[res, res] bool: the pixels whose ``sub`` x ``sub`` camera rays all hit the blob first (not the lamp, not
    the background), so that figures over them hold neither the lamp's edge nor a silhouette."""
    n = res * sub
    ij = np.stack(np.meshgrid(np.arange(n), np.arange(n), indexing="xy"), -1).reshape(-1, 2)
    pos = mi.Point2f(*((ij + 0.5) / n).T.astype(np.float32))
    rays, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    si = mscene.ray_intersect(rays)
    hit = np.asarray(si.is_valid(), bool) & ~np.asarray(si.shape.is_emitter(), bool)
    return hit.reshape(res, sub, res, sub).transpose(0, 2, 1, 3).reshape(res, res, sub * sub).all(-1)


def blob_figures(img, var, gt, noise_map, blob) -> dict:
    """Over the ``blob`` pixels of a render ``img`` (its per-pixel variance ``var``) against the reference ``gt``:
    the energy ratio per channel and the bias² (MSE minus the render's variance and the reference's own noise over
    those pixels; None where the reference's noise map is unknown, then ``mse_minus_variance`` holds it)."""
    if not blob.any():
        return {"pixels": 0}
    e, g = np.asarray(img)[blob], gt[blob]
    mse_var = float(np.mean((e - g) ** 2) - np.mean(np.asarray(var)[blob]))
    return {"pixels": int(blob.sum()), "energy": (e.sum(0) / np.maximum(g.sum(0), 1e-30)).tolist(),
            "mse_minus_variance": mse_var,
            "bias2": None if noise_map is None else mse_var - float(np.mean(noise_map[blob]))}


def bench_8dna(out_dir, *, asset=None, farfield=None, size: str = "small", res: int = 64, spp: int = 128, gt_spp: int = 4096,
               seed: int = 0, reference_renderer_spp: int = 0, reference_npz=None, converged_spp: int = 0,
               example: str = "default", light=None, quiet: bool = False) -> dict:
    """Run the benchmark; writes ``bench_8dna.json``, ``bench_8dna.md`` and ``8dna_*.png`` into ``out_dir``.

    ``light``: the sphere light's centre (x, y, z in m; default the example's LIGHT_CENTER), outside the blob's box by
    more than its radius (USAGE otherwise). Figures over the blob's own pixels (:func:`blob_pixels`) are reported
    beside the image-wide ones: where the lamp is in view its edge pixels dominate those."""
    from nasset_bakers.mitsuba.eightdna import bake
    from nasset_benchmarks.accuracy import check_asset_fits
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.eightdna_example import CAMERA, EXAMPLE_ASSET_IDS, LIGHT_CENTER, LIGHT_RADIANCE, LIGHT_RADIUS, write_example_scene

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    out = Path(out_dir)
    if res < 4 or spp < 2 or gt_spp < 2:
        raise UsageError("--res must be >= 4 and --spp, --gt-spp >= 2")
    if example not in ("default", "heterogeneous"):
        raise UsageError(f"--example must be default or heterogeneous, got {example!r}")
    light_center = check_light(LIGHT_CENTER if light is None else light)
    # what was given is checked before anything is baked or rendered
    checked = {}  # path -> the asset opened for the checks (opened once)
    for path, ff in ((asset, False), (farfield, True)):
        if path is not None:
            checked[Path(path)] = check_given_asset(path, far_field=ff)
    asset, farfield = (None if p is None else Path(p) for p in (asset, farfield))
    stored = None if reference_npz is None else _reference_npz(reference_npz, res, light_center, example)
    output_folder(out)  # created once what was given is known to be usable
    t_all = time.perf_counter()
    setup: dict[str, float] = {}
    mi = load_mitsuba()
    mi.set_log_level(mi.LogLevel.Error)
    xml = write_example_scene(out / "scene", res=res, heterogeneous=example == "heterogeneous", light_center=light_center)
    mscene = mi.load_file(str(xml))
    for flag, path in (("--asset", asset), ("--farfield", farfield)):  # a given asset of another object: not the blob's bounds
        if path is not None:
            check_asset_fits(mi, mscene, {sid: path for sid in EXAMPLE_ASSET_IDS}, scene_file=str(xml), flag=flag,
                             opened=checked)
    bakes = {}
    for name, path, ff in (("8dna", asset, False), ("far-field", farfield, True)):
        if path is None:
            tag = "" if example == "default" else f"_{example}"
            path = out / f"blob{tag}_{size}{'_farfield' if ff else ''}.usdc"
            if not path.is_file():
                say(f"baking the example ({name}, {size}) -> {path}")
                t = time.perf_counter()
                bakes[name] = bake(None, None, path, size=size, example=example, seed=seed, far_field=ff, quiet=quiet,
                                   summary_stream=sys.stderr)
                setup[f"bake_{name}_s"] = time.perf_counter() - t
        if name == "8dna":
            asset = Path(path)
        else:
            farfield = Path(path)

    sensor = _mi_sensor(mi, res, CAMERA)
    shapes = [s for s in mscene.shapes() if s.id() in EXAMPLE_ASSET_IDS]
    light = SphereLight(light_center, LIGHT_RADIUS, LIGHT_RADIANCE)
    blob = blob_pixels(mi, mscene, sensor, res)

    # reference (or the one an earlier run stored, for the same resolution)
    t = time.perf_counter()
    if stored is not None:
        gt, var_gt, gt_spp, noise_map = stored
        say(f"reference: {reference_npz} ({gt_spp} spp)")
    else:
        say(f"reference: Mitsuba {mi.variant()} volpath {gt_spp} spp at {res}x{res}")
        chunks = max(2, math.ceil(gt_spp / 256))
        per = max(1, gt_spp // chunks)
        imgs = []
        for k in range(chunks):
            imgs.append(_mi_render(mi, mscene, sensor, per, 1000 + k))
            if k % 8 == 7:
                say(f"  reference chunk {k + 1}/{chunks} {time.perf_counter() - t:.0f}s")
        gt = np.mean(imgs, 0)
        h = chunks // 2
        noise_map = (np.mean(imgs[:h], 0) - np.mean(imgs[h:2 * h], 0)) ** 2 / 4.0  # per pixel and channel, two halves
        var_gt = float(np.mean(noise_map))
    setup["reference_s"] = time.perf_counter() - t

    rows = {}
    # path tracing
    _mi_render(mi, mscene, sensor, spp, 50_000)
    t = time.perf_counter()
    pt = _mi_render(mi, mscene, sensor, spp, 11)
    dt = time.perf_counter() - t
    pt2 = _mi_render(mi, mscene, sensor, spp, 12)
    rows["path tracing (Mitsuba volpath)"] = {"image": pt, "time_s": dt, "variance": float(np.mean((pt - pt2) ** 2) / 2.0)}
    say(f"  path tracing {spp} spp: {dt:.2f}s")
    # neural
    evs = {}
    for name, path, ff in (("8dna (8D, ours)", asset, False), ("far-field (6D baseline)", farfield, True)):
        ev = _open(path).evaluator()
        evs[name] = ev
        r = NearFieldRenderer(mi, shapes, ev, light, far_field=ff)
        r.render(8, 1, CAMERA, seed=99)  # warm-up (onnxruntime first-run allocations)
        r.network_s = 0.0
        t = time.perf_counter()
        img, var = r.render(res, spp, CAMERA, seed=seed + 5)
        dt = time.perf_counter() - t
        rows[name] = {"image": img, "time_s": dt, "variance": float(var.mean()), "network_s": r.network_s}
        say(f"  {name} {spp} spp: {dt:.2f}s")
        if converged_spp > spp:  # Table 1 also at many spp: the model's own (bias) error, little noise left
            img_c, var_c = r.render(res, converged_spp, CAMERA, seed=seed + 17)
            rows[name]["converged"] = {"spp": converged_spp, "variance": float(var_c.mean()),
                                       "mse": float(np.mean((img_c - gt) ** 2)) - var_gt,
                                       "blob": blob_figures(img_c, var_c, gt, noise_map, blob)}
            say(f"  {name} {converged_spp} spp (converged error): MSE {rows[name]['converged']['mse']:.3e}")
    if reference_renderer_spp > 0:
        rows["8dna in reference_renderer"] = _reference_renderer(out, xml, asset, res, reference_renderer_spp, seed, say)

    table = []
    pt_name = "path tracing (Mitsuba volpath)"
    for name, r in rows.items():
        mse_raw = float(np.mean((r["image"] - gt) ** 2))
        table.append({"method": name, "spp": r.get("spp", spp), "mse": mse_raw - var_gt, "mse_raw": mse_raw,
                      "variance": r["variance"], "bias2_estimate": mse_raw - var_gt - r["variance"], "time_s": r["time_s"],
                      "network_s": r.get("network_s"), "mean_radiance": float(r["image"].mean()), "converged": r.get("converged")})
    # path tracing is unbiased: MSE = V / spp and time ~ spp, so its equal-error spp and time follow from its point
    pt = table[0]
    assert pt["method"] == pt_name
    for t in table[1:]:
        if t["mse"] > var_gt and pt["mse"] > var_gt:  # below the reference's own noise there is no meaningful ratio
            spp_eq = pt["spp"] * pt["mse"] / t["mse"]
            t["path_tracing_equal_error"] = {"spp": spp_eq, "time_s": pt["time_s"] * spp_eq / pt["spp"],
                                             "speedup": pt["time_s"] * spp_eq / pt["spp"] / t["time_s"]}
    mask = gt.max(-1) > 0
    report = {
        "benchmark": "8dna",
        "scene": f"built-in translucent example ({example}) + small sphere light (converters/mitsuba/eightdna_example.py)",
        "light": {"type": "sphere", "center": list(light_center), "radius_m": LIGHT_RADIUS, "radiance": list(LIGHT_RADIANCE)},
        "assets": {"8dna": str(asset), "far_field": str(farfield)},
        "asset_sizes": {k: _prov(p) for k, p in (("8dna", asset), ("far_field", farfield))},
        "resolution": [res, res], "spp": spp,
        "reference": {"spp": gt_spp, "noise_variance": var_gt, "mean_radiance": float(gt.mean()),
                      "lit_pixel_fraction": float(mask.mean()), "blob_pixels": int(blob.sum()),
                      "noise_variance_blob": None if noise_map is None else float(np.mean(noise_map[blob]))},
        "mitsuba": {"version": mi.__version__, "variant": mi.variant()},
        "table": table,
        "timing_includes": {"path tracing": "one mi.render call + readback, after a warm-up render at the same spp",
                            "neural": "one NearFieldRenderer.render call (Mitsuba ray casts, numpy shading, onnxruntime "
                                      "networks), after asset load, session creation and a warm-up render"},
        "machine": machine(),
        "setup_times_s": {**{k: round(v, 2) for k, v in setup.items()}, "total_s": round(time.perf_counter() - t_all, 2)},
        "bake_summaries": bakes or None,
        "paper": PAPER,
    }
    report["files"] = [str(out / n) for n in ("bench_8dna.json", "bench_8dna.md", "8dna_images.png", "8dna_tables.png")]
    _plots(out, gt, rows, table, spp)
    write_text_atomic(out / "bench_8dna.json", json.dumps(report, indent=2))
    write_text_atomic(out / "bench_8dna.md", summary_markdown(report))
    with atomic_output(out / "bench_8dna_images.npz", "images file") as tmp:  # reused as --reference-npz: never half written
        maps = {} if noise_map is None else {"reference_noise_map": noise_map.astype(np.float32)}
        np.savez_compressed(tmp, reference=gt.astype(np.float32), reference_spp=gt_spp, reference_noise_variance=var_gt,
                            light_center=np.asarray(light_center, np.float64), example=np.asarray(example), **maps,
                            **{f"img{k}": r["image"].astype(np.float32) for k, r in enumerate(rows.values())})
    return report


def _reference_renderer(out, xml, asset, res, spp, seed, say) -> dict:
    """The 8D asset through nasset_reference_renderer (USD scene from the Mitsuba XML via convert-scene)."""
    import warnings

    from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS
    from nasset_converters.mitsuba.usd_export import convert_scene
    from nasset_reference_renderer import RenderSettings, load_scene, render
    from nasset_reference_renderer.integrator import prepare_assets
    from nasset_reference_renderer.plan import make_plan
    from nasset_reference_renderer.scene import SceneWarning

    conv = convert_scene(xml, out / "scene" / "scene_neural.usda", replace={sid: asset for sid in EXAMPLE_ASSET_IDS},
                         check_usd=False)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(str(conv.output))
    base = RenderSettings(spp=1, seed=seed, width=res, height=res, max_depth=2)
    plan = make_plan(scene, width=res, height=res, spp=1, max_depth=2, tile=base.tile, batch=base.batch)
    prepare_assets(scene, plan, base)
    render(scene, base)
    s = RenderSettings(spp=spp, seed=seed + 7, width=res, height=res, max_depth=2)
    t = time.perf_counter()
    result = render(scene, s)
    dt = time.perf_counter() - t
    say(f"  reference_renderer 8dna {spp} spp: {dt:.2f}s")
    return {"image": np.nan_to_num(np.asarray(result.image, np.float64)[..., :3]), "time_s": dt,
            "variance": float(np.mean(result.variance)), "spp": spp}


def _prov(path) -> dict | None:
    try:
        from nasset_sdk.asset import Asset

        a = Asset.open(path, load="none")
        p = a.provenance or {}
        return {"size": p.get("size"), "model": p.get("model"), "bytes": Path(path).stat().st_size,
                "steps": (p.get("training") or {}).get("steps"), "train_s": (p.get("timings_s") or {}).get("train_s")}
    except Exception:  # noqa: BLE001 - informative only
        return None


def _tonemap(img, scale):
    return np.clip((np.maximum(img, 0) / scale) ** (1 / 2.2), 0, 1)


def _plots(out: Path, gt, rows: dict, table: list, spp: int) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    scale = max(float(np.percentile(gt, 99.5)), 1e-6)
    names = list(rows)
    fig, ax = plt.subplots(2, len(names) + 1, figsize=(3.0 * (len(names) + 1), 6.2), dpi=110)
    ax[0, 0].imshow(_tonemap(gt, scale))
    ax[0, 0].set_title("Mitsuba reference", fontsize=8)
    errs = [np.abs(r["image"] - gt).mean(-1) for r in rows.values()]
    emax = max(float(np.percentile(np.concatenate([e.ravel() for e in errs]), 99)), 1e-6)
    ax[1, 0].axis("off")
    ax[1, 0].text(0.0, 0.5, f"|error| (mean over RGB)\ncolour scale 0..{emax:.3g}", fontsize=8)
    for k, (name, r) in enumerate(rows.items()):
        row = table[k]
        ax[0, k + 1].imshow(_tonemap(r["image"], scale))
        ax[0, k + 1].set_title(f"{name}\n{row['spp']} spp, {row['time_s']:.1f}s", fontsize=8)
        im = ax[1, k + 1].imshow(errs[k], cmap="inferno", vmin=0, vmax=emax)
        ax[1, k + 1].set_title(f"MSE {row['mse']:.2e}", fontsize=8)
    for a in ax.ravel():
        a.set_xticks([])
        a.set_yticks([])
    fig.colorbar(im, ax=ax[1, -1], fraction=0.046)
    fig.tight_layout()
    save_figure(fig, out / "8dna_images.png")
    plt.close(fig)
    fig, ax = plt.subplots(1, 3, figsize=(11, 3.4), dpi=110)
    labels = [t["method"].split(" (")[0] for t in table]
    colors = ["#4477aa", "#ee6677", "#228833", "#ccbb44"][: len(table)]
    for a, key, title in ((ax[0], "mse", f"Table 1: MSE vs reference at {spp} spp"), (ax[1], "variance", f"Table 2: variance at {spp} spp"),
                          (ax[2], "time_s", f"Table 2: time at {spp} spp (s)")):
        vals = [max(t[key], 1e-12) for t in table]
        width = 0.8
        if key == "mse" and any(t.get("converged") for t in table):
            width = 0.4
            conv = [max(t["converged"]["mse"] - t["converged"]["variance"], 1e-12) if t.get("converged") else np.nan for t in table]
            a.bar(np.arange(len(vals)) + 0.2, conv, width=width, color=colors, hatch="//", alpha=0.5,
                  label="bias² (many spp)")
            a.legend(fontsize=7)
        a.bar(np.arange(len(vals)) - (0.2 if width < 0.8 else 0), vals, width=width, color=colors)
        a.set_xticks(range(len(vals)))
        a.set_xticklabels(labels, rotation=20, fontsize=7)
        a.set_yscale("log")
        a.set_title(title, fontsize=9)
        a.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    save_figure(fig, out / "8dna_tables.png")
    plt.close(fig)


def summary_markdown(r: dict) -> str:
    lines = [
        f"# 8dna benchmark: near-field light ({r['resolution'][0]}x{r['resolution'][1]}, {r['spp']} spp)",
        "",
        f"Reference: Mitsuba {r['mitsuba']['variant']} volpath, {r['reference']['spp']} spp (noise variance "
        f"{r['reference']['noise_variance']:.2e}, subtracted from every MSE); mean radiance {r['reference']['mean_radiance']:.4f}.",
        "",
        "| method | spp | MSE (Table 1) | MSE / bias² at many spp (model error) | variance (Table 2) | time s (Table 2) "
        "| path tracing at equal MSE |",
        "|---|---|---|---|---|---|---|",
    ]
    for t in r["table"]:
        c = t.get("converged")
        conv = (f"{c['mse']:.3e} / {c['mse'] - c['variance']:.3e} ({c['spp']} spp)" if c else
                ("0 (unbiased)" if t["method"].startswith("path") else ""))
        eq = t.get("path_tracing_equal_error")
        eqs = f"{eq['spp']:.0f} spp, {eq['time_s']:.2f}s ({eq['speedup']:.2f}x)" if eq else ""
        lines.append(f"| {t['method']} | {t['spp']} | {t['mse']:.3e} | {conv} | {t['variance']:.3e} | {t['time_s']:.2f} | {eqs} |")
    ref = r["reference"]
    blob_rows = [(t["method"], t["converged"]["blob"]) for t in r["table"] if (t.get("converged") or {}).get("blob", {}).get("pixels")]
    if blob_rows:
        noise = ref.get("noise_variance_blob")
        lines += ["", f"Over the blob's {ref['blob_pixels']} pixels (all 4 x 4 sub-pixel rays hit it: no lamp, no silhouette; "
                  f"light at {', '.join(f'{v:g}' for v in r['light']['center'])}; reference noise there "
                  + (f"{noise:.2e}" if noise is not None else "unknown: an images file from before it was stored") + "):", "",
                  "| method | bias² over the blob | MSE − variance over the blob | energy % (R / G / B) |", "|---|---|---|---|"]
        for name, b in blob_rows:
            bias = "" if b.get("bias2") is None else f"{b['bias2']:.3e}"
            lines.append(f"| {name} | {bias} | {b['mse_minus_variance']:.3e} | "
                         + " / ".join(f"{100 * v:.1f}" for v in b["energy"]) + " |")
    m = r["machine"]
    lines += ["", "MSE: over all pixels and channels, minus the reference's own noise variance. Bias²: that MSE minus the "
              "render's own variance (the error left at infinite spp). Variance: mean per-pixel variance of the estimate. "
              "Path tracing at equal MSE: the spp and time Mitsuba needs to reach the method's MSE (unbiased: "
              "MSE = V / spp, time proportional to spp), and that time over the method's time (> 1: the method is faster); "
              "left blank where an MSE is below the reference's own noise variance.",
              "", f"Machine: {m['usable_cores']} usable cores, load average {m['load_avg'][0]:.1f} at the end (shared).",
              "Timing: " + "; ".join(f"{k}: {v}" for k, v in r["timing_includes"].items()), "", r["paper"], ""]
    return "\n".join(lines)


def summary_text(r: dict) -> str:
    return summary_markdown(r)


def add_args(p) -> None:
    """Options of ``nasset bench 8dna``."""
    p.add_argument("-o", "--output", default="bench_8dna", help="output folder (JSON, markdown, PNGs, scene)")
    p.add_argument("--example", default="default", choices=["default", "heterogeneous"],
                   help="the example's medium: homogeneous (default) or a density grid")
    p.add_argument("--asset", default=None, help="baked 8D asset of the example (default: bake one)")
    p.add_argument("--farfield", default=None, help="baked 6D far-field baseline of the example (default: bake one)")
    p.add_argument("--size", default=None, choices=["tiny", "small", "hq"], help="preset when baking (default small; tiny with --quick)")
    p.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=None, help="image width = height (default 64; 32 with --quick)")
    p.add_argument("--spp", type=count_arg(1, MAX_SPP), default=None, help="samples per pixel of the compared renders (default 128; 32 with --quick)")
    p.add_argument("--gt-spp", type=count_arg(2, MAX_SPP), default=None, help="reference spp (default 4096; 512 with --quick)")
    p.add_argument("--reference-renderer-spp", type=count_arg(0, MAX_SPP), default=0,
                   help="also render the 8D asset through reference_renderer at this spp (0: skip)")
    p.add_argument("--converged-spp", type=count_arg(0, MAX_SPP), default=None,
                   help="also render both neural assets at this spp for their model error (default 512; 0 with --quick)")
    p.add_argument("--reference-npz", default=None, help="reuse the reference image of an earlier run (its bench_8dna_images.npz)")
    p.add_argument("--light", type=light_arg, default=None, metavar="X,Y,Z",
                   help="the sphere light's centre in m (default 0.35,0.04,0.12, right of the blob; e.g. 0.25,-0.1,-0.25 "
                        "backlights it); outside the blob's box. Write --light=X,Y,Z when X is negative")
    p.add_argument("--quick", action="store_true",
                   help="tiny bakes and small renders, a few minutes (a smoke run: errors near the reference's noise)")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--json", action="store_true", help="print the report as JSON (progress is silenced)")


def run(args) -> int:
    """CLI entry: ``nasset bench 8dna ...``."""
    q = QUICK if args.quick else {}
    report = bench_8dna(args.output, asset=args.asset, farfield=args.farfield, size=args.size or q.get("size", "small"),
                        res=args.res or q.get("res", 64), spp=args.spp or q.get("spp", 128),
                        gt_spp=args.gt_spp or q.get("gt_spp", 4096), seed=args.seed,
                        reference_renderer_spp=args.reference_renderer_spp, reference_npz=args.reference_npz,
                        converged_spp=args.converged_spp if args.converged_spp is not None else q.get("converged_spp", 512),
                        example=args.example, light=args.light, quiet=args.json)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(summary_text(report))
        print("wrote " + ", ".join(report["files"]))
    return 0
