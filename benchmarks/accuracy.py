"""``nasset bench accuracy``: a baked asset in its own scene against unbiased ground truth from the source renderer.

spec/accuracy.md#in-scene-accuracy. For a Mitsuba 3 scene and ``--replace ID[,ID]=ASSET``:

* **reference**: the original scene rendered by Mitsuba (``llvm_ad_rgb``, the scene's own
  integrator, no clamp) at ``--spp`` in two independent halves (disjoint seeds), each the mean of
  chunks of at most ``CHUNK_SPP`` samples;
* **estimate**: the scene converted by ``nasset convert-scene --replace`` (the asset in place of the
  shapes) rendered by the reference renderer at ``--nr-spp``, its own variance of the mean kept;
* **mask**: the asset's pixels *from the source renderer*: Mitsuba's own camera rays (the scene
  sensor's ``sample_ray`` at ``MASK_SUBSAMPLES``² stratified positions per pixel) intersected with
  the original scene; a sub-sample counts when the first shape it hits is one of the replaced
  shapes; a pixel belongs to the mask when at least half of its sub-samples do;
* **figures** (nasset_sdk.metrics, spec/accuracy.md#metrics): per-channel energy ratio with its
  standard error, PSNR with the reference's noise ceiling, bias-corrected MSE, HDR-FLIP, over the
  mask (and, for context, over the whole image).

For a Blender ``.blend`` and ``--replace OBJECT=ASSET`` the same, with Cycles (CPU, box filter,
no clamps, the scene's own bounce limit B for every bounce type) rendering the reference halves
through the scene's camera, and the mask from Cycles: the film's alpha on a transparent film with
every other object a holdout (``MASK_SUBSAMPLES``² samples per pixel), i.e. the fraction of the
pixel's camera samples whose first visible surface is one of the replaced objects. The reference
renderer's depth defaults to the converted stage's ``nasset:maxDepth`` (B + 1, spec/bake-blender.md).

Writes ``reference.exr`` (+ ``reference_a.exr``, ``reference_b.exr``), ``neural.exr`` (+ ``neural_var.exr``, the
variance of its per-pixel mean),
``reference.png``, ``neural.png``, ``mask.png``, ``error.png`` (relative error over the mask,
blue = too dark, red = too bright), ``flip.png`` when FLIP is available, ``accuracy.json`` and
``accuracy.md``.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nasset_converters.mitsuba.scene import BOX_TOLERANCE, box_offset
from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg, seed_arg
from nasset_sdk.errors import UsageError, error, path_arg
from nasset_sdk.images import output_folder, write_text_atomic

from .common import camera_sensor

#: samples per Mitsuba render call (bounds memory; the halves are means of such chunks)
CHUNK_SPP = 256
#: stratified sub-samples per pixel side for the mask
MASK_SUBSAMPLES = 4
QUICK = {"res": 48, "spp": 512, "nr_spp": 16}
DEFAULT = {"res": 128, "spp": 8192, "nr_spp": 64}


def _say(quiet: bool):
    return (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))


def _bar(total: int, desc: str, quiet: bool):
    try:
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, unit="spp", disable=quiet, file=sys.stderr)
    except ImportError:  # pragma: no cover - tqdm is a dependency
        class _Null:
            def update(self, n):
                pass

            def close(self):
                pass

        return _Null()


def sensor_for(mi, scene, width: int, *, file: str = ""):
    """A box-filtered copy of the scene's camera (``common.camera_sensor``: perspective, thinlens or orthographic, as
    the converted stage has it) ``width`` wide at its film's aspect; returns (sensor, (height, width)).
    CONVERT_SCENE_LOAD when the scene has no such camera (none, ``radiancemeter``, ...): the benches compare images
    seen from the scene's camera."""
    sensors = scene.sensors()
    fw, fh = (int(v) for v in sensors[0].film().size()) if sensors else (1, 1)
    height = max(1, int(round(width * fh / max(fw, 1))))
    sensor = camera_sensor(mi, sensors[0], width, height) if sensors else None
    if sensor is None:
        kind = str(sensors[0]).split("[")[0].strip() if sensors else "none"
        raise error("CONVERT_SCENE_LOAD", f"the scene's camera ({kind}) is not a perspective, thinlens or orthographic "
                    "camera: the benches compare images seen from the scene's own camera; add a <sensor "
                    "type=\"perspective\">", file=str(file))
    return sensor, (height, int(width))


def render_halves(render, spp: int, seed: int = 0, *, desc: str, quiet: bool = False):
    """Two independent unclamped renders of ``spp // 2`` samples each (seeds disjoint), each the mean of
    chunks of at most CHUNK_SPP samples. ``render(n, seed) -> [H, W, 3]`` is one source-renderer call
    (NaN/Inf samples count as 0). Returns (half a, half b, samples per half)."""
    half = max(1, spp // 2)
    bar = _bar(2 * half, desc, quiet)
    out = []
    for h in range(2):
        acc, done, k = None, 0, 0
        while done < half:
            n = min(CHUNK_SPP, half - done)
            img = np.nan_to_num(np.asarray(render(n, 1_000_003 * (2 * seed + h) + k), np.float64)[..., :3],
                                nan=0.0, posinf=0.0, neginf=0.0)
            acc = img * n if acc is None else acc + img * n
            done, k = done + n, k + 1
            bar.update(n)
        out.append(acc / done)
    bar.close()
    return out[0], out[1], half


def scene_digest(scene_file) -> str:
    """sha256 of the scene XML and of the files it names (``filename`` values), for reusing a reference."""
    import hashlib
    import re

    path = Path(scene_file)
    h = hashlib.sha256()
    text = path.read_bytes()
    h.update(text)
    for name in sorted(set(re.findall(rb'name="filename"\s+value="([^"]+)"', text))):
        f = path.parent / name.decode("utf-8", "replace")
        h.update(name)
        if f.is_file():
            h.update(f.read_bytes())
    return h.hexdigest()


def cached_reference(out: Path, key: dict):
    """(a, b) from an earlier run in ``out`` with the same key (scene digest, size, spp, seed, Mitsuba), else None."""
    from nasset_reference_renderer.film import read_exr

    kp = out / "reference_key.json"
    try:
        if json.loads(kp.read_text()) != key:
            return None
        return (read_exr(out / "reference_a.exr").astype(np.float64), read_exr(out / "reference_b.exr").astype(np.float64))
    except (OSError, ValueError, RuntimeError):
        return None


def mitsuba_halves(mi, scene, sensor, hw, scene_file, out: Path, spp: int, seed: int, *, say, quiet: bool = False):
    """The unclamped two-half Mitsuba reference of ``scene`` seen by ``sensor`` (``hw``: [H, W]): reused from
    ``out`` when its reference_key.json equals this run's key (scene digest, size, spp, seed, Mitsuba),
    else rendered by :func:`render_halves` (the stale key removed; the caller writes the key once the
    halves are on disk). Returns (a, b, samples per half, key, reused)."""
    key = {"scene_sha256": scene_digest(scene_file), "size": list(hw), "spp": int(spp), "seed": int(seed),
           "mitsuba": f"{mi.__version__} {mi.variant()}", "chunk": CHUNK_SPP}
    cached = cached_reference(out, key)
    if cached is not None and cached[0].shape[:2] == tuple(hw):
        say(f"reference: reusing {out / 'reference_a.exr'} and reference_b.exr (same scene, size, spp, seed)")
        return cached[0], cached[1], max(1, spp // 2), key, True
    say(f"reference: Mitsuba {mi.variant()} {spp} spp at {hw[1]}x{hw[0]} in two halves, unclamped")
    a, b, half = render_halves(lambda n, s: mi.render(scene, sensor=sensor, spp=int(n), seed=int(s)), spp, seed,
                               desc="mitsuba reference", quiet=quiet)
    (out / "reference_key.json").unlink(missing_ok=True)
    return a, b, half, key, False


def object_mask(mi, scene, sensor, shape_ids, shape_hw, sub: int = MASK_SUBSAMPLES) -> np.ndarray:
    """Fraction [H, W] of each pixel's stratified camera sub-samples whose first hit is one of the shapes."""
    import drjit as dr

    h, w = shape_hw
    targets = [s for s in scene.shapes() if s.id() in set(shape_ids)]
    cov = np.zeros(h * w * sub * sub, np.float32)
    if not targets:
        return cov.reshape(h, w, -1).mean(-1)
    if not hasattr(dr, "arange") or not str(mi.variant()).startswith(("llvm", "cuda")):
        raise error("CONVERT_BACKEND", "the object mask needs a JIT Mitsuba variant (llvm_ad_rgb)")
    idx = dr.arange(mi.UInt32, h * w * sub * sub)
    pix, s = idx // (sub * sub), idx % (sub * sub)
    px, py = mi.Float(pix % w), mi.Float(pix // w)
    pos = mi.Point2f((px + (mi.Float(s % sub) + 0.5) / sub) / w, (py + (mi.Float(s // sub) + 0.5) / sub) / h)
    ray, _ = sensor.sample_ray(0.0, 0.5, pos, mi.Point2f(0.5, 0.5))
    si = scene.ray_intersect(ray)
    hit = mi.Bool(False)
    for t in targets:
        hit |= si.shape == mi.ShapePtr(t)
    cov = np.asarray(hit, np.float32)
    return cov.reshape(h, w, sub * sub).mean(-1)


def _is_curve(shape) -> bool:
    return "curve" in str(shape).split("[")[0].lower()


def check_asset_fits(mi, scene, replace: dict, *, scene_file: str = "", flag: str = "--replace",
                     kinds: tuple | None = None, opened: dict | None = None) -> list[dict]:
    """Per distinct asset file: {asset, ids, kind, variant}; typed errors when scene and asset do not match.

    CONVERT_ASSET_REFERENCE: a missing or unreadable file. BENCH_ASSET_MISMATCH: an id the asset was not
    baked from (its bounding box differs from the replaced shapes' by more than BOX_TOLERANCE of the
    diagonal). BENCH_ASSET_KIND: a fiber asset for mesh shapes (or a surface asset for curves), a neupress
    asset for shapes without a dielectric boundary (neupress carries subsurface transport behind a rough
    dielectric), or, with ``kinds`` (a bench built for them), an asset of another kind. ``flag``: the option
    that named the asset, for the messages. ``opened``: {path: asset} the caller has already opened (without payloads)
    and checked as readable, so each file is opened once."""
    import mitsuba as mi

    from nasset_converters.mitsuba.scene import bounds_offset, no_such_shape, refuse_emitter

    from .common import open_given_asset, require_kind

    by_id = {s.id(): s for s in scene.shapes() if s.id()}
    groups: dict[Path, list[str]] = {}
    for sid, file in replace.items():
        if sid not in by_id:
            raise error("CONVERT_SHAPE_UNKNOWN", "--replace: " + no_such_shape(mi, scene, sid), file=scene_file)
        groups.setdefault(path_arg(file, f"{flag} {sid}: the asset"), []).append(sid)
    out = []
    for file, ids in groups.items():
        asset = (opened or {}).get(file) or open_given_asset(file, f"{flag} {','.join(ids)}")
        if kinds is not None:
            require_kind(asset, file, kinds, flag)
        shapes = [by_id[i] for i in ids]
        for shape in shapes:
            refuse_emitter(shape, file=scene_file)
        curves = [i for i, s in zip(ids, shapes, strict=True) if _is_curve(s)]
        if asset.variant == "fiber" and len(curves) != len(ids):
            raise error("BENCH_ASSET_KIND", f"{file.name} is a {asset.kind} fiber asset but "
                        f"{sorted(set(ids) - set(curves))} are surfaces", file=str(file))
        if asset.variant != "fiber" and curves:
            raise error("BENCH_ASSET_KIND", f"{file.name} is a {asset.kind} {asset.variant} asset but {curves} are curves "
                        "(they need a fiber asset)", file=str(file))
        if asset.kind == "neupress":  # one of the shapes is the boundary; the others may be inside it
            if not any("dielectric" in str(s.bsdf()).split("[")[0].lower() for s in shapes):
                raise error("BENCH_ASSET_KIND", f"{file.name} is a neupress asset (subsurface behind a rough dielectric) but "
                            f"none of {ids} has a dielectric boundary", file=str(file))
        off = bounds_offset(shapes, asset.geometry().points)
        if off > BOX_TOLERANCE:
            src = (asset.provenance or {}).get("source", {}).get("shapes")
            raise error("BENCH_ASSET_MISMATCH", f"{file.name} was not baked from {ids}: its bounds differ from theirs by "
                        f"{100 * off:.0f} % of the diagonal" + (f" (it was baked from {src})" if src else ""), file=str(file))
        out.append({"asset": str(file), "ids": ids, "kind": asset.kind, "variant": asset.variant, "bounds_offset": off})
    return out


def _png(path: Path, img: np.ndarray, exposure: float = 0.0) -> None:
    from nasset_reference_renderer.film import tonemap
    from nasset_sdk.images import write_png

    write_png(path, tonemap(img, exposure))


def error_map(est, ref, mask) -> np.ndarray:
    """uint8 [H, W, 3]: relative luminance error over the mask (blue: too dark, red: too bright; +-50 % saturates)."""
    lum = lambda x: x @ np.array([0.2126, 0.7152, 0.0722])  # noqa: E731
    r, e = lum(ref), lum(est)
    floor = 0.02 * max(float(np.percentile(r[mask], 99.5)) if mask.any() else 1.0, 1e-6)
    rel = np.clip((e - r) / np.maximum(r, floor) / 0.5, -1.0, 1.0)
    out = np.full(r.shape + (3,), 40, np.float64)
    m = mask
    out[m, 0] = 255 * np.maximum(rel[m], 0) + 255 * (1 - np.abs(rel[m])) * 0.9
    out[m, 1] = 255 * (1 - np.abs(rel[m])) * 0.9
    out[m, 2] = 255 * np.maximum(-rel[m], 0) + 255 * (1 - np.abs(rel[m])) * 0.9
    return np.clip(np.nan_to_num(out), 0, 255).astype(np.uint8)


@dataclass
class SourceReference:
    """What a source renderer gives the benchmark: the reference in two halves, the asset's pixel
    coverage, the converted scene and the descriptions that go into the report."""

    a: np.ndarray  # [H, W, 3] first half (mean of spp_per_half samples)
    b: np.ndarray  # [H, W, 3] second half, independent seeds
    half: int  # samples per half
    coverage: np.ndarray  # [H, W] fraction of the pixel's camera samples whose first hit is the asset's shapes
    fits: list  # check_asset_fits / blender_asset_fits rows
    converted: Path  # the converted USD scene with the assets in place
    max_depth: int | None  # default reference-renderer depth matching the source; None: the converted stage's
    reference: dict  # report["reference"]
    mask_source: str
    reused: bool = False
    cache_key: dict | None = None  # written as reference_key.json once the halves are on disk


#: the estimate's depth when the scene's integrator states none (e.g. ``direct``)
FALLBACK_DEPTH = 24


def estimate_depth(integrator: dict) -> int:
    """The reference renderer's max_depth for a converted scene's ``integrator`` record: Mitsuba's max_depth - 1
    (the renderer counts scattering vertices, Mitsuba path segments); an unbounded one (-1) is the renderer's
    MAX_DEPTH with Russian roulette, as Mitsuba's; FALLBACK_DEPTH when the integrator states no depth."""
    from nasset_reference_renderer.integrator import MAX_DEPTH

    md = integrator.get("renderer_max_depth")
    return FALLBACK_DEPTH if md is None else (MAX_DEPTH if md < 0 else max(1, int(md)))


def mitsuba_reference(scene_file, rep: dict, out: Path, *, res: int, spp: int, seed: int, quiet: bool, say) -> SourceReference:
    """The Mitsuba side: check the assets fit, convert, render the reference halves (reusing a cached
    pair for the same scene, size, spp and seed) and the object mask from Mitsuba's camera rays."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import far_from_origin, load_scene, media_caveats, require_integrator
    from nasset_converters.mitsuba.usd_export import convert_scene

    mi = load_mitsuba()  # CONVERT_BACKEND when mitsuba is missing
    mi.set_log_level(mi.LogLevel.Error)
    mscene = load_scene(mi, scene_file)
    require_integrator(mscene, scene_file)
    fits = check_asset_fits(mi, mscene, rep, scene_file=str(scene_file))
    converted = convert_scene(scene_file, out / "scene_neural.usda", replace=rep, check_usd=False)
    sensor, hw = sensor_for(mi, mscene, res, file=str(scene_file))
    a, b, half, key, reused = mitsuba_halves(mi, mscene, sensor, hw, scene_file, out, spp, seed, say=say, quiet=quiet)
    cov = object_mask(mi, mscene, sensor, list(rep), hw)
    reference = {"renderer": f"mitsuba {mi.__version__}", "variant": mi.variant(), "integrator": converted.integrator,
                 **conversion_notes(converted, say)}
    replaced = [s for s in mscene.shapes() if s.id() in rep]
    caveats = [c for c in (delta_light_caveat(mi, mscene, list(rep)), far_from_origin(mi, replaced)) if c] + media_caveats(
        mi, mscene, rep)
    for caveat in caveats:
        say(f"warning: {caveat}")
    if caveats:
        reference["warnings"] = caveats
    return SourceReference(
        a, b, half, cov, fits, Path(converted.output), estimate_depth(converted.integrator),
        reference, "mitsuba camera rays, first hit", reused=reused, cache_key=key)


def conversion_notes(converted, say) -> dict:
    """The converter's warnings (what the converted scene leaves out or approximates: a light it cannot convert, a
    material it simplifies), said as ``conversion:`` lines and returned as ``{"conversion_warnings": [...]}`` for the
    report (empty dict when there are none): the estimate renders that scene, so they can explain what the figures
    show (a dropped projector emitter read as an asset keeping 16-28 % of the energy)."""
    notes = list(converted.warnings)
    for note in notes:
        say(f"conversion: {note}")
    return {"conversion_warnings": notes} if notes else {}


def delta_light_caveat(mi, scene, ids: list[str]) -> str | None:
    """A warning when Mitsuba cannot render the reference's light through a replaced shape: a delta emitter
    (directional, point, spot) is never reached by next-event estimation through a smooth dielectric boundary, so
    the light it sends through the object is missing from Mitsuba's image, while the asset (baked with a small
    area light, spec/bake.md#light) carries it. None when no replaced shape has such a boundary or no light is delta."""
    from nasset_converters.mitsuba.scene import blocks_delta_light

    shapes = [s for s in scene.shapes() if s.id() in ids]
    if not blocks_delta_light(shapes):
        return None
    delta = mi.EmitterFlags.DeltaPosition | mi.EmitterFlags.DeltaDirection
    lights = [e.id() or type(e).__name__ for e in scene.emitters() if int(e.flags()) & int(delta)]
    if not lights:
        return None
    return (f"delta light(s) {lights} cannot reach the inside of {ids} through their smooth dielectric boundary in "
            "Mitsuba (next-event estimation never meets a delta light through a delta BSDF): the reference lacks the "
            "light they send through the object, the asset does not, so it will read too bright. Measure with a "
            "rough dielectric boundary or with small area lights instead (spec/accuracy.md#in-scene-accuracy)")


def blender_asset_fits(rep: dict, *, scene_file: str = "") -> list[dict]:
    """As check_asset_fits, for the objects of the open .blend (the geometry the Blender bake exports)."""
    from nasset_converters.blender import scene as bsc

    from .common import open_given_asset

    groups: dict[Path, list[str]] = {}
    for name, file in rep.items():
        groups.setdefault(Path(file), []).append(name)
    out = []
    for file, ids in groups.items():
        asset = open_given_asset(file, f"--replace {','.join(ids)}")
        variant, geo, _ = bsc.asset_geometry(bsc.pick_objects(ids, file=scene_file), file=scene_file)
        if asset.variant != variant:
            raise error("BENCH_ASSET_KIND", f"{file.name} is a {asset.kind} {asset.variant} asset but {ids} need a "
                        f"{variant} asset", file=str(file))
        src = np.asarray(geo.points, np.float64)
        off = box_offset(np.stack([src.min(0), src.max(0)]), asset.geometry().points)
        if off > BOX_TOLERANCE:
            raise error("BENCH_ASSET_MISMATCH", f"{file.name} was not baked from {ids}: its bounds differ from theirs by "
                        f"{100 * off:.0f} % of the diagonal", file=str(file))
        out.append({"asset": str(file), "ids": ids, "kind": asset.kind, "variant": asset.variant, "bounds_offset": off})
    return out


def blender_reference(scene_file, rep: dict, out: Path, *, res: int, spp: int, seed: int, quiet: bool, say) -> SourceReference:
    """The Blender side: convert, check the assets fit, render the unclamped Cycles reference halves
    through the scene's camera (its aspect kept) and the object coverage from Cycles itself."""
    from nasset_converters.blender import load_bpy
    from nasset_converters.blender import scene as bsc
    from nasset_converters.blender.cycles import object_coverage, render_cycles, setup_cycles
    from nasset_converters.blender.usd_export import convert_scene

    bpy = load_bpy()  # CONVERT_BACKEND when bpy is missing
    converted = convert_scene(scene_file, out / "scene_neural.usda", replace=rep, check_usd=False)
    bsc.open_blend(scene_file)
    camera = bpy.context.scene.camera
    if camera is None or camera.data.type not in ("PERSP", "ORTHO"):  # as sensor_for on the Mitsuba side
        raise error("CONVERT_SCENE_LOAD", f"the scene's camera ({'none' if camera is None else camera.data.type}) is "
                    "not a perspective or orthographic one: the benches compare images seen from the scene's own "
                    "camera; add one and make it the scene's active camera", file=str(scene_file))
    fits = blender_asset_fits(rep, scene_file=str(scene_file))
    w, h = converted.resolution
    height = max(1, int(round(res * h / max(w, 1))))
    # the scene's own bounce limit, the one the converted stage's nasset:maxDepth (B + 1) stands for
    max_bounces = int(converted.integrator["max_bounces"])
    setup_cycles(bpy, res, height, max_bounces=max_bounces)
    say(f"reference: Cycles {spp} spp at {res}x{height} in two halves, unclamped")
    exr = out / "cycles_chunk.exr"
    a, b, half = render_halves(lambda n, s: render_cycles(bpy, exr, n, seed=s), spp, seed, desc="cycles reference", quiet=quiet)
    cov = object_coverage(bpy, bsc.pick_objects(list(rep), file=str(scene_file)), exr, spp=MASK_SUBSAMPLES ** 2)
    exr.unlink(missing_ok=True)
    return SourceReference(
        a, b, half, cov, fits, Path(converted.output), None,
        {"renderer": f"cycles {bpy.app.version_string}", "variant": "CPU", "integrator": {"max_bounces": max_bounces},
         **conversion_notes(converted, say)},
        "cycles film alpha with every other object a holdout")


def bench_accuracy(scene_file, replace, out_dir, *, res: int = 128, spp: int = 8192, nr_spp: int = 64,
                   max_depth: int | None = None, seed: int = 0, quiet: bool = False) -> dict:
    """Run the benchmark (module docstring); returns the report dict (also written as JSON + markdown).
    ``scene_file``: a Mitsuba 3 .xml or a Blender .blend (the source renderer follows the suffix)."""
    from nasset_sdk.metrics import accuracy, flip_map

    say = _say(quiet)
    for name, v in (("res", res), ("spp", spp), ("nr-spp", nr_spp)):
        if int(v) < (8 if name == "res" else 2 if name == "spp" else 1):
            raise UsageError(f"--{name} too small: {v}")
    suffix = Path(str(scene_file)).suffix.lower()
    sources = {".xml": mitsuba_reference, ".blend": blender_reference}
    if suffix not in sources:
        raise UsageError(f"the scene must be a Mitsuba 3 .xml or a Blender .blend file, got {Path(str(scene_file)).name!r}")
    if not Path(scene_file).is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(scene_file))
    if suffix == ".xml":
        from nasset_converters.mitsuba.usd_export import parse_replace
    else:
        from nasset_converters.blender.usd_export import parse_replace
    rep = parse_replace(replace)
    if not rep:
        raise UsageError("give at least one --replace ID[,ID]=ASSET.usdc")
    out = Path(out_dir)
    output_folder(out)
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    src = sources[suffix](scene_file, rep, out, res=res, spp=spp, seed=seed, quiet=quiet, say=say)
    times["reference_s"] = time.perf_counter() - t0
    a, b, half = src.a, src.b, src.half
    hw = a.shape[:2]
    max_depth = src.max_depth if max_depth is None else max_depth
    mask = src.coverage >= 0.5
    if not mask.any():
        raise error("BENCH_ASSET_MISMATCH", f"the replaced shapes {sorted(rep)} cover no pixel of the camera's view",
                    file=str(scene_file))

    t = time.perf_counter()
    from nasset_reference_renderer import RenderSettings, render
    from nasset_reference_renderer import load_scene as load_usd
    from nasset_reference_renderer.integrator import resolve_settings
    from nasset_reference_renderer.scene import SceneWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        uscene = load_usd(str(src.converted))
    settings = resolve_settings(RenderSettings(spp=int(nr_spp), seed=seed + 7, width=hw[1], height=hw[0],
                                               max_depth=max_depth, progress=not quiet), uscene)
    max_depth = settings.max_depth
    say(f"estimate: reference renderer {nr_spp} spp, max_depth {max_depth}")
    result = render(uscene, settings)
    est = np.nan_to_num(np.asarray(result.image, np.float64)[..., :3])
    est_var = np.nan_to_num(np.asarray(result.variance, np.float64)[..., :3])
    times["estimate_s"] = time.perf_counter() - t

    obj = accuracy(est, a, b, mask, est_var=est_var)
    full = accuracy(est, a, b, None, est_var=est_var, flip=False)
    ref = 0.5 * (a + b)
    from nasset_reference_renderer.film import write_exr

    files = []
    for name, img in (("reference", ref), ("reference_a", a), ("reference_b", b), ("neural", est), ("neural_var", est_var)):
        write_exr(out / f"{name}.exr", img.astype(np.float32))
        files.append(str(out / f"{name}.exr"))
    _png(out / "reference.png", ref)
    _png(out / "neural.png", est)
    from nasset_sdk.images import write_png as png8

    png8(out / "mask.png", np.repeat((mask * 255).astype(np.uint8)[..., None], 3, -1))
    png8(out / "error.png", error_map(est, ref, mask))
    files += [str(out / n) for n in ("reference.png", "neural.png", "mask.png", "error.png")]
    fmap = flip_map(est, ref)
    if fmap is not None:
        v = np.clip(np.nan_to_num(fmap), 0, 1)
        png8(out / "flip.png", np.stack([255 * v, 255 * v * v, 255 * (1 - v) * v], -1).astype(np.uint8))
        files.append(str(out / "flip.png"))
    if src.cache_key is not None:
        write_text_atomic(out / "reference_key.json", json.dumps(src.cache_key))
    times["total_s"] = time.perf_counter() - t0
    report = {
        "benchmark": "accuracy",
        "scene": str(scene_file),
        "replaced": src.fits,
        "resolution": [hw[1], hw[0]],
        "reference": {**src.reference, "spp": 2 * half, "halves": 2, "spp_per_half": half, "clamp": None,
                      "reused": src.reused},
        "estimate": {"renderer": "reference_renderer", "spp": int(nr_spp), "max_depth": int(max_depth)},
        "mask": {"source": src.mask_source, "subsamples": MASK_SUBSAMPLES ** 2, "threshold": 0.5,
                 "pixels": int(mask.sum())},
        "object": obj.to_dict(),
        "image": full.to_dict(),
        "files": files + [str(out / "accuracy.json"), str(out / "accuracy.md")],
        "times_s": {k: round(v, 2) for k, v in times.items()},
        "definitions": "spec/accuracy.md#metrics",
    }
    write_text_atomic(out / "accuracy.json", json.dumps(report, indent=2))
    write_text_atomic(out / "accuracy.md", markdown(report))
    return report


def markdown(r: dict) -> str:
    o, f = r["object"], r["image"]

    def num(x, scale=1.0, digits=1) -> str:  # None: undefined (a black reference: stored as null, accuracy.md#metrics)
        return "n/a" if x is None else f"{scale * x:.{digits}f}"

    def row(name, a):
        e = " / ".join(num(x, 100) for x in a["energy_ratio"])
        se = " / ".join(num(x, 100) for x in a["energy_se"])
        fl = "—" if a.get("flip") is None else f"{a['flip']:.3f}"
        return (f"| {name} | {a['pixels']} | {e} (± {se}) | {num(a['psnr_db'], digits=2)} | {num(a['ceiling_db'], digits=2)} | "
                f"{a['claimed_psnr']} | {fl} |")

    ref = r["reference"]
    replaced = ", ".join(",".join(x["ids"]) + " = " + Path(x["asset"]).name + f" ({x['kind']} {x['variant']})" for x in r["replaced"])
    lines = [
        f"# In-scene accuracy: {Path(r['scene']).name}",
        "",
        f"Replaced: {replaced}. "
        f"Reference: {ref['renderer']} ({ref['variant']}), {ref['spp']} spp in two independent halves, unclamped; estimate: "
        f"reference renderer, {r['estimate']['spp']} spp; {r['resolution'][0]}×{r['resolution'][1]}. "
        "Definitions: spec/accuracy.md#metrics.",
        "",
        "| region | pixels | energy % of reference (R / G / B) | PSNR dB | ceiling dB | claimed | FLIP |",
        "|---|---|---|---|---|---|---|",
        row("object (mask from the source renderer)", o),
        row("whole image", f),
        "",
        "Images: reference.png, neural.png, mask.png, error.png (relative luminance error over the mask; blue too dark, "
        "red too bright, ±50 % saturates)" + (", flip.png" if any(x.endswith("flip.png") for x in r["files"]) else "") + ".",
        "",
        "Times: " + ", ".join(f"{k[:-2]} {v:.1f} s" for k, v in r["times_s"].items()) + ".",
        "",
    ] + [f"**Warning:** {w}\n" for w in ref.get("warnings", [])] + (
        ["The converted scene the estimate renders differs from the source where the converter says so:", ""]
        + [f"- {w}" for w in ref.get("conversion_warnings", [])] + [""] if ref.get("conversion_warnings") else [])
    return "\n".join(lines)


def summary_text(r: dict) -> str:
    from nasset_sdk.metrics import Accuracy

    o = r["object"]
    a = Accuracy(**{k: v for k, v in o.items() if k in Accuracy.__dataclass_fields__})
    return (f"in-scene accuracy over the object ({o['pixels']} pixels, mask from {r['reference']['renderer']}): {a.line()}\n"
            f"reference: {r['reference']['spp']} spp unclamped in two halves; estimate {r['estimate']['spp']} spp\n"
            + "".join(f"warning: {w}\n" for w in r["reference"].get("warnings", []))
            + (f"conversion: {len(conv)} warning(s) about the converted scene the estimate renders (accuracy.md)\n"
               if (conv := r["reference"].get("conversion_warnings")) else "")
            + "wrote " + ", ".join(r["files"]))


def add_args(p) -> None:
    """Options of ``nasset bench accuracy``."""
    p.add_argument("scene", help="Mitsuba 3 scene .xml or Blender .blend (the original, with the shapes or objects the "
                   "asset was baked from); the reference is rendered by that scene's own renderer")
    p.add_argument("--replace", action="append", required=True, metavar="SHAPE_ID[,SHAPE_ID]=ASSET",
                   help="the baked asset in place of these shapes (Mitsuba ids) or objects (Blender names); repeatable")
    p.add_argument("-o", "--output", default="bench_accuracy", help="output folder (images, JSON, markdown, converted scene)")
    p.add_argument("--spp", type=count_arg(2, MAX_SPP), default=None,
                   help=f"Mitsuba reference spp, both halves together (default {DEFAULT['spp']}; {QUICK['spp']} with --quick)")
    p.add_argument("--nr-spp", type=count_arg(1, MAX_SPP), default=None,
                   help=f"reference-renderer spp (default {DEFAULT['nr_spp']}; {QUICK['nr_spp']} with --quick)")
    p.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=None,
                   help=f"image width (default {DEFAULT['res']}; {QUICK['res']} with --quick); height keeps the scene's aspect")
    p.add_argument("--max-depth", type=count_arg(0, 1024), default=None, help="reference renderer depth (default: Mitsuba's max_depth - 1, "
                   "1024 with Russian roulette when unbounded; Blender: the converted scene's nasset:maxDepth, Cycles' bounces + 1)")
    p.add_argument("--quick", action="store_true", help="small defaults that finish in a few minutes")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--json", action="store_true", help="print the report as JSON (progress is silenced)")


def run(args) -> int:
    """CLI entry: ``nasset bench accuracy ...``."""
    d = QUICK if args.quick else DEFAULT
    report = bench_accuracy(args.scene, args.replace, args.output, res=args.res or d["res"], spp=args.spp or d["spp"],
                            nr_spp=args.nr_spp or d["nr_spp"], max_depth=args.max_depth, seed=args.seed, quiet=args.json)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(summary_text(report))
    return 0


