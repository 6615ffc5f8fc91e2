"""``nasset bake --kind neupress``: a Mitsuba 3 translucent object -> a neupress asset (spec/bake-neupress.md).

Stages (each with a progress bar): scene (load, pick the asset's shapes, find its rough-dielectric
boundary) -> dataset (subsurface-only ground truth, ``neupress_dataset``) -> train (appearance network,
then the sampling network against it, then the SH PRT coefficients from it; ``train_neupress``) ->
export (ONNX + tensors through AssetBuilder: components ``core``, ``sampling``, ``prt``) -> check
(re-open the written asset and evaluate it with the SDK on the held-out views).

The dataset folder (``--resume DIR``, default ``OUTPUT.bake/``) keeps the rendered views and the
appearance training state, so an interrupted bake continues where it stopped; the asset file is
written atomically.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

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
    psnr_line,
    times_line,
    warnings_said,
    worker_lines,
    write_near_field,
)
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder

DATA_PRESETS = presets.NEUPRESS_MITSUBA_DATA  # the table lives in nasset_bakers/presets.py
DATA_NOISE = presets.NEUPRESS_MITSUBA_DATA_NOISE
EXAMPLES = ("default", "high-albedo")


def _fit_appearance(train_data: dict, val_data: dict, domain, job: dict, checkpoint) -> None:
    """A torchrun process other than rank 0 (nasset_bakers.stages.train_share): its share of the appearance network."""
    from nasset_bakers.train.neupress import NeupressTrainSettings, train_appearance

    train_appearance(train_data, val_data, domain, NeupressTrainSettings(**job["train"]), checkpoint=checkpoint)


def bake(
    scene: str | Path | None,
    asset_ids: list[str] | None,
    output: str | Path,
    *,
    size: str = "small",
    example: str | bool | None = None,
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
    workers: int | None = None,
    cluster: str | None = None,
    near_field_fetch: str | float = "auto",
) -> dict:
    """Run the whole neupress bake; returns the summary dict (also stored in the asset's provenance).
    ``near_field_fetch``: 'auto' (measured after training, spec/bake.md#near-field) or f in [0, 1] to store.

    ``clamp``: per-path-sample clamp of the training targets (default 0: none; removed energy stored).
    ``workers``/``cluster``: render the views on Ray workers (nasset_bakers.cluster).

    ``light_angle``: only 0 (delta lights) is supported -- the boundary must be a rough dielectric."""
    from nasset_bakers.cluster import ViewSource, check_workers
    from nasset_bakers.stages import progress_bar, render_views, send_job, train_share, train_with_progress
    from nasset_bakers.train.common import require_torch, training_key
    from nasset_bakers.train.neupress import (
        TRAIN_PRESETS,
        NeupressTrainSettings,
        TorchCheckpoint,
        check_asset,
        export_mlp,
        export_skip_mlp,
        prt_coefficients,
        train_appearance,
        train_sampling,
        vertex_normals,
    )
    from nasset_bakers.train.parallel import data_parallel
    from nasset_converters.mitsuba import CONVERTER_VERSION, load_mitsuba
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import neupress_dataset as nd
    from nasset_converters.mitsuba import scene as msc
    from nasset_sdk.asset import AssetBuilder

    output = check_options(size, DATA_PRESETS, output, seed=seed, scene=scene, views=views, res=res, epochs=epochs, spp=spp)
    check_workers(workers, cluster)
    if light_angle not in (None, 0, 0.0):
        raise UsageError("--light-angle is not used by neupress bakes (delta lights through a rough boundary); leave it unset")
    if example is True:
        example = "default"
    if example not in (None, False) and example not in EXAMPLES:
        raise UsageError(f"unknown neupress example {example!r} ({', '.join(EXAMPLES)})")
    dp = data_parallel(require_torch(), device)  # under torchrun: this process's rank (spec/bake.md#training-devices)
    if not dp.is_main:  # the appearance network trains data-parallel; the rest is rank 0's
        return train_share(dp, lambda store, split, count, job: nd.load_split(store, split, count), _fit_appearance)
    work = Path(resume) if resume else output.with_name(output.name + ".bake")
    output_folder(work, "bake's work folder")  # before the scene: an example scene is written into it
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    times: dict[str, float] = {}
    t_all = time.perf_counter()

    # -- stage 1: scene ---------------------------------------------------------------------------
    t = time.perf_counter()
    torch = require_torch()
    with warnings_said(say):
        mi = load_mitsuba(variant)
    mi.set_log_level(mi.LogLevel.Error)
    if example == "high-albedo":
        from nasset_converters.mitsuba.high_albedo_example import EXAMPLE_ASSET_IDS, write_example_scene
    elif example:
        from nasset_converters.mitsuba.neupress_example import EXAMPLE_ASSET_IDS, write_example_scene
    if example:
        scene = write_example_scene(work / "example_scene", size)
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    if scene is None:
        raise UsageError("give a scene file or --example")
    scene = Path(scene)
    msc_scene = msc.load_scene(mi, scene)
    shapes = msc.pick_shapes(msc_scene, asset_ids or [], file=str(scene))
    bshapes, eta, alpha = nd.boundary_of(mi, shapes, file=str(scene))
    with warnings_said(say):
        geo = msc.mesh_geometry(mi, bshapes)
    check_geometry_scale(geo, [b.id() for b in bshapes], scene)
    center, radius = msc.bounding_sphere(geo)
    dset = replace(nd.NeupressDataSettings(), **DATA_PRESETS[size], seed=seed)
    if views is not None:
        dset = replace(dset, views=int(views), val_views=max(1, int(views) // 16))
    if res is not None:
        dset = replace(dset, res=int(res))
    if spp is not None:
        dset = replace(dset, spp=int(spp))
    if clamp is not None:
        if not clamp >= 0:
            raise UsageError(f"clamp must be >= 0 (0: none), got {clamp}")
        dset = replace(dset, clamp=float(clamp))
    dset = replace(dset, max_depth=msc.training_depth(msc_scene.integrator(), dset.max_depth))
    for warning in msc.bake_media_warnings(msc_scene, asset_ids, dset.max_depth):
        say(f"warning: {warning}")
    origin = msc.render_origin(mi, shapes)  # where _view_renderer moves them from (spec/bake.md#far-from-the-origin)
    if far := msc.far_for_bake(mi, shapes):  # far shapes render moved to the origin, unless they cannot move
        say(f"warning: {far}")
    iso = None  # the shapes isolated in this process (views, near-field calibration)
    if workers is None:
        iso = _isolated(mi, shapes, center, radius, dset)
        views_from = _views_of(mi, iso, bshapes, center, radius, dset)
    else:  # each worker loads the scene itself
        views_from = ViewSource("nasset_bakers.mitsuba.neupress:view_renderer",
                                {"scene": scene, "asset_ids": list(asset_ids or []), "dset": dset, "variant": mi.variant(),
                                 "threads": 1})
    times["scene_s"] = time.perf_counter() - t

    # -- stage 2: dataset -------------------------------------------------------------------------
    t = time.perf_counter()
    store = ds.DatasetDir(work)
    meta = {**ds.settings_digest(scene, asset_ids, dset, mi.variant()), "kind": "neupress"}
    if origin.any():  # views rendered moved (spec/bake.md#far-from-the-origin) are not those of a folder made before
        meta["render_origin"] = origin.tolist()
    store.prepare(meta)
    per_worker = render_views(store, dset.views, dset.val_views, views_from, desc="render views", work=work, quiet=quiet,
                              say=say, workers=workers, cluster=cluster)
    train_data = nd.load_split(store, "train", dset.views)
    val_data = nd.load_split(store, "val", dset.val_views)
    if len(val_data["x"]) == 0 or len(train_data["x"]) == 0:
        raise error("CONVERT_TRAINING", "no samples: no camera ray hit the asset", file=str(scene))
    # more training views where the targets are too noisy for the network to average out (spec/bake.md#data-noise);
    # a count given with --views is the user's
    noise, dset, train_data, more = data_noise_stage(store, dset, train_data, val_data, DATA_NOISE[size] if views is None else None,
                                                     views_from, lambda n: nd.load_split(store, "train", n), work=work, quiet=quiet, say=say,
                                                     workers=workers, cluster=cluster)
    per_worker = more or per_worker
    times["dataset_s"] = time.perf_counter() - t

    # -- stage 3: train ---------------------------------------------------------------------------
    t = time.perf_counter()
    builder = AssetBuilder("neupress", variant="surface")
    builder.set_geometry(geo)
    domain = builder.domain
    tset = NeupressTrainSettings(size=size, seed=seed, device=device, **TRAIN_PRESETS[size])
    if epochs is not None:
        tset = replace(tset, epochs=int(epochs))
    data_key = {**meta, "settings": {**meta["settings"], "views": dset.views}}  # the views trained on (data noise)
    ckpt = TorchCheckpoint(work / "train_state.pt", {"data": data_key, "train": training_key(tset),
                                                      "domain": [list(map(float, d)) for d in domain]})
    send_job(dp, work=work, views=dset.views, val_views=dset.val_views, domain=domain, settings=tset, checkpoint=ckpt)
    app = train_with_progress(
        lambda progress: train_appearance(train_data, val_data, domain, tset, progress=progress, checkpoint=ckpt),
        total=tset.epochs, desc="train appearance", work=work, quiet=quiet, say=say)
    times["train_appearance_s"] = time.perf_counter() - t

    t = time.perf_counter()
    bar = progress_bar(total=tset.sampling_epochs, desc="train sampling (KL)", unit="epoch", disable=quiet)

    def sprog(epoch, kl):
        bar.n = epoch + 1
        bar.set_postfix(kl=f"{kl:.3f}")
        bar.refresh()

    samp = train_sampling(app, train_data, domain, tset, progress=sprog)
    bar.close()
    times["train_sampling_s"] = time.perf_counter() - t

    t = time.perf_counter()
    normals = vertex_normals(geo)
    bar = progress_bar(total=len(geo.points), desc="SH PRT", unit="vertex", disable=quiet)

    def pprog(done):
        bar.n = done
        bar.refresh()

    sh = prt_coefficients(app, geo.points, normals, domain, tset, progress=pprog)
    bar.close()
    if not np.isfinite(sh).all() or np.abs(sh).max() > 60000:
        raise error("CONVERT_TRAINING", "PRT coefficients are not finite or overflow float16")
    times["prt_s"] = time.perf_counter() - t

    # -- stage 4: export --------------------------------------------------------------------------
    t = time.perf_counter()
    app_onnx = export_skip_mlp(app.model)
    sigma_onnx = export_mlp(samp.model)
    core = builder.component("core", required=True, purpose="evaluation", quality=None)
    core.add_tensor("fourier", app.G, dtype="float32", layout="frequency,input")
    core.add_tensor("boundary", np.array([eta, alpha]), dtype="float32", layout="parameter")
    core.add_network("appearance", app_onnx)
    sc = builder.component("sampling", required=False, purpose="importance-sampling", quality=None)
    sc.add_tensor("fourier", samp.G, dtype="float32", layout="frequency,input")
    sc.add_network("sigma", sigma_onnx)
    pc = builder.component("prt", required=False, purpose="prt", quality=None)
    pc.add_tensor("sh", sh, dtype="float16", layout="vertex,theta_o,phi_o,sh,rgb")
    prov = {
        "generator": "nasset bake",
        "converter": f"converters.mitsuba {CONVERTER_VERSION}",
        "converterVersion": CONVERTER_VERSION,
        "source": {"renderer": f"mitsuba {mi.__version__}", "variant": mi.variant(), "scene": str(scene),
                   "scene_sha256": meta["scene_sha256"], "shapes": list(asset_ids or []), "example": example or None,
                   "boundary_shapes": [s.id() for s in bshapes], "bsdfs": msc.bsdf_names(shapes)},
        "ground_truth": {"quantity": "subsurface only: first boundary vertex samples the transmission lobe "
                                     "(spec/bake-neupress.md#data)",
                         "light": {"type": "directional", "irradiance": 1.0, "directions": "uniform full sphere, per pixel"}},
        "data": {**dset.__dict__, "train_samples": int(len(train_data["x"])), "val_samples": int(len(val_data["x"])),
                 "clamp_removed": clamp_removed(train_data), "reference": "held-out views unclamped, two independent halves",
                 "noise": noise},
        "training": {**tset.__dict__, "device": app.device, "framework": f"torch {torch.__version__}",
                     "final_loss": app.history[-1]["loss"] if app.history else None,
                     "sampling_kl": samp.kl, "sampling_kl_uniform": samp.kl_uniform, "sampling_kl_best_sigma": samp.kl_best,
                     "energy_gain": app.energy_gain},
        "validation": {**app.val, "psnr_definition": "spec/bake.md#psnr"},
        "size": size,
        "timings_s": {k: round(v, 3) for k, v in times.items()},
    }
    builder.provenance = finite(prov)
    path = builder.write(output)
    times["export_s"] = time.perf_counter() - t

    # -- stage 5: check ---------------------------------------------------------------------------
    t = time.perf_counter()
    check = check_asset(path, val_data, app, samp, sh)
    times["check_s"] = time.perf_counter() - t

    # -- stage 6: where renderers fetch the asset's light (spec/bake.md#near-field) ------------------
    t = time.perf_counter()
    near = near_field_stage(near_field_fetch, check, size, seed, quiet,
                            lambda settings, target, progress: _calibrate(mi, iso or _isolated(mi, shapes, center, radius, dset),
                                                                          geo, dset, path, center, radius, settings, target,
                                                                          progress))
    path = write_near_field(builder, prov, near, output) or path
    times["near_field_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t_all
    summary = {
        "asset": str(path),
        "kind": "neupress",
        "asset_bytes": path.stat().st_size,
        "component_bytes": check["component_bytes"],
        "dataset_dir": str(work),
        "train_samples": int(len(train_data["x"])),
        "val_samples": int(len(val_data["x"])),
        "views": dset.views, "val_views": dset.val_views, "res": dset.res, "spp": dset.spp,
        "val_res": dset.val_res, "val_spp": dset.val_spp,
        "boundary": {"eta": eta, "alpha": alpha},
        "variant": mi.variant(), "device": app.device,
        "val_psnr_db": app.val["psnr_db"],
        **{k: app.val.get(k) for k in ("kept_epoch", "epochs", "keep")},
        "val_mse": app.val["mse"],
        "sdk_val_psnr_db": check["psnr_db"],
        "val_accuracy": app.val.get("accuracy"), "sdk_val_accuracy": check.get("accuracy"),
        "clamp": dset.clamp, "clamp_removed": prov["data"]["clamp_removed"],
        "data_noise": noise,
        "near_field": near,
        "energy_gain": app.energy_gain,
        "sdk_vs_torch_max_abs": check["max_abs_diff"],
        "sigma_sdk_vs_torch_max_abs_log": check["sigma_max_abs_log_diff"],
        "prt_roundtrip_max_abs": check["prt_max_abs"],
        "sampling_kl_nats": samp.kl, "sampling_kl_uniform_nats": samp.kl_uniform, "sampling_kl_best_sigma_nats": samp.kl_best,
        "times_s": {k: round(v, 2) for k, v in times.items()},
        "workers": per_worker,
    }
    if not quiet:
        _print_summary(summary, summary_stream or sys.stdout)
    return finite(summary)


def _print_summary(s: dict, stream) -> None:
    t = s["times_s"]
    cb = s["component_bytes"]
    lines = [
        f"baked {s['asset']}  ({s['asset_bytes'] / 1024:.1f} KiB: " + ", ".join(f"{k} {v / 1024:.1f} KiB" for k, v in cb.items()) + ")",
        f"  mitsuba {s['variant']}, training on {s['device']}; boundary eta {s['boundary']['eta']:.3f}, "
        f"alpha {s['boundary']['alpha']:.3f}",
        dataset_line(s) + f"  (kept in {s['dataset_dir']})",
        *accuracy_lines(s.get("sdk_val_accuracy"), "held-out subsurface S (unclamped reference)"),
        psnr_line(s, "held-out display PSNR (subsurface S; 99.5th pct, clipped)"),
        *clamp_lines(s),
        *filter(None, [data_noise_line(s.get("data_noise")), energy_gain_line(s.get("energy_gain"))]),
        near_field_line(s["near_field"]),
        f"  sampling lobe KL: {s['sampling_kl_nats']:.3f} nats (uniform {s['sampling_kl_uniform_nats']:.3f}, "
        f"best single sigma per record {s['sampling_kl_best_sigma_nats']:.3f})",
        f"  parity: SDK vs torch max |diff| {s['sdk_vs_torch_max_abs']:.2e}; log sigma {s['sigma_sdk_vs_torch_max_abs_log']:.2e}; "
        f"PRT round trip {s['prt_roundtrip_max_abs']:.1e}",
        times_line(t),
        *worker_lines(s.get("workers")),
    ]
    print("\n".join(lines), file=stream)


register_baker("mitsuba", "neupress", bake)


def _isolated(mi, shapes, center, radius, dset):
    """The shapes alone (moved to the origin: Mitsuba's ray offset far from it, spec/bake.md#far-from-the-origin)."""
    from nasset_converters.mitsuba import scene as msc

    origin = msc.move_to_origin(mi, shapes)
    return msc.IsolatedAsset(mi, shapes, center, radius, angle_deg=0.0, max_depth=dset.max_depth, origin=origin)


def _views_of(mi, iso, bshapes, center, radius, dset):
    """``render_one(split, i)`` of the dataset stage: subsurface transport behind the boundary."""
    from nasset_converters.mitsuba import neupress_dataset as nd

    renderer = nd.SubsurfaceRenderer(mi, iso, dset, bshapes[0].interior_medium())
    return lambda split, i: nd.render_view(renderer, center, radius, i, validation=split == "val")


def _view_renderer(mi, shapes, bshapes, center, radius, dset):
    """``render_one(split, i)`` of the dataset stage on shapes isolated for it."""
    return _views_of(mi, _isolated(mi, shapes, center, radius, dset), bshapes, center, radius, dset)


def _calibrate(mi, iso, geo, dset, path, center, radius, settings, target, progress) -> dict:
    """Stage 6 (:func:`nasset_bakers.stages.near_field_stage`): the written asset's whole integrand, S^ + f_r |n.wi|
    (the shadowed branch S^ alone: V_self = 0), against Mitsuba's radiance of the shapes (boundary reflection and
    subsurface transport) under the calibration's lights."""
    from nasset_bakers.train.common import reopen_asset
    from nasset_converters.caster import Caster
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import near_field as nf

    asset, ev = reopen_asset(path)
    renderer = ds.Renderer(mi, iso, ds.DataSettings(max_depth=dset.max_depth), shadows=Caster("surface", geo))

    def transport(x, n, wo, wi):
        s = ev.evaluate(x, n, wo, wi)
        return s + ev.surface_reflection(n, wo, wi), s

    lo, hi = asset.domain
    return nf.calibrate(renderer, center, radius, settings, transport, 0.5 * (lo + hi), target, progress=progress)


def view_renderer(scene, asset_ids, dset, variant=None, threads: int = 0):
    """``render_one(split, i)`` built from the scene file (a cluster worker's copy of stage 1);
    ``threads`` > 0 limits Dr.Jit's thread pool (a worker owns one CPU)."""
    import warnings

    from nasset_converters.mitsuba import neupress_dataset as nd
    from nasset_converters.mitsuba import scene as msc

    mi, shapes = msc.open_shapes(scene, asset_ids, variant=variant, threads=threads)
    bshapes, _, _ = nd.boundary_of(mi, shapes, file=str(scene))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the driver already reported them
        center, radius = msc.bounding_sphere(msc.mesh_geometry(mi, bshapes))
    return _view_renderer(mi, shapes, bshapes, center, radius, dset)
