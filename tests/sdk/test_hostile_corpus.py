"""End to end: nothing validates that later fails to open, evaluate or render (issue 13, spec/security.md).

Collects every case of ``tests/corpus/make_corpus.py`` and of every ``tests/corpus/gen_*.py`` module
that exposes ``make_cases(out_dir) -> list[Case]``. For each asset case: ``validate_file``; the expected
code must be reported; a case that validates with 0 errors must then ``Asset.open`` (all components),
run every network on random queries and the kind's evaluator (finite outputs), and render 16x16 in the
studio scene through the real renderer with a finite image written to EXR and PNG. Any exception there,
typed or not, counts as validated-then-failed. Scene cases (``Case.scene``) are rendered and must raise
their typed code (or, with code None, render finite).

All work runs in one worker subprocess, case after case, with a time bound per case: a crash, or a hang
that repeats in a fresh worker with three times the bound, fails that case; the worker restarts for the
rest. Validation first runs in-process without the crash probe as a fast path for clear rejections;
every case it does not clearly reject (it validates, reports another code, crashes or hangs) and every
``Case.probe`` case is judged by the validator as ``nasset validate`` runs it, with its crash probe.
"""

from __future__ import annotations

import importlib
import json
import os
import selectors
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

HERE = Path(__file__).resolve().parent
CORPUS = HERE.parent / "corpus"
CASE_TIMEOUT = float(os.environ.get("NASSET_HOSTILE_CASE_TIMEOUT", "60"))
#: In-process validation (no crash probe) of one file normally takes ~1 s; past this the case is retried with the probe.
INPROCESS_VALIDATE_TIMEOUT = 15.0
QUERIES = 256
TAG = "@@hostile "  # prefix of the worker's protocol lines


# ---------------------------------------------------------------------------------------------
# collection (parent)


def generators() -> list[tuple[str, object]]:
    """(family, make function) for make_corpus and every gen_*.py exposing make_cases."""
    out = []
    only = os.environ.get("NASSET_HOSTILE_ONLY")  # e.g. "gen_render": one generator while developing it
    for path in [CORPUS / "make_corpus.py", *sorted(CORPUS.glob("gen_*.py"))]:
        if only and path.stem not in only.split(","):
            continue
        mod = importlib.import_module(f"tests.corpus.{path.stem}")
        fn = getattr(mod, "make_corpus", None) if path.stem == "make_corpus" else getattr(mod, "make_cases", None)
        if fn is not None:
            out.append((path.stem, fn))
    return out


def case_class(family: str, name: str) -> str:
    """Summary row of a case: the generator, refined by an ``rN_`` name prefix (issue class N)."""
    head = name.split("_", 1)[0]
    if len(head) >= 2 and head[0] in "rc" and head[1:].isdigit():
        return f"{family}:class{head[1:]}"
    return family


@dataclass
class Outcome:
    family: str
    name: str
    code: str | None
    scene: bool
    validated: bool | None = None
    codes: list = field(default_factory=list)
    failure: str = ""  # empty: as expected
    kind: str = ""  # validate-then-fail | wrong-code | render-failed | crash | hang | generator
    seconds: float = 0.0


def _worker_cmd() -> list[str]:
    return [sys.executable, "-u", str(Path(__file__).resolve()), "--worker"]


class Worker:
    """One subprocess evaluating cases sent as JSON lines; restarted after a crash or a hang."""

    def __init__(self) -> None:
        self.proc = None

    def start(self):
        root = os.environ.get("NASSET_HOSTILE_ROOT", str(HERE.parents[1]))  # another checkout: measure its code on the same cases
        env = dict(os.environ, PYTHONPATH=os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]))
        self.proc = subprocess.Popen(_worker_cmd(), stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL,
                                     text=True, bufsize=1, env=env, start_new_session=True)
        self.sel = selectors.DefaultSelector()
        self.sel.register(self.proc.stdout, selectors.EVENT_READ)

    def stop(self):
        if self.proc is not None:
            try:
                os.killpg(self.proc.pid, 9)
            except ProcessLookupError:
                pass
            self.proc.wait()
            self.proc = None

    def run(self, job: dict, timeout: float, validate_timeout: float | None = None) -> tuple[dict | None, str, str]:
        """(result or None, last stage reached, 'crash' | 'hang' | ''); ``validate_timeout`` bounds the validate stage alone."""
        if self.proc is None:
            self.start()
        self.proc.stdin.write(json.dumps(job) + "\n")
        self.proc.stdin.flush()
        stage = "start"
        deadline = time.monotonic() + timeout + 20.0  # + worker start-up
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                self.stop()
                return None, stage, "hang"
            if not self.sel.select(left):
                continue
            line = self.proc.stdout.readline()
            if not line:
                self.stop()
                return None, stage, "crash"
            if not line.startswith(TAG):
                continue  # a library printing on the worker's stdout
            msg = json.loads(line[len(TAG):])
            if "stage" in msg:
                stage = msg["stage"]
                if stage == "validate":
                    deadline = time.monotonic() + (validate_timeout or timeout)
                elif validate_timeout:
                    deadline = time.monotonic() + timeout
                continue
            return msg, stage, ""


def run_cases(cases: list[tuple[str, object]]) -> list[Outcome]:
    worker = Worker()
    outcomes = []
    try:
        for family, case in cases:
            o = Outcome(family, case.name, case.code, bool(getattr(case, "scene", False)))
            probe = bool(getattr(case, "probe", False))
            job = {"path": str(case.path), "code": case.code, "severity": case.severity, "scene": o.scene, "probe": probe}
            t0 = time.monotonic()
            res, stage, trouble = worker.run(job, CASE_TIMEOUT, None if o.scene or probe else INPROCESS_VALIDATE_TIMEOUT)
            if not o.scene and not probe and (trouble and stage in ("start", "validate") or not trouble and (res["validated"] or res["kind"])):
                # the verdict is the validator as `nasset validate` runs it: with its crash probe (contains crashing
                # files, measures decoded array sizes); the in-process pass is only a fast path for clear rejections
                job["probe"] = True
                res, stage, trouble = worker.run(job, CASE_TIMEOUT)
            if trouble == "hang":  # once more in a fresh worker with 3x the time: a shared machine can stall a
                res, stage, trouble = worker.run(job, 3 * CASE_TIMEOUT)  # cold start; a real hang hangs again
            if trouble:
                o.kind, o.failure = trouble, f"{trouble} during {stage}"
                if stage not in ("start", "validate"):
                    o.validated = True
            else:
                o.validated, o.codes = res["validated"], res["codes"]
                o.kind, o.failure = res["kind"], res["failure"]
            o.seconds = time.monotonic() - t0
            outcomes.append(o)
    finally:
        worker.stop()
    return outcomes


def summary(outcomes: list[Outcome]) -> str:
    rows: dict[str, list[int]] = {}
    for o in outcomes:
        r = rows.setdefault(case_class(o.family, o.name), [0, 0, 0, 0])
        r[0] += 1
        r[1] += bool(o.validated)
        r[2] += o.kind in ("validate-then-fail", "crash", "hang") and bool(o.validated)
        r[3] += bool(o.failure)
    lines = [f"{'class':<28} {'cases':>6} {'validated':>10} {'validated-then-failed':>22} {'failures':>9}"]
    for k in sorted(rows):
        c, v, vf, f = rows[k]
        lines.append(f"{k:<28} {c:>6} {v:>10} {vf:>22} {f:>9}")
    tot = [sum(r[i] for r in rows.values()) for i in range(4)]
    lines.append(f"{'total':<28} {tot[0]:>6} {tot[1]:>10} {tot[2]:>22} {tot[3]:>9}")
    return "\n".join(lines)


def test_nothing_validates_that_later_fails(tmp_path):
    t0 = time.monotonic()
    cases, problems = [], []
    for family, make in generators():
        try:
            for case in make(tmp_path / family):
                cases.append((family, case))
        except Exception as exc:  # a broken generator must not hide the others
            problems.append(f"{family}: generator raised {type(exc).__name__}: {exc}")
    assert cases, "no hostile cases collected"
    t_gen = time.monotonic() - t0
    outcomes = run_cases(cases)
    text = summary(outcomes)
    elapsed = time.monotonic() - t0
    slow = sorted(outcomes, key=lambda o: -o.seconds)[:5]
    print(f"\n{text}\n{len(outcomes)} cases in {elapsed:.0f} s (generators {t_gen:.0f} s); slowest: "
          + ", ".join(f"{o.name} {o.seconds:.1f} s" for o in slow))
    report = os.environ.get("NASSET_HOSTILE_REPORT")
    if report:
        Path(report).write_text(json.dumps({"elapsed_s": elapsed, "summary": text,
                                            "cases": [o.__dict__ for o in outcomes], "generator_problems": problems}, indent=1))
    failures = [f"{o.family}/{o.name} [{o.kind}] expected {o.code}, validator {o.codes}: {o.failure}" for o in outcomes if o.failure]
    assert not problems and not failures, "\n".join(problems + failures) + "\n" + text


# ---------------------------------------------------------------------------------------------
# worker (child process)


def _finite(a) -> bool:
    import numpy as np

    a = np.asarray(a)
    return a.dtype.kind not in "fc" or bool(np.isfinite(a).all())


def _exercise_asset(path: str) -> None:
    """Open with every component, run each network and the kind's evaluator on random queries; raise on trouble."""
    import numpy as np

    from nasset_sdk.asset import Asset

    rng = np.random.default_rng(0)
    asset = Asset.open(path, load="all")
    for comp, info in asset.components().items():
        if not info.loaded:
            continue
        for name, ref in asset.network_refs(comp).items():
            sess = asset.session(comp, name, intra_threads=1)
            feeds = {n: rng.uniform(-1, 1, (QUERIES, int(w))).astype(np.float32)
                     for n, w in zip(ref.info.input_names, ref.info.input_widths, strict=True)}
            for out in sess.run(None, feeds):
                if not _finite(out):
                    raise AssertionError(f"network {comp}/{name}: non-finite output on inputs in [-1, 1]")
    lo, hi = (np.asarray(v, np.float64) for v in asset.domain)
    x = lo + (hi - lo) * rng.random((QUERIES, 3))

    def unit():
        v = rng.normal(size=(QUERIES, 3))
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    ev = asset.evaluator(intra_threads=1)
    n, wo, wi = unit(), unit(), unit()
    outs = []
    if asset.kind == "8dna":
        outs.append(ev.albedo(x, wo))
        ui, wi2, pdf = ev.sample(x, wo, 0, rng)
        outs += [ui, wi2, pdf, ev.pdf_rgb(x, wo, ui, wi2), ev.transport(x, wo, ui, wi2), ev.direct_eval(n, wo, wi)]
    elif hasattr(ev, "evaluate"):
        r = ev.evaluate(x, n, wo, wi)
        outs += list(r) if isinstance(r, tuple) else [r]
    for i, o in enumerate(outs):
        if not _finite(o):
            raise AssertionError(f"{asset.kind} evaluator output {i} is not finite")


def _render(path: str, tmp: str) -> None:
    """Render ``path`` (scene, or asset in the studio scene) at 16x16; the image and the files written must be finite."""
    import numpy as np

    from nasset_reference_renderer.film import read_exr, tonemap, write_exr, write_png
    from nasset_reference_renderer.integrator import RenderSettings, render
    from nasset_reference_renderer.scene import load_scene

    scene = load_scene(path)
    result = render(scene, RenderSettings(spp=2, width=16, height=16, max_depth=3, seed=0, threads=1))
    img = result.image
    f32 = float(np.finfo(np.float32).max)
    if not np.isfinite(img).all() or not np.isfinite(result.variance).all() or np.abs(img).max() > f32:
        raise AssertionError("rendered image holds Inf/NaN or values beyond float32")
    exr = os.path.join(tmp, "out.exr")
    write_exr(exr, img)
    write_exr(exr, result.variance)
    if not np.isfinite(read_exr(exr)).all():
        raise AssertionError("written EXR holds Inf/NaN")
    write_exr(exr, img)
    if not np.isfinite(read_exr(exr)).all():
        raise AssertionError("written EXR holds Inf/NaN")
    write_png(os.path.join(tmp, "out.png"), tonemap(img))


def _describe(exc: BaseException) -> tuple[str | None, str]:
    from nasset_sdk.errors import NassetError

    if isinstance(exc, NassetError):
        return exc.code, str(exc)[:300]
    return None, f"{type(exc).__name__}: {str(exc)[:300]}"


def _job(job: dict, tmp: str) -> dict:
    from nasset_sdk.validate import validate_file

    def stage(s):
        print(TAG + json.dumps({"stage": s}), flush=True)

    res = {"validated": None, "codes": [], "kind": "", "failure": ""}
    code = job["code"]
    if job["scene"]:
        stage("render")
        try:
            _render(job["path"], tmp)
        except Exception as exc:  # noqa: BLE001 - every outcome is classified
            got, text = _describe(exc)
            if code is None or got != code:
                res["kind"] = "render-failed"
                res["failure"] = f"raised {got or 'an untyped error'} ({text}), expected {code or 'a finite render'}"
            return res
        if code is not None:
            res["kind"], res["failure"] = "render-failed", f"rendered without the expected {code}"
        return res
    stage("validate")
    report = validate_file(job["path"], probe=job["probe"])
    res["codes"] = sorted(report.codes())
    res["validated"] = report.ok
    if code is not None and code not in report.codes(job["severity"]):
        res["kind"], res["failure"] = "wrong-code", f"validator did not report {code} ({job['severity']})"
    if not report.ok:
        return res
    try:
        stage("open-evaluate")
        _exercise_asset(job["path"])
        stage("render")
        _render(job["path"], tmp)
    except Exception as exc:  # noqa: BLE001 - any failure after a clean validation is the validator's miss
        got, text = _describe(exc)
        res["kind"] = "validate-then-fail"
        res["failure"] = f"validated, then {got or 'untyped error'}: {text}"
    return res


def worker_main() -> int:
    import warnings

    warnings.simplefilter("ignore")
    proto = os.fdopen(os.dup(1), "w", buffering=1)  # the protocol channel; anything else printed goes to stderr
    os.dup2(2, 1)
    sys.stdout = proto
    with tempfile.TemporaryDirectory() as tmp:
        for line in sys.stdin:
            job = json.loads(line)
            print(TAG + json.dumps(_job(job, tmp)), flush=True)
    return 0


if __name__ == "__main__" and "--worker" in sys.argv:
    sys.exit(worker_main())
