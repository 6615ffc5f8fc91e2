"""``nasset conformance``: run a renderer on the conformance cases and compare with the references.

The cases are package data of the SDK, ``nasset_sdk/conformance_cases/<case>/`` (scene.usda, assets,
reference.exr, case.json), so the suite runs from an installed wheel; spec/conformance.md describes the suite, the metric, the tolerances
and the command-template contract. Any renderer can be checked: ``--renderer`` is a command
template with ``{scene} {out} {spp} {width} {height} {seed}`` placeholders, split like a shell
command line (no shell runs it). Exit code 0 when every case passes, 1 otherwise.
"""

from __future__ import annotations

import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from .errors import UsageError
from .images import write_text_atomic

DEFAULT_RENDERER = "nasset render {scene} -o {out} --spp {spp} --seed {seed} --width {width} --height {height} --quiet"
PLACEHOLDERS = ("scene", "out", "spp", "width", "height", "seed")
SUITE_ENV = "NASSET_CONFORMANCE_SUITE"
#: the suite shipped with the SDK (package data)
CASES_DIR = Path(__file__).resolve().parent / "conformance_cases"


# -- metric ------------------------------------------------------------------------------------
def block_means(image: np.ndarray, block: int) -> np.ndarray:
    """[H/b, W/b, 3] means of b x b pixel blocks (H and W must be multiples of b)."""
    img = np.asarray(image, np.float64)
    h, w, c = img.shape
    b = int(block)
    if b < 1 or h % b or w % b:
        raise ValueError(f"image {w}x{h} is not a whole number of {b}x{b} blocks")
    return img.reshape(h // b, b, w // b, b, c).mean((1, 3))


def _float_pair(image, reference) -> tuple[np.ndarray, np.ndarray]:
    """Both images as float64 arrays of one shape (ValueError naming both shapes otherwise)."""
    img = np.asarray(image, np.float64)
    ref = np.asarray(reference, np.float64)
    if img.shape != ref.shape:
        raise ValueError(f"image shape {img.shape} differs from the reference's {ref.shape}")
    return img, ref


def rmse_normalised(image: np.ndarray, reference: np.ndarray, block: int = 1) -> float:
    """Root-mean-square difference of the b x b block means over every block and channel, divided by
    the reference's mean radiance (all pixels and channels). Non-finite pixels give +inf."""
    img, ref = _float_pair(image, reference)
    if not np.isfinite(img).all():
        return float("inf")
    d = block_means(img, block) - block_means(ref, block)
    norm = float(ref.mean())
    return float(np.sqrt(np.mean(d * d)) / (norm if norm > 0 else 1.0))


METRICS = {"rmse_normalised": rmse_normalised}


def mean_bias(image: np.ndarray, reference: np.ndarray) -> float:
    """|mean(image) / mean(reference) - 1|, means over all pixels and channels: a brightness bias.

    Monte Carlo noise averages over the whole image, so this separates a bias from noise where the
    block RMSE cannot. Non-finite pixels give +inf."""
    img, ref = _float_pair(image, reference)
    if not np.isfinite(img).all():
        return float("inf")
    norm = float(ref.mean())
    return float(abs(img.mean() / norm - 1.0)) if norm > 0 else float(abs(img.mean()))


def compare(image: np.ndarray, reference: np.ndarray, case: dict) -> dict:
    """Both checks of a case: ``error`` (the case's metric) within ``tolerance`` and, where the case
    has a ``bias_tolerance``, ``bias_error`` (:func:`mean_bias`) within it. Returns
    ``{"error", "bias_error", "passed"}`` (errors are floats, +inf for non-finite images; bias_error None without the check)."""
    err = METRICS[case["metric"]](image, reference, case.get("block", 1))
    passed = bool(np.isfinite(err) and err <= case["tolerance"])
    bias = None
    if case.get("bias_tolerance") is not None:
        bias = mean_bias(image, reference)
        passed = passed and bool(np.isfinite(bias) and bias <= case["bias_tolerance"])
    return {"error": err, "bias_error": bias, "passed": passed}


# -- suite ---------------------------------------------------------------------------------------
def find_suite(suite: str | os.PathLike | None = None) -> Path:
    """The cases folder: ``suite``, else $NASSET_CONFORMANCE_SUITE, else the cases installed with this package."""
    candidates = []
    if suite:
        candidates.append(Path(suite))
    elif os.environ.get(SUITE_ENV):
        candidates.append(Path(os.environ[SUITE_ENV]))
    else:
        candidates.append(CASES_DIR)
    for c in candidates:
        if c.is_dir() and (c / "case.json").is_file():  # a single case folder
            return c
        if c.is_dir() and any((p / "case.json").is_file() for p in c.iterdir() if p.is_dir()):
            return c
        if c.is_dir() and (c / "cases").is_dir():  # a folder holding cases/
            return c / "cases"
    raise UsageError(f"no conformance cases found; they are installed in {CASES_DIR} "
                     f"(pass --suite DIR or set {SUITE_ENV}); looked in: {', '.join(map(str, candidates))}")


def load_cases(suite: Path, names=None) -> list[dict]:
    suite = Path(suite)
    if (suite / "case.json").is_file():
        folders = [suite]
    else:
        folders = sorted(p for p in suite.iterdir() if (p / "case.json").is_file())
    by_name = {p.name: p for p in folders}
    if names:
        unknown = [n for n in names if n not in by_name]
        if unknown:
            raise UsageError(f"unknown cases {unknown}; the suite has: {', '.join(by_name)}")
        folders = [by_name[n] for n in names]
    out = []
    for p in folders:
        with open(p / "case.json") as fh:
            info = json.load(fh)
        out.append({"name": p.name, "dir": p, **info})
    return out


# -- renderer command ----------------------------------------------------------------------------
def format_command(template: str, *, option: str = "--renderer", placeholders=PLACEHOLDERS, **values) -> list[str]:
    """Split ``template`` (the value of ``option``) like a POSIX shell and substitute the placeholders in every argument."""
    try:
        argv = shlex.split(template)
    except ValueError as exc:
        raise UsageError(f"{option}: cannot split the command template: {exc}") from None
    if not argv:
        raise UsageError(f"{option}: empty command template")
    out = []
    for a in argv:
        try:
            out.append(a.format_map({k: str(v) for k, v in values.items()}))
        except (KeyError, IndexError, ValueError) as exc:
            raise UsageError(f"{option}: bad placeholder in {a!r} ({exc}); known: "
                             + ", ".join("{" + p + "}" for p in placeholders)) from None
    if out[0] == "nasset" and shutil.which("nasset") is None:  # not on PATH (e.g. a venv not activated)
        out = [sys.executable, "-m", "nasset_sdk.cli"] + out[1:]
    return out


def run_tool(cmd: list[str], row: dict, what: str, log_path: Path, *, timeout: float, env=None) -> bool:
    """Run a renderer or evaluator command of one case, its output (stdout + stderr) saved to ``log_path``;
    sets ``row["seconds"]`` and, when it cannot run, times out or exits non-zero, ``row["message"]``.
    True when it exited 0."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, timeout=timeout)
    except FileNotFoundError as exc:
        row["message"] = f"cannot run the {what}: {exc}"
        return False
    except subprocess.TimeoutExpired:
        row["seconds"] = round(time.perf_counter() - t0, 2)
        row["message"] = f"{what} timed out after {timeout:g} s"
        return False
    row["seconds"] = round(time.perf_counter() - t0, 2)
    log = proc.stdout.decode("utf-8", "replace")
    write_text_atomic(log_path, log)
    if proc.returncode != 0:
        row["message"] = f"{what} exited with status {proc.returncode}: " + " | ".join(log.strip().splitlines()[-3:])[-400:]
        return False
    return True


def run_case(case: dict, template: str, workdir: Path, *, seed: int = 0, timeout: float = 600.0, spp_scale: int = 1) -> dict:
    """Render one case with the command template and compare; returns the case's report row."""
    from .images import read_exr

    name = case["name"]
    out_dir = Path(workdir) / name
    out_dir.mkdir(parents=True, exist_ok=True)
    out = (out_dir / "image.exr").resolve()
    if out.exists():
        out.unlink()
    spp = int(case["spp"]) * int(spp_scale)
    cmd = format_command(template, scene=(Path(case["dir"]) / "scene.usda").resolve(), out=out, spp=spp,
                         width=case["width"], height=case["height"], seed=seed)
    row = {"case": name, "status": "error", "passed": False, "error": None, "tolerance": case["tolerance"],
           "bias_error": None, "bias_tolerance": case.get("bias_tolerance"),
           "metric": case["metric"], "block": case.get("block", 1), "spp": spp, "seconds": None, "image": str(out),
           "error_map": None, "message": "", "command": cmd}
    env = dict(os.environ, NASSET_CONFORMANCE_CASE=str(Path(case["dir"]).resolve()))
    if not run_tool(cmd, row, "renderer", out_dir / "renderer.log", timeout=timeout, env=env):
        return row
    if not out.is_file():
        row["message"] = f"renderer wrote no image at {out}"
        return row
    try:
        image = read_exr(out)
    except Exception as exc:  # noqa: BLE001 - any unreadable output fails the case
        row["message"] = f"cannot read the image: {exc}"
        return row
    ref = read_exr(Path(case["dir"]) / "reference.exr")
    if image.shape != ref.shape:
        row["message"] = f"image is {image.shape[1]}x{image.shape[0]}, the case needs {ref.shape[1]}x{ref.shape[0]}"
        return row
    cmp = compare(image, ref, case)
    err, bias = cmp["error"], cmp["bias_error"]
    row["error"] = err if np.isfinite(err) else None
    row["bias_error"] = bias if bias is not None and np.isfinite(bias) else None
    row["passed"] = cmp["passed"]
    row["status"] = "pass" if row["passed"] else "fail"
    if not np.isfinite(err):
        row["message"] = "image holds NaN or Inf"
    elif bias is not None and bias > row["bias_tolerance"]:
        row["message"] = f"mean brightness off by {bias:.4f} (bias tolerance {row['bias_tolerance']:.4f})"
    if not row["passed"]:
        path = out_dir / "error.png"
        write_error_map(path, image, ref)
        row["error_map"] = str(path)
    return row


# -- error map -------------------------------------------------------------------------------------
_STOPS = np.array([[0.0, 0.0, 0.0], [0.25, 0.0, 0.55], [0.85, 0.15, 0.25], [1.0, 0.65, 0.0], [1.0, 1.0, 0.85]])


def false_colour(x: np.ndarray) -> np.ndarray:
    """[H, W] values in [0, 1] -> [H, W, 3] uint8 (black - purple - red - orange - pale yellow)."""
    t = np.clip(np.nan_to_num(x), 0.0, 1.0) * (len(_STOPS) - 1)
    i = np.minimum(t.astype(int), len(_STOPS) - 2)
    f = (t - i)[..., None]
    rgb = _STOPS[i] * (1 - f) + _STOPS[i + 1] * f
    return np.round(rgb * 255).astype(np.uint8)


def write_error_map(path, image: np.ndarray, reference: np.ndarray, zoom: int = 4) -> None:
    """PNG with three panels: reference, image (same tone mapping), false-colour |image - reference|
    (mean over channels) normalised by its 99th percentile."""
    from .images import tonemap, write_png

    img = np.nan_to_num(np.asarray(image, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    ref = np.asarray(reference, np.float64)
    diff = np.abs(img - ref).mean(-1)
    scale = float(np.percentile(diff, 99)) or float(diff.max()) or 1.0
    gap = np.full((ref.shape[0], 2, 3), 255, np.uint8)
    panel = np.concatenate([tonemap(ref), gap, tonemap(img), gap, false_colour(diff / scale)], 1)
    panel = panel.repeat(zoom, 0).repeat(zoom, 1)
    write_png(str(path), panel)


# -- whole suite -----------------------------------------------------------------------------------
def run_suite(template: str = DEFAULT_RENDERER, *, suite=None, cases=None, workdir=None, seed: int = 0, timeout: float = 600.0,
              spp_scale: int = 1, progress=None) -> dict:
    root = find_suite(suite)
    selected = load_cases(root, cases)
    if workdir is None:
        workdir = Path(tempfile.mkdtemp(prefix="nasset-conformance-"))
    workdir = Path(workdir)
    workdir.mkdir(parents=True, exist_ok=True)
    rows = []
    t0 = time.perf_counter()
    for c in selected:
        row = run_case(c, template, workdir, seed=seed, timeout=timeout, spp_scale=spp_scale)
        rows.append(row)
        if progress:
            progress(row)
    n_pass = sum(r["passed"] for r in rows)
    return {"ok": n_pass == len(rows), "renderer": template, "suite": str(root), "workdir": str(workdir), "seed": seed,
            "spp_scale": spp_scale, "passed": n_pass, "failed": len(rows) - n_pass, "seconds": round(time.perf_counter() - t0, 2),
            "cases": rows}


def format_row(r: dict) -> str:
    err = "-" if r["error"] is None else f"{r['error']:.4f}"
    ratio = "" if r["error"] is None else f"{r['error'] / r['tolerance']:6.2f}"
    secs = "-" if r["seconds"] is None else f"{r['seconds']:.1f}"
    line = f"{r['case']:<28} {r['status'].upper():<5} {err:>9} {r['tolerance']:>9.4f} {ratio:>6} {secs:>7}"
    if r["message"]:
        line += f"  {r['message']}"
    if r["error_map"]:
        line += f"  error map: {r['error_map']}"
    return line


def format_table(report: dict) -> str:
    head = f"{'case':<28} {'':<5} {'error':>9} {'tol':>9} {'ratio':>6} {'sec':>7}"
    lines = [head, "-" * len(head)] + [format_row(r) for r in report["cases"]]
    lines.append(f"{report['passed']}/{len(report['cases'])} cases pass ({report['seconds']:.1f} s); outputs in {report['workdir']}")
    return "\n".join(lines)


def run(args) -> int:
    """CLI: nasset conformance (``--evaluator``: the evaluator test vectors instead of images)."""
    if getattr(args, "evaluator", None):
        from .conformance_evaluator import run as run_vectors

        return run_vectors(args)
    if args.spp_scale < 1 or args.timeout <= 0:
        raise UsageError("--spp-scale must be >= 1 and --timeout > 0")
    if args.list:
        for c in load_cases(find_suite(args.suite), args.cases):
            print(f"{c['name']:<28} {c['width']}x{c['height']} {c['spp']:>4} spp  tol {c['tolerance']:.4f}  {c['description']}")
        return 0
    format_command(args.renderer, **{p: "x" for p in PLACEHOLDERS})  # template errors before any render
    progress = None if args.json else (lambda r: print(format_row(r), flush=True))
    if progress:
        print(f"{'case':<28} {'':<5} {'error':>9} {'tol':>9} {'ratio':>6} {'sec':>7}", flush=True)
    report = run_suite(args.renderer, suite=args.suite, cases=args.cases, workdir=args.workdir, seed=args.seed,
                       timeout=args.timeout, spp_scale=args.spp_scale, progress=progress)
    if args.json:
        print(json.dumps(report, indent=2, default=str))
    else:
        print(f"{report['passed']}/{len(report['cases'])} cases pass ({report['seconds']:.1f} s); outputs in {report['workdir']}")
    return 0 if report["ok"] else 1
