"""``nasset bench error-vs-time SCENE.xml --replace ID=ASSET.usdc``: the same engine with and without the asset.

Both renders run in Mitsuba's JIT (``llvm_ad_rgb`` here, ``cuda_ad_rgb`` with ``--variant``), in this
process, one after the other, through one camera at one resolution:

* **reference**: the original scene with its own integrator (``volpath`` for media) at ``--gt-spp``,
  as two independent unclamped halves (``accuracy.render_halves``; kept in the output folder and
  reused for the same scene, size, spp and seed); its noise variance ``mean((a - b)^2) / 4`` is
  subtracted from every MSE and reported;
* **(a) path tracing**: the original scene, the same integrator, at each of ``--mi-spp``;
* **(b) asset**: the scene with the replaced shapes swapped for the asset (``nasset_mitsuba_plugin``:
  the ``nasset_path`` integrator with the scene integrator's ``max_depth`` and ``rr_depth``), at each of
  ``--nr-spp``.

Timing (``time.perf_counter``) is one ``mi.render`` call plus the read-back, after a warm-up render at
the same spp (JIT kernels compiled and cached): the least of ``repeats`` such calls (other jobs on a
shared machine only ever add time); the MSE is that of the first. Reported: the points (spp, time, MSE), the asset's
**bias floor** (its last point's MSE minus its own variance, measured from a second render at that spp),
the **equal-error speedup** at each asset point and at the bias floor (``common.equal_error_speedup``),
and the **per-sample cost ratio** (asset time per spp / path tracing time per spp, at the largest spp
both ran, timed in alternating pairs: :func:`alternating_cost`). The MSE, floor and speedups are given
twice: over the whole image, and over the **object's pixels** (mask from Mitsuba's camera rays on the replaced
shapes, ``accuracy.object_mask``, half coverage), where the asset does its work; the whole image adds the rest
of the scene's noise, which both renders share. Plot (PNG) + JSON in the output folder.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from nasset_benchmarks.accuracy import check_asset_fits, mitsuba_halves, object_mask, sensor_for
from nasset_benchmarks.common import equal_error_speedup, machine, mi_render, plot
from nasset_converters.mitsuba.scene import integrator_depths, load_scene, media_caveats, require_integrator
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder, write_text_atomic


def bench_equal_engine(scene_file, replace: dict, out_dir, *, res: int = 128, gt_spp: int = 4096, mi_spp=(1, 4, 16, 64),
                       nr_spp=(1, 4, 16, 64), seed: int = 0, variant: str | None = None, repeats: int = 3,
                       quiet: bool = False) -> dict:
    """Run the benchmark (module docstring); writes ``error_vs_time.json`` and ``error_vs_time.png`` into ``out_dir``."""
    from nasset_mitsuba_plugin.plugins import INTEGRATOR
    from nasset_mitsuba_plugin.scene import load_file
    from nasset_mitsuba_plugin.variant import jit_mitsuba

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    if res < 8 or gt_spp < 2:
        raise UsageError(f"--res must be >= 8 and --gt-spp >= 2 (got {res}, {gt_spp})")
    if not Path(scene_file).is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(scene_file))
    if not replace:
        raise UsageError("give at least one --replace ID[,ID]=ASSET.usdc")
    out = Path(out_dir)
    output_folder(out)
    mi = jit_mitsuba(variant)
    mi.set_log_level(mi.LogLevel.Error)
    t_setup = time.perf_counter()
    original = load_scene(mi, scene_file)
    require_integrator(original, scene_file)
    check_asset_fits(mi, original, replace, scene_file=str(scene_file))  # ids, files, kinds, the shapes they were baked from
    caveats = media_caveats(mi, original, replace)
    for caveat in caveats:
        say(f"warning: {caveat}")
    settings = {"max_depth": -1, "rr_depth": 5} | integrator_depths(original.integrator())  # Mitsuba's defaults
    with_asset = load_file(scene_file, mi=mi, replace={k: str(v) for k, v in replace.items()}, own_integrator=True)
    nasset = mi.load_dict({"type": INTEGRATOR, "max_depth": settings["max_depth"] if settings["max_depth"] > 0 else 1024,
                           "rr_depth": settings["rr_depth"]})
    sensor, hw = sensor_for(mi, original, res, file=str(scene_file))

    def pt(spp, s):
        return mi_render(mi, original, sensor, spp, s)

    def na(spp, s):
        return np.asarray(mi.render(with_asset, sensor=sensor, integrator=nasset, spp=int(spp), seed=int(s)), np.float64)[..., :3]

    t = time.perf_counter()
    a, b, half, key, reused = mitsuba_halves(mi, original, sensor, hw, scene_file, out, gt_spp, seed, say=say, quiet=quiet)
    if not reused:
        from nasset_reference_renderer.film import write_exr

        for name, img in (("reference_a", a), ("reference_b", b)):
            write_exr(out / f"{name}.exr", img.astype(np.float32))
        write_text_atomic(out / "reference_key.json", json.dumps(key))
    t_ref = time.perf_counter() - t
    ref = 0.5 * (a + b)
    var_ref = float(np.mean((a - b) ** 2) / 4.0)
    mask = object_mask(mi, original, sensor, [i for k in replace for i in str(k).split(",")], hw) >= 0.5
    var_ref_obj = float(np.mean(((a - b) ** 2)[mask]) / 4.0) if mask.any() else 0.0

    def points(render, spps, base, name):
        pts = []
        for k, spp in enumerate(spps):
            render(spp, 90_000 + base + k)  # warm-up: compile / fetch this spp's kernel
            times_k, img = [], None
            for r in range(max(1, int(repeats))):
                t = time.perf_counter()
                out = render(spp, base + k + 1000 * r)
                times_k.append(time.perf_counter() - t)
                img = out if img is None else img
            dt = min(times_k)  # the least disturbed of the repeats (shared machines)
            sq = np.nan_to_num(img - ref) ** 2
            mse_raw = float(np.mean(sq))
            pts.append({"spp": int(spp), "time_s": dt, "mse": mse_raw - var_ref, "mse_raw": mse_raw, "image": img,
                        "mse_object": float(np.mean(sq[mask])) - var_ref_obj if mask.any() else None})
            say(f"  {name} {spp:5d} spp  {dt:8.3f}s  MSE {mse_raw - var_ref:.3e}")
        return pts

    mi_points = points(pt, mi_spp, 10, "path tracing")
    nr_points = points(na, nr_spp, 5000, "asset       ")
    last = nr_points[-1]
    second = na(last["spp"], 7777)
    d2 = (last["image"] - second) ** 2
    var_last = float(np.mean(d2) / 2.0)  # one render's pixel variance, from two seeds
    last["variance"] = var_last
    floor = last["mse"] - var_last
    obj = None
    if mask.any():
        floor_obj = last["mse_object"] - float(np.mean(d2[mask]) / 2.0)
        mean_asset = 0.5 * (last["image"] + second)[mask].mean(0)  # [3], two renders at the last spp
        energy = mean_asset / np.maximum(ref[mask].mean(0), 1e-12)
        on = [[{"spp": p["spp"], "time_s": p["time_s"], "mse": p["mse_object"]} for p in pts] for pts in (mi_points, nr_points)]
        speed_obj = equal_error_speedup(*on)
        best_obj = max((s for s in speed_obj if s["speedup"] is not None), key=lambda s: s["speedup"], default=None)
        obj = {"pixels": int(mask.sum()), "mask": "mitsuba camera rays, first hit on the replaced shapes, >= half coverage",
               "reference_noise_variance": var_ref_obj, "bias_floor_mse": floor_obj,
               "energy_ratio": [float(e) for e in energy],  # asset / reference over the object, at the last spp
               "bias_floor_relative_rmse": math.sqrt(max(floor_obj, 0.0)) / max(float(np.mean(ref[mask])), 1e-12),
               "equal_error": speed_obj, "best_equal_error_speedup": None if best_obj is None else best_obj["speedup"]}
    for p in mi_points + nr_points:
        p.pop("image")
    speed = equal_error_speedup(mi_points, nr_points)
    floor_eq = equal_error_speedup(mi_points, [{"spp": 0, "mse": floor, "time_s": 1.0}])
    common = max(set(mi_spp) & set(nr_spp), default=None)
    cost = None if common is None else alternating_cost(pt, na, common, repeats)
    best = max((s for s in speed if s["speedup"] is not None), key=lambda s: s["speedup"], default=None)
    mean = float(np.mean(ref))
    report = {
        "benchmark": "error-vs-time (equal engine)",
        "scene": str(scene_file),
        "replace": {k: str(v) for k, v in replace.items()},
        "resolution": [hw[1], hw[0]],
        "mitsuba": {"version": mi.__version__, "variant": mi.variant(), "integrator": str(original.integrator()).splitlines()[0],
                    "settings": settings},
        "reference": {"spp": 2 * half, "mean_radiance": mean, "noise_variance": var_ref, "time_s": t_ref, "reused": reused,
                      "noise_relative_rmse": math.sqrt(var_ref) / max(mean, 1e-12), "warnings": caveats},
        "path_tracing_points": mi_points,
        "asset_points": nr_points,
        "bias_floor_mse": floor,
        "bias_floor_relative_rmse": math.sqrt(max(floor, 0.0)) / max(mean, 1e-12),
        "bias_floor_path_tracing_equivalent": None if not floor_eq or floor_eq[0]["mitsuba_spp"] is None else
        {"spp": floor_eq[0]["mitsuba_spp"], "time_s": floor_eq[0]["mitsuba_time_s"]},
        "equal_error": speed,
        "best_equal_error_speedup": None if best is None else best["speedup"],
        "per_sample_cost": cost,
        "object": obj,  # the same over the object's pixels (None when the replaced shapes are not in view)
        "timing_includes": f"one mi.render call + image read-back, after a warm-up render at the same spp (no scene load, no JIT "
                           f"compile); the least of {max(1, int(repeats))} repeats",
        "machine": machine(),
        "setup_s": round(time.perf_counter() - t_setup, 2),
    }
    report["plot_backend"] = plot(out / "error_vs_time.png", mi_points, nr_points, floor,
                                  f"{Path(scene_file).name} {hw[1]}x{hw[0]}, {mi.variant()}",
                                  labels=("Mitsuba path tracing (original scene)", "Mitsuba + nasset plugin (asset scene)"))
    report["files"] = [str(out / "error_vs_time.json"), str(out / "error_vs_time.png")]
    tmp = out / "error_vs_time.json.tmp"
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out / "error_vs_time.json")
    return report


def alternating_cost(pt, na, spp: int, repeats: int, clock=time.perf_counter) -> dict:
    """Per-sample cost at ``spp``: path tracing and asset renders alternating, ``max(3, repeats)`` pairs (both
    kernels already compiled by the points at this spp). The points' own times are measured in blocks (every
    path-tracing point, then every asset point), so another job's burst on a shared machine can land on one
    side only; pairs see the same load. ``ratio``: least asset time / least path-tracing time (the
    documented definition); ``paired_median``: the median of the pairs' own ratios."""
    tp, tn = [], []
    for r in range(max(3, int(repeats))):
        t = clock()
        pt(spp, 70_000 + r)
        tp.append(clock() - t)
        t = clock()
        na(spp, 80_000 + r)
        tn.append(clock() - t)
    pairs = [b / max(a, 1e-12) for a, b in zip(tp, tn, strict=True)]
    return {"spp": int(spp), "path_tracing_s": min(tp), "asset_s": min(tn), "ratio": min(tn) / max(min(tp), 1e-12),
            "paired_median": float(np.median(pairs)), "pairs": len(pairs),
            "method": "path tracing and asset renders alternating; least of each, and the median of the pairs' ratios"}


def summary_text(r: dict) -> str:
    ref = r["reference"]
    lines = [f"error vs time in one engine ({r['mitsuba']['variant']}), {r['scene']} at {r['resolution'][0]}x{r['resolution'][1]}; "
             f"reference {ref['spp']} spp (noise variance {ref['noise_variance']:.2e} subtracted, relative RMSE "
             f"{ref['noise_relative_rmse']:.1%})",
             f"{'':14s}{'spp':>6s} {'time s':>9s} {'MSE':>10s}"]
    for name, pts in (("path tracing", r["path_tracing_points"]), ("asset", r["asset_points"])):
        for p in pts:
            lines.append(f"{name:14s}{p['spp']:6d} {p['time_s']:9.3f} {p['mse']:10.3e}")
    lines.append(f"asset bias floor: MSE {r['bias_floor_mse']:.3e} (relative RMSE {r['bias_floor_relative_rmse']:.1%})")
    fe = r["bias_floor_path_tracing_equivalent"]
    if fe:
        lines.append(f"  path tracing reaches the floor at about {fe['spp']:.1f} spp ({fe['time_s']:.3f}s)")
    for s in r["equal_error"]:
        lines.append(f"  asset {s['spp']:4d} spp: " + ("error within the reference's noise" if s["speedup"] is None else
                     f"path tracing needs {s['mitsuba_spp']:.1f} spp / {s['mitsuba_time_s']:.3f}s -> speedup {s['speedup']:.2f}x"))
    o = r.get("object")
    if o:
        lines.append(f"over the object's {o['pixels']} pixels (reference noise variance {o['reference_noise_variance']:.2e} "
                     f"subtracted): asset bias floor MSE {o['bias_floor_mse']:.3e} (relative RMSE {o['bias_floor_relative_rmse']:.1%})")
        if o.get("energy_ratio"):
            lines.append("  asset energy / reference over the object (R/G/B): "
                         + " / ".join("n/a" if e is None else f"{100 * e:.1f} %" for e in o["energy_ratio"]))  # None: black
        for s in o["equal_error"]:
            lines.append(f"  asset {s['spp']:4d} spp: object MSE {s['mse']:.3e}, " + (
                "within the reference's noise" if s["speedup"] is None else
                f"path tracing needs {s['mitsuba_spp']:.1f} spp / {s['mitsuba_time_s']:.3f}s -> speedup {s['speedup']:.2f}x"))
    c = r["per_sample_cost"]
    if c:
        lines.append(f"per-sample cost at {c['spp']} spp ({c['pairs']} alternating pairs): asset {c['asset_s']:.3f}s / path "
                     f"tracing {c['path_tracing_s']:.3f}s = {c['ratio']:.2f} (median of the pairs {c['paired_median']:.2f})")
    return "\n".join(lines)
