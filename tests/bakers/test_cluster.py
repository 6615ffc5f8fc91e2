"""The view stage of a bake on Ray workers (nasset_bakers.cluster, spec/bake.md#cluster).

One local Ray cluster (loopback only) serves the module. The datasets compared are the Mitsuba rna
example's at a toy size: the views a bake renders in one process, on one worker and on two workers
must be the same arrays, also when a worker is killed mid-stage.
"""

from __future__ import annotations

import os
import signal
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_bakers import cluster  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402

VIEWS, VAL_VIEWS = 6, 2


@pytest.fixture(scope="module")
def ray_local():
    ray = cluster.require_ray(local=True)
    started = cluster.connect(ray, None)
    yield ray
    if started:
        ray.shutdown()


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """The ViewSource of the Mitsuba rna example at a toy size (as the bake builds it for workers)."""
    from nasset_bakers.presets import RNA_MITSUBA_DATA
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene

    scene = write_example_scene(tmp_path_factory.mktemp("cluster_scene"))
    dset = replace(ds.DataSettings(), **RNA_MITSUBA_DATA["tiny"], seed=3)
    dset = replace(dset, views=VIEWS, val_views=VAL_VIEWS, res=16, val_res=16, spp=4, val_spp=8)
    return cluster.ViewSource("nasset_bakers.mitsuba.rna:view_renderer",
                              {"scene": scene, "asset_ids": list(EXAMPLE_ASSET_IDS), "dset": dset, "variant": None})


def _render(tmp_path, name, source, **kw):
    from nasset_bakers.stages import render_views
    from nasset_converters.mitsuba.dataset import DatasetDir

    store = DatasetDir(tmp_path / name)
    store.prepare({"test": name})
    summary = render_views(store, VIEWS, VAL_VIEWS, source, desc=name, work=store.root, quiet=True, say=lambda *a: None, **kw)
    return store, summary


def _same(a, b) -> None:
    for split, n in (("train", VIEWS), ("val", VAL_VIEWS)):
        for i in range(n):
            x, y = a.load(split, i), b.load(split, i)
            assert sorted(x) == sorted(y), (split, i)
            for k in x:
                np.testing.assert_array_equal(x[k], y[k], err_msg=f"{split} view {i} field {k}")


@pytest.fixture(scope="module")
def one_process(tmp_path_factory, source):
    return _render(tmp_path_factory.mktemp("one"), "one", source)[0]


def test_workers_write_the_same_dataset(ray_local, source, one_process, tmp_path):
    one_worker, s1 = _render(tmp_path, "w1", source, workers=1)
    two_workers, s2 = _render(tmp_path, "w2", source, workers=2)
    _same(one_process, one_worker)
    _same(one_process, two_workers)
    assert sum(w["jobs"] for w in s1.values()) == VIEWS + VAL_VIEWS and len(s1) == 1
    assert sum(w["jobs"] for w in s2.values()) == VIEWS + VAL_VIEWS and len(s2) == 2  # both workers rendered


def slow_view_renderer(seconds: float, **kwargs):
    """The Mitsuba rna view renderer, each view taking ``seconds`` longer (so a test can kill a worker mid-view)."""
    import time

    from nasset_bakers.mitsuba.rna import view_renderer

    render_one = view_renderer(**kwargs)

    def slow(split, i):
        time.sleep(seconds)
        return render_one(split, i)

    return slow


def _rendering_worker_pid(timeout: float = 120.0) -> int:
    """The pid of a Ray worker process busy in ViewWorker.render (Ray names its processes by task)."""
    import time

    end = time.monotonic() + timeout
    while time.monotonic() < end:
        for proc in Path("/proc").glob("[0-9]*"):
            try:
                if (proc / "cmdline").read_bytes().startswith(b"ray::ViewWorker.render"):
                    return int(proc.name)
            except OSError:
                continue
        time.sleep(0.05)
    raise AssertionError("no worker was seen rendering")


def test_a_killed_worker_views_are_rendered_again(ray_local, source, one_process, tmp_path):
    from tqdm import tqdm

    from nasset_converters.mitsuba.dataset import DatasetDir

    store = DatasetDir(tmp_path / "killed")
    store.prepare({"test": "killed"})
    killed = []

    def kill_one(actors):
        pid = _rendering_worker_pid()
        os.kill(pid, signal.SIGKILL)  # mid-view, as a node's OOM killer or a lost machine would
        killed.append(pid)

    slow = cluster.ViewSource("tests.bakers.test_cluster:slow_view_renderer", {"seconds": 1.0, **source.kwargs})
    todo = [("train", i) for i in range(VIEWS)] + [("val", i) for i in range(VAL_VIEWS)]
    summary = cluster.render_views_on_cluster(store, todo, slow, workers=2, address=None, bar=tqdm(disable=True),
                                              say=lambda *a: None, on_started=kill_one)
    assert killed and killed[0] not in summary  # the killed process saved nothing
    assert sum(w["jobs"] for w in summary.values()) == VIEWS + VAL_VIEWS  # its view was rendered again
    assert len(summary) == 2  # by the restarted worker (a new process) and the other one
    _same(one_process, store)
    assert not list(store.root.rglob("*.part.npz"))  # nothing half-written


# -- the 8dna forward-sampler stage ------------------------------------------------------------------
TUPLES = 5000  # of one fill: 2048 rays per shard (shard_rays), a few shards


@pytest.fixture(scope="module")
def shard_source(tmp_path_factory):
    """The ViewSource of the 8dna example's shard sampler (as the bake builds it for workers)."""
    from nasset_converters.mitsuba.eightdna_example import EXAMPLE_ASSET_IDS, write_example_scene

    scene = write_example_scene(tmp_path_factory.mktemp("eightdna_scene"))
    return cluster.ViewSource("nasset_bakers.mitsuba.eightdna:shard_sampler",
                              {"scene": scene, "asset_ids": list(EXAMPLE_ASSET_IDS), "domain": ([-0.6] * 3, [0.6] * 3),
                               "rr_depth": 4, "max_depth": 256, "variant": None})


@pytest.fixture(scope="module")
def shards_here(shard_source):
    """Two fills (streams 0 and 1) traced in this process, one shard at a time."""
    from nasset_converters.mitsuba.eightdna_sampler import ShardedTuples, local_runner

    src = ShardedTuples(11, local_runner(shard_source.build()))
    return [src.fill(TUPLES, stream) for stream in (0, 1)]


def _same_tuples(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k], err_msg=f"field {k}")


def test_8dna_shards_are_the_same_on_any_number_of_workers(ray_local, shard_source, shards_here):
    from nasset_converters.mitsuba.eightdna_sampler import ShardedTuples

    for k in (1, 2):
        with cluster.WorkerPool(shard_source, workers=k, address=None, say=lambda *a: None) as pool:
            src = ShardedTuples(11, pool.run, batch=k)
            there = [src.fill(TUPLES, stream) for stream in (0, 1)]
        for a, b in zip(shards_here, there, strict=True):
            _same_tuples(a, b)
        assert len(pool.summary) == k and src.stats["shards"] == sum(w["jobs"] for w in pool.summary.values())
    # independent shards and streams: no tuple drawn twice (a key that ignored the shard or stream would repeat them)
    xo = np.concatenate([f["xo"] for f in shards_here])
    assert len(xo) == 2 * TUPLES and len(np.unique(xo, axis=0)) == len(xo)


def slow_shard_sampler(seconds: float, **kwargs):
    """The 8dna shard sampler, each shard taking ``seconds`` longer (so a test can kill a worker mid-shard)."""
    import time

    from nasset_bakers.mitsuba.eightdna import shard_sampler

    sample_shard = shard_sampler(**kwargs)

    def slow(key, rays):
        time.sleep(seconds)
        return sample_shard(key, rays)

    return slow


def test_a_killed_8dna_worker_shard_is_traced_again(ray_local, shard_source, shards_here):
    from nasset_converters.mitsuba.eightdna_sampler import ShardedTuples

    killed = []

    def kill_one(actors):
        if not killed:
            pid = _rendering_worker_pid()
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    slow = cluster.ViewSource("tests.bakers.test_cluster:slow_shard_sampler", {"seconds": 1.0, **shard_source.kwargs})
    with cluster.WorkerPool(slow, workers=2, address=None, say=lambda *a: None) as pool:
        src = ShardedTuples(11, lambda jobs, on_result: pool.run(jobs, on_result, on_started=kill_one), batch=2)
        _same_tuples(shards_here[0], src.fill(TUPLES, 0))
    assert killed and killed[0] not in pool.summary and len(pool.summary) == 2  # restarted in a new process


def _neupress_source(tmp_path):
    from nasset_bakers.presets import NEUPRESS_MITSUBA_DATA
    from nasset_converters.mitsuba import neupress_dataset as nd
    from nasset_converters.mitsuba.neupress_example import EXAMPLE_ASSET_IDS, write_example_scene

    scene = write_example_scene(tmp_path / "scene", "tiny")
    dset = replace(nd.NeupressDataSettings(), **NEUPRESS_MITSUBA_DATA["tiny"], seed=1)
    dset = replace(dset, views=VIEWS, val_views=VAL_VIEWS, res=12, val_res=12, spp=4, val_spp=8)
    return cluster.ViewSource("nasset_bakers.mitsuba.neupress:view_renderer",
                              {"scene": scene, "asset_ids": list(EXAMPLE_ASSET_IDS), "dset": dset, "variant": None})


def _blender_source(tmp_path):
    pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")
    from nasset_bakers.presets import RNA_BLENDER_DATA
    from nasset_converters.blender import dataset as bds

    dset = replace(bds.DataSettings(), **RNA_BLENDER_DATA["tiny"], seed=2)
    dset = replace(dset, views=VIEWS, val_views=VAL_VIEWS, res=12, val_res=12, spp=4, val_spp=8)
    return cluster.ViewSource("nasset_bakers.blender.rna:view_renderer",
                              {"scene": None, "example": "blender-surface", "asset_ids": ["Monkey"], "dset": dset,
                               "work": str(tmp_path), "threads": 1})


def _mitsuba_curves_source(tmp_path):
    from nasset_bakers.presets import RNA_MITSUBA_DATA
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.hair_example import EXAMPLE_ASSET_IDS, write_example_scene

    scene = write_example_scene(tmp_path / "hair_scene", "tiny")
    dset = replace(ds.DataSettings(), **RNA_MITSUBA_DATA["tiny"], seed=4)
    dset = replace(dset, views=VIEWS, val_views=VAL_VIEWS, res=16, val_res=16, spp=4, val_spp=8)
    return cluster.ViewSource("nasset_bakers.mitsuba.rna:view_renderer",
                              {"scene": scene, "asset_ids": list(EXAMPLE_ASSET_IDS), "dset": dset, "variant": None})


@pytest.mark.parametrize("make", [_neupress_source, _blender_source, _mitsuba_curves_source],
                         ids=["neupress", "blender", "mitsuba-curves"])
def test_other_bakers_views_on_workers(ray_local, make, tmp_path):
    """The neupress (Mitsuba), rna (Cycles) and rna fiber (Mitsuba curves) view factories: two workers write what
    one process writes."""
    src = make(tmp_path)
    here, _ = _render(tmp_path, "here", src)
    there, summary = _render(tmp_path, "there", src, workers=2)
    _same(here, there)
    assert sum(w["jobs"] for w in summary.values()) == VIEWS + VAL_VIEWS
    assert not list(tmp_path.glob("cycles_*"))  # workers removed their Cycles temporary folders


def test_missing_ray_is_one_clear_message(monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(NassetError) as e:
        cluster.check_workers(2, None)
    assert e.value.code == "CONVERT_BACKEND" and "nasset-sdk[cluster]" in str(e.value)


def renderer_missing(**kwargs):
    """The Mitsuba rna view renderer in a worker where Mitsuba is not installed."""
    sys.modules["mitsuba"] = None  # an import of it now fails as on a node without the package
    from nasset_bakers.mitsuba.rna import view_renderer

    return view_renderer(**kwargs)


def test_worker_without_the_renderer_gives_the_typed_error(ray_local, source, tmp_path):
    missing = cluster.ViewSource("tests.bakers.test_cluster:renderer_missing", source.kwargs)
    with pytest.raises(NassetError) as e:
        _render(tmp_path, "missing", missing, workers=1)
    assert e.value.code == "CONVERT_BACKEND" and "mitsuba is not installed" in str(e.value)


def test_unreachable_cluster_fails_before_the_bake(tmp_path):
    from nasset_sdk.cli import main

    with pytest.raises(NassetError) as e:
        cluster.check_workers(2, "127.0.0.1:1")
    assert e.value.code == "CONVERT_BACKEND" and "127.0.0.1:1" in str(e.value)
    rc = main(["bake", "--example", "default", "--kind", "rna", "-o", str(tmp_path / "a.usdc"), "--size", "tiny",
               "--workers", "2", "--cluster", "127.0.0.1:1"])
    assert rc == 1 and not (tmp_path / "a.usdc.bake").exists()  # refused before any work


def test_worker_options_are_checked(tmp_path):
    from nasset_sdk.cli import main

    assert main(["bake", "--example", "default", "--kind", "rna", "-o", str(tmp_path / "a.usdc"), "--cluster", "x:1"]) == 2
    assert main(["bake", "--example", "default", "--kind", "rna", "-o", str(tmp_path / "a.usdc"), "--workers", "0"]) == 2


@pytest.mark.slow
def test_8dna_bake_on_workers_equals_one_process(ray_local, tmp_path):
    """``bake --kind 8dna --workers 2``: the held-out tuples and the trained asset's tensors equal a one-process bake's."""
    from nasset_bakers.mitsuba.eightdna import bake
    from nasset_sdk.asset import Asset

    runs = {}
    for name, kw in (("here", {}), ("there", {"workers": 2})):
        s = bake(None, None, tmp_path / f"{name}.usdc", size="tiny", example="default", epochs=3, spp=3, quiet=True, **kw)
        with np.load(Path(s["work_dir"]) / "heldout_tiny_0.npz") as z:
            held = {k: z[k] for k in z.files}
        a = Asset.open(s["asset"])
        a.load("all")
        runs[name] = (s, held, {t: np.asarray(a.tensor("core", t)) for t in ("triplane", "s1Grid")})
    (s1, h1, t1), (s2, h2, t2) = runs["here"], runs["there"]
    _same_tuples(h1, h2)
    for k in t1:
        np.testing.assert_array_equal(t1[k], t2[k], err_msg=k)
    assert s1["workers"] is None and len(s2["workers"]) == 2
