"""``nasset bake --kind 8dna``: a Mitsuba scene's translucent object -> an 8dna asset (spec/bake-8dna.md).

Stages: load scene (pick the asset's shapes, read the boundary BSDF for the analytic direct lobe)
-> held-out tuples (path-traced once, kept in the work folder) -> train (online buffer of
path-traced tuples regenerated as it is consumed, PyTorch) -> export (ONNX + tensors through
AssetBuilder, written atomically) -> renormalise (albedo / the flow's lit share, 8D only) -> check (re-open the asset: SDK vs
torch pdf / albedo parity on the held-out tuples, held-out NLL, ``nasset validate``). Each stage shows a progress bar; a summary
closes the run.

The work folder (``--resume DIR``, default ``OUTPUT.bake/``) keeps the held-out tuples and the
training checkpoint (every 250 steps), so an interrupted bake continues at the last checkpoint.
``--example`` bakes the built-in translucent example (``--example heterogeneous``: its grid-medium
variant; converters/mitsuba/eightdna_example.py). Options of the rna bake that have no meaning here
(``--views``, ``--res``, ``--light-angle``) raise a UsageError; ``--epochs N`` sets the number of
optimisation steps and ``--spp N`` the online buffer size in thousands of tuples.
"""

from __future__ import annotations

import contextlib
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from nasset_bakers import presets
from nasset_bakers.registry import register_baker
from nasset_bakers.stages import check_geometry_scale, check_options, finite, progress_bar, times_line, warnings_said, worker_lines
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder

SAMPLER_PRESETS = presets.EIGHTDNA_MITSUBA_SAMPLER  # the table lives in nasset_bakers/presets.py
RENORM_PRESETS = presets.EIGHTDNA_RENORM
LAYOUTS = {"triplane": "plane,v,u,channel", "woCube": "face,t,s,channel", "s1Grid": "texel,channel",
           "s3Grid": "texel,channel", "s12Cube": "face,t,s,channel", "splineMinimums": "parameter"}
BAKE_VERSION = "8dna-0.2.0"  # 0.2: tuples drawn in deterministic shards (spec/bake.md#cluster)
#: held-out tuples on which the lit energy mean(alpha V) / mean(beta) is measured (spec/bake-8dna.md#renormalise)
HELD_LIT = 2048


def boundary_of(mi, shapes) -> tuple[float, float]:
    """(eta, GGX alpha) of the asset's boundary BSDF (all shapes must share it); roughdielectric GGX or dielectric."""
    from nasset_converters.mitsuba import scene as msc

    found = set()
    for s in shapes:
        b = s.bsdf()
        name = str(b).split("[")[0].strip()
        if name == "RoughDielectric":
            eta, alpha = msc.ggx_dielectric(mi, s, kind="8dna")
        elif name == "SmoothDielectric":
            eta, alpha = msc.dielectric_eta(mi.traverse(b)), 1e-3
        else:
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {s.id()!r}: boundary BSDF {name} is not a (rough) dielectric; the 8dna "
                        "direct lobe stores a GGX rough dielectric (spec/kinds/8dna.md)")
        found.add((round(eta, 6), round(alpha, 6)))
    if len(found) != 1:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"asset shapes have different boundaries {sorted(found)}; 8dna stores one")
    if all(s.interior_medium() is None for s in shapes):  # a clear, empty dielectric: nothing scatters inside
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"asset shapes {[s.id() for s in shapes]} have no interior medium: an 8dna "
                    "asset stores the light a medium scatters inside a dielectric boundary (spec/bake-8dna.md); give "
                    "the shape an <medium name=\"interior\">, or bake an empty glass object as rna")
    return next(iter(found))


def _save_npz(path: Path, data: dict) -> None:
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **data)
    os.replace(tmp, path)


def heldout_tuples(source, n: int, path: Path, progress=None) -> dict:
    """``n`` held-out tuples (their own shard stream of ``source``, a ShardedTuples), cached in ``path`` (.npz) for resumes."""
    from nasset_converters.mitsuba.eightdna_sampler import FIELDS, HELDOUT_STREAM

    if path.is_file():
        with np.load(path, allow_pickle=False) as z:
            if set(FIELDS) <= set(z.files) and len(z["beta"]) == n:
                return {k: z[k] for k in FIELDS}
    data = source.fill(n, HELDOUT_STREAM, progress=progress)
    _save_npz(path, data)
    return data


@contextlib.contextmanager
def tuple_bar(total: int, desc: str, quiet: bool):
    """A progress bar over traced tuples; yields ``progress(have, total)`` for ShardedTuples.fill."""
    bar = progress_bar(total=total, desc=desc, unit="tuple", disable=quiet, leave=False)

    def progress(have, total):
        bar.total = total
        bar.n = have
        bar.refresh()

    try:
        yield progress
    finally:
        bar.close()


def shard_sampler(scene, asset_ids, domain, rr_depth: int, max_depth: int, variant=None, threads: int = 0):
    """``sample_shard(key, rays)`` of a PathSampler built from the scene file (a cluster worker's copy
    of stage 1); ``domain``: the encoding box (lo, hi) [3] each; ``threads`` > 0 limits Dr.Jit's pool."""
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.eightdna_sampler import PathSampler

    mi, shapes = msc.open_shapes(scene, asset_ids, variant=variant, threads=threads)
    lo, hi = domain
    return PathSampler(mi, shapes, lo, hi, rr_depth=rr_depth, max_depth=max_depth).sample_shard


def renormalise_stage(result, path: Path, source, backtrace_hits, held: dict, lo, hi, points: int, cache: Path, seed: int) -> dict:
    """Fit ``result.model``'s albedo to alpha / V (:mod:`nasset_bakers.train.eightdna_renorm`) on ``points`` fresh
    (x_o, w_o) of ``source`` (a ShardedTuples; cached in ``cache``), lit or not as ``backtrace_hits(u, w)``
    says; the held-out tuples measure the lit energy mean(alpha V) / mean(beta) before and after."""
    from nasset_bakers.train.common import reopen_asset
    from nasset_bakers.train.eightdna import torch_eval
    from nasset_bakers.train.eightdna_renorm import renormalise_albedo, valid_mass

    _, ev = reopen_asset(path)
    pts = heldout_tuples(source, points, cache)
    V = valid_mass(ev, backtrace_hits, pts["xo"], pts["wo"], seed=seed)
    h = {k: v[:HELD_LIT] for k, v in held.items()}
    Vh = valid_mass(ev, backtrace_hits, h["xo"], h["wo"], seed=seed + 1)
    beta = h["beta"].astype(np.float64)
    lit = lambda a: ((a * Vh).mean(0) / np.maximum(beta.mean(0), 1e-12)).tolist()  # noqa: E731
    before = lit(torch_eval(result.model, h, lo, hi)[0])
    rn = renormalise_albedo(result.model, pts, V, lo, hi, seed=seed)
    after = lit(torch_eval(result.model, h, lo, hi)[0])
    se = (beta.std(0) / np.sqrt(len(beta)) / np.maximum(beta.mean(0), 1e-12)).tolist()
    return {**rn.__dict__, "heldout_lit_energy_before": before, "heldout_lit_energy_after": after,
            "heldout_lit_energy_se": se, "heldout_valid_mass": Vh.mean(0).tolist(), "heldout_points": len(beta)}


def scene_shapes(mi, scene, asset_ids, example, work: Path, say, baked_depth: int = -1):
    """(scene path, asset ids, shapes) of a bake, saying where the scene's integrator shows less of the shapes' media
    than a sampler of depth ``baked_depth`` holds."""
    from nasset_converters.mitsuba import scene as msc

    if example is not None:
        from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS, write_example_scene

        if example not in ("default", True, "heterogeneous"):
            raise UsageError(f"unknown 8dna example {example!r} (default, heterogeneous)")
        scene = write_example_scene(work / "example_scene", heterogeneous=example == "heterogeneous")
        asset_ids = list(asset_ids or EXAMPLE_ASSET_IDS)
    if scene is None:
        raise UsageError("give a scene file or --example")
    scene = Path(scene)
    mscene = msc.load_scene(mi, scene)
    shapes = msc.pick_shapes(mscene, asset_ids or [], file=str(scene))
    for warning in msc.bake_media_warnings(mscene, asset_ids, baked_depth):
        say(f"warning: {warning}")
    return scene, list(asset_ids), shapes


def bake(scene, asset_ids, output, *, size: str = "small", example=None, resume=None, views=None, res=None, epochs=None,
         spp=None, light_angle=None, seed: int = 0, device: str = "auto", quiet: bool = False, summary_stream=None,
         far_field: bool = False, workers: int | None = None, cluster: str | None = None, renormalise: bool = True,
         **_ignored) -> dict:
    """Run the whole 8dna bake; returns the summary dict (also stored in the asset's provenance).

    ``renormalise``: fit the albedo to the flow's lit share (spec/bake-8dna.md#renormalise; 8D only; False: ablation).
    ``workers``/``cluster``: trace the held-out tuples and every buffer fill on Ray workers
    (nasset_bakers.cluster), in the same deterministic shards as in one process (spec/bake.md#cluster).

    ``far_field=True`` bakes the 6D far-field baseline instead (spec/bake-8dna.md#far-field): the same
    asset layout, whose conditioners 3-4 ignore u_i (flows 1-2 untrained); only the benchmark uses it.
    """
    from nasset_bakers.cluster import ViewSource, WorkerPool, check_workers
    from nasset_bakers.train.common import TorchCheckpoint, require_torch
    from nasset_bakers.train.eightdna import TRAIN_PRESETS, TrainSettings, export, heldout_nll, parity_with_sdk, train
    from nasset_bakers.train.parallel import data_parallel
    from nasset_converters.mitsuba import CONVERTER_VERSION, load_mitsuba
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.eightdna_sampler import OnlineBuffer, PathSampler, ShardedTuples, local_runner
    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.validate import validate_file

    output = check_options(size, TRAIN_PRESETS, output, seed=seed, scene=scene, epochs=epochs, spp=spp)
    for name, val in (("views", views), ("res", res), ("light-angle", light_angle)):
        if val is not None:
            raise UsageError(f"--{name} has no meaning for kind 8dna (forward path sampling needs no views or light; "
                             "spec/bake-8dna.md#options)")
    check_workers(workers, cluster)
    if workers is not None and int(os.environ.get("WORLD_SIZE", "1") or 1) > 1:
        raise UsageError("--workers does not apply under torchrun (every process traces its own buffer fills; "
                         "spec/bake.md#training-devices)")
    dp = data_parallel(require_torch(), device)  # under torchrun: this process's rank (spec/bake.md#training-devices)
    if not dp.is_main:  # wait for rank 0's scene (an example is written once) and held-out tuples
        job = dp.from_main(require_torch())
        scene, asset_ids, example, quiet = job["scene"], job["asset_ids"], None, True
    work = Path(resume) if resume else output.with_name(output.name + ".bake")
    output_folder(work, "bake's work folder")
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    times: dict[str, float] = {}
    t_all = time.perf_counter()

    # -- stage 1: scene -----------------------------------------------------------------------------
    t = time.perf_counter()
    require_torch()
    with warnings_said(say):
        mi = load_mitsuba()
    if not mi.variant().startswith("llvm"):
        raise error("CONVERT_BACKEND", f"the 8dna sampler needs a vectorised Mitsuba variant (llvm_ad_rgb), got {mi.variant()}")
    mi.set_log_level(mi.LogLevel.Error)
    scene, asset_ids, shapes = scene_shapes(mi, scene, asset_ids, example, work, say,
                                            baked_depth=SAMPLER_PRESETS[size]["max_depth"])
    with warnings_said(say):
        geo = msc.mesh_geometry(mi, shapes)
    check_geometry_scale(geo, asset_ids, scene)
    eta, alpha = boundary_of(mi, shapes)
    builder = AssetBuilder("8dna", variant="surface")
    builder.set_geometry(geo)
    lo, hi = builder.domain
    sp = SAMPLER_PRESETS[size]
    tset = replace(TrainSettings(size=size, seed=seed, device=device, far_field=bool(far_field)), **TRAIN_PRESETS[size])
    if epochs is not None:
        tset = replace(tset, steps=int(epochs))
    if spp is not None:
        tset = replace(tset, buffer=int(spp) * 1000)
    if workers is None:
        pool = None
        tuples = ShardedTuples(seed, local_runner(PathSampler(mi, shapes, lo, hi, rr_depth=sp["rr_depth"], max_depth=sp["max_depth"]).sample_shard))
    else:  # each worker loads the scene itself and traces whole shards
        pool = WorkerPool(ViewSource("nasset_bakers.mitsuba.eightdna:shard_sampler",
                                     {"scene": scene, "asset_ids": asset_ids, "domain": ([float(v) for v in lo], [float(v) for v in hi]),
                                      "rr_depth": sp["rr_depth"], "max_depth": sp["max_depth"], "variant": mi.variant(), "threads": 1}),
                          workers=workers, address=cluster, say=say).__enter__()
        tuples = ShardedTuples(seed, pool.run, batch=workers)
    times["scene_s"] = time.perf_counter() - t

    try:
        # -- stage 2: held-out tuples --------------------------------------------------------------------
        t = time.perf_counter()

        scene_sha = __import__("hashlib").sha256(scene.read_bytes()).hexdigest()
        key = {"scene_sha256": scene_sha, "shapes": asset_ids, "train": tset.__dict__, "sampler": sp, "version": BAKE_VERSION,
               "domain": [list(map(float, lo)), list(map(float, hi))], "variant": mi.variant()}
        say(f"held-out tuples: {sp['heldout']}")
        if dp.is_main:  # the folder's cached tuples are this scene's, shapes' and sampler's, or it is refused
            ds.DatasetDir(work).claim({"kind": "8dna", "converter": CONVERTER_VERSION, "scene": str(scene.resolve()),
                                       **{k: key[k] for k in ("scene_sha256", "shapes", "sampler", "version", "domain")}})
            with tuple_bar(sp["heldout"], "trace held-out", quiet) as held_progress:
                held = heldout_tuples(tuples, sp["heldout"], work / f"heldout_{size}_{seed}.npz", progress=held_progress)
            dp.from_main(require_torch(), {"scene": str(scene), "asset_ids": list(asset_ids)})
        times["heldout_s"] = time.perf_counter() - t

        # -- stage 3: train on the online buffer ---------------------------------------------------------
        t = time.perf_counter()
        fill = contextlib.ExitStack()
        buffer = OnlineBuffer(tuples, tset.buffer, reuse=tset.reuse, seed=seed,
                              progress=fill.enter_context(tuple_bar(tset.buffer, "trace buffer", quiet)))
        bar = progress_bar(total=tset.steps, desc="train 6D far-field" if far_field else "train 8dna", unit="step", disable=quiet)

        def progress(step, nll, l2):
            bar.n = step
            bar.set_postfix(nll=f"{nll:.3g}", albedo_l2=f"{l2:.3g}", refills=buffer.refreshes)
            bar.refresh()

        ckpt = TorchCheckpoint(work / ("train_state_farfield.pt" if far_field else "train_state.pt"), key)
        try:
            result = train(buffer, (lo, hi), tset, progress=progress, checkpoint=ckpt)
        except KeyboardInterrupt:
            say(f"\ninterrupted; training state kept in {work} -- rerun with --resume {work}")
            raise
        finally:
            bar.close()
            fill.close()
        times["train_s"] = time.perf_counter() - t
        if not dp.is_main:  # its share of the training is done; the asset is rank 0's
            return {"rank": dp.rank, "world": dp.world, "asset": None}
    finally:
        if pool is not None:  # the workers are needed for sampling only
            pool.__exit__(None, None, None)

    # -- stage 4: export -----------------------------------------------------------------------------
    t = time.perf_counter()

    def write_asset(networks: dict, provenance: dict, to: Path) -> Path:
        b = AssetBuilder("8dna", variant="surface")
        b.set_geometry(geo)
        core = b.component("core", required=True, purpose="evaluation", quality=None)
        for name, arr in result.tensors.items():
            core.add_tensor(name, arr, dtype="float32", layout=LAYOUTS[name])
        core.add_tensor("direct", np.array([eta, alpha], np.float32), dtype="float32", layout="parameter")
        for name, data in networks.items():
            core.add_network(name, data)
        b.provenance = finite(provenance)
        return b.write(to)

    st = tuples.stats
    prov = {
        "generator": "nasset bake",
        "converter": f"converters.mitsuba {CONVERTER_VERSION}",
        "converterVersion": CONVERTER_VERSION,
        "bake": BAKE_VERSION,
        "model": "6D far-field baseline (conditioners 3-4 ignore u_i; flows 1-2 untrained)" if far_field else "8D",
        "source": {"renderer": f"mitsuba {mi.__version__}", "variant": mi.variant(), "scene": str(scene),
                   "scene_sha256": scene_sha, "shapes": asset_ids, "example": example is not None,
                   "bsdfs": msc.bsdf_names(shapes)},
        "direct": {"eta": eta, "alpha": alpha},
        "sampler": {**sp, "separate_direct": True, "tuples_traced": int(st["hits"]), "rays_started": int(st["started"]),
                    "buffer_refreshes": int(result.refreshes), "mean_beta": None},
        "training": {**tset.__dict__, "device": result.device, "framework": f"torch {require_torch().__version__}",
                     "final_nll": result.history[-1]["nll"] if result.history else None,
                     "final_albedo_l2": result.history[-1]["albedo_l2"] if result.history else None},
        "onnx": {"opset": 17, "max_abs_diff_vs_torch": result.onnx_max_abs_diff},
        "size": size,
        "timings_s": {k: round(v, 3) for k, v in times.items()},
    }
    prov["sampler"]["mean_beta"] = [float(v) for v in held["beta"].mean(0)]
    renorm = renormalise and not far_field
    # (USD keeps an opened layer per path: the asset measured by the renormalisation is a separate file)
    path = write_asset(result.networks, prov, work / "before_renormalise.usdc" if renorm else output)
    times["export_s"] = time.perf_counter() - t
    if renorm:  # -- stage 4b: albedo / lit share of the flow (spec/bake-8dna.md#renormalise)
        t = time.perf_counter()
        say("renormalising the albedo for the flow's unlit mass")
        renorm_sampler = PathSampler(mi, shapes, lo, hi, rr_depth=sp["rr_depth"], max_depth=sp["max_depth"])
        renorm_source = ShardedTuples(seed + 104729, local_runner(renorm_sampler.sample_shard))
        prov["renormalise"] = renormalise_stage(result, path, renorm_source, renorm_sampler.backtrace_hits, held, lo, hi,
                                                RENORM_PRESETS[size]["points"], work / f"renorm_{size}_{seed}.npz", seed)
        networks = dict(result.networks)
        networks["albedo"] = export(result.model)[1]["albedo"]
        path = write_asset(networks, prov, output)
        times["renormalise_s"] = time.perf_counter() - t

    # -- stage 5: check the written asset ------------------------------------------------------------
    t = time.perf_counter()
    par = parity_with_sdk(result.model, path, {k: v[:2048] for k, v in held.items()}, far_field=far_field)
    nll = heldout_nll(result.model, held, lo, hi, far_field=far_field)
    rep = validate_file(path, probe=False)
    if not rep.ok:
        raise error("CONVERT_TRAINING", f"the written asset fails validation: {rep.format_text()[:400]}", file=str(path))
    times["check_s"] = time.perf_counter() - t
    times["total_s"] = time.perf_counter() - t_all
    summary = {
        "asset": str(path),
        "kind": "8dna",
        "model": prov["model"],
        "asset_bytes": path.stat().st_size,
        "work_dir": str(work),
        "size": size,
        "steps": tset.steps, "batch": tset.batch, "buffer": tset.buffer, "buffer_refreshes": result.refreshes,
        "tuples_traced": int(st["hits"]), "heldout_tuples": int(len(held["beta"])),
        "heldout_mean_beta": prov["sampler"]["mean_beta"],
        "heldout_nll": nll,
        "final_train_nll": prov["training"]["final_nll"],
        "final_albedo_l2": prov["training"]["final_albedo_l2"],
        "sdk_vs_torch": par,
        "onnx_vs_torch_max_abs": result.onnx_max_abs_diff,
        "validate": rep.counts,
        "renormalise": prov.get("renormalise"),
        "variant": mi.variant(), "device": result.device,
        "times_s": {k: round(v, 2) for k, v in times.items()},
        "workers": pool.summary if pool is not None else None,
    }
    if not quiet:
        _print_summary(summary, summary_stream or sys.stdout)
    return finite(summary)


def _print_summary(s: dict, stream) -> None:
    p = s["sdk_vs_torch"]
    lines = [
        f"baked {s['asset']}  ({s['asset_bytes'] / 1024:.1f} KiB, {s['model']})",
        f"  mitsuba {s['variant']} forward path sampler: {s['tuples_traced']} tuples traced, buffer {s['buffer']} x "
        f"{s['buffer_refreshes']} fills; training on {s['device']}: {s['steps']} steps of {s['batch']}",
        f"  held-out ({s['heldout_tuples']} tuples, kept in {s['work_dir']}): NLL {s['heldout_nll']:.3f} nats per unit beta, "
        f"mean beta {', '.join(f'{v:.3f}' for v in s['heldout_mean_beta'])}",
        f"  parity SDK vs torch: albedo max |diff| {p['albedo_max_abs']:.2e}, pdf max rel {p['pdf_max_rel']:.2e} "
        f"(median {p['pdf_median_rel']:.1e}); ONNX vs torch {s['onnx_vs_torch_max_abs']:.2e}",
        f"  validate: {s['validate']['error']} errors, {s['validate']['warning']} warnings",
        *([] if not s.get("renormalise") else [
            f"  renormalised albedo: flow's lit share {', '.join(f'{v:.3f}' for v in s['renormalise']['valid_mass'])}; "
            "held-out lit energy mean(alpha V) / mean(beta) "
            f"{', '.join(f'{v:.3f}' for v in s['renormalise']['heldout_lit_energy_before'])} -> "
            f"{', '.join(f'{v:.3f}' for v in s['renormalise']['heldout_lit_energy_after'])} "
            f"(+- {', '.join(f'{v:.3f}' for v in s['renormalise']['heldout_lit_energy_se'])})"]),
        times_line(s["times_s"]),
        *worker_lines(s.get("workers"), unit="shards"),
    ]
    print("\n".join(lines), file=stream)


__all__ = ["bake", "boundary_of", "SAMPLER_PRESETS"]


register_baker("mitsuba", "8dna", bake)
