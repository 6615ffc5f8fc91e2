"""``nasset bench cluster``: the view-rendering stage of a bake in one process and on 1 and 2 Ray workers.

spec/bake.md#cluster. The dataset stage of the built-in Mitsuba rna example (``--size``) is rendered
into fresh folders: once in this process (the scene already loaded, as ``nasset bake`` does), once
on one worker and once on ``--workers`` workers of a local Ray cluster started beforehand (its start
is reported apart; a worker's own start -- loading Mitsuba and the scene -- is part of the stage, as
in a bake; each worker renders with one Dr.Jit thread, as in a bake, the process with all of them).
Prints the times and the ratios; the datasets are checked equal array for array.
"""

from __future__ import annotations

import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def _dataset_equal(a, b, views: int, val_views: int) -> bool:
    for split, n in (("train", views), ("val", val_views)):
        for i in range(n):
            x, y = a.load(split, i), b.load(split, i)
            if sorted(x) != sorted(y) or not all(np.array_equal(x[k], y[k]) for k in x):
                return False
    return True


def run_bench(*, size: str = "tiny", workers: int = 2, views: int | None = None, quiet: bool = False) -> dict:
    from nasset_bakers import cluster
    from nasset_bakers.mitsuba.rna import view_renderer
    from nasset_bakers.presets import RNA_MITSUBA_DATA
    from nasset_bakers.stages import render_views
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    tmp = Path(tempfile.mkdtemp(prefix="bench_cluster_"))
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
    kwargs = {**kwargs, "threads": 1}  # a worker owns one CPU, as a bake's workers do
    t = time.perf_counter()
    ray = cluster.require_ray(local=True)
    started = cluster.connect(ray, None)
    t_start = time.perf_counter() - t
    try:
        source = cluster.ViewSource("nasset_bakers.mitsuba.rna:view_renderer", kwargs)
        one, t_one = stage("w1", source, workers=1)
        many, t_many = stage(f"w{workers}", source, workers=workers)
    finally:
        if started:
            ray.shutdown()
    return {
        "benchmark": "cluster view stage", "example": "mitsuba rna default", "size": size, "views": n,
        "res": dset.res, "spp": dset.spp, "ray_start_s": round(t_start, 2),
        "seconds": {"process": round(t_here, 2), "1 worker": round(t_one, 2), f"{workers} workers": round(t_many, 2)},
        "views_per_s": {"process": n / t_here, "1 worker": n / t_one, f"{workers} workers": n / t_many},
        "speedup_vs_1_worker": t_one / t_many, "speedup_vs_process": t_here / t_many,
        "datasets_equal": _dataset_equal(here, one, dset.views, dset.val_views) and _dataset_equal(here, many, dset.views, dset.val_views),
    }


def add_args(p) -> None:
    p.add_argument("--size", default="tiny", choices=["tiny", "small", "hq"], help="data preset of the example (default tiny)")
    p.add_argument("--views", type=int, default=None, help="training views (default: the preset's)")
    p.add_argument("--workers", type=int, default=2, help="workers of the last run (default 2)")
    p.add_argument("--json", action="store_true")


def run(args) -> int:
    r = run_bench(size=args.size, workers=args.workers, views=args.views, quiet=args.json)
    if args.json:
        print(json.dumps(r, indent=2))
    else:
        s = r["seconds"]
        print(f"view stage of the {r['example']} example ({r['size']}: {r['views']} views at {r['res']}^2, {r['spp']} spp); "
              f"Ray start {r['ray_start_s']} s (not counted)")
        for k, v in s.items():
            print(f"  {k:10s} {v:8.2f} s  {r['views_per_s'][k]:.2f} views/s")
        print(f"  speedup {r['speedup_vs_1_worker']:.2f}x over 1 worker, {r['speedup_vs_process']:.2f}x over one process; "
              f"datasets equal: {r['datasets_equal']}")
    return 0
