"""Benchmark (not a test): render throughput vs the bound set by onnxruntime and Embree.

    python -m nasset_benchmarks.renderer_throughput [--size small] [--res 256] [--spp 8] [--threads 1,2] [--repeat 3]
    python -m nasset_benchmarks.renderer_throughput --scene 8dna-near [--size small | --asset A.usdc] [--res 128] [--spp 2]
    python -m nasset_benchmarks.renderer_throughput --hair [--strands 20000] [--segments 4] [--res 128] [--spp 4]
    python -m nasset_benchmarks.renderer_throughput --usd SCENE.usda [--res 64] [--spp 16] [--repeat 3]
    python -m nasset_benchmarks.renderer_throughput --lights 8,64,512 [--res 64] [--spp 16] [--repeat 3]

Scene: one rna asset under a distant light (no other objects: NEE only). For each onnxruntime
thread setting, in one process and with that same setting throughout, it renders ``--repeat``
times and measures

* the decoder's raw onnxruntime throughput (the render's own session, random inputs, best over
  a few batch sizes: the bound should be the best the runtime can do, not one unlucky size),
* Embree's raw closest-hit throughput (rays at the asset, best over a few batch sizes),

then prints camera samples/s (median), the bound
1 / (evals_per_sample / onnx_rate + rays_per_sample / embree_rate), their ratio, where the render's
time goes (trace = Embree calls and their conversions, onnx = decoder runs, triplane = feature
lookups, encode = the rest of the network input, other = numpy path-tracing bookkeeping) and,
with ``--profile N``, the N functions with the most own time in one profiled render.

Rates are per second of this process's CPU time (``--clock cpu``, the default: steady on a machine shared
with other jobs, where wall time swings 2x) or of wall time (``--clock wall``); the time splits are wall
time within the render.

``--scene 8dna-near`` (:func:`eightdna_near_field`): one 8dna asset (the example of ``--size``, random
networks, or a baked ``--asset``, the camera and light framed on its box) lit by a small sphere light at
about one box size (near field: light samples at x_o and at every flow sample u_i). It prints camera
samples/s (median), onnxruntime calls and network rows per camera sample and the time split (trace, onnx,
network = the rest of the evaluator: encodings and spline math, other).

The process's heap is set as the ``nasset`` command sets it (``--allocator nasset``, the default:
nasset_sdk.process.tune_allocator) or left at glibc's defaults (``--allocator default``).

``--usd SCENE`` (:func:`main_usd`): any scene, e.g. one from ``nasset convert-scene``: the setup's CPU time
by phase and peak memory (on dense hair the setup, not the render loop, is what a short render waits for),
then camera samples/s and Embree queries per camera sample of the render loop.

``--lights N,...`` (:func:`main_lights`): a floor and a ball under N small sphere lights of powers spanning 100x,
rendered with every light sampled at every vertex (``light_draws = 0``) and with the default draws
(spec/renderer.md#light-selection), alternating, in one process: CPU time, Embree queries per camera sample, the
per-sample variance (the film's variance of the pixel means times spp, averaged over the image) and the speed-up at
equal error, (time x variance) of every light over that of the draws; the two image means with their standard errors
say whether they agree.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import pstats
import tempfile
import time
from pathlib import Path

import numpy as np

BATCHES = (4096, 8192, 16384, 65536)

#: the clock of rates (``--clock``): this process's CPU time (default; onnxruntime runs on one thread and
#: Embree traces on the calling thread, so it is the work done, steady on a machine shared with other
#: jobs) or wall time. Time splits are always wall time within the render.
_clock = time.process_time


class _TimedSession:
    """Wraps an onnxruntime session; accumulates the wall time of ``run``."""

    def __init__(self, session) -> None:
        self.session, self.time, self.calls, self.rows = session, 0.0, 0, 0

    def run(self, output_names, input_feed, *args, **kw):
        t = time.perf_counter()
        try:
            return self.session.run(output_names, input_feed, *args, **kw)
        finally:
            self.time += time.perf_counter() - t
            self.calls += 1
            self.rows += len(next(iter(input_feed.values()))) if input_feed else 0

    def __getattr__(self, name):
        return getattr(self.session, name)


def _best_rate(fn, n: int, min_time: float = 0.15, rounds: int = 3) -> float:
    """Best items/s of fn() over a few timed rounds (each at least ``min_time`` seconds)."""
    fn()  # warm up
    best = 0.0
    for _ in range(rounds):
        reps, t0 = 0, _clock()
        while True:
            fn()
            reps += 1
            dt = _clock() - t0
            if dt >= min_time:
                break
        best = max(best, reps * n / dt)
    return best


def _scene(size: str):
    from nasset_reference_renderer.scene import load_scene
    from nasset_reference_renderer.testscenes import SceneBuilder, random_rna_asset

    tmp = Path(tempfile.mkdtemp())
    asset = random_rna_asset(tmp / "a.usdc", size=size)
    b = SceneBuilder()
    b.camera((0, 0.3, 2.2), (0, 0, 0), focal=35)
    b.distant("Sun", (0.4, 1.0, 0.3), 3.0)
    b.asset("Obj", asset)
    return load_scene(b.write(tmp / "bench.usda"))


def run_one(scene, a, threads: int) -> dict:
    from nasset_reference_renderer.accel import EmbreeBackend
    from nasset_reference_renderer.integrator import RenderSettings, prepare_assets, render, resolve_settings
    from nasset_reference_renderer.plan import make_plan
    from nasset_sdk.kinds import rna

    settings = resolve_settings(RenderSettings(spp=a.spp, width=a.res, height=a.res, threads=threads, batch=a.batch, workers=a.workers), scene)
    for data in scene.assets:
        data.evaluator = None  # a fresh evaluator (and session) for this thread setting
    width, height = scene.camera.default_resolution(settings.width, settings.height)
    plan = make_plan(scene, width=width, height=height, spp=settings.spp, max_depth=settings.max_depth,
                     tile=settings.tile, batch=settings.batch)
    prepare_assets(scene, plan, settings)
    ev = scene.assets[0].evaluator
    timed = _TimedSession(ev.session)
    ev.session = timed
    tri_time = [0.0]
    triplane = rna.triplane

    def timed_triplane(*args):
        t = time.perf_counter()
        try:
            return triplane(*args)
        finally:
            tri_time[0] += time.perf_counter() - t

    render(scene, RenderSettings(spp=1, width=16, height=16, threads=threads))  # warm up
    runs = []
    rna.triplane = timed_triplane
    try:
        for _ in range(a.repeat):
            timed.time, tri_time[0] = 0.0, 0.0
            c0 = _clock()
            st = render(scene, settings).stats
            runs.append((_clock() - c0, st.time_total, st.time["trace"], timed.time, tri_time[0], st.time["network"], st))
    finally:
        rna.triplane = triplane
    runs.sort(key=lambda r: r[0])
    clock_t, total, trace, onnx_t, tri_t, net_t, st = runs[len(runs) // 2]  # the median run
    out = dict(threads=threads, st=st, rate=st.camera_samples / clock_t, total=total, trace=trace, onnx=onnx_t,
               triplane=tri_t, encode=net_t - onnx_t - tri_t, other=total - trace - net_t,
               rates=[r[6].camera_samples / r[0] for r in runs])
    if a.profile:
        pr = cProfile.Profile()
        pr.enable()
        render(scene, settings)
        pr.disable()
        s = io.StringIO()
        pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(a.profile)
        out["profile"] = s.getvalue()
    ev.session = timed.session

    # raw decoder throughput: the render's session (same thread setting), best batch size
    width_in = ev.session.get_inputs()[0].shape[1]
    rng = np.random.default_rng(0)
    onnx_rates = {}
    for n in BATCHES:
        x = rng.random((n, width_in)).astype(np.float32)
        onnx_rates[n] = _best_rate(lambda x=x: ev.session.run(None, {"x": x}), n)
    # raw Embree throughput: closest hit, coherent-ish random rays at the asset, best batch size
    emb = EmbreeBackend(scene.triangles)
    emb_rates = {}
    for n in BATCHES:
        o = np.tile([[0.0, 0.3, 2.2]], (n, 1))
        d = rng.normal(0, 0.15, (n, 3)) + [0, -0.3, -2.2]
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        emb_rates[n] = _best_rate(lambda o=o, d=d, n=n: emb.closest(o, d, np.full(n, np.inf)), n)
    out.update(onnx_rates=onnx_rates, emb_rates=emb_rates)
    return out


def _eightdna_scene(size: str, asset: str | None = None):
    """The near-field scene around the ``size`` example asset, or around the 8dna asset file ``asset``."""
    from nasset_reference_renderer.scene import load_scene
    from nasset_reference_renderer.testscenes import SceneBuilder
    from nasset_sdk.asset import Asset
    from nasset_sdk.examples import example_builder

    tmp = Path(tempfile.mkdtemp())
    given = asset is not None
    asset = Path(asset).resolve() if given else example_builder("8dna", size=size, seed=0).write(tmp / "e.usdc")
    centre, scale = np.zeros(3), 1.0  # the example's box: 1.02 on a side, centred
    if given:
        lo, hi = (np.asarray(v, np.float64) for v in Asset.open(asset).domain)
        centre, scale = (lo + hi) / 2, float(np.max(hi - lo)) / 1.02
    at = lambda p: tuple(centre + scale * np.asarray(p))  # noqa: E731 -- the layout framed on the asset's box
    b = SceneBuilder()
    b.camera(at((0, 0.4, 3.0)), tuple(centre), focal=55)
    b.sphere_light("Bulb", at((0.9, 0.9, 0.8)), 0.35 * scale, 8.0)  # near field: about one box size from the asset
    b.asset("Obj", asset)
    return load_scene(b.write(tmp / "bench8.usda"))


def _wrap_sessions(ev) -> list[_TimedSession]:
    """Replace every onnxruntime session the 8dna evaluator runs by a timed one; returns them."""
    timed = []

    def wrap(s):
        timed.append(_TimedSession(s))
        return timed[-1]

    ev.albedo_session = wrap(ev.albedo_session)
    ev.flow_sessions = [wrap(s) for s in ev.flow_sessions]
    if getattr(ev, "tails", None) is not None:
        ev.head = wrap(ev.head)
        ev.tails = [(wrap(s), names) for s, names in ev.tails]
    return timed


def eightdna_near_field(a, threads: int) -> dict:
    """Render the 8dna near-field scene ``a.repeat`` times; the median run's rates and time split."""
    from nasset_reference_renderer.integrator import RenderSettings, prepare_assets, render, resolve_settings
    from nasset_reference_renderer.plan import make_plan

    scene = _eightdna_scene(a.size, a.asset)
    settings = resolve_settings(RenderSettings(spp=a.spp, width=a.res, height=a.res, threads=threads, batch=a.batch, workers=a.workers), scene)
    width, height = scene.camera.default_resolution(settings.width, settings.height)
    plan = make_plan(scene, width=width, height=height, spp=settings.spp, max_depth=settings.max_depth,
                     tile=settings.tile, batch=settings.batch)
    prepare_assets(scene, plan, settings)
    timed = _wrap_sessions(scene.assets[0].evaluator)
    render(scene, RenderSettings(spp=1, width=16, height=16, threads=threads))  # warm up
    runs = []
    for _ in range(a.repeat):
        for t in timed:
            t.time, t.calls, t.rows = 0.0, 0, 0
        c0 = _clock()
        st = render(scene, settings).stats
        clock_t = _clock() - c0
        onnx_t = sum(t.time for t in timed)
        runs.append(dict(clock=clock_t, total=st.time_total, trace=st.time["trace"], onnx=onnx_t, network=st.time["network"] - onnx_t,
                         other=st.time_total - st.time["trace"] - st.time["network"], st=st,
                         calls=sum(t.calls for t in timed), rows=sum(t.rows for t in timed)))
    runs.sort(key=lambda r: r["clock"])
    out = runs[len(runs) // 2]
    out["rate"] = out["st"].camera_samples / out["clock"]
    out["rates"] = [r["st"].camera_samples / r["clock"] for r in runs]
    return out


def _print_eightdna(a, threads: int) -> None:
    r = eightdna_near_field(a, threads)
    n = r["st"].camera_samples
    print(f"\n== 8dna near field, onnxruntime intra-op threads {threads} ==")
    print(f"render:      {r['rate']:12,.0f} camera samples/s  ({r['total']:.3f} s; runs "
          + ", ".join(f"{x:,.0f}" for x in sorted(r["rates"])) + ")")
    print(f"per sample:  {r['calls'] / n:.4f} onnxruntime calls, {r['rows'] / n:.2f} network rows, "
          f"{r['st'].rays / n:.3f} rays")
    parts = [(k, r[k]) for k in ("trace", "onnx", "network", "other")]
    print("time:        " + ", ".join(f"{k} {v:.3f} s ({100 * v / r['total']:.0f}%)" for k, v in parts))


# -- dense hair: geometry queries whose cost does not grow with the fibres a ray crosses --------------------------
def hair_scene(n_strands: int, segments: int, floor: bool):
    """A synthetic rna fiber asset (random networks, :func:`dense_hair_curves`) under a distant light,
    optionally over a floor (then hair vertices also trace continuation rays)."""
    import warnings

    from nasset_reference_renderer.scene import load_scene
    from nasset_reference_renderer.testscenes import SceneBuilder, dense_hair_curves, random_rna_fiber_asset

    tmp = Path(tempfile.mkdtemp())
    asset = random_rna_fiber_asset(tmp / "hair.usdc", dense_hair_curves(n_strands, segments), seed=3)
    b = SceneBuilder()
    b.camera((0, 0.2, 2.0), (0, 0.1, 0), focal=35)
    b.distant("Sun", (0.4, 1.0, 0.3), 3.0)
    if floor:
        b.quad("Floor", (0, -0.6, 0), 4.0)
    b.asset("Hair", asset)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # no fallback material warnings
        return load_scene(b.write(tmp / "hair.usda"))


def run_hair(scene, a) -> dict:
    """One timed render of a hair scene (after a warm-up): samples/s, rays per sample, setup and trace time."""
    from nasset_reference_renderer.integrator import RenderSettings, render

    t0 = time.perf_counter()
    warm = render(scene, RenderSettings(spp=1, width=8, height=8, threads=1))  # loads and compiles the decoder
    first_setup = time.perf_counter() - t0 - warm.stats.time_total  # the first render builds the Embree structures
    t0 = time.perf_counter()
    st = render(scene, RenderSettings(spp=a.spp, width=a.res, height=a.res * 3 // 4, threads=1, batch=a.batch,
                                      workers=a.workers)).stats
    wall = time.perf_counter() - t0
    # the render loop only: the setup builds Embree's BVH on several threads
    loop = st.cpu_total if _clock is time.process_time else st.time_total
    return dict(rate=st.camera_samples / loop, rays=st.rays / st.camera_samples, total=st.time_total,
                trace=st.time["trace"], setup=wall - st.time_total, first_setup=first_setup, samples=st.camera_samples)


def tessellation_bytes(scene) -> dict:
    """Bytes per fiber segment the renderer holds for the scene's fibre prisms, without Embree's BVH nodes:
    ``renderer`` its numpy arrays per triangle (world corners, instance and local ids, unit face normals; neural
    triangles have no corner normals or texture coordinates), ``embree`` the arrays Embree reads in place (float32
    world points per instance, the quads and their tables per asset: nasset_sdk/embree.py)."""
    fibres = [data for data in scene.assets if data.fiber is not None]
    segs = sum(len(data.fiber.p0) * len(data.prims) for data in fibres)
    n_tri = sum(len(data.fiber.faces) * len(data.prims) for data in fibres)
    per_tri = (scene.triangles.itemsize * 9 + scene.tri_inst.itemsize + scene.tri_local.itemsize
               + scene.tri_ng.itemsize * 3)
    embree = sum(12 * (len(data.fiber.points) + 1) * len(data.prims)
                 + sum(a.nbytes for a in (data.fiber.quads, data.fiber.quad_tri, data.fiber.quad_corners) if a is not None)
                 for data in fibres)
    per_seg = lambda b: b / max(segs, 1)  # noqa: E731
    return dict(segments=segs, triangles=n_tri, tri_per_segment=per_seg(n_tri), renderer=per_seg(per_tri * n_tri),
                embree=per_seg(embree), bytes_per_segment=per_seg(per_tri * n_tri + embree))


def main_hair(a) -> int:
    import resource

    print(f"dense hair: {a.strands} strands x {a.segments} segments, {a.res}x{a.res * 3 // 4} x {a.spp} spp, "
          "onnxruntime 1 thread")
    for floor in (False, True):
        scene = hair_scene(a.strands, a.segments, floor)
        mem = tessellation_bytes(scene)
        r = run_hair(scene, a)
        print(f"{'hair over a floor' if floor else 'hair alone (NEE only)'}: {r['rate']:,.0f} camera samples/s, "
              f"{r['rays']:.2f} rays/sample, trace {r['trace']:.2f} of {r['total']:.2f} s, setup: first render "
              f"{r['first_setup']:.2f} s (plan, decoder, integrator arrays, Embree build), this render {r['setup']:.2f} s")
        del scene
    print(f"tessellation: {mem['triangles']:,} triangles, {mem['tri_per_segment']:.0f} per segment, "
          f"{mem['bytes_per_segment']:,.0f} B per segment ({mem['renderer']:,.0f} in renderer arrays, "
          f"{mem['embree']:,.0f} in arrays Embree reads, without its BVH); peak RSS "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:,.0f} MiB")
    return 0


def main_usd(a) -> int:
    """A user's scene (``--usd FILE``): the setup's CPU time by phase (loading, with the fibre tessellation, then
    the acceleration structures) and peak memory, then the render loop at --res x --res x --spp."""
    import resource

    from nasset_reference_renderer import RenderSettings, load_scene, render

    t = time.process_time()
    scene = load_scene(a.usd)
    t_load = time.process_time() - t
    t = time.process_time()
    render(scene, RenderSettings(width=8, height=8, spp=1, progress=False))  # builds the structures (kept by the scene)
    t_struct = time.process_time() - t
    mem = tessellation_bytes(scene) if any(d.fiber is not None for d in scene.assets) else None
    print(f"scene: {a.usd}, {len(scene.triangles):,} triangles; setup (CPU s): load {t_load:.1f}, structures and "
          f"first render {t_struct:.1f}; peak RSS {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:,.0f} MiB")
    if mem:
        print(f"fibres: {mem['triangles']:,} triangles, {mem['bytes_per_segment']:,.0f} B per segment "
              f"({mem['renderer']:,.0f} in renderer arrays, {mem['embree']:,.0f} in arrays Embree reads)")
    for _ in range(a.repeat):
        st = render(scene, RenderSettings(width=a.res, height=a.res, spp=a.spp, progress=False, workers=a.workers)).stats
        loop = st.cpu_total if a.clock == "cpu" else st.time_total
        print(f"render {a.res}x{a.res} x {a.spp} spp: {st.camera_samples / loop:,.0f} camera samples/s, "
              f"{st.rays / st.camera_samples:.2f} Embree queries per camera sample, trace {st.time['trace']:.2f} of "
              f"{st.time_total:.2f} s wall")
    return 0


def many_lights_scene(n: int, path) -> str:
    """A 16 x 16 floor and a ball under ``n`` sphere lights (radius 0.05-0.2, 0.3-3 m up, powers over 100x about a
    total that does not depend on ``n``, random colours, hidden from the camera: their own pixels would dominate the
    variance), seen from above at an angle. Returns the written scene's path."""
    from pxr import Sdf

    from nasset_reference_renderer.testscenes import SceneBuilder

    rng = np.random.default_rng(n)
    b = SceneBuilder()
    b.camera((0, 5, 7), (0, 0, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 16.0, diffuse=(0.6, 0.6, 0.6))
    b.sphere_mesh("Ball", (0, 1, 0), 1.0, diffuse=(0.5, 0.3, 0.2))
    for i in range(n):
        p = (rng.uniform(-8, 8), rng.uniform(0.3, 3.0), rng.uniform(-8, 8))
        r = rng.uniform(0.05, 0.2)
        light = b.sphere_light(f"L{i}", p, r, 20.0 / (n * r * r) * 10 ** rng.uniform(-1, 1),
                               color=tuple(rng.uniform(0.3, 1.0, 3)))
        light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool).Set(False)
    return b.write(path)


def main_lights(a) -> int:

    from nasset_reference_renderer import RenderSettings, load_scene, render

    print(f"many lights: {a.res}x{a.res} x {a.spp} spp, max depth 4, every light (light_draws 0) against the default "
          f"draws, alternating, least CPU time of {a.repeat}")
    print("| lights | every light: s, queries / camera sample, variance | draws: s, queries / camera sample, variance "
          "| time ratio | equal-error speed-up | image means (every / draws, standard errors) |")
    with tempfile.TemporaryDirectory() as tmp:
        for n in [int(v) for v in a.lights.split(",")]:
            scene = load_scene(many_lights_scene(n, Path(tmp) / f"lights{n}.usda"))
            runs = {0: [], RenderSettings.light_draws: []}
            for _ in range(a.repeat):
                for draws in runs:
                    res = render(scene, RenderSettings(width=a.res, height=a.res, spp=a.spp, max_depth=4, seed=len(runs[draws]),
                                                       workers=a.workers, light_draws=draws))
                    runs[draws].append(res)
            row = {}
            for draws, rs in runs.items():
                t = min(r.stats.cpu_total if a.clock == "cpu" else r.stats.time_total for r in rs)
                r = rs[0]
                k = r.image.shape[0] * r.image.shape[1]
                var = float(r.variance.mean()) * a.spp
                row[draws] = (t, r.stats.rays / r.stats.camera_samples, var, r.image.mean(), np.sqrt(r.variance.mean(-1).sum()) / k)
            (t0, q0, v0, m0, e0), (t1, q1, v1, m1, e1) = row[0], row[RenderSettings.light_draws]
            print(f"| {n} | {t0:.2f}, {q0:.1f}, {v0:.3g} | {t1:.2f}, {q1:.1f}, {v1:.3g} | {t0 / t1:.2f}x | "
                  f"{t0 * v0 / (t1 * v1):.2f}x | {m0:.4f} ± {e0:.4f} / {m1:.4f} ± {e1:.4f} |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scene", default="rna", choices=("rna", "8dna-near"))
    ap.add_argument("--size", default="small")
    ap.add_argument("--asset", metavar="FILE", help="--scene 8dna-near: this 8dna asset instead of the --size example")
    ap.add_argument("--res", type=int, default=256)
    ap.add_argument("--spp", type=int, default=8)
    ap.add_argument("--threads", default="1,2", help="onnxruntime intra-op threads, a comma list (0: its default)")
    ap.add_argument("--batch", type=int, default=65536)
    ap.add_argument("--repeat", type=int, default=3, help="renders per setting (the median is reported)")
    ap.add_argument("--profile", type=int, default=12, help="top entries of a profiled render (0: none)")
    ap.add_argument("--hair", action="store_true", help="dense-hair scenes instead (see main_hair)")
    ap.add_argument("--usd", metavar="FILE", help="a USD scene instead: setup by phase, then the render loop (main_usd)")
    ap.add_argument("--lights", metavar="N,...", help="scenes of N sphere lights instead: every light against the "
                                                      "draws of spec/renderer.md#light-selection (main_lights)")
    ap.add_argument("--strands", type=int, default=20000)
    ap.add_argument("--segments", type=int, default=4)
    ap.add_argument("--workers", type=int, default=1,
                    help="render threads (default 1: the CPU-time rates and the bound are one thread's; compare more "
                         "threads with --clock wall)")
    ap.add_argument("--clock", default="cpu", choices=("cpu", "wall"),
                    help="rates per second of this process's CPU time (steady under other jobs) or of wall time")
    ap.add_argument("--allocator", default="nasset", choices=("nasset", "default"),
                    help="the heap settings the `nasset` command runs with (nasset_sdk.process), or glibc's defaults")
    a = ap.parse_args(argv)
    if a.asset and (a.scene != "8dna-near" or not Path(a.asset).is_file()):
        ap.error(f"--asset {a.asset}: " + ("applies to --scene 8dna-near only" if a.scene != "8dna-near" else "no such file"))
    global _clock
    _clock = time.process_time if a.clock == "cpu" else time.perf_counter
    print(f"rates per second of {'CPU time of this process' if a.clock == 'cpu' else 'wall time'}; render threads {a.workers}")
    if a.allocator == "nasset":
        from nasset_sdk.process import tune_allocator

        tuned = tune_allocator()
        print("allocator: " + ("the nasset command's heap settings" if tuned else "unchanged (not glibc, or set by the user)"))
    if a.scene == "8dna-near":
        what = f"asset {a.asset}" if a.asset else f"'{a.size}' example asset"
        print(f"scene: 8dna {what}, sphere light in the near field, {a.res}x{a.res} x {a.spp} spp "
              f"(median of {a.repeat} renders per thread setting)")
        for threads in [int(t) for t in a.threads.split(",")]:
            _print_eightdna(a, threads)
        return 0
    if a.hair:
        return main_hair(a)
    if a.usd:
        return main_usd(a)
    if a.lights:
        return main_lights(a)
    scene = _scene(a.size)
    print(f"scene: rna '{a.size}' asset, distant light, {a.res}x{a.res} x {a.spp} spp "
          f"(median of {a.repeat} renders per thread setting)")
    for threads in [int(t) for t in a.threads.split(",")]:
        r = run_one(scene, a, threads)
        st = r["st"]
        onnx_rate, ray_rate = max(r["onnx_rates"].values()), max(r["emb_rates"].values())
        evals_ps = st.network_evals / st.camera_samples
        rays_ps = st.rays / st.camera_samples
        bound = 1.0 / (evals_ps / onnx_rate + rays_ps / ray_rate)
        fmt = lambda d: ", ".join(f"{n}: {v / 1e6:.2f}M" for n, v in d.items())  # noqa: E731
        print(f"\n== onnxruntime intra-op threads {threads} ==")
        print(f"render:      {r['rate']:12,.0f} camera samples/s  ({r['total']:.3f} s; runs "
              + ", ".join(f"{x:,.0f}" for x in sorted(r["rates"])) + ")")
        print(f"onnxruntime: {onnx_rate:12,.0f} decoder evals/s (best; per batch {fmt(r['onnx_rates'])})")
        print(f"embree:      {ray_rate:12,.0f} rays/s (best; per batch {fmt(r['emb_rates'])})")
        print(f"per sample:  {evals_ps:.3f} network evals, {rays_ps:.3f} rays")
        if a.workers == 1:  # the bound is one thread's
            print(f"bound:       {bound:12,.0f} samples/s -> ratio {r['rate'] / bound:.2f}")
        parts = [("trace", r["trace"]), ("onnx", r["onnx"]), ("triplane", r["triplane"]), ("encode", r["encode"]),
                 ("other", r["other"])]
        print("time:        " + ", ".join(f"{k} {v:.3f} s ({100 * v / r['total']:.0f}%)" for k, v in parts))
        in_render = st.network_evals / max(r["onnx"], 1e-12), st.rays / max(r["trace"], 1e-12)
        print(f"in render:   onnxruntime {in_render[0]:,.0f} evals/s, trace {in_render[1]:,.0f} rays/s (incl. conversions)")
        if "profile" in r:
            lines = r["profile"].strip().splitlines()
            start = next((i for i, line in enumerate(lines) if line.lstrip().startswith("ncalls")), 0)
            print("profile (own time, one render under cProfile):")
            print("\n".join("  " + line for line in lines[start:]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
