"""``nasset bench neupress``: the NeuPreSS paper's Table 1 on the built-in translucent example
(spec/bake-neupress.md#benchmark, docs/bench-neupress.md).

One run, one camera, one resolution, the example's environment map as the only light:

* **ground truth**: Mitsuba (``llvm_ad_rgb``, the scene's ``volpath``) at ``--gt-spp``, in independent chunks
  (their disagreement estimates its own noise);
* **path tracing**: the same Mitsuba scene at each spp of the sweep;
* **network + dome / lobe / MIS**: the reference renderer on the scene converted by ``nasset convert-scene``
  with ``boundary`` + ``inner`` replaced by the baked asset (``--neupress-sampling dome|lobe|mis``);
* **SH PRT**: the same with ``--prt``.

Every method is rendered at each spp of ``--spp`` (after a warm-up render), giving MSE / SSIM / FLIP against
time (the plot); the table rows are the methods **at equal spp** (``--equal-spp``) and **at equal time**
(each method at the spp whose predicted time, from its own sweep, matches the time of the network + MIS row
at equal spp; then rendered and timed again). Storage: the asset's component bytes against the bytes of the
source scene's medium grids and meshes. Lazy loading: the components each method's render plan loaded, and
the bytes a dome-sampling render reads from the asset against a PRT render (child processes with
``USDC_USE_PREAD=1``, ``rchar`` of /proc/self/io).

Timing (wall clock, best of ``--repeat`` identical renders) covers rendering only: one ``mi.render`` +
readback for Mitsuba (JIT kernels compiled in a warm-up render at that spp), one ``nasset_reference_renderer.render``
call (plan, BVH, wavefronts, networks, film) after scene load
and asset/session setup for the neural methods. Both run in this process, one after the other.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np

from nasset_benchmarks.common import ints, save_figure
from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg, seed_arg
from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import output_folder, write_text_atomic

QUICK = {"res": 64, "gt_spp": 256, "spp": "1,4,16", "equal_spp": 4}
FULL = {"res": 128, "gt_spp": 2048, "spp": "1,2,4,8,16,32", "equal_spp": 16}
METHODS = ("path tracing", "network + dome", "network + lobe", "network + MIS", "SH PRT")
_MODES = {"network + dome": dict(neupress_sampling="dome"), "network + lobe": dict(neupress_sampling="lobe"),
          "network + MIS": dict(neupress_sampling="mis"), "SH PRT": dict(prt=True)}
PAPER = ("NeuPreSS Table 1 (RTX GPU, 256 spp neural vs 10000 spp path tracing): path tracing ~1850-2500 s; network with lobe "
         "sampling ~2-4 s; storage of the networks 0.2-1.3 MB against 16-500 MB of volume data.")


# ----------------------------------------------------------------------------------------
# metrics


def ssim(a: np.ndarray, b: np.ndarray) -> float:
    """Mean SSIM (Wang et al. 2004: Gaussian window sigma 1.5, K1 0.01, K2 0.03, L 1) of the sRGB-encoded,
    [0, 1]-clipped images [H, W, 3], averaged over channels."""
    from scipy.ndimage import gaussian_filter

    def enc(x):
        x = np.clip(np.nan_to_num(np.asarray(x, np.float64)), 0.0, 1.0)
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)

    x, y = enc(a), enc(b)
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    out = []
    for c in range(x.shape[2]):
        f = lambda v: gaussian_filter(v, 1.5, truncate=3.5)  # noqa: E731
        mx, my = f(x[..., c]), f(y[..., c])
        sxx = f(x[..., c] ** 2) - mx * mx
        syy = f(y[..., c] ** 2) - my * my
        sxy = f(x[..., c] * y[..., c]) - mx * my
        m = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx * mx + my * my + c1) * (sxx + syy + c2))
        out.append(float(m.mean()))
    return float(np.mean(out))


def flip(ref: np.ndarray, test: np.ndarray) -> float:
    """Mean HDR-FLIP (flip_evaluator, default 67 ppd) of linear RGB images [H, W, 3]."""
    import flip_evaluator

    r = np.ascontiguousarray(np.clip(np.nan_to_num(ref), 0, None), np.float32)
    t = np.ascontiguousarray(np.clip(np.nan_to_num(test), 0, None), np.float32)
    return float(flip_evaluator.evaluate(r, t, "HDR", applyMagma=False)[1])


def metrics(img: np.ndarray, gt: np.ndarray, var_gt: float) -> dict:
    mse = float(np.mean((img - gt) ** 2))
    return {"mse": mse, "mse_minus_gt_noise": mse - var_gt, "ssim": ssim(img, gt), "flip": flip(gt, img)}


# ----------------------------------------------------------------------------------------
# lazy-loading measurement (child processes)

_CHILD = r'''
import json, sys, warnings
import onnx, onnxruntime, embreex  # noqa  imported up front: only the asset's bytes are counted below
import nasset_sdk.kinds.neupress, nasset_sdk.networks, nasset_reference_renderer.shaders.neupress  # noqa
from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.integrator import prepare_assets
from nasset_reference_renderer.plan import make_plan
def rchar():
    with open("/proc/self/io") as fh:
        return int(next(l for l in fh if l.startswith("rchar")).split()[1])
mode = sys.argv[2]
with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    scene = load_scene(sys.argv[1])
kw = {"prt": True} if mode == "prt" else {"neupress_sampling": mode}
s = RenderSettings(width=8, height=8, spp=1, max_depth=3, **kw)
plan = make_plan(scene, width=8, height=8, spp=1, max_depth=3, tile=s.tile, batch=s.batch, **kw)
before = rchar()
prepare_assets(scene, plan, s)
render(scene, s, plan=plan)
read = rchar() - before
comps = scene.assets[0].asset.components()
print(json.dumps({"bytes": read, "loaded": sorted(n for n, c in comps.items() if c.loaded)}))
'''


def lazy_loading(scene_usd: Path) -> dict:
    """{mode: {bytes read while the render plan's components are loaded and an 8x8 image rendered, loaded components}}."""
    env = dict(os.environ, USDC_USE_PREAD="1", PXR_WORK_THREAD_LIMIT="1")
    out = {}
    for mode in ("dome", "mis", "prt"):
        r = subprocess.run([sys.executable, "-c", _CHILD, str(scene_usd), mode], capture_output=True, text=True, env=env,
                           timeout=300, cwd=str(Path(__file__).resolve().parents[2]))
        if r.returncode != 0:
            out[mode] = {"error": r.stderr.strip().splitlines()[-1][:300] if r.stderr.strip() else f"exit {r.returncode}"}
            continue
        out[mode] = json.loads(r.stdout.strip().splitlines()[-1])
    return out


# ----------------------------------------------------------------------------------------


def bench_neupress(out_dir, *, asset=None, size: str = "small", res: int = 128, gt_spp: int = 2048, spp=(1, 2, 4, 8, 16, 32),
                   equal_spp: int = 16, max_depth: int = 16, repeat: int = 2, seed: int = 0, quiet: bool = False) -> dict:
    """Run the benchmark; writes neupress_table.{json,md}, neupress_error_vs_time.png, neupress_images.png into out_dir."""
    from nasset_benchmarks.accuracy import check_asset_fits
    from nasset_benchmarks.common import ground_truth, machine, mi_render, mi_sensor, open_given_asset
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.neupress_example import EXAMPLE_ASSET_IDS, write_example_scene
    from nasset_converters.mitsuba.usd_export import convert_scene
    from nasset_reference_renderer import RenderSettings, load_scene, render
    from nasset_reference_renderer.scene import SceneWarning
    from nasset_sdk.asset import Asset

    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    out = Path(out_dir)
    output_folder(out)
    if res < 8:
        raise UsageError(f"--res must be >= 8, got {res}")
    t_setup = time.perf_counter()
    setup: dict[str, float] = {}

    if asset is None:
        from nasset_bakers.mitsuba.neupress import bake

        asset = out / f"neupress_example_{size}.usdc"
        if not asset.is_file():
            say(f"baking the neupress example ({size}) -> {asset}")
            t = time.perf_counter()
            bake(None, None, asset, size=size, example="default", quiet=quiet, seed=seed, summary_stream=sys.stderr)
            setup["bake_s"] = time.perf_counter() - t
    asset = Path(asset)
    prov = open_given_asset(asset, "--asset").provenance or {}
    a_size = prov.get("size", size)
    if (prov.get("source") or {}).get("example") is None and prov.get("generator") == "nasset bake":
        raise error("BENCH_ASSET_MISMATCH", f"--asset {asset} was not baked from the neupress example (its geometry would not "
                    "match the scene)", file=str(asset))

    xml = write_example_scene(out / "scene", a_size if a_size in ("tiny", "small", "hq") else "small")
    mi = load_mitsuba()
    mi.set_log_level(mi.LogLevel.Error)
    mscene = mi.load_file(str(xml))
    check_asset_fits(mi, mscene, {sid: asset for sid in EXAMPLE_ASSET_IDS}, scene_file=str(xml), flag="--asset",
                     kinds=("neupress",))
    converted = convert_scene(xml, out / "scene" / "scene_neural.usda", replace={sid: asset for sid in EXAMPLE_ASSET_IDS},
                              check_usd=False)
    sensor = mi_sensor(mi, mscene, res)

    say(f"ground truth: Mitsuba {mi.variant()} {gt_spp} spp at {res}x{res}")
    t = time.perf_counter()
    cache = out / f"ground_truth_{res}_{gt_spp}_{a_size}.npz"  # a rerun of the same setting reuses it
    if cache.is_file():
        with np.load(cache) as z:
            gt, var_gt = z["gt"], float(z["var"])
    else:
        gt, var_gt = ground_truth(mi, mscene, sensor, gt_spp, chunk=max(16, gt_spp // 8), say=say)
        tmp = cache.with_name(cache.stem + ".part.npz")
        np.savez(tmp, gt=gt, var=var_gt)
        tmp.replace(cache)
    setup["ground_truth_s"] = time.perf_counter() - t

    def scene_for():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", SceneWarning)
            return load_scene(str(converted.output))

    scenes: dict = {}
    loaded: dict = {}
    warmed: set = set()

    def render_method(method: str, n: int, sd: int) -> tuple[np.ndarray, float]:
        if method == "path tracing":
            if n not in warmed:  # JIT kernels are specialised per spp: compile outside the timing
                mi_render(mi, mscene, sensor, n, 50_000 + n)
                warmed.add(n)
            best = math.inf
            for _ in range(repeat):  # best of ``repeat``: the least disturbed by other load on the machine
                t0 = time.perf_counter()
                img = mi_render(mi, mscene, sensor, n, sd)
                best = min(best, time.perf_counter() - t0)
            return img, best
        if method not in scenes:  # one scene per method: each loads only what its plan needs
            scenes[method] = scene_for()
            warm = render(scenes[method], RenderSettings(spp=1, seed=99, width=res, height=res, max_depth=max_depth,
                                                         **_MODES[method]))
            comps = scenes[method].assets[0].asset.components()
            loaded[method] = {"plan": list(warm.plan.components[str(scenes[method].assets[0].path)][0]),
                              "loaded": sorted(k for k, c in comps.items() if c.loaded)}
        s = RenderSettings(spp=n, seed=sd, width=res, height=res, max_depth=max_depth, **_MODES[method])
        best = math.inf
        for _ in range(repeat):
            t0 = time.perf_counter()
            r = render(scenes[method], s)
            best = min(best, time.perf_counter() - t0)
        return np.asarray(r.image, np.float64)[..., :3], best

    sweep: dict[str, list] = {m: [] for m in METHODS}
    images: dict[str, np.ndarray] = {}
    for m in METHODS:
        for k, n in enumerate(spp):
            img, dt = render_method(m, n, 10 + k)
            if not np.isfinite(img).all():
                raise RuntimeError(f"{m} produced NaN/Inf at {n} spp")
            row = {"spp": n, "time_s": dt, **metrics(img, gt, var_gt)}
            sweep[m].append(row)
            say(f"  {m:16s} {n:4d} spp {dt:8.3f}s  MSE {row['mse']:.3e}  SSIM {row['ssim']:.4f}  FLIP {row['flip']:.4f}")

    # equal spp
    eq_spp = []
    for m in METHODS:
        img, dt = render_method(m, equal_spp, 777)
        images[m] = img
        eq_spp.append({"method": m, "spp": equal_spp, "time_s": dt, **metrics(img, gt, var_gt)})
    target = next(r["time_s"] for r in eq_spp if r["method"] == "network + MIS")

    # equal time: spp from each method's own time-vs-spp line (least squares, t = a + c spp, a >= 0)
    eq_time = []
    for m in METHODS:
        s_ = np.array([p["spp"] for p in sweep[m]], np.float64)
        t_ = np.array([p["time_s"] for p in sweep[m]], np.float64)
        c, a = np.polyfit(s_, t_, 1) if len(s_) > 1 else (t_[0] / s_[0], 0.0)
        if a < 0 or c <= 0:
            a, c = 0.0, float(np.sum(t_ * s_) / np.sum(s_ * s_))
        n = int(max(1, min(4096, round((target - a) / max(c, 1e-9)))))
        img, dt = render_method(m, n, 888)
        eq_time.append({"method": m, "spp": n, "time_s": dt, **metrics(img, gt, var_gt)})
        say(f"  equal time {m:16s} {n:5d} spp {dt:8.3f}s (target {target:.3f}s)")

    # storage
    comp_bytes = {}
    a_all = Asset.open(asset, load="all")
    for name in a_all.components():
        comp_bytes[name] = int(sum(r.nbytes for r in a_all.tensor_refs(name).values())
                               + sum(len(a_all.network_bytes(name, k)) for k in a_all.network_refs(name)))
    src_bytes = {p.name: p.stat().st_size for p in sorted((out / "scene" / "media").glob("*.vol"))}
    mesh_bytes = {p.name: p.stat().st_size for p in sorted((out / "scene" / "meshes").glob("*.ply"))}
    storage = {"asset_file_bytes": asset.stat().st_size, "asset_component_bytes": comp_bytes,
               "source_medium_grid_bytes": src_bytes, "source_mesh_bytes": mesh_bytes}
    for r in eq_spp + eq_time:
        r["storage_bytes"] = (sum(src_bytes.values()) + sum(mesh_bytes.values()) if r["method"] == "path tracing" else
                              comp_bytes.get("core", 0) + (comp_bytes.get("prt", 0) if r["method"] == "SH PRT" else 0)
                              + (comp_bytes.get("sampling", 0) if r["method"] in ("network + lobe", "network + MIS") else 0))

    say("lazy loading: bytes read by dome / MIS / PRT renders")
    lazy = lazy_loading(converted.output)
    report = {
        "benchmark": "neupress (NeuPreSS Table 1)",
        "scene": "built-in neupress example (spec/bake-neupress.md#example), environment map only",
        "asset": str(asset), "asset_size_preset": a_size,
        "resolution": [res, res], "max_depth_reference_renderer": max_depth,
        "mitsuba": {"version": mi.__version__, "variant": mi.variant(), "integrator": converted.integrator},
        "timing_repeat": repeat,
        "ground_truth": {"spp": gt_spp, "mean_radiance": float(gt.mean()), "noise_variance": var_gt},
        "sweep": sweep, "equal_spp": eq_spp, "equal_time": eq_time, "equal_time_target_s": target,
        "storage": storage, "lazy_loading": {"render_plans": loaded, "bytes_read": lazy},
        "timing_includes": {
            "path tracing": "one mi.render call + image readback after a warm-up render at the same spp",
            "neural": "one reference_renderer.render call (plan, BVH, wavefronts, network evaluations, film) after scene "
                      "load, asset/onnxruntime setup and a warm-up render",
        },
        "machine": machine(),
        "setup_times_s": {**{k: round(v, 2) for k, v in setup.items()}, "total_s": round(time.perf_counter() - t_setup, 2)},
        "paper": PAPER,
        "bake": {k: prov.get(k) for k in ("timings_s", "validation", "size")},
    }
    write_text_atomic(out / "neupress_table.json", json.dumps(report, indent=2))
    write_text_atomic(out / "neupress_table.md", markdown_table(report))
    plot(out / "neupress_error_vs_time.png", sweep, eq_time, f"neupress example {res}x{res}, GT {gt_spp} spp")
    image_strip(out / "neupress_images.png", gt, images, equal_spp)
    report["files"] = [str(out / f) for f in ("neupress_table.json", "neupress_table.md", "neupress_error_vs_time.png",
                                              "neupress_images.png")]
    write_text_atomic(out / "neupress_table.json", json.dumps(report, indent=2))
    return report


def markdown_table(r: dict) -> str:
    def rows(items):
        lines = ["| method | spp | time (s) | storage | MSE | SSIM | FLIP |", "|---|---:|---:|---:|---:|---:|---:|"]
        for x in items:
            lines.append(f"| {x['method']} | {x['spp']} | {x['time_s']:.3f} | {x['storage_bytes'] / 1024:.1f} KiB | "
                         f"{x['mse']:.3e} | {x['ssim']:.4f} | {x['flip']:.4f} |")
        return "\n".join(lines)

    g = r["ground_truth"]
    lz = r["lazy_loading"]["bytes_read"]
    lazy = ", ".join(f"{k}: {v.get('bytes', 'n/a')} B ({'+'.join(v.get('loaded', []))})" for k, v in lz.items())
    return "\n".join([
        f"Resolution {r['resolution'][0]}x{r['resolution'][1]}; ground truth Mitsuba {g['spp']} spp (noise variance "
        f"{g['noise_variance']:.2e}, mean radiance {g['mean_radiance']:.4f}); {r['machine']['usable_cores']} cores, load "
        f"average {r['machine']['load_avg'][0]:.2f}.",
        "", f"**Equal spp** ({r['equal_spp'][0]['spp']} spp)", "", rows(r["equal_spp"]),
        "", f"**Equal time** (target: network + MIS at equal spp, {r['equal_time_target_s']:.3f} s)", "", rows(r["equal_time"]),
        "", f"Lazy loading (bytes read from the asset while a render loads what its plan needs): {lazy}", "",
    ])


def plot(path: Path, sweep: dict, eq_time: list, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), dpi=110)
    marks = dict(zip(METHODS, ("o-", "s-", "^-", "D-", "v-"), strict=True))
    for ax, key, label in ((axes[0], "mse", "MSE vs ground truth"), (axes[1], "flip", "mean FLIP vs ground truth")):
        for m, pts in sweep.items():
            ax.loglog([p["time_s"] for p in pts], [max(p[key], 1e-12) for p in pts], marks[m], label=m, ms=4)
            for p in pts:
                ax.annotate(str(p["spp"]), (p["time_s"], max(p[key], 1e-12)), textcoords="offset points", xytext=(3, 3),
                            fontsize=6)
        ax.set_xlabel("render time (s, wall clock)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def image_strip(path: Path, gt: np.ndarray, images: dict, spp: int) -> None:
    """Ground truth and every method at equal spp, tone-mapped (exposure 1, sRGB), one row with labels."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    items = [("ground truth", gt)] + [(f"{m} ({spp} spp)", images[m]) for m in METHODS]
    fig, axes = plt.subplots(1, len(items), figsize=(2.2 * len(items), 2.5), dpi=110)
    for ax, (name, img) in zip(axes, items, strict=True):
        x = np.clip(np.nan_to_num(img), 0, 1)
        ax.imshow(np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055))
        ax.set_title(name, fontsize=7)
        ax.axis("off")
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)


def add_args(p) -> None:
    """Options of ``nasset bench neupress``."""
    p.add_argument("-o", "--output", default="bench_neupress", help="output folder (table JSON/markdown, plots, scene)")
    p.add_argument("--asset", default=None, help="a neupress asset baked from the example (default: bake one)")
    p.add_argument("--size", default="small", choices=["tiny", "small"], help="preset when baking (default small)")
    p.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=None, help="image width = height (default 128; 64 with --quick)")
    p.add_argument("--gt-spp", type=count_arg(2, MAX_SPP), default=None, help="ground-truth spp (default 2048; 256 with --quick)")
    p.add_argument("--spp", default=None, help="spp sweep for every method (default 1,2,4,8,16,32; 1,4,16 with --quick)")
    p.add_argument("--equal-spp", type=count_arg(1, MAX_SPP), default=None, help="spp of the equal-spp table (default 16; 4 with --quick)")
    p.add_argument("--max-depth", type=count_arg(0, 1024), default=16, help="reference renderer path depth (default 16)")
    p.add_argument("--repeat", type=count_arg(1, 1000), default=2, help="time each render as the best of N identical renders (default 2)")
    p.add_argument("--quick", action="store_true", help="small defaults that finish in a few minutes")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--json", action="store_true", help="print the report as JSON (progress is silenced)")


def run(args) -> int:
    """CLI entry: ``nasset bench neupress ...``."""
    d = QUICK if args.quick else FULL
    if args.equal_spp is not None and args.equal_spp < 1:
        raise UsageError(f"--equal-spp must be >= 1, got {args.equal_spp}")
    report = bench_neupress(
        args.output, asset=args.asset, size=args.size if args.asset or not args.quick else "tiny",
        res=args.res or d["res"], gt_spp=args.gt_spp or d["gt_spp"], spp=ints(args.spp or d["spp"], "spp"),
        equal_spp=args.equal_spp or d["equal_spp"], max_depth=args.max_depth, repeat=args.repeat, seed=args.seed,
        quiet=args.json,
    )
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(markdown_table(report))
        print("wrote " + ", ".join(report["files"]))
    return 0

