"""``nasset bench cluster``: the view-rendering stage and the 8dna sampler stage of a bake in one
process and on 1 and K Ray workers.

spec/bake.md#cluster. Views: the dataset stage of the built-in Mitsuba rna example (``--size``)
rendered into fresh folders. 8dna sampler: one online-buffer fill of the built-in 8dna example (the
preset's buffer, or ``--tuples``) traced in deterministic shards. Each stage runs once in this process
(the scene already loaded, as ``nasset bake`` does), once on one worker and once on ``--workers``
workers of one local Ray cluster (its start is reported apart; a worker's own start -- loading Mitsuba
and the scene -- is part of the stage, as in a bake; each worker runs one Dr.Jit thread, as in a
bake, the process all of them). Prints the times and the ratios; the results are checked equal array
for array."""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from nasset_sdk.cli import count_arg


def _dataset_equal(a, b, views: int, val_views: int) -> bool:
    for split, n in (("train", views), ("val", val_views)):
        for i in range(n):
            x, y = a.load(split, i), b.load(split, i)
            if sorted(x) != sorted(y) or not all(np.array_equal(x[k], y[k]) for k in x):
                return False
    return True


def _views_stage(ray_started, *, size: str, workers: int, views: int | None, quiet: bool, say, tmp: Path) -> dict:
    from nasset_bakers import cluster
    from nasset_bakers.mitsuba.rna import view_renderer
    from nasset_bakers.presets import RNA_MITSUBA_DATA
    from nasset_bakers.stages import render_views
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene

    scene = write_example_scene(tmp / "scene")
    dset = replace(ds.DataSettings(), **RNA_MITSUBA_DATA[size], seed=0)
    if views is not None:
        dset = replace(dset, views=int(views), val_views=max(1, int(views) // 8))
    kwargs = {"scene": scene, "asset_ids": list(EXAMPLE_ASSET_IDS), "dset": dset, "variant": None}
    n = dset.views + dset.val_views

    def stage(name, source, **kw):
        store = ds.DatasetDir(tmp / name)
        store.prepare({"bench": name})
        t = time.perf_counter()
        render_views(store, dset.views, dset.val_views, source, desc=name, work=store.root, quiet=quiet, say=say, **kw)
        return store, time.perf_counter() - t

    render_one = view_renderer(**kwargs)  # loaded once beforehand, as the single-process bake has it
    here, t_here = stage("process", render_one)
    ray_started()
    source = cluster.ViewSource("nasset_bakers.mitsuba.rna:view_renderer", {**kwargs, "threads": 1})  # a worker owns one CPU
    one, t_one = stage("w1", source, workers=1)
    many, t_many = stage(f"w{workers}", source, workers=workers)
    return {
        "stage": "views", "example": "mitsuba rna default", "size": size, "views": n, "res": dset.res, "spp": dset.spp,
        "seconds": {"process": round(t_here, 2), "1 worker": round(t_one, 2), f"{workers} workers": round(t_many, 2)},
        "views_per_s": {"process": n / t_here, "1 worker": n / t_one, f"{workers} workers": n / t_many},
        "speedup_vs_1_worker": t_one / t_many, "speedup_vs_process": t_here / t_many,
        "datasets_equal": _dataset_equal(here, one, dset.views, dset.val_views) and _dataset_equal(here, many, dset.views, dset.val_views),
    }


def _sampler_stage(ray_started, *, size: str, workers: int, tuples: int | None, quiet: bool, say, tmp: Path) -> dict:
    """The 8dna forward-sampler stage: one buffer fill of the example (``tuples``, default the preset's buffer)."""
    from nasset_bakers import cluster
    from nasset_bakers.mitsuba.eightdna import shard_sampler, tuple_bar
    from nasset_bakers.presets import EIGHTDNA_MITSUBA_SAMPLER, EIGHTDNA_TRAIN
    from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS, write_example_scene
    from nasset_converters.mitsuba.eightdna_sampler import ShardedTuples, local_runner, shard_rays

    sp = EIGHTDNA_MITSUBA_SAMPLER[size]
    n = int(tuples or EIGHTDNA_TRAIN[size]["buffer"])
    kwargs = {"scene": write_example_scene(tmp / "scene_8dna"), "asset_ids": list(EXAMPLE_ASSET_IDS),
              "domain": ([-0.6] * 3, [0.6] * 3), "rr_depth": sp["rr_depth"], "max_depth": sp["max_depth"], "variant": None}

    def stage(name, run, batch):
        src = ShardedTuples(0, run, batch=batch)
        t = time.perf_counter()
        with tuple_bar(n, name, quiet) as progress:
            data = src.fill(n, 1, progress=progress)
        return data, time.perf_counter() - t, src.stats["shards"]

    here, t_here, _ = stage("process", local_runner(shard_sampler(**kwargs)), 1)  # loaded beforehand, as in a bake
    ray_started()
    source = cluster.ViewSource("nasset_bakers.mitsuba.eightdna:shard_sampler", {**kwargs, "threads": 1})
    with cluster.WorkerPool(source, workers=1, address=None, say=say) as pool:
        one, t_one, _ = stage("w1", pool.run, 1)
    with cluster.WorkerPool(source, workers=workers, address=None, say=say) as pool:
        many, t_many, shards = stage(f"w{workers}", pool.run, workers)
    busy = {str(pid): round(w["seconds"], 2) for pid, w in pool.summary.items()}
    equal = all(np.array_equal(here[k], d[k]) for d in (one, many) for k in here)
    return {
        "stage": "8dna sampler", "example": "mitsuba 8dna default", "size": size, "tuples": n, "rays_per_shard": shard_rays(n),
        "shards": shards,
        "seconds": {"process": round(t_here, 2), "1 worker": round(t_one, 2), f"{workers} workers": round(t_many, 2)},
        "tuples_per_s": {"process": n / t_here, "1 worker": n / t_one, f"{workers} workers": n / t_many},
        "speedup_vs_1_worker": t_one / t_many, "speedup_vs_process": t_here / t_many, "datasets_equal": equal,
        "busy_s_per_worker": busy,
    }


def run_bench(*, size: str = "tiny", workers: int = 2, views: int | None = None, tuples: int | None = None,
              stages: tuple[str, ...] = ("views", "8dna"), quiet: bool = False) -> dict:
    """Time each stage of ``stages`` ("views": rna view rendering, "8dna": one sampler buffer fill) in one
    process, on 1 worker and on ``workers`` workers of one local Ray cluster (its start timed apart)."""
    from nasset_bakers import cluster

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    tmp = Path(tempfile.mkdtemp(prefix="bench_cluster_"))
    ray = cluster.require_ray(local=True)
    start = {"s": None, "started": False}

    def ray_started() -> None:  # after the first single-process run, so Ray's idle processes do not share its CPUs
        if start["s"] is None:
            t = time.perf_counter()
            start["started"] = cluster.connect(ray, None)
            start["s"] = time.perf_counter() - t

    out: dict = {"benchmark": "cluster stages", "workers": workers}
    try:
        if "views" in stages:
            out["views"] = _views_stage(ray_started, size=size, workers=workers, views=views, quiet=quiet, say=say, tmp=tmp)
        if "8dna" in stages:
            out["8dna"] = _sampler_stage(ray_started, size=size, workers=workers, tuples=tuples, quiet=quiet, say=say, tmp=tmp)
    finally:
        if start["started"]:
            ray.shutdown()
    out["ray_start_s"] = round(start["s"] or 0.0, 2)
    return out


def add_args(p) -> None:
    p.add_argument("--size", default="tiny", choices=["tiny", "small", "hq"], help="preset of the examples (default tiny)")
    p.add_argument("--views", type=count_arg(1, 65536), default=None, help="training views of the view stage (default: the preset's)")
    p.add_argument("--tuples", type=count_arg(1, 1 << 26), default=None, help="tuples of the 8dna sampler fill (default: the preset's buffer)")
    p.add_argument("--stage", action="append", choices=["views", "8dna"], default=None,
                   help="stage to time (repeat; default both)")
    p.add_argument("--workers", type=count_arg(1, 4096), default=2, help="workers of the last run (default 2)")
    p.add_argument("--json", action="store_true")


def run(args) -> int:
    r = run_bench(size=args.size, workers=args.workers, views=args.views, tuples=args.tuples,
                  stages=tuple(args.stage or ("views", "8dna")), quiet=args.json)
    if args.json:
        print(json.dumps(r, indent=2))
        return 0
    print(f"Ray start {r['ray_start_s']} s (not counted)")
    for key, unit in (("views", "views"), ("8dna", "tuples")):
        if key not in r:
            continue
        st = r[key]
        what = (f"{st['views']} views at {st['res']}^2, {st['spp']} spp" if key == "views"
                else f"{st['tuples']} tuples in {st['shards']} shards of {st['rays_per_shard']} rays")
        print(f"{st['stage']} stage of the {st['example']} example ({st['size']}: {what})")
        for k, v in st["seconds"].items():
            print(f"  {k:10s} {v:8.2f} s  {st[unit + '_per_s'][k]:.2f} {unit}/s")
        print(f"  speedup {st['speedup_vs_1_worker']:.2f}x over 1 worker, {st['speedup_vs_process']:.2f}x over one process; "
              f"results equal: {st['datasets_equal']}")
    return 0
