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

import json
import math
import sys
import time
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np

from .errors import UsageError, error

#: data presets (converters.mitsuba.dataset.DataSettings fields). lights_per_view 0: every training
#: pixel has its own random light; held-out views: one light per view, lower res, many more spp
#: (their noise bounds the measurable PSNR; spec/bake.md#psnr). Measured in spec/bake.md#ablations.
DATA_PRESETS = {
    "tiny": dict(views=16, val_views=2, res=24, spp=8, val_res=24, val_spp=64, lights_per_view=0),
    "small": dict(views=96, val_views=8, res=96, spp=64, val_res=64, val_spp=1024, lights_per_view=0),
    "hq": dict(views=200, val_views=16, res=160, spp=128, val_res=96, val_spp=2048, lights_per_view=0),
}


#: default angular radius (deg) of the distant light for assets behind smooth dielectrics: measured
#: (converters/mitsuba/light_study.py, spec/bake.md#light) 5 deg costs +5 % bias and 2.2x the
#: per-pixel noise of a rough boundary under a delta light; 2 deg: +2 % but 7.6x the noise.
SMOOTH_DIELECTRIC_LIGHT_ANGLE = 5.0


def _finite(v):
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return _finite(v.item())
    return v


def check_options(size: str, presets, output, **counts) -> Path:
    """Argument checks every baker shares: a known preset, counts >= 1 where given, an asset file name.

    Returns ``output`` as a Path; raises UsageError."""
    if size not in presets:
        raise UsageError(f"--size must be one of {sorted(presets)}, got {size!r}")
    for name, val in counts.items():
        if val is not None and int(val) < 1:
            raise UsageError(f"--{name} must be >= 1, got {val}")
    output = Path(output)
    if output.suffix not in (".usdc", ".usda", ".usd"):
        raise UsageError(f"output must end in .usdc/.usda/.usd, got {output.name!r}")
    return output


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
) -> dict:
    """Run the whole bake; returns the summary dict (also stored in the asset's provenance).

    ``clamp``: per-path-sample clamp of the training targets (default 0: none; the energy it removes
    is measured and stored, spec/bake.md#clamp); ``loss``: training loss (default: TrainSettings')."""
    from converters.bake_stages import render_views, train_with_progress
    from converters.mitsuba import CONVERTER_VERSION, load_mitsuba
    from converters.mitsuba import dataset as ds
    from converters.mitsuba import scene as msc
    from converters.train_rna import TRAIN_PRESETS, TorchCheckpoint, TrainSettings, _torch, train

    from .asset import AssetBuilder

    output = check_options(size, DATA_PRESETS, output, views=views, res=res, epochs=epochs, spp=spp)
    if light_angle is not None and not (0.0 <= light_angle < 45.0):
        raise UsageError(f"--light-angle must be in [0, 45) degrees, got {light_angle}")
    work = Path(resume) if resume else output.with_name(output.name + ".bake")
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    times: dict[str, float] = {}
    t_all = time.perf_counter()

    # -- stage 1: scene ---------------------------------------------------------------------------
    t = time.perf_counter()
    _torch()  # fail early (typed) when torch is missing, before minutes of rendering
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        mi = load_mitsuba(variant)
    for w in caught:
        say(f"warning: {w.message}")
    mi.set_log_level(mi.LogLevel.Error)
    if example == "high-albedo":
        from converters.mitsuba.high_albedo_example import EXAMPLE_ASSET_IDS, write_example_scene

        scene = write_example_scene(work / "example_scene")
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    elif example:
        from converters.mitsuba.example_scene import EXAMPLE_ASSET_IDS, write_example_scene

        scene = write_example_scene(work / "example_scene")
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    if scene is None:
        raise UsageError("give a scene file or --example")
    scene = Path(scene)
    msc_scene = msc.load_scene(mi, scene)
    shapes = msc.pick_shapes(msc_scene, asset_ids or [], file=str(scene))
    geo = msc.mesh_geometry(mi, shapes)
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
    from converters.mitsuba.high_albedo_example import scene_max_depth

    md = scene_max_depth(msc_scene)  # ground truth as deep as the scene's own integrator (spec/accuracy.md)
    if md is not None and (md < 0 or md > dset.max_depth):
        dset = replace(dset, max_depth=md if md > 0 else 1024)
    iso = msc.IsolatedAsset(mi, shapes, center, radius, angle_deg=dset.light_angle_deg, max_depth=dset.max_depth)
    renderer = ds.Renderer(mi, iso, dset)
    times["scene_s"] = time.perf_counter() - t

    # -- stage 2: dataset -------------------------------------------------------------------------
    t = time.perf_counter()
    store = ds.DatasetDir(work)
    meta = ds.settings_digest(scene, asset_ids, dset, mi.variant())
    store.prepare(meta)
    render_views(store, dset.views, dset.val_views,
                 lambda split, i: ds.render_view(renderer, center, radius, i, validation=split == "val"),
                 desc="render views", work=work, quiet=quiet, say=say)
    train_data = store.load_split("train", dset.views)
    val_data = store.load_split("val", dset.val_views)
    times["dataset_s"] = time.perf_counter() - t
    if len(val_data["x"]) == 0:
        raise error("CONVERT_TRAINING", "no validation samples: no validation camera ray hit the asset")

    # -- stage 3: train ---------------------------------------------------------------------------
    t = time.perf_counter()
    builder = AssetBuilder("rna", variant="surface")
    builder.set_geometry(geo)
    domain = builder.domain
    tset = TrainSettings(size=size, seed=seed, device=device, **TRAIN_PRESETS[size])
    if epochs is not None:
        tset = replace(tset, epochs=int(epochs))
    if loss is not None:
        tset = replace(tset, loss=str(loss))
    ckpt = TorchCheckpoint(work / "train_state.pt", {"data": meta, "train": tset.__dict__,
                                                      "domain": [list(map(float, d)) for d in domain]})
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
                 "clamp_removed": clamp_removed(train_data), "reference": "held-out views unclamped, two independent halves"},
        "training": {**tset.__dict__, "device": result.device, "framework": f"torch {_torch().__version__}",
                     "final_loss": result.history[-1]["loss"] if result.history else None},
        "validation": {**result.val, "psnr_definition": "spec/bake.md#psnr"},
        "onnx": {"opset": 17, "max_abs_diff_vs_torch": result.onnx_max_abs_diff},
        "size": size,
        "timings_s": {k: round(v, 3) for k, v in times.items()},
    }
    builder.provenance = _finite(prov)
    path = builder.write(output)
    times["export_s"] = time.perf_counter() - t

    # -- stage 5: check the written asset with the SDK --------------------------------------------
    t = time.perf_counter()
    check = check_asset(path, val_data, result)
    times["check_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t_all
    summary = {
        "asset": str(path),
        "asset_bytes": path.stat().st_size,
        "dataset_dir": str(work),
        "train_samples": int(len(train_data["x"])),
        "val_samples": int(len(val_data["x"])),
        "views": dset.views, "val_views": dset.val_views, "res": dset.res, "spp": dset.spp,
        "val_res": dset.val_res or dset.res, "val_spp": dset.val_spp,
        "variant": mi.variant(), "device": result.device,
        "val_psnr_db": result.val["psnr_db"],
        "val_accuracy": result.val.get("accuracy"),
        "sdk_val_accuracy": check.get("accuracy"),
        "clamp": dset.clamp, "clamp_removed": prov["data"]["clamp_removed"],
        "sdk_val_psnr_db": check["psnr_db"],
        "sdk_vs_torch_max_abs": check["max_abs_diff"],
        "onnx_vs_torch_max_abs": result.onnx_max_abs_diff,
        "times_s": {k: round(v, 2) for k, v in times.items()},
    }
    if not quiet:
        _print_summary(summary, summary_stream or sys.stdout)
    return summary


def check_asset(path, val_data: dict, result) -> dict:
    """Re-open the asset and evaluate it with the SDK on the held-out samples (rna surface, or fiber with ``h``)."""
    from converters.train_rna import _tensors, _torch, display_psnr, predict, select_branch

    from .asset import Asset

    asset = Asset.open(path)
    asset.load("all")
    ev = asset.evaluator()
    un, sh = ev.evaluate(val_data["x"], val_data["n"], val_data["wo"], val_data["wi"], val_data.get("h"))
    y_sdk = np.concatenate([un, sh], axis=1)
    torch = _torch()
    dev = next(result.model.parameters()).device
    lo, hi = asset.domain
    y_torch = np.maximum(predict(result.model, _tensors(torch, val_data, lo, hi, dev)), 0.0)
    diff = float(np.max(np.abs(y_sdk - y_torch))) if len(y_sdk) else 0.0
    from converters.train_rna import held_out_accuracy

    psnr = display_psnr(select_branch(y_sdk, val_data["vis"]), val_data["rgb"])[0]
    return {"psnr_db": psnr, "max_abs_diff": diff, "accuracy": held_out_accuracy(select_branch(y_sdk, val_data["vis"]), val_data)}


def clamp_removed(train_data: dict) -> dict | None:
    """Share of the training targets' energy per channel that the clamp removed (None: not recorded)."""
    if "energy" not in train_data:
        return None
    e = np.asarray(train_data["energy"], np.float64)
    r = np.asarray(train_data["clamp_removed"], np.float64)
    return {"fraction": [float(x) for x in r / np.where(e > 0, e, np.nan)], "energy": [float(x) for x in e]}


def accuracy_lines(acc: dict | None, label: str = "held-out (unclamped reference)") -> list[str]:
    """Summary lines of a spec/accuracy.md#metrics dict: energy per channel, PSNR and its ceiling."""
    if not acc:
        return []
    e = "/".join(f"{100 * r:.1f}" for r in acc["energy_ratio"])
    se = "/".join(f"{100 * r:.1f}" for r in acc["energy_se"])
    return [f"  {label}: energy {e} % (RGB, +-{se}), PSNR {acc['psnr_db']:.2f} dB, "
            f"ceiling {acc['ceiling_db']:.2f} dB -> claimed {acc['claimed_psnr']}"]


def _print_summary(s: dict, stream) -> None:
    t = s["times_s"]
    lines = [
        f"baked {s['asset']}  ({s['asset_bytes'] / 1024:.1f} KiB)",
        f"  mitsuba {s['variant']}, training on {s['device']}",
        f"  dataset: {s['views']} views at {s['res']}^2, {s['spp']} spp + {s['val_views']} held-out at "
        f"{s['val_res']}^2, {s['val_spp']} spp -> "
        f"{s['train_samples']} train / {s['val_samples']} held-out samples  (kept in {s['dataset_dir']})",
        *accuracy_lines(s.get("sdk_val_accuracy")),
        f"  held-out display PSNR (99.5th pct, clipped): {s['val_psnr_db']:.2f} dB (torch), {s['sdk_val_psnr_db']:.2f} dB (SDK evaluator)",
        *([f"  training clamp {s['clamp']} /sr removed " + "/".join(f"{100 * f:.1f}" for f in s['clamp_removed']['fraction'])
           + " % of the targets' energy (RGB)"] if s.get("clamp") and s.get("clamp_removed") else []),
        f"  parity: SDK vs torch max |diff| {s['sdk_vs_torch_max_abs']:.2e}; ONNX vs torch {s['onnx_vs_torch_max_abs']:.2e}",
        "  time: " + ", ".join(f"{k[:-2]} {v:.1f}s" for k, v in t.items()),
    ]
    print("\n".join(lines), file=stream)


def baker_for(kind: str, scene, example: str | None):
    """The bake function for a kind and a source: Mitsuba ``.xml`` (rna, neupress, 8dna) or Blender ``.blend`` (rna).

    Every baker takes ``(scene, asset_ids, output, **options)`` and returns the summary dict."""
    blender = (scene is not None and str(scene).lower().endswith(".blend")) or (example or "").startswith("blender")
    if blender:
        if kind != "rna":
            raise UsageError(f"Blender scenes bake to kind rna only, not {kind!r}")
        from converters.blender.bake import bake as blender_bake

        return blender_bake
    if kind == "neupress":
        from converters.mitsuba.neupress_bake import bake as neupress_bake

        return neupress_bake
    if kind == "8dna":
        from converters.mitsuba.eightdna_bake import bake as eightdna_bake

        return eightdna_bake
    if kind != "rna":
        raise UsageError(f"unknown kind {kind!r}")
    if example not in (None, "default", "high-albedo"):
        raise UsageError(f"unknown rna example {example!r} (default, high-albedo, blender-surface, blender-hair)")
    return lambda scene, ids, out, example=None, **kw: bake(scene, ids, out, example=example or False, **kw)


def run(args) -> int:
    """CLI entry: see ``nasset bake --help``."""
    fn = baker_for(args.kind, args.scene, args.example)
    if getattr(args, "clamp", None) is not None and (args.kind == "8dna" or str(args.scene or "").lower().endswith(".blend")
                                                     or str(args.example or "").startswith("blender")):
        raise UsageError("--clamp applies to Mitsuba rna and neupress bakes only")
    summary = fn(
        args.scene, args.asset, args.output, size=args.size, example=args.example, resume=args.resume,
        views=args.views, res=args.res, epochs=args.epochs, spp=args.spp, light_angle=args.light_angle,
        seed=args.seed, device=args.device, quiet=args.quiet,
        **({"clamp": args.clamp} if getattr(args, "clamp", None) is not None else {}),
        summary_stream=sys.stderr if getattr(args, "json", False) else sys.stdout,
    )
    if getattr(args, "json", False):
        print(json.dumps(_finite(summary), indent=2))
    return 0
