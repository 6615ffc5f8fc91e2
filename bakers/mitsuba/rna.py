"""``nasset bake``: a Mitsuba 3 scene's object -> a trained neural asset (spec/bake.md).

Stages: load scene -> render dataset (Mitsuba) -> train (PyTorch) -> export (ONNX + tensors
through AssetBuilder) -> check (re-open the written asset, evaluate it with the SDK on the
held-out views). Each stage shows a progress bar; a summary with per-stage times, dataset size,
held-out PSNR and asset size closes the run.

The dataset folder (``--resume DIR``, default ``OUTPUT.bake/``) is kept after an interruption
(and after success), so a new run with the same settings continues where the last one stopped.
The asset file is written atomically: an interrupted bake never leaves a half-written asset.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

from nasset_bakers import presets
from nasset_bakers.registry import register_baker
from nasset_bakers.stages import (
    accuracy_lines,
    check_geometry_scale,
    check_options,
    clamp_lines,
    clamp_removed,
    data_noise_line,
    data_noise_stage,
    dataset_line,
    energy_gain_line,
    finite,
    near_field_line,
    near_field_stage,
    plane_blur_line,
    psnr_line,
    see_through_line,
    times_line,
    warnings_said,
    worker_lines,
    write_near_field,
)
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder

DATA_PRESETS = presets.RNA_MITSUBA_DATA  # the table lives in nasset_bakers/presets.py
DATA_NOISE = presets.RNA_MITSUBA_DATA_NOISE


#: default angular radius (deg) of the distant light for assets behind smooth dielectrics: measured
#: (benchmarks/light_study.py, spec/bake.md#light) 5 deg costs +5 % bias and 2.2x the
#: per-pixel noise of a rough boundary under a delta light; 2 deg: +2 % but 7.6x the noise.
SMOOTH_DIELECTRIC_LIGHT_ANGLE = 5.0


def bake(
    scene: str | Path | None,
    asset_ids: list[str] | None,
    output: str | Path,
    *,
    size: str = "small",
    example: bool | str = False,
    resume: str | Path | None = None,
    views: int | None = None,
    res: int | None = None,
    epochs: int | None = None,
    spp: int | None = None,
    light_angle: float | None = None,
    seed: int = 0,
    device: str = "auto",
    quiet: bool = False,
    variant: str | None = None,
    summary_stream=None,
    clamp: float | None = None,
    loss: str | None = None,
    workers: int | None = None,
    cluster: str | None = None,
    near_field_fetch: str | float = "auto",
) -> dict:
    """Run the whole bake; returns the summary dict (also stored in the asset's provenance).

    ``clamp``: per-path-sample clamp of the training targets (default 0: none; the energy it removes
    is measured and stored, spec/bake.md#clamp); ``loss``: training loss (default: TrainSettings');
    ``workers``/``cluster``: render the views on Ray workers (nasset_bakers.cluster); ``near_field_fetch``: 'auto'
    (measured after training, surface assets; fibers keep 0, spec/bake.md#near-field) or f in [0, 1] to store."""
    from nasset_bakers.cluster import ViewSource, check_workers
    from nasset_bakers.stages import render_views, send_job, train_share, train_with_progress
    from nasset_bakers.train.common import TorchCheckpoint, require_torch, training_key
    from nasset_bakers.train.parallel import data_parallel
    from nasset_bakers.train.rna import TRAIN_PRESETS, TrainSettings, check_asset, train
    from nasset_converters.mitsuba import CONVERTER_VERSION, load_mitsuba
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import scene as msc
    from nasset_sdk.asset import AssetBuilder

    output = check_options(size, DATA_PRESETS, output, seed=seed, scene=scene, views=views, res=res, epochs=epochs, spp=spp)
    check_workers(workers, cluster)
    if light_angle is not None and not (0.0 <= light_angle < 45.0):
        raise UsageError(f"--light-angle must be in [0, 45) degrees, got {light_angle}")
    dp = data_parallel(require_torch(), device)  # under torchrun: this process's rank (spec/bake.md#training-devices)
    if not dp.is_main:
        return train_share(dp)
    work = Path(resume) if resume else output.with_name(output.name + ".bake")
    output_folder(work, "bake's work folder")  # before the scene: an example scene is written into it
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    times: dict[str, float] = {}
    t_all = time.perf_counter()

    # -- stage 1: scene ---------------------------------------------------------------------------
    t = time.perf_counter()
    require_torch()  # fail early (typed) when torch is missing, before minutes of rendering
    with warnings_said(say):
        mi = load_mitsuba(variant)
    mi.set_log_level(mi.LogLevel.Error)
    if example == "high-albedo":
        from nasset_converters.mitsuba.high_albedo_example import EXAMPLE_ASSET_IDS, write_example_scene

        scene = write_example_scene(work / "example_scene")
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    elif example == "hair-dense":
        from nasset_converters.mitsuba.hair_example import EXAMPLE_ASSET_IDS, write_example_scene

        scene = write_example_scene(work / "example_scene", size)
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    elif example:
        from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene

        scene = write_example_scene(work / "example_scene")
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    if scene is None:
        raise UsageError("give a scene file or --example")
    scene = Path(scene)
    msc_scene = msc.load_scene(mi, scene)
    shapes = msc.pick_shapes(msc_scene, asset_ids or [], file=str(scene), curves=True)
    with warnings_said(say):
        asset_variant, geo = msc.asset_geometry(mi, shapes)
    check_geometry_scale(geo, asset_ids, scene)
    center, radius = msc.bounding_sphere(geo)
    blocks = msc.blocks_delta_light(shapes)
    if light_angle is None:
        light_angle = SMOOTH_DIELECTRIC_LIGHT_ANGLE if blocks else 0.0
        if blocks:
            say("note: the asset has a smooth dielectric boundary, which a delta light cannot reach; "
                f"using a distant light of angular radius {light_angle} deg (spec/bake.md#light)")
    elif blocks and light_angle == 0.0:
        say("warning: --light-angle 0 with a smooth dielectric boundary: light transport inside it will be black")
    dset = replace(ds.DataSettings(), **DATA_PRESETS[size], light_angle_deg=float(light_angle), seed=seed)
    if views is not None:
        dset = replace(dset, views=int(views), val_views=max(1, int(views) // 8))
    if res is not None:
        dset = replace(dset, res=int(res))
    if spp is not None:  # training views only: the held-out reference keeps the preset's (low) noise
        dset = replace(dset, spp=int(spp))
    if clamp is not None:
        if not clamp >= 0:
            raise UsageError(f"clamp must be >= 0 (0: none), got {clamp}")
        dset = replace(dset, clamp=float(clamp))
    dset = replace(dset, max_depth=msc.training_depth(msc_scene.integrator(), dset.max_depth))
    for warning in msc.bake_media_warnings(msc_scene, asset_ids, dset.max_depth):
        say(f"warning: {warning}")
    if clear := msc.see_through(mi, shapes):
        say(see_through_line("shape(s)", clear, msc.SEE_THROUGH_SHARE))
    origin = msc.render_origin(mi, shapes)  # where _view_renderer moves them from (spec/bake.md#far-from-the-origin)
    if far := msc.far_for_bake(mi, shapes):  # far shapes render moved to the origin, unless they cannot move
        say(f"warning: {far}")
    if mirrors := msc.mirror_shapes(mi, shapes):
        why = (f"their BSDFs ({', '.join(sorted(set(msc.bsdf_names([s for s in shapes if s.id() in mirrors]))))}) reflect "
               "light along mirror directions only: rna stores smooth transport, and a distant light reaches a camera "
               "off a mirror along one direction alone (spec/bake.md#mirrors)")
        if len(mirrors) == len(shapes):
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"asset shape(s) {mirrors}: {why}; every training view would be "
                        "black. Bake a rough one (roughconductor)", file=str(scene))
        say(f"warning: shape(s) {mirrors}: {why}; they will render black, without what they mirror of the scene")
    renderer = None  # the Mitsuba queries of this process (views, near-field calibration)
    if workers is None:
        renderer = _renderer(mi, shapes, geo, center, radius, dset)
        views_from = _views_of(renderer, center, radius)
    else:  # each worker loads the scene itself
        views_from = ViewSource("nasset_bakers.mitsuba.rna:view_renderer",
                                {"scene": scene, "asset_ids": list(asset_ids or []), "dset": dset, "variant": mi.variant(),
                                 "threads": 1})
    times["scene_s"] = time.perf_counter() - t

    # -- stage 2: dataset -------------------------------------------------------------------------
    t = time.perf_counter()
    store = ds.DatasetDir(work)
    meta = ds.settings_digest(scene, asset_ids, dset, mi.variant())
    if origin.any():  # views rendered moved (spec/bake.md#far-from-the-origin) are not those of a folder made before
        meta["render_origin"] = origin.tolist()
    store.prepare(meta)
    per_worker = render_views(store, dset.views, dset.val_views, views_from, desc="render views", work=work, quiet=quiet,
                              say=say, workers=workers, cluster=cluster)
    train_data = store.load_split("train", dset.views)
    val_data = store.load_split("val", dset.val_views)
    if len(val_data["x"]) == 0:
        raise error("CONVERT_TRAINING", "no validation samples: no validation camera ray hit the asset")

    # more training views where the targets are too noisy for the network to average out (spec/bake.md#data-noise);
    # a count given with --views is the user's
    noise, dset, train_data, more = data_noise_stage(store, dset, train_data, val_data, DATA_NOISE[size] if views is None else None,
                                                     views_from, lambda n: store.load_split("train", n), work=work, quiet=quiet, say=say,
                                                     workers=workers, cluster=cluster)
    per_worker = more or per_worker
    times["dataset_s"] = time.perf_counter() - t

    # -- stage 3: train ---------------------------------------------------------------------------
    t = time.perf_counter()
    builder = AssetBuilder("rna", variant=asset_variant)
    builder.set_geometry(geo)
    domain = builder.domain
    fiber_train = presets.RNA_MITSUBA_FIBER_TRAIN.get(size, {}) if asset_variant == "fiber" else {}
    tset = TrainSettings(size=size, seed=seed, device=device, **{**TRAIN_PRESETS[size], **fiber_train})
    if epochs is not None:
        tset = replace(tset, epochs=int(epochs))
    if loss is not None:
        tset = replace(tset, loss=str(loss))
    data_key = {**meta, "settings": {**meta["settings"], "views": dset.views}}  # the views trained on (data noise)
    ckpt = TorchCheckpoint(work / "train_state.pt", {"data": data_key, "train": training_key(tset),
                                                      "domain": [list(map(float, d)) for d in domain]})
    send_job(dp, work=work, views=dset.views, val_views=dset.val_views, domain=domain, settings=tset, checkpoint=ckpt)
    result = train_with_progress(
        lambda progress: train(train_data, val_data, domain, tset, progress=progress, checkpoint=ckpt),
        total=tset.epochs, desc="train", work=work, quiet=quiet, say=say)
    times["train_s"] = time.perf_counter() - t

    # -- stage 4: export --------------------------------------------------------------------------
    t = time.perf_counter()
    core = builder.component("core", required=True, purpose="evaluation", quality=None)
    core.add_tensor("triplane", result.planes, dtype="float16", layout="plane,v,u,channel")
    core.add_network("decoder", result.onnx)
    prov = {
        "generator": "nasset bake",
        "converter": f"converters.mitsuba {CONVERTER_VERSION}",
        "converterVersion": CONVERTER_VERSION,
        "source": {"renderer": f"mitsuba {mi.__version__}", "variant": mi.variant(), "scene": str(scene),
                   "scene_sha256": meta["scene_sha256"], "shapes": list(asset_ids), "example": example if isinstance(example, str) else bool(example),
                   "bsdfs": msc.bsdf_names(shapes)},
        "light": {"type": "directional" if dset.light_angle_deg == 0 else "distant-sphere",
                  "angular_radius_deg": dset.light_angle_deg, "irradiance": 1.0},
        "data": {**dset.__dict__, "train_samples": int(len(train_data["x"])), "val_samples": int(len(val_data["x"])),
                 "clamp_removed": clamp_removed(train_data), "reference": "held-out views unclamped, two independent halves",
                 "noise": noise, **_mask_statistics(train_data)},
        "training": {**tset.__dict__, "device": result.device, "framework": f"torch {require_torch().__version__}",
                     "final_loss": result.history[-1]["loss"] if result.history else None, "energy_gain": result.energy_gain,
                     "plane_blur_selection": result.plane_blur},
        "validation": {**result.val, "psnr_definition": "spec/bake.md#psnr"},
        "onnx": {"opset": 17, "max_abs_diff_vs_torch": result.onnx_max_abs_diff},
        "size": size,
        "timings_s": {k: round(v, 3) for k, v in times.items()},
    }
    builder.provenance = finite(prov)
    path = builder.write(output)
    times["export_s"] = time.perf_counter() - t

    # -- stage 5: check the written asset with the SDK --------------------------------------------
    t = time.perf_counter()
    check = check_asset(path, val_data, result)
    times["check_s"] = time.perf_counter() - t

    # -- stage 6: where renderers fetch the asset's light (spec/bake.md#near-field) ------------------
    t = time.perf_counter()
    near = _near_field(near_field_fetch, asset_variant, size, seed, check, domain, quiet,
                       lambda: renderer or _renderer(mi, shapes, geo, center, radius, dset), path, center, radius)
    path = write_near_field(builder, prov, near, output) or path
    times["near_field_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t_all
    summary = {
        "asset": str(path),
        "asset_bytes": path.stat().st_size,
        "dataset_dir": str(work),
        "train_samples": int(len(train_data["x"])),
        "val_samples": int(len(val_data["x"])),
        "views": dset.views, "val_views": dset.val_views, "res": dset.res, "spp": dset.spp,
        "val_res": dset.val_res or dset.res, "val_spp": dset.val_spp,
        "variant": mi.variant(), "device": result.device, "asset_variant": asset_variant,
        **_mask_statistics(train_data),
        "val_psnr_db": result.val["psnr_db"],
        **{k: result.val.get(k) for k in ("kept_epoch", "epochs", "keep")},
        "val_accuracy": result.val.get("accuracy"),
        "sdk_val_accuracy": check.get("accuracy"),
        "clamp": dset.clamp, "clamp_removed": prov["data"]["clamp_removed"], "data_noise": noise,
        "near_field": near,
        "sdk_val_psnr_db": check["psnr_db"],
        "sdk_vs_torch_max_abs": check["max_abs_diff"],
        "onnx_vs_torch_max_abs": result.onnx_max_abs_diff,
        "energy_gain": result.energy_gain,
        "plane_blur": result.plane_blur,
        "times_s": {k: round(v, 2) for k, v in times.items()},
        "workers": per_worker,
    }
    if not quiet:
        _print_summary(summary, summary_stream or sys.stdout)
    return summary


def _print_summary(s: dict, stream) -> None:
    t = s["times_s"]
    lines = [
        f"baked {s['asset']}  ({s['asset_bytes'] / 1024:.1f} KiB)",
        f"  mitsuba {s['variant']}, training on {s['device']}",
        dataset_line(s) + f"  (kept in {s['dataset_dir']})",
        *([f"  fiber mask: Mitsuba's curves and the prisms disagree on {100 * s['mask_disagreement']:.2f} % of the "
           "covered training pixels"] if s.get("mask_disagreement") is not None else []),
        *accuracy_lines(s.get("sdk_val_accuracy")),
        psnr_line(s, "held-out display PSNR (99.5th pct, clipped)"),
        *filter(None, [data_noise_line(s.get("data_noise")), plane_blur_line(s.get("plane_blur")),
                       energy_gain_line(s.get("energy_gain"))]),
        *clamp_lines(s),
        near_field_line(s["near_field"]),
        f"  parity: SDK vs torch max |diff| {s['sdk_vs_torch_max_abs']:.2e}; ONNX vs torch {s['onnx_vs_torch_max_abs']:.2e}",
        times_line(t),
        *worker_lines(s.get("workers")),
    ]
    print("\n".join(lines), file=stream)


def _mask_statistics(data: dict) -> dict:
    """Fiber bakes: the fraction of covered pixels on which Mitsuba's curves and the prisms disagree."""
    if "disagree" not in data:
        return {}
    return {"mask_disagreement": float(data["disagree"]) / max(int(data["covered"]), 1)}


def _renderer(mi, shapes, geo, center, radius, dset):
    """The Mitsuba queries on the shapes isolated under the bake's light (curves: the geometric inputs from the prisms
    the renderer traces, spec/bake.md#mitsuba-curves). Moves the shapes to the origin (once per process)."""
    from nasset_converters.caster import Caster
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import scene as msc
    from nasset_sdk.geometry import CurvesGeometry

    origin = msc.move_to_origin(mi, shapes)  # Mitsuba's ray offset far from the origin (spec/bake.md#far-from-the-origin)
    iso = msc.IsolatedAsset(mi, shapes, center, radius, angle_deg=dset.light_angle_deg, max_depth=dset.max_depth,
                            origin=origin)
    fibers = isinstance(geo, CurvesGeometry)  # surfaces: V offset as the renderer offsets it (spec/bake.md#data)
    return ds.Renderer(mi, iso, dset, caster=Caster("fiber", geo) if fibers else None,
                       shadows=None if fibers else Caster("surface", geo))


def _views_of(renderer, center, radius):
    """``render_one(split, i)`` of the dataset stage."""
    from nasset_converters.mitsuba import dataset as ds

    return lambda split, i: ds.render_view(renderer, center, radius, i, validation=split == "val")


def _view_renderer(mi, shapes, geo, center, radius, dset):
    """``render_one(split, i)`` of the dataset stage, on a renderer of its own."""
    return _views_of(_renderer(mi, shapes, geo, center, radius, dset), center, radius)


def _near_field(option, asset_variant: str, size: str, seed: int, check: dict, domain, quiet: bool, renderer_of, path,
                center, radius) -> dict:
    """Stage 6 (:func:`nasset_bakers.stages.near_field_stage`): T of the written asset against Mitsuba's radiance of
    the shapes; fiber assets keep 0 unless f is given."""
    from nasset_bakers.train.common import reopen_asset
    from nasset_converters.mitsuba import near_field as nf

    if option == "auto" and asset_variant != "surface":
        return {"fetch": 0.0, "measured": False, "why": "fiber assets are not measured (spec/bake.md#near-field)"}

    def measure(settings, target, progress):
        _, ev = reopen_asset(path)
        return nf.calibrate(renderer_of(), center, radius, settings, ev.evaluate, 0.5 * (domain[0] + domain[1]), target,
                            progress=progress)

    return near_field_stage(option, check, size, seed, quiet, measure)


def view_renderer(scene, asset_ids, dset, variant=None, threads: int = 0):
    """``render_one(split, i)`` built from the scene file (a cluster worker's copy of stage 1);
    ``threads`` > 0 limits Dr.Jit's thread pool (a worker owns one CPU)."""
    from nasset_converters.mitsuba import scene as msc

    mi, shapes = msc.open_shapes(scene, asset_ids, variant=variant, threads=threads, curves=True)
    _, geo = msc.asset_geometry(mi, shapes)
    center, radius = msc.bounding_sphere(geo)
    return _view_renderer(mi, shapes, geo, center, radius, dset)


def bake_named_example(scene, asset_ids, output, *, example: str | None = None, **options) -> dict:
    """:func:`bake` with ``example`` a name as the other bakers take it (Mitsuba rna: default, high-albedo, hair-dense)."""
    if example not in (None, "default", "high-albedo", "hair-dense"):
        raise UsageError(f"unknown rna example {example!r} (default, high-albedo, hair-dense, blender-surface, blender-hair, "
                         "blender-hair-dense)")
    return bake(scene, asset_ids, output, example=example or False, **options)


register_baker("mitsuba", "rna", bake_named_example)
