"""``nasset bench blender``: Cycles path tracing vs the reference renderer with a baked rna asset.

For each Blender example (``blender-surface``: the subsurface Suzanne; ``blender-hair``: the hair
tuft), rendered through the example's camera at ``--res`` with all its lights (sun, area, world):

* **ground truth**: Cycles (CPU, box filter 1 px, no clamping) of the original scene at
  ``--gt-spp`` in independent chunks (seeds differ);
* **(a) Cycles**: the original scene at each of ``--cy-spp``;
* **(b) neural**: the reference renderer on the scene converted by ``nasset convert-scene`` with
  the asset object replaced by the baked asset, at each of ``--nr-spp``.

Error and timing follow the Mitsuba error-vs-time benchmark (benchmarks/error_vs_time.py): MSE
over all pixels and channels minus the ground truth's own noise; Cycles time is one
``bpy.ops.render.render`` plus reading the EXR back, after a warm-up render at the same spp with
persistent data on (scene sync and BVH build excluded); neural time is one ``render()`` after
scene load, session setup and a warm-up. Equal-error speedup: Cycles' fitted time to reach each
neural point's MSE over the neural time (``equal_error_speedup``).

The h ablation (paper Fig. 15) trains the hair asset twice on the same Cycles dataset -- with h
and with h fixed to 0 -- and reports both held-out PSNRs (spec/bake.md#psnr) and the PSNR of a
close-up render against a Cycles close-up.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from nasset_benchmarks.common import save_figure
from nasset_converters.blender.cycles import render_cycles, setup_cycles
from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg, seed_arg
from nasset_sdk.errors import UsageError
from nasset_sdk.images import output_folder, write_text_atomic

QUICK = {"res": 64, "gt_spp": 1024, "cy_spp": "4,16,64", "nr_spp": "1,4,16", "size": "tiny"}
FULL = {"res": 128, "gt_spp": 4096, "cy_spp": "4,16,64,256", "nr_spp": "1,4,16,64", "size": "small"}
PAPER = "RNA (sec. 6.3) reports 7x on the Lego (1024^2, Cycles 4096 spp 247 s vs 16 spp 34 s) and 60x on the blonde hair."


def _ground_truth(bpy, path, spp: int, chunk: int = 256, say=print):
    """Cycles ground truth in independent chunks: (mean [H,W,3], noise variance of the mean, half a, half b)."""
    n = max(2, math.ceil(spp / chunk))
    per = max(1, spp // n)
    imgs = []
    t = time.perf_counter()
    for k in range(n):
        imgs.append(render_cycles(bpy, path, per, 1000 + k))
        say(f"  ground truth chunk {k + 1}/{n} ({per} spp) {time.perf_counter() - t:.1f}s")
    imgs = np.stack(imgs)
    a, b = imgs[: n // 2].mean(0), imgs[n // 2: 2 * (n // 2)].mean(0)
    return imgs.mean(0), float(np.mean((a - b) ** 2) / 4.0), a, b


def _png(path: Path, img: np.ndarray, peak: float) -> None:
    from nasset_sdk.images import write_png

    x = np.clip(np.nan_to_num(img / max(peak, 1e-12)), 0.0, 1.0) ** (1.0 / 2.2)
    write_png(path, (x * 255.0 + 0.5).astype(np.uint8))


def bench_example(out: Path, example: str, *, size: str, res: int, gt_spp: int, cy_spp, nr_spp, max_depth: int,
                  seed: int, say, asset=None) -> dict:
    """One example's error-vs-time curves; writes its images next to the report."""
    from nasset_bakers.blender.rna import bake
    from nasset_benchmarks.common import equal_error_speedup
    from nasset_converters.blender import load_bpy
    from nasset_converters.blender.examples import EXAMPLES, build_example
    from nasset_converters.blender.usd_export import convert_scene
    from nasset_reference_renderer import RenderSettings, load_scene, render
    from nasset_reference_renderer.integrator import prepare_assets
    from nasset_reference_renderer.plan import make_plan
    from nasset_reference_renderer.scene import SceneWarning

    bpy = load_bpy()
    times = {}
    if asset is None:
        asset = out / f"{example}_{size}.usdc"
        if not asset.is_file():
            say(f"baking {example} ({size}) -> {asset}")
            t = time.perf_counter()
            bake_summary = bake(None, None, asset, size=size, example=example, seed=seed, quiet=True)
            times["bake_s"] = time.perf_counter() - t
            say(f"  held-out PSNR {bake_summary['sdk_val_psnr_db']:.2f} dB")
    asset = Path(asset)
    scene_usd = out / f"{example}_neural.usda"
    convert_scene(None, scene_usd, replace={EXAMPLES[example][0]: asset}, check_usd=False, example=example)
    build_example(example)
    setup_cycles(bpy, res)
    exr = out / f"{example}_cycles.exr"
    say(f"{example}: ground truth Cycles {gt_spp} spp at {res}x{res}")
    t = time.perf_counter()
    gt, var_gt, gt_a, gt_b = _ground_truth(bpy, exr, gt_spp, say=say)
    times["ground_truth_s"] = time.perf_counter() - t
    cy_points = []
    low = None
    for k, spp in enumerate(cy_spp):
        render_cycles(bpy, exr, spp, 50_000 + k)  # warm-up (persistent data: sync and BVH kept)
        t = time.perf_counter()
        img = render_cycles(bpy, exr, spp, 10 + k)
        dt = time.perf_counter() - t
        mse = float(np.mean((img - gt) ** 2)) - var_gt
        cy_points.append({"spp": spp, "time_s": dt, "mse": mse, "mse_raw": mse + var_gt})
        low = img if low is None else low
        say(f"  cycles {spp:5d} spp  {dt:8.3f}s  MSE {mse:.3e}")
    exr.unlink(missing_ok=True)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(str(scene_usd))
    base = RenderSettings(spp=1, seed=seed, width=res, height=res, max_depth=max_depth)
    plan = make_plan(scene, width=res, height=res, spp=1, max_depth=max_depth, tile=base.tile, batch=base.batch)
    prepare_assets(scene, plan, base)
    render(scene, base)
    nr_points = []
    nimg = None
    for k, spp in enumerate(nr_spp):
        s = RenderSettings(spp=spp, seed=seed + 100 + k, width=res, height=res, max_depth=max_depth)
        t = time.perf_counter()
        result = render(scene, s)
        dt = time.perf_counter() - t
        nimg = result.image[..., :3]
        nvar = result.variance[..., :3]
        var_nr = float(result.variance.mean())
        mse = float(np.mean((nimg - gt) ** 2)) - var_gt
        nr_points.append({"spp": spp, "time_s": dt, "mse": mse, "mse_raw": mse + var_gt, "variance": var_nr,
                          "network_evals": int(result.stats.network_evals)})
        say(f"  neural {spp:5d} spp  {dt:8.3f}s  MSE {mse:.3e}  (own variance {var_nr:.2e})")
    peak = float(np.percentile(gt, 99.5))
    for name, img in (("gt", gt), ("cycles_low", low), ("neural", nimg)):
        _png(out / f"blender_{example.removeprefix('blender-').replace('-', '_')}_{name}.png", img, peak)
    last = nr_points[-1]
    floor = last["mse"] - last["variance"]
    speed = equal_error_speedup(cy_points, nr_points)
    best = max((s for s in speed if s["speedup"] is not None), key=lambda s: s["speedup"], default=None)
    from nasset_sdk.metrics import accuracy

    acc = accuracy(nimg, gt_a, gt_b, None, est_var=nvar, flip=False)
    return {
        "example": example, "asset": str(asset), "resolution": [res, res],
        "ground_truth": {"spp": gt_spp, "mean_radiance": float(gt.mean()), "noise_variance": var_gt},
        "cycles_points": cy_points, "neural_points": nr_points, "bias_floor_mse": floor,
        "bias_floor_relative_rmse": math.sqrt(max(floor, 0.0)) / max(float(gt.mean()), 1e-12),
        "neural_image_accuracy": acc.to_dict(),  # whole image, unclamped two-half ground truth (spec/accuracy.md#metrics)
        "equal_error": speed, "best_equal_error_speedup": None if best is None else best["speedup"],
        "interpolated_speedup": interpolated_speedup(cy_points, nr_points),
        "setup_times_s": {k: round(v, 2) for k, v in times.items()},
    }


def interpolated_speedup(cy_points: list[dict], nr_points: list[dict]) -> list[dict]:
    """Cycles' time at each neural point's MSE, interpolated in log-log between the *measured* Cycles
    points (the end segments extrapolated), over the neural time. Unlike the affine fit of
    ``equal_error_speedup`` it does not let one slow point on a shared machine move every estimate."""
    pts = sorted((p for p in cy_points if p["mse"] > 0), key=lambda p: p["spp"])
    out = []
    for q in nr_points:
        if len(pts) < 2 or q["mse"] <= 0:
            out.append({"spp": q["spp"], "cycles_time_s": None, "speedup": None})
            continue
        lm = np.log([p["mse"] for p in pts])
        lt = np.log([p["time_s"] for p in pts])
        k = int(np.clip(np.searchsorted(-lm, -math.log(q["mse"])), 1, len(pts) - 1))  # mse falls with spp
        w = (math.log(q["mse"]) - lm[k - 1]) / (lm[k] - lm[k - 1])
        t = float(math.exp(lt[k - 1] + w * (lt[k] - lt[k - 1])))
        out.append({"spp": q["spp"], "cycles_time_s": t, "speedup": t / q["time_s"]})
    return out


def h_ablation(out: Path, *, size: str, seed: int, say) -> dict:
    """Hair asset with and without h on one Cycles dataset: held-out PSNR both ways."""
    from nasset_bakers.blender.rna import bake

    res = {}
    work = out / f"blender-hair_{size}.usdc.bake"  # the benchmark's own hair dataset (and with-h training state)
    for h_input in (True, False):
        path = out / f"blender-hair_{size}{'' if h_input else '_no_h'}.usdc"
        t = time.perf_counter()
        s = bake(None, None, path, size=size, example="blender-hair", seed=seed, quiet=True, resume=work, h_input=h_input)
        res["with_h" if h_input else "without_h"] = {"val_psnr_db": s["sdk_val_psnr_db"], "asset": str(path),
                                                     "train_s": s["times_s"]["train_s"], "total_s": round(time.perf_counter() - t, 2)}
        say(f"  h ablation ({'with' if h_input else 'without'} h): held-out PSNR {s['sdk_val_psnr_db']:.2f} dB")
    res["gain_db"] = res["with_h"]["val_psnr_db"] - res["without_h"]["val_psnr_db"]
    res["val_samples"] = s["val_samples"]
    return res


def plot(path: Path, reports: list) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, len(reports), figsize=(6.0 * len(reports), 4.4), dpi=110)
    axes = np.atleast_1d(axes)
    for ax, r in zip(axes, reports, strict=True):
        for pts, label, mk in ((r["cycles_points"], "Cycles path tracing (original)", "o-"),
                               (r["neural_points"], "reference renderer + baked asset", "s-")):
            good = [p for p in pts if p["mse"] > 0]
            ax.loglog([p["time_s"] for p in good], [p["mse"] for p in good], mk, label=label)
            for p in good:
                ax.annotate(f"{p['spp']}", (p["time_s"], p["mse"]), textcoords="offset points", xytext=(4, 4), fontsize=7)
        if r["bias_floor_mse"] > 0:
            ax.axhline(r["bias_floor_mse"], color="gray", ls="--", lw=1, label=f"asset bias floor {r['bias_floor_mse']:.2e}")
        ax.set_title(f"{r['example']} {r['resolution'][0]}x{r['resolution'][1]}", fontsize=9)
        ax.set_xlabel("render time (s, wall clock)")
        ax.set_ylabel("MSE vs Cycles ground truth")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def run_bench(out_dir, *, size: str, res: int, gt_spp: int, cy_spp, nr_spp, max_depth: int = 8, seed: int = 0,
              examples=("blender-surface", "blender-hair"), ablation: bool = True, quiet: bool = False) -> dict:
    from nasset_benchmarks.common import machine

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    out = Path(out_dir)
    output_folder(out)
    if res < 4:
        raise UsageError(f"--res must be >= 4, got {res}")
    t0 = time.perf_counter()
    reports = [bench_example(out, ex, size=size, res=res, gt_spp=gt_spp, cy_spp=cy_spp, nr_spp=nr_spp,
                             max_depth=max_depth, seed=seed, say=say) for ex in examples]
    report = {
        "benchmark": "blender error-vs-time", "size": size, "examples": reports,
        "h_ablation": h_ablation(out, size=size, seed=seed, say=say) if ablation else None,
        "reference_renderer": {"max_depth": max_depth}, "paper": PAPER, "machine": machine(),
        "total_s": round(time.perf_counter() - t0, 1),
        "timing_includes": {
            "cycles": "one bpy.ops.render.render (CPU, persistent data) + EXR readback, after a warm-up at the same spp",
            "neural": "one reference_renderer.render call after scene load, session setup and a warm-up render"},
    }
    plot(out / "blender_error_vs_time.png", reports)
    report["files"] = [str(out / "blender_error_vs_time.json"), str(out / "blender_error_vs_time.png")]
    write_text_atomic(out / "blender_error_vs_time.json", json.dumps(report, indent=2))
    return report


def _accuracy_line(a: dict) -> str:
    def num(x, scale=1.0, digits=1) -> str:  # None: undefined (a black reference: stored as null, accuracy.md#metrics)
        return "n/a" if x is None else f"{scale * x:.{digits}f}"

    e = "/".join(num(x, 100) for x in a["energy_ratio"])
    return f"energy {e} % (RGB), PSNR {num(a['psnr_db'], digits=2)} dB, ground-truth noise ceiling {num(a['ceiling_db'], digits=2)} dB"


def summary_text(r: dict) -> str:
    lines = []
    for e in r["examples"]:
        lines.append(f"{e['example']} at {e['resolution'][0]}^2, asset {e['asset']}; Cycles ground truth "
                     f"{e['ground_truth']['spp']} spp (noise variance {e['ground_truth']['noise_variance']:.2e}, subtracted)")
        for name, pts in (("cycles", e["cycles_points"]), ("neural", e["neural_points"])):
            for p in pts:
                lines.append(f"  {name:7s}{p['spp']:6d} spp {p['time_s']:9.3f}s  MSE {p['mse']:.3e}")
        lines.append(f"  asset bias floor MSE {e['bias_floor_mse']:.3e} (relative RMSE {e['bias_floor_relative_rmse']:.1%}); "
                     f"neural image (whole, highest spp): {_accuracy_line(e['neural_image_accuracy'])}")
        for s in e["equal_error"]:
            if s["speedup"] is None:
                lines.append(f"  neural {s['spp']:4d} spp: no equal-error point (error within ground-truth noise)")
            else:
                lines.append(f"  neural {s['spp']:4d} spp: Cycles needs {s['mitsuba_spp']:.1f} spp / {s['mitsuba_time_s']:.3f}s "
                             f"-> speedup {s['speedup']:.2f}x")
        b = e["best_equal_error_speedup"]
        lines.append(f"  best equal-error speedup (affine fit): {'n/a' if b is None else f'{b:.2f}x'}")
        lines.append("  interpolated between measured Cycles points: " + ", ".join(
            f"{s['spp']} spp {s['speedup']:.2f}x" for s in e.get("interpolated_speedup", []) if s["speedup"] is not None))
    a = r.get("h_ablation")
    if a:
        lines.append(f"h ablation (hair, {a['val_samples']} held-out samples): with h {a['with_h']['val_psnr_db']:.2f} dB, "
                     f"without h {a['without_h']['val_psnr_db']:.2f} dB ({a['gain_db']:+.2f} dB)")
    lines.append(r["paper"])
    m = r["machine"]
    lines.append(f"machine: {m['usable_cores']} usable cores, load average {m['load_avg'][0]:.2f} (shared machines inflate both timings)")
    return "\n".join(lines)


def add_args(p) -> None:
    """Options of ``nasset bench blender``."""
    p.add_argument("-o", "--output", default="bench_blender", help="output folder (JSON, plot PNG, images, assets)")
    p.add_argument("--size", default=None, choices=["tiny", "small", "hq"], help="bake preset (default small; tiny with --quick)")
    p.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=None, help="image width = height (default 128; 64 with --quick)")
    p.add_argument("--gt-spp", type=count_arg(2, MAX_SPP), default=None, help="Cycles ground-truth spp (default 4096; 1024 with --quick)")
    p.add_argument("--cy-spp", default=None, help="Cycles spp list (default 4,16,64,256)")
    p.add_argument("--nr-spp", default=None, help="reference-renderer spp list (default 1,4,16,64)")
    p.add_argument("--max-depth", type=count_arg(0, 1024), default=8, help="reference renderer path depth (default 8)")
    p.add_argument("--examples", default="blender-surface,blender-hair", help="comma-separated examples")
    p.add_argument("--no-ablation", action="store_true", help="skip the h ablation")
    p.add_argument("--quick", action="store_true", help="tiny bakes and small images (a few minutes)")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--json", action="store_true", help="print the report as JSON (progress is silenced)")


def run(args) -> int:
    """CLI entry: ``nasset bench blender ...``."""
    from nasset_benchmarks.common import ints
    from nasset_converters.blender.examples import EXAMPLES

    d = QUICK if args.quick else FULL
    examples = [e.strip() for e in str(args.examples).split(",") if e.strip()]
    for e in examples:
        if e not in EXAMPLES:
            raise UsageError(f"--examples: unknown example {e!r} ({', '.join(EXAMPLES)})")
    if not examples:
        raise UsageError(f"--examples names no example ({', '.join(EXAMPLES)})")
    report = run_bench(
        args.output, size=args.size or d["size"], res=args.res or d["res"], gt_spp=args.gt_spp or d["gt_spp"],
        cy_spp=ints(args.cy_spp or d["cy_spp"], "cy-spp"), nr_spp=ints(args.nr_spp or d["nr_spp"], "nr-spp"),
        max_depth=args.max_depth, seed=args.seed, examples=examples, ablation=not args.no_ablation, quiet=args.json)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(summary_text(report))
        print("wrote " + ", ".join(report["files"]))
    return 0
