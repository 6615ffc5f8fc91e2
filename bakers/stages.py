"""Stages every baker shares: option checks, rendering the views of a resumable dataset, training with a
progress bar, and provenance made JSON-safe.

Both keep what is done on Ctrl-C (views on disk, the training checkpoint) and say how to resume.
"""

from __future__ import annotations

import math
import warnings
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from nasset_sdk.errors import UsageError, error, path_arg
from nasset_sdk.geometry import scale_problem
from nasset_sdk.images import output_folder

from .train.common import MAX_GAIN_SE


def progress_bar(**kw):
    """A tqdm bar (``disable=True`` for quiet runs)."""
    from tqdm.auto import tqdm

    return tqdm(**kw)


def render_views(store, views: int, val_views: int, render_one, *, desc: str, work: Path, quiet: bool,
                 say: Callable[..., None], workers: int | None = None, cluster: str | None = None,
                 say_resume: bool = True) -> dict | None:
    """Render and save every training and held-out view ``store`` lacks.

    ``render_one``: ``(split, i) -> dict of arrays``, or a :class:`nasset_bakers.cluster.ViewSource`
    that builds one. With ``workers`` the views are rendered by that many Ray workers (``cluster``:
    the address of an existing cluster; default a local one), each building ``render_one`` from the
    ViewSource once; returns the per-worker summary then (None in one process)."""
    from nasset_bakers.cluster import ViewSource, render_views_on_cluster

    jobs = [("train", i) for i in range(views)] + [("val", i) for i in range(val_views)]
    todo = [j for j in jobs if not store.has(*j)]
    if len(todo) < len(jobs) and say_resume:
        say(f"resuming: {len(jobs) - len(todo)} of {len(jobs)} views already in {work}")
    bar = progress_bar(total=len(jobs), initial=len(jobs) - len(todo), desc=desc, unit="view", disable=quiet)
    try:
        if workers is not None:
            if not isinstance(render_one, ViewSource):
                raise UsageError("this bake's views cannot be rendered by workers (no ViewSource)")
            return render_views_on_cluster(store, todo, render_one, workers=workers, address=cluster, bar=bar, say=say)
        built = isinstance(render_one, ViewSource)
        fn = render_one.build() if built else render_one
        try:
            for split, i in todo:
                store.save(split, i, fn(split, i))
                bar.update(1)
        finally:
            if built and hasattr(fn, "close"):
                fn.close()
        return None
    except KeyboardInterrupt:
        say(f"\ninterrupted; the dataset so far is kept in {work} -- rerun with --resume {work}")
        raise
    finally:
        bar.close()


def worker_lines(summary: dict | None, unit: str = "views") -> list[str]:
    """Summary lines of a cluster stage (:class:`nasset_bakers.cluster.WorkerPool` summary): jobs
    (``unit``: views, sampler shards) and seconds per worker."""
    if not summary:
        return []
    return ["  workers: " + ", ".join(f"pid {pid} {w['jobs']} {unit} in {w['seconds']:.1f}s" for pid, w in sorted(summary.items()))]


def train_with_progress(run: Callable[[Callable], object], *, total: int, desc: str, work: Path, quiet: bool,
                        say: Callable[..., None]):
    """``run(progress)`` with a bar over ``total`` epochs; ``progress(epoch, loss, val_psnr)`` updates it."""
    bar = progress_bar(total=total, desc=desc, unit="epoch", disable=quiet)
    last = {"psnr": float("nan")}

    def progress(epoch, loss, val_psnr):
        if math.isfinite(val_psnr):
            last["psnr"] = val_psnr
        bar.n = epoch + 1
        bar.set_postfix(loss=f"{loss:.3g}", val_psnr=f"{last['psnr']:.2f}")
        bar.refresh()

    try:
        return run(progress)
    except KeyboardInterrupt:
        say(f"\ninterrupted; dataset and training state kept in {work} -- rerun with --resume {work}")
        raise
    finally:
        bar.close()


def finite(v):
    """``v`` with non-finite floats replaced by None, numpy scalars by Python ones, tuples by lists (JSON-safe)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [finite(x) for x in v]
    if isinstance(v, (np.floating, np.integer)):
        return finite(v.item())
    return v


#: the largest value each count option takes: a training view of --res 4096 is 16 M pixels (its per-pixel arrays
#: ~1 GiB); the others bound run time only, at values no bake needs
MAX_COUNTS = {"res": 4096, "views": 65536, "spp": 1 << 20, "epochs": 100_000}


def check_options(size: str, presets, output, *, seed: int = 0, scene=None, **counts) -> Path:
    """Argument checks every baker shares: a known preset, counts integers in 1 .. MAX_COUNTS where given, a seed in
    0 .. MAX_SEED, a scene file given as a path (or None), an asset file name.

    Returns ``output`` as a Path; raises UsageError."""
    from nasset_sdk.cli import MAX_SEED

    if size not in presets:
        raise UsageError(f"--size must be one of {sorted(presets)}, got {size!r}")
    for name, val in counts.items():
        if val is None:
            continue
        if isinstance(val, bool) or not isinstance(val, (int, np.integer)):
            raise UsageError(f"--{name} must be an integer, got {val!r}")
        if val < 1:
            raise UsageError(f"--{name} must be >= 1, got {val}")
        if val > MAX_COUNTS[name]:
            raise UsageError(f"--{name} must be <= {MAX_COUNTS[name]}, got {val}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed <= MAX_SEED:
        raise UsageError(f"--seed must be an integer in 0 .. {MAX_SEED}, got {seed!r}")
    if scene is not None:
        path_arg(scene, "the scene")
    output = path_arg(output, "the output")
    if output.suffix not in (".usdc", ".usda", ".usd"):
        raise UsageError(f"output must end in .usdc/.usda/.usd, got {output.name!r}")
    if output.is_dir():
        raise error("WRITE_FAILED", "the output names a folder", file=str(output))
    # at the start, not when the asset is written after the whole bake (a --resume folder elsewhere kept a missing or
    # uncreatable one unnoticed until then)
    output_folder(output.parent, "asset's folder")
    return output


# -- summary lines every baker prints ---------------------------------------------------------------
def check_geometry_scale(geo, shapes, file) -> None:
    """Refuse, before any rendering, shapes whose geometry (the asset's object space is the scene's) the validator
    would refuse as ``GEOMETRY_SCALE`` (:func:`nasset_sdk.geometry.scale_problem`: an object farther from the origin
    than 1000 x its size, beyond what a float32 renderer resolves): before, the bake rendered and trained and then
    wrote an asset that ``nasset validate`` refuses (8dna: refused it after training)."""
    if why := scale_problem(*geo.bounds()):
        raise error("GEOMETRY_SCALE", f"asset shapes {list(shapes)} would make an invalid asset: {why} "
                    "(spec/security.md#bounds); move the scene towards the origin, or bake the object placed there and "
                    "place the asset back in the scene with a transform", file=str(file))


def dataset_line(s: dict) -> str:
    """``  dataset: V views at R^2, S spp + H held-out at ... -> N train / M held-out samples`` of a summary dict."""
    return (f"  dataset: {s['views']} views at {s['res']}^2, {s['spp']} spp + {s['val_views']} held-out at "
            f"{s['val_res']}^2, {s['val_spp']} spp -> {s['train_samples']} train / {s['val_samples']} held-out samples")


@contextmanager
def warnings_said(say):
    """Run the block with Python warnings recorded, then ``say`` each as a ``warning:`` line (the bakes' summary
    voice, instead of Python's ``file:line: RuntimeWarning`` form)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        yield
    for w in caught:
        say(f"warning: {w.message}")


def see_through_line(what: str, names: list, share: float) -> str:
    """The rna bakes' warning for ``what`` (``shape(s)``, ``object(s)``) ``names`` that light crosses unscattered
    (spec/bake.md#see-through; more than ``share`` of it)."""
    return (f"warning: {what} {names} let light through unscattered (a clear, thin or masked surface over at most a thin "
            f"medium: over {share:.0%} of it crosses): rna stores smooth transport, so what they show of the scene "
            "behind them will be missing or blurred in every render of the asset (spec/bake.md#see-through)")


def _db(value) -> str:
    """``12.34 dB``, or ``n/a`` where a PSNR is undefined (None or not finite: a black held-out reference)."""
    return f"{value:.2f} dB" if value is not None and math.isfinite(value) else "n/a"


def psnr_line(s: dict, label: str = "held-out PSNR") -> str:
    """The held-out PSNR of the trained model (torch) and of the written asset (SDK evaluator), and which
    epoch's state the asset keeps."""
    line = f"  {label}: {_db(s['val_psnr_db'])} (torch), {_db(s['sdk_val_psnr_db'])} (SDK evaluator)"
    if s.get("kept_epoch"):
        line += f"; kept epoch {s['kept_epoch']} of {s['epochs']} ({s['keep']}: highest held-out display PSNR)" \
            if s.get("keep") == "best" else f"; kept the last of {s['epochs']} epochs"
    return line


def times_line(times: dict) -> str:
    """``  time: scene 1.2s, dataset 3.4s, ...`` from ``{"scene_s": 1.2, ...}``."""
    return "  time: " + ", ".join(f"{k[:-2]} {v:.1f}s" for k, v in times.items())


def clamp_removed(train_data: dict) -> dict | None:
    """Share of the training targets' energy per channel that the clamp removed (None: not recorded)."""
    if "energy" not in train_data:
        return None
    e = np.asarray(train_data["energy"], np.float64)
    r = np.asarray(train_data["clamp_removed"], np.float64)
    return {"fraction": [float(x) for x in r / np.where(e > 0, e, np.nan)], "energy": [float(x) for x in e]}


def data_noise(train_samples: int, spp: float, val_data: dict, val_spp: int) -> dict | None:
    """The relative Monte Carlo noise of a training set (spec/bake.md#data-noise).

    From the held-out views' two independent halves (``rgb_a``, ``rgb_b`` [M, 3], each of ``val_spp // 2`` paths):
    the variance of one path sample per pixel and channel, sigma^2 = (val_spp // 2) (a - b)^2 / 2, and the
    path samples' relative variance r = mean sigma^2 / (mean radiance)^2; the training set's ``train_samples``
    targets of ``spp`` paths then carry ``noise`` = r / (train_samples spp), the relative variance of their
    mean. None without halves, samples or signal."""
    if "rgb_a" not in val_data or not len(val_data["rgb_a"]) or train_samples <= 0 or spp <= 0:
        return None
    a = np.asarray(val_data["rgb_a"], np.float64)
    b = np.asarray(val_data["rgb_b"], np.float64)
    mean = float(np.mean(0.5 * (a + b)))
    if not (np.isfinite(a).all() and np.isfinite(b).all()) or mean <= 0:
        return None
    half = max(1, int(val_spp) // 2)
    rel = float(np.mean(half * (a - b) ** 2 / 2)) / mean ** 2
    return {"path_relative_variance": rel, "train_samples": int(train_samples), "spp": float(spp),
            "noise": rel / (train_samples * spp)}


def views_for_noise(views: int, noise: float, target: float, max_factor: float) -> int:
    """Training views that bring a training set's ``noise`` (:func:`data_noise`, of ``views`` views) down to
    ``target``, the noise falling as 1 / views: ``views`` where it is already there, at most
    ``floor(views * max_factor)``."""
    if not (noise > target > 0) or not math.isfinite(noise):
        return int(views)
    return int(min(math.ceil(views * noise / target), math.floor(views * max_factor)))


def data_noise_stage(store, dset, train_data: dict, val_data: dict, rule: dict | None, render_one, load_train, *,
                     work: Path, quiet: bool, say: Callable[..., None], workers: int | None = None,
                     cluster: str | None = None):
    """The data-noise stage of a bake (spec/bake.md#data-noise), after its views are rendered: measure the training
    set's :func:`data_noise`; where a ``rule`` {target, max_factor} is given and the noise is above its target, render
    (:func:`render_views` with ``render_one``) the training views up to the count :func:`views_for_noise` asks for and
    read them (``load_train(views)``). Returns (the provenance record or None, ``dset`` with the views trained on,
    train_data, the cluster summary of the views added or None)."""
    spp = getattr(dset, "spp_per_target", dset.spp)  # several suns per render: each target gets a share of the paths
    noise = data_noise(len(train_data["x"]), spp, val_data, dset.val_spp)
    if noise is None:
        return None, dset, train_data, None
    noise = {**noise, "views": dset.views, "target": rule["target"] if rule else None, "views_used": dset.views,
             "noise_used": noise["noise"], "capped": False}
    more = views_for_noise(dset.views, noise["noise"], rule["target"], rule["max_factor"]) if rule else dset.views
    if more <= dset.views:
        return noise, dset, train_data, None
    say(f"data noise {noise['noise']:.2e} above the target {rule['target']:.1e}: {more - dset.views} more training views")
    summary = render_views(store, more, dset.val_views, render_one, desc="render views (data noise)", work=work, quiet=quiet,
                           say=say, workers=workers, cluster=cluster, say_resume=False)
    train_data = load_train(more)
    noise.update(views_used=more, noise_used=noise["path_relative_variance"] / (len(train_data["x"]) * spp),
                 capped=more >= math.floor(dset.views * rule["max_factor"]))
    return noise, replace(dset, views=more), train_data, summary


def data_noise_line(noise: dict | None) -> str | None:
    """``  data noise: ...`` of a bake that measured it (spec/bake.md#data-noise)."""
    if not noise:
        return None
    line = (f"  data noise: {noise['noise']:.2e} at {noise['views']} training views (path samples' relative variance "
            f"{noise['path_relative_variance']:.0f})")
    if noise.get("target") is None:
        return line
    if noise["views_used"] == noise["views"]:
        return line + f", within the target {noise['target']:.1e}"
    capped = ", the most views allowed" if noise["capped"] else ""
    return line + f" -> {noise['noise_used']:.2e} at {noise['views_used']} views (target {noise['target']:.1e}{capped})"


def accuracy_lines(acc: dict | None, label: str = "held-out (unclamped reference)") -> list[str]:
    """Summary lines of a spec/accuracy.md#metrics dict: energy per channel (with groups: the views as the units of
    its standard error, and the per-view spread), PSNR and its ceiling."""
    if not acc:
        return []
    def pct(values) -> str:
        return "/".join("n/a" if r is None else f"{100 * r:.1f}" for r in values)

    g = acc.get("groups")
    units = ""
    if g:  # views as the units (spec/accuracy.md#metrics): their count and the per-view spread
        units = (f"; {g['count']} views as units, per view {pct(g['ratio_min'])} to {pct(g['ratio_max'])} %, "
                 f"sd {pct(g['ratio_sd'])} %")
    return [f"  {label}: energy {pct(acc['energy_ratio'])} % (RGB, +-{pct(acc['energy_se'])}{units}), "
            f"PSNR {_db(acc['psnr_db'])}, ceiling {_db(acc['ceiling_db'])} -> claimed {acc['claimed_psnr']}"]


def clamp_lines(s: dict) -> list[str]:
    """The training clamp and the share of the targets' energy it removed, when a bake clamped."""
    if not (s.get("clamp") and s.get("clamp_removed")):
        return []
    return [f"  training clamp {s['clamp']} /sr removed " + "/".join(f"{100 * f:.1f}" for f in s["clamp_removed"]["fraction"])
            + " % of the targets' energy (RGB)"]


def near_field_stage(option, check: dict, size: str, seed: int, quiet: bool, measure) -> dict:
    """Stage 6 of the Mitsuba rna and neupress bakes (spec/bake.md#near-field): the near-field fetch fraction to store.
    ``option``: f given (stored as is) or 'auto': ``measure(settings, target_ratio, progress)``
    (:func:`nasset_converters.mitsuba.near_field.calibrate` on the baker's renderer and transport) with the preset's
    settings, against the held-out distant-light energy ratio the SDK measured on the written asset (``check``'s
    accuracy; 1 where it is known no better than TARGET_SE per channel). Returns {fetch, measured, ...}."""
    from nasset_converters.mitsuba import near_field as nf

    from . import presets

    if option != "auto":
        return {"fetch": float(option), "measured": False, "why": "given (--near-field-fetch)"}
    acc = check.get("accuracy") or {}
    ratio, se = acc.get("energy_ratio"), acc.get("energy_se")
    known = ratio and se and all(isinstance(r, float) and r > 0 for r in ratio) \
        and all(isinstance(e, float) and e <= nf.TARGET_SE for e in se)  # one held-out view: no standard error
    settings = nf.NearFieldSettings(**presets.MITSUBA_NEAR_FIELD[size], seed=seed)
    bar = progress_bar(total=settings.views, desc="near field", unit="view", disable=quiet)
    try:
        out = measure(settings, ratio if known else [1.0, 1.0, 1.0], lambda: bar.update(1))
    finally:
        bar.close()
    return {**out, "measured": True}


def write_near_field(builder, prov: dict, near: dict, output) -> Path | None:
    """Write the baked asset again with stage 6's fetch fraction and its provenance ``near_field`` (where f > 0 or it
    was measured); returns the path written, None when the first write stands."""
    if not (near["fetch"] > 0 or near["measured"]):
        return None
    builder.near_field_fetch = near["fetch"]
    builder.provenance = finite({**prov, "near_field": near})
    return builder.write(output)


def energy_gain_line(gain: dict | None) -> str | None:
    """The output gain a bake applied after training (spec/bake.md#energy-gain): one dict of
    ``train.common.energy_gain``, or rna's {"unshadowed": ..., "shadowed": ...}; None when it was off."""
    if not gain:
        return None
    parts = {"": gain} if "gain" in gain else {k: g for k, g in gain.items() if g}

    def one(label, g):
        se = "" if g.get("se") is None else " ± " + "/".join(f"{100 * e:.1f}" for e in g["se"])
        kept = "" if all(g["applied"]) else f", 1 where ± > {100 * MAX_GAIN_SE:g} %"
        return (f"{label}{'/'.join(f'{x:.3f}' for x in g['gain'])} (the network kept "
                + "/".join(f"{100 * r:.1f}" for r in g["ratio"]) + f" %{se} of its training set's energy{kept})")

    return "  energy gain (RGB): " + "; ".join(one(f"{k} " if k else "", g) for k, g in parts.items())


def plane_blur_line(blur: dict | None) -> str | None:
    """The final blur of an rna bake's feature planes (spec/bake.md#plane-blur); None when it was not chosen."""
    if not blur:
        return None
    mse = dict(zip(blur["footprints"], blur["mse"], strict=True))
    why = ("the schedule's" if blur["chosen"] == blur["schedule"]
           else f"held-out MSE {mse[blur['chosen']]:.3g} against {mse[blur['schedule']]:.3g} at the schedule's {blur['schedule']:g}")
    return f"  plane blur: footprint {blur['chosen']:g} texels ({why}; tried {', '.join(f'{f:g}' for f in blur['footprints'])})"


def near_field_line(near: dict) -> str:
    """Where renderers fetch the baked rna asset's light (spec/bake.md#near-field)."""
    f = near["fetch"]
    if not near.get("measured"):
        return f"  near-field fetch f = {f:g}: {near.get('why', 'given')}"
    pct = "/".join(f"{100 * r:.1f}" for r in near["energy_ratio_f0"])
    return (f"  near-field fetch f = {f:.2f} (halves {near['fetch_halves'][0]:.2f} / {near['fetch_halves'][1]:.2f}): under "
            f"lights near the asset it kept {pct} % of Mitsuba's energy (RGB) with the distant-light rule, "
            + "/".join(f"{100 * r:.1f}" for r in near["energy_ratio"]) + " % with f, against "
            + "/".join(f"{100 * r:.1f}" for r in near["target_ratio"]) + " % under its held-out distant lights")


def send_job(dp, *, work: Path, views: int, val_views: int, domain, settings, checkpoint, **extra) -> None:
    """Rank 0 of a torchrun bake: send the other processes (:func:`train_share`) what they train with:
    the dataset folder and its view counts, the domain, the training settings (a dataclass) and the
    checkpoint (path and key: they resume from the same epoch); ``extra``: what the bake's loader needs.
    Nothing in one process."""
    from .train.common import require_torch

    dp.from_main(require_torch(), {
        "work": str(work), "views": int(views), "val_views": int(val_views), "domain": [list(map(float, d)) for d in domain],
        "train": dict(settings.__dict__), "checkpoint": str(checkpoint.path), "checkpoint_key": checkpoint.key, **extra})


def train_share(dp, load=None, fit=None) -> dict:
    """A torchrun process other than rank 0 (spec/bake.md#training-devices): wait for the job of
    :func:`send_job`, train its share of every batch, and leave checkpoints and the asset to rank 0.
    ``load(store, split, count, job)`` reads a split (default: the Mitsuba rna dataset's
    ``store.load_split``); ``fit(train_data, val_data, domain, job, checkpoint)`` trains (default: the
    rna trainer)."""
    from nasset_converters.mitsuba import dataset as ds

    from .train.common import TorchCheckpoint, require_torch

    load = load or (lambda store, split, count, job: store.load_split(split, count))
    job = dp.from_main(require_torch())
    store = ds.DatasetDir(Path(job["work"]))
    ckpt = TorchCheckpoint(Path(job["checkpoint"]), job["checkpoint_key"])  # read (resume) only: rank 0 saves
    (fit or _fit_rna)(load(store, "train", job["views"], job), load(store, "val", job["val_views"], job), job["domain"],
                      job, ckpt)
    return {"rank": dp.rank, "world": dp.world, "asset": None}


def _fit_rna(train_data: dict, val_data: dict, domain, job: dict, checkpoint) -> None:
    """:func:`train_share`'s default: the rna trainer with rank 0's settings."""
    from .train.rna import TrainSettings, train

    train(train_data, val_data, domain, TrainSettings(**job["train"]), checkpoint=checkpoint)
