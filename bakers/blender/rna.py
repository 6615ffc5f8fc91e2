"""``nasset bake SCENE.blend --asset OBJECT --kind rna``: a Blender object -> an rna asset (spec/bake-blender.md).

Stages (as the Mitsuba bake, bakers/mitsuba/rna.py): open the .blend (or generate an example) and
export the asset's geometry -> render the dataset with Cycles (nasset_converters.blender.dataset) ->
train (nasset_bakers.train.rna, the one rna trainer; fibers add the h input) -> export (ONNX +
float16 triplane through AssetBuilder, atomic) -> check (re-open the asset and evaluate it with
the SDK on the held-out views). Meshes give variant ``surface``, hair (Curves objects, particle
hair) variant ``fiber``. The dataset folder (``--resume DIR``, default ``OUTPUT.bake/``) is kept,
so an interrupted bake continues at the first missing view or the last training checkpoint.

Options: ``--views/--res/--spp/--epochs/--seed/--device`` as for Mitsuba; ``--light-angle`` is
the sun's angular radius in degrees (default 0.5). ``clamp``: Cycles' per-sample clamp of the
training views, direct and indirect alike (default 0: none; the paper clamps at 20 / 10, which
throws away the long paths of light materials, spec/bake.md#clamp; Cycles does not report what a
clamp removed, so the provenance says it was not measured). ``h_input=False`` (Python only; the benchmark's ablation) trains a fiber
asset with h fixed to 0.
"""

from __future__ import annotations

import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from nasset_bakers import presets
from nasset_bakers.registry import register_baker
from nasset_bakers.stages import (
    accuracy_lines,
    check_geometry_scale,
    data_noise_line,
    data_noise_stage,
    dataset_line,
    energy_gain_line,
    plane_blur_line,
    psnr_line,
    see_through_line,
    times_line,
    worker_lines,
)
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder

DATA_PRESETS = presets.RNA_BLENDER_DATA  # the table lives in nasset_bakers/presets.py
DATA_NOISE = presets.RNA_BLENDER_DATA_NOISE
DEFAULT_LIGHT_ANGLE = 0.5


def bake(
    scene, asset_ids, output, *, size: str = "small", example: str | None = None, resume=None, views=None, res=None,
    epochs=None, spp=None, light_angle=None, seed: int = 0, device: str = "auto", quiet: bool = False,
    summary_stream=None, h_input: bool = True, threads: int = 0, lights_per_view: int | None = None, clamp: float | None = None,
    workers: int | None = None, cluster: str | None = None, **_ignored,
) -> dict:
    """Run the whole bake; returns the summary dict (also stored in the asset's provenance).
    ``workers``/``cluster``: render the views on Ray workers (nasset_bakers.cluster), one Cycles thread each."""
    from nasset_bakers.cluster import ViewSource, check_workers
    from nasset_bakers.stages import check_options, finite, render_views, send_job, train_share, train_with_progress
    from nasset_bakers.train.common import TorchCheckpoint, require_torch, training_key
    from nasset_bakers.train.parallel import data_parallel
    from nasset_bakers.train.rna import TrainSettings, check_asset, train
    from nasset_converters.blender import CONVERTER_VERSION, load_bpy
    from nasset_converters.blender import dataset as ds
    from nasset_converters.blender import scene as bsc
    from nasset_sdk.asset import AssetBuilder

    output = check_options(size, DATA_PRESETS, output, seed=seed, scene=scene, views=views, res=res, epochs=epochs, spp=spp)
    check_workers(workers, cluster)
    if light_angle is not None and not (0.0 <= light_angle < 45.0):
        raise UsageError(f"--light-angle must be in [0, 45) degrees, got {light_angle}")
    if lights_per_view is not None and (isinstance(lights_per_view, bool) or not isinstance(lights_per_view, int)
                                        or lights_per_view < 1):
        raise UsageError(f"lights_per_view (--suns-per-view) must be an integer >= 1, got {lights_per_view!r}")
    if example is not None and scene is not None:
        raise UsageError("give a .blend scene or --example, not both")
    dp = data_parallel(require_torch(), device)  # under torchrun: this process's rank (spec/bake.md#training-devices)
    if not dp.is_main:
        return train_share(dp, _load_split)
    work = Path(resume) if resume else output.with_name(output.name + ".bake")
    output_folder(work, "bake's work folder")  # before the scene: an example scene is written into it
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    times: dict[str, float] = {}
    t_all = time.perf_counter()

    # -- stage 1: scene ---------------------------------------------------------------------------
    t = time.perf_counter()
    require_torch()
    bpy = load_bpy()
    work.mkdir(parents=True, exist_ok=True)
    if example is not None:
        from nasset_converters.blender.examples import EXAMPLES, build_example

        if example not in EXAMPLES:
            raise UsageError(f"unknown Blender example {example!r} ({', '.join(EXAMPLES)})")
        build_example(example)
        asset_ids = list(asset_ids or EXAMPLES[example])
        source_key, scene_label = f"example:{example}", f"example {example}"
    else:
        if scene is None:
            raise UsageError("give a .blend scene or --example blender-surface|blender-hair|blender-hair-dense")
        bsc.open_blend(scene)
        source_key, scene_label = ds.file_sha256(scene), str(scene)
    objs = bsc.pick_objects(asset_ids or [], file=scene_label)
    variant, geo, notes = bsc.asset_geometry(objs, file=scene_label)
    check_geometry_scale(geo, asset_ids, scene_label)
    for n in notes:
        say(f"warning: {n}")
    if clear := (bsc.see_through(objs) if variant == "surface" else []):
        say(see_through_line("object(s)", clear, bsc.SEE_THROUGH_SHARE))
    if variant != "fiber" and not h_input:
        raise UsageError("h_input=False applies to fiber assets only")
    center, radius = bsc.bounding_sphere(geo)
    materials = bsc.material_names(objs)
    bsc.isolate(objs)
    data_fields, train_fields = variant_preset(size, variant)
    dset = replace(ds.DataSettings(), **data_fields, seed=seed,
                   light_angle_deg=float(DEFAULT_LIGHT_ANGLE if light_angle is None else light_angle))
    if views is not None:
        dset = replace(dset, views=int(views), val_views=max(1, int(views) // 12))
    if res is not None:
        dset = replace(dset, res=int(res))
    if spp is not None:
        dset = replace(dset, spp=int(spp))
    if lights_per_view is not None:  # suns per training view (spec/bake-blender.md#light-groups); None: the preset's
        dset = replace(dset, lights_per_view=lights_per_view)
    if clamp is not None:
        if not clamp >= 0:
            raise UsageError(f"clamp must be >= 0 (0: none), got {clamp}")
        dset = replace(dset, clamp_direct=float(clamp), clamp_indirect=float(clamp))
    if workers is None:
        views_from = _view_renderer(variant, geo, center, radius, dset, work, threads)
    else:  # each worker opens the scene itself
        views_from = ViewSource("nasset_bakers.blender.rna:view_renderer", {
            "scene": None if example is not None else str(scene), "example": example, "asset_ids": list(asset_ids),
            "dset": dset, "work": str(work), "threads": threads or 1})
    times["scene_s"] = time.perf_counter() - t

    # -- stage 2: dataset -------------------------------------------------------------------------
    t = time.perf_counter()
    store = ds.DatasetDir(work)
    meta = ds.settings_digest(source_key, asset_ids, variant, dset)
    store.prepare(meta)
    job = {"fiber": variant == "fiber", "h_input": h_input}
    try:
        per_worker = render_views(store, dset.views, dset.val_views, views_from, desc="cycles views", work=work,
                                  quiet=quiet, say=say, workers=workers, cluster=cluster)
        train_data = _load_split(store, "train", dset.views, job)
        val_data = _load_split(store, "val", dset.val_views, job)
        if len(val_data["x"]) == 0:
            raise error("CONVERT_TRAINING", "no validation samples: no held-out camera ray hit the asset", file=scene_label)
        # more training views where the targets are too noisy for the network to average out (spec/bake.md#data-noise);
        # a count given with --views is the user's
        noise, dset, train_data, more = data_noise_stage(store, dset, train_data, val_data,
                                                         DATA_NOISE[size] if views is None else None, views_from,
                                                         lambda n: _load_split(store, "train", n, job), work=work,
                                                         quiet=quiet, say=say, workers=workers, cluster=cluster)
        per_worker = more or per_worker
    finally:
        if workers is None:
            views_from.close()
    times["dataset_s"] = time.perf_counter() - t
    disagree = (train_data["disagree"] + val_data["disagree"]) / max(1, train_data["covered"] + val_data["covered"])

    # -- stage 3: train ---------------------------------------------------------------------------
    t = time.perf_counter()
    builder = AssetBuilder("rna", variant=variant)
    builder.set_geometry(geo)
    domain = builder.domain
    tset = TrainSettings(size=size, seed=seed, device=device, **train_fields)
    if epochs is not None:
        tset = replace(tset, epochs=int(epochs))
    data_key = {**meta, "settings": {**meta["settings"], "views": dset.views}}  # the views trained on (data noise)
    ckpt = TorchCheckpoint(work / ("train_state.pt" if h_input else "train_state_no_h.pt"),
                           {"data": data_key, "train": training_key(tset), "h_input": h_input,
                            "domain": [list(map(float, d)) for d in domain]})
    send_job(dp, work=work, views=dset.views, val_views=dset.val_views, domain=domain, settings=tset, checkpoint=ckpt, **job)
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
        "converter": f"converters.blender {CONVERTER_VERSION}",
        "converterVersion": CONVERTER_VERSION,
        "source": {"renderer": f"blender {bpy.app.version_string} cycles (CPU)", "scene": scene_label,
                   "source_key": source_key, "objects": list(asset_ids), "example": example,
                   "materials": materials, "notes": notes},
        "light": {"type": "distant-sphere" if dset.light_angle_deg > 0 else "directional",
                  "angular_radius_deg": dset.light_angle_deg, "irradiance": 1.0,
                  "clamp_direct": dset.clamp_direct, "clamp_indirect": dset.clamp_indirect,
                  "clamp_removed": None if (dset.clamp_direct or dset.clamp_indirect) else 0.0},
        "data": {**dset.__dict__, "train_samples": int(len(train_data["x"])), "val_samples": int(len(val_data["x"])),
                 "mask_disagreement": disagree, "h_input": h_input, "noise": noise},
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

    # -- stage 5: check ---------------------------------------------------------------------------
    t = time.perf_counter()
    check = check_asset(path, val_data, result)
    times["check_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t_all
    summary = {
        "asset": str(path), "asset_bytes": path.stat().st_size, "dataset_dir": str(work), "variant": variant,
        "objects": list(asset_ids), "train_samples": int(len(train_data["x"])), "val_samples": int(len(val_data["x"])),
        "views": dset.views, "val_views": dset.val_views, "res": dset.res, "spp": dset.spp,
        "val_res": dset.val_res or dset.res, "val_spp": dset.val_spp, "renderer": f"cycles {bpy.app.version_string}",
        "device": result.device, "h_input": h_input, "mask_disagreement": disagree,
        "val_psnr_db": result.val["psnr_db"],
        **{k: result.val.get(k) for k in ("kept_epoch", "epochs", "keep")}, "sdk_val_psnr_db": check["psnr_db"],
        "val_accuracy": result.val.get("accuracy"), "sdk_val_accuracy": check.get("accuracy"),
        "sdk_vs_torch_max_abs": check["max_abs_diff"], "onnx_vs_torch_max_abs": result.onnx_max_abs_diff,
        "energy_gain": result.energy_gain,
        "plane_blur": result.plane_blur,
        "data_noise": noise,
        "times_s": {k: round(v, 2) for k, v in times.items()},
        "workers": per_worker,
    }
    if not quiet:
        _print_summary(summary, summary_stream or sys.stdout)
    return summary


def _load_split(store, split: str, count: int, job: dict) -> dict:
    """A split of the Cycles dataset as the trainer takes it (fiber: h, zeroed when ``job['h_input']`` is off)."""
    from nasset_converters.blender import dataset as ds

    data = ds.load_split(store, split, count, job["fiber"])
    if job["fiber"] and not job["h_input"]:
        data["h"] = np.zeros_like(data["h"])
    return data


def _print_summary(s: dict, stream) -> None:
    t = s["times_s"]
    lines = [
        f"baked {s['asset']}  ({s['asset_bytes'] / 1024:.1f} KiB, rna {s['variant']}{'' if s['h_input'] else ', h fixed to 0'})",
        f"  {s['renderer']} ground truth, training on {s['device']}",
        dataset_line(s) + f" (mask disagreement {s['mask_disagreement']:.2%}; kept in {s['dataset_dir']})",
        *accuracy_lines(s.get("sdk_val_accuracy")),
        psnr_line(s, "held-out display PSNR (99.5th pct, clipped)"),
        *filter(None, [data_noise_line(s.get("data_noise")), plane_blur_line(s.get("plane_blur")),
                       energy_gain_line(s.get("energy_gain"))]),
        f"  parity: SDK vs torch max |diff| {s['sdk_vs_torch_max_abs']:.2e}; ONNX vs torch {s['onnx_vs_torch_max_abs']:.2e}",
        times_line(t),
        *worker_lines(s.get("workers")),
    ]
    print("\n".join(lines), file=stream)


register_baker("blender", "rna", bake)


def _view_renderer(variant, geo, center, radius, dset, work, threads: int = 0):
    """``render_one(split, i)`` of the dataset stage (Cycles on the isolated objects); ``.close()`` removes its temporary files."""
    from nasset_converters.blender import dataset as ds
    from nasset_converters.caster import Caster

    rig = ds.CyclesRig(dset, work, threads=threads)
    caster = Caster(variant, geo)

    def render_one(split, i):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return ds.render_view(rig, caster, center, radius, i, validation=split == "val")

    render_one.close = rig.close
    return render_one


def variant_preset(size: str, variant: str) -> tuple[dict, dict]:
    """The DataSettings and TrainSettings fields of preset ``size`` for a ``variant`` ("surface" or "fiber")
    asset: Blender's training length (presets.RNA_BLENDER_TRAIN); fibers render more views and train a wider decoder
    (presets.RNA_BLENDER_FIBER_DATA, _TRAIN)."""
    fiber = variant == "fiber"
    return ({**DATA_PRESETS[size], **(presets.RNA_BLENDER_FIBER_DATA.get(size, {}) if fiber else {})},
            {**presets.RNA_TRAIN[size], **presets.RNA_BLENDER_TRAIN.get(size, {}),
             **(presets.RNA_BLENDER_FIBER_TRAIN.get(size, {}) if fiber else {})})


def view_renderer(scene, example, asset_ids, dset, work, threads: int = 1):
    """``render_one(split, i)`` built from the .blend or the example (a cluster worker's copy of stage 1)."""
    from nasset_converters.blender import load_bpy
    from nasset_converters.blender import scene as bsc

    load_bpy()
    if example is not None:
        from nasset_converters.blender.examples import build_example

        build_example(example)
    else:
        bsc.open_blend(scene)
    objs = bsc.pick_objects(asset_ids, file=str(scene or example))
    variant, geo, _ = bsc.asset_geometry(objs, file=str(scene or example))
    center, radius = bsc.bounding_sphere(geo)
    bsc.isolate(objs)
    return _view_renderer(variant, geo, center, radius, dset, work, threads)
