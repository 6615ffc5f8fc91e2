"""What the benchmarks share: the machine probe, option parsing, Mitsuba sensor and ground truth,
the equal-error speedup fit and the error-vs-time plot."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np

from nasset_sdk.cli import MAX_SPP
from nasset_sdk.errors import UsageError, error


def machine() -> dict:
    """The machine a benchmark ran on: CPU, usable cores, load average (stored with every result)."""
    import os
    import platform

    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    return {"cpu": platform.processor() or platform.machine(), "usable_cores": cores, "load_avg": list(os.getloadavg())}


def ints(text: str, name: str) -> list[int]:
    """Sorted distinct integers in 1 .. MAX_SPP of a comma-separated option value (``--spp 1,4,16``)."""
    try:
        vals = sorted({int(v) for v in str(text).split(",") if v.strip()})
    except ValueError:
        raise UsageError(f"--{name} must be a comma-separated list of integers, got {text!r}") from None
    if not vals or vals[0] < 1 or vals[-1] > MAX_SPP:
        raise UsageError(f"--{name} needs integers in 1 .. {MAX_SPP}, got {text!r}")
    return vals


def open_given_asset(path, what: str):
    """The asset a user named (``what``: the option and the shapes it stands in for, for the message), opened without
    its payloads: CONVERT_ASSET_REFERENCE where the file is missing or not a readable neural asset."""
    from nasset_sdk.asset import Asset

    file = Path(path)
    if not file.is_file():
        raise error("CONVERT_ASSET_REFERENCE", f"{what}: {file} does not exist", file=str(file))
    try:
        return Asset.open(file, load="none")
    except Exception as exc:  # noqa: BLE001 - any unreadable asset is the same user error here
        raise error("CONVERT_ASSET_REFERENCE", f"{what}: {file} is not a readable neural asset "
                    f"({getattr(exc, 'code', type(exc).__name__)})", file=str(file)) from None


def require_kind(asset, path, kinds: tuple, what: str) -> None:
    """BENCH_ASSET_KIND unless ``asset`` is a surface asset of one of ``kinds`` (a bench built for them)."""
    if asset.kind not in kinds or asset.variant != "surface":
        raise error("BENCH_ASSET_KIND", f"{what}: {Path(path).name} is a {asset.kind} {asset.variant} asset; this bench needs "
                    f"a {' or '.join(kinds)} surface asset", file=str(path))


def save_figure(fig, path) -> None:
    """Write a matplotlib figure to ``path`` (format from its suffix) atomically (nasset_sdk.images.atomic_output)."""
    from nasset_sdk.images import atomic_output

    with atomic_output(path, "plot") as tmp:
        fig.savefig(tmp)


def camera_sensor(mi, sensor, width: int, height: int):
    """A box-filtered ``width`` x ``height`` copy of a Mitsuba ``sensor``'s camera: its pose and its model
    (``perspective`` with its horizontal field of view, ``thinlens`` with its aperture and focus distance, or
    ``orthographic`` with its to_world scale), as the converted stage describes it (spec/renderer.md#cameras).
    None for a sensor without one of these cameras (``radiancemeter``, ...)."""
    p = mi.traverse(sensor)
    if "to_world" not in p:
        return None
    m = np.asarray(p["to_world"].matrix, np.float64).reshape(4, 4, -1)[:, :, 0]
    d = {"to_world": mi.ScalarTransform4f(m.tolist()), "sampler": {"type": "independent"},
         "film": {"type": "hdrfilm", "width": int(width), "height": int(height), "rfilter": {"type": "box"}, "pixel_format": "rgb"}}
    if "x_fov" in p:
        d |= {"type": "perspective", "fov": float(np.asarray(p["x_fov"]).ravel()[0]), "fov_axis": "x"}
        if "aperture_radius" in p:
            d |= {"type": "thinlens", "aperture_radius": float(np.asarray(p["aperture_radius"]).ravel()[0]),
                  "focus_distance": float(np.asarray(p["focus_distance"]).ravel()[0])}
    elif str(sensor).startswith("OrthographicCamera"):  # Mitsuba's class name (its Python type is ProjectiveCamera)
        d["type"] = "orthographic"
    else:
        return None
    return mi.load_dict(d)


def mi_sensor(mi, scene, res: int):
    """A box-filtered res x res copy of the scene's camera (:func:`camera_sensor`)."""
    sensor = camera_sensor(mi, scene.sensors()[0], res, res)
    if sensor is None:
        raise error("CONVERT_SCENE_LOAD", f"the scene's sensor ({str(scene.sensors()[0]).split('[')[0].strip()}) is not a "
                    "perspective, thinlens or orthographic camera")
    return sensor


def mi_render(mi, scene, sensor, spp: int, seed: int) -> np.ndarray:
    """One Mitsuba render, [H, W, 3] float64 RGB."""
    img = mi.render(scene, sensor=sensor, spp=int(spp), seed=int(seed))
    return np.asarray(img, np.float64)[..., :3]


def ground_truth(mi, scene, sensor, spp: int, chunk: int = 256, say=print) -> tuple[np.ndarray, float]:
    """Mean of independent chunks (seeds 1000+); returns (image, estimated variance of its pixels' means)."""
    n = max(2, math.ceil(spp / chunk))
    per = max(1, spp // n)
    imgs = []
    t = time.perf_counter()
    for k in range(n):
        imgs.append(mi_render(mi, scene, sensor, per, 1000 + k))
        say(f"  ground truth chunk {k + 1}/{n} ({per} spp) {time.perf_counter() - t:.1f}s")
    imgs = np.stack(imgs)
    a, b = imgs[: n // 2].mean(0), imgs[n // 2: 2 * (n // 2)].mean(0)
    var_gt = float(np.mean((a - b) ** 2) / 4.0)  # variance of the mean of both halves
    return imgs.mean(0), var_gt


def equal_error_speedup(mi_points: list[dict], nr_points: list[dict]) -> list[dict]:
    """Mitsuba's fitted time to reach each neural point's error / the neural point's time.

    Mitsuba is unbiased: MSE = V / spp, and its render time is affine in spp, time = a + c spp
    (a: per-call cost -- kernel recording and launch -- that dominates small images). V is fitted
    in log space, (a, c) by least squares with a >= 0, over the Mitsuba points. Errors at or below
    zero (within the ground truth's noise) have no equal-error time.
    """
    ok = [p for p in mi_points if p["mse"] > 0]
    if not ok:
        return []
    log_v = float(np.mean([math.log(p["mse"] * p["spp"]) for p in ok]))
    spp = np.array([p["spp"] for p in mi_points], np.float64)
    tm = np.array([p["time_s"] for p in mi_points], np.float64)
    if len(spp) >= 2 and np.ptp(spp) > 0:
        c, a = np.polyfit(spp, tm, 1)
        if a < 0 or c <= 0:
            a, c = 0.0, float(np.sum(tm * spp) / np.sum(spp * spp))
    else:
        a, c = 0.0, float(tm[0] / spp[0])
    out = []
    for p in nr_points:
        if p["mse"] <= 0:
            out.append({"spp": p["spp"], "mse": p["mse"], "mitsuba_spp": None, "mitsuba_time_s": None, "speedup": None})
            continue
        spp_eq = math.exp(log_v) / p["mse"]
        t_eq = float(a + c * spp_eq)
        out.append({"spp": p["spp"], "mse": p["mse"], "mitsuba_spp": spp_eq, "mitsuba_time_s": t_eq,
                    "speedup": t_eq / p["time_s"]})
    return out


def plot(path: Path, mi_points, nr_points, floor, title: str,
         labels=("Mitsuba path tracing (original scene)", "reference renderer + baked asset")) -> str:
    """Log-log MSE vs time; matplotlib when installed, else a minimal built-in PNG plot. Returns the backend used.
    ``labels``: legend entries of the two curves."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        _plot_fallback(path, mi_points, nr_points)
        return "builtin"
    fig, ax = plt.subplots(figsize=(6.4, 4.4), dpi=120)
    for pts, label, mk in ((mi_points, labels[0], "o-"), (nr_points, labels[1], "s-")):
        good = [p for p in pts if p["mse"] > 0]
        ax.loglog([p["time_s"] for p in good], [p["mse"] for p in good], mk, label=label)
        for p in good:
            ax.annotate(f"{p['spp']}", (p["time_s"], p["mse"]), textcoords="offset points", xytext=(4, 4), fontsize=7)
    if floor is not None and floor > 0:
        ax.axhline(floor, color="gray", ls="--", lw=1, label=f"asset bias floor {floor:.2e}")
    ax.set_xlabel("render time (s, wall clock)")
    ax.set_ylabel("MSE vs ground truth")
    ax.set_title(title, fontsize=9)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save_figure(fig, path)
    plt.close(fig)
    return "matplotlib"


def _plot_fallback(path: Path, mi_points, nr_points, size=(480, 360)) -> None:
    from nasset_sdk.images import write_png

    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    pts = [p for p in mi_points + nr_points if p["mse"] > 0 and p["time_s"] > 0]
    if not pts:
        write_png(path, img)
        return
    lx = np.log10([p["time_s"] for p in pts])
    ly = np.log10([p["mse"] for p in pts])
    x0, x1, y0, y1 = lx.min() - 0.1, lx.max() + 0.1, ly.min() - 0.1, ly.max() + 0.1
    img[h - 20, 20:w - 10] = 0
    img[10:h - 20, 20] = 0
    for pts_i, color in ((mi_points, (30, 90, 200)), (nr_points, (220, 80, 20))):
        for p in pts_i:
            if p["mse"] <= 0 or p["time_s"] <= 0:
                continue
            x = int(20 + (math.log10(p["time_s"]) - x0) / (x1 - x0) * (w - 40))
            y = int(h - 20 - (math.log10(p["mse"]) - y0) / (y1 - y0) * (h - 40))
            img[max(y - 3, 0):y + 4, max(x - 3, 0):x + 4] = color
    write_png(path, img)
