"""Open untrusted USD layers without risking the calling process (spec/security.md#parsing).

usd-core's crate (``.usdc``) reader trusts the file's structural sections: a corrupted file can
make ``Sdf.Layer.FindOrOpen`` segfault or loop for ever inside C++ (measured on usd-core 26.11:
about 1 in 250 random corruptions of a small asset), which no ``try``/``except`` can catch.

:func:`probe` therefore opens the file first in a short-lived child Python process with a wall
clock timeout and an address-space limit, and reports how the child ended; :func:`ensure_readable`
turns a crashed, hung or failed probe into a typed ``FILE_UNREADABLE`` error naming the file.
Only a file whose probe passed is opened in-process.

Levels:

``"layer"``  open the layer (parses every structural section of a crate: tokens, strings,
             fields, paths, specs). Cheap; catches the crashes and hangs observed.
``"full"``   also read every field value of every spec (tensor and network arrays included,
             every variant) and compose the stage with all payloads loaded. Reads the whole file.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from .errors import error

LEVELS = ("layer", "full")
DEFAULT_TIMEOUT_S = 120.0
#: Address-space cap for the probe child, on top of the file size (a corrupted count must not
#: let the child allocate the machine's memory). usd-core + numpy start at ~1.5 GiB of VM.
ADDRESS_SPACE_BASE = 6 << 30


@dataclass(frozen=True)
class ProbeResult:
    """How the probe child ended. ``ok`` means the file opened (and, at level 'full', read) cleanly."""

    ok: bool
    status: str  # "ok" | "error" | "crashed" | "timeout" | "memory" | "spawn-failed"
    detail: str
    returncode: int | None
    seconds: float
    code: str = "FILE_UNREADABLE"  # the error code a failed probe maps to

    def message(self) -> str:
        if self.status == "memory":
            return f"reading it needs more memory than its bound ({self.detail}): arrays decompress beyond the format bounds"
        if self.code == "ARRAY_TOO_LARGE":
            return self.detail
        if self.status == "crashed":
            return f"USD crashed while reading it ({self.detail})"
        if self.status == "timeout":
            return f"USD did not finish reading it within {self.detail}"
        return f"USD cannot open it: {self.detail}"


_CHILD = r"""
import json, sys
def main(path, level):
    from pxr import Sdf, Tf, Usd
    import nasset_sdk  # registers the schema so the stage composes as in the parent
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Exception as exc:
        return {"ok": False, "detail": (str(exc).strip().splitlines() or [type(exc).__name__])[-1][:300]}
    if layer is None:
        return {"ok": False, "detail": "not a USD layer"}
    if level == "full":
        from nasset_sdk.limits import array_bound, decoded_bound
        from nasset_sdk.paths import has_external, strip_external
        import os
        total = [0]
        big = []
        def measure(spec_path, key, value):
            if isinstance(value, dict):  # metadata dictionaries nest arrays too
                for v in value.values():
                    measure(spec_path, key, v)
                return
            tname = type(value).__name__
            if not tname.endswith("Array") or tname == "AssetPathArray":
                return
            n = len(value)
            lanes = int(tname[3]) if tname[:3] in ("Vec", "Qua") and tname[3:4].isdigit() else 16 if tname.startswith("Matrix4") else 1
            scalar = tname[4:] if tname.startswith("Vec") else tname
            item = lanes * (2 if "Half" in scalar or scalar[:1] == "h" else 1 if "UChar" in scalar or "Bool" in scalar
                            else 8 if "Double" in scalar or "Int64" in scalar or scalar[:1] == "d" else 4)
            total[0] += n * item
            name = spec_path.name if spec_path.IsPropertyPath() else key
            if n > array_bound(name, key):
                big.append(f"{spec_path.StripAllVariantSelections()} {key}: {n} elements > {array_bound(name, key)}")
        try:
            def visit(spec_path):
                spec = layer.GetObjectAtPath(spec_path)
                if spec is None:
                    return
                for key in spec.ListInfoKeys():
                    try:
                        measure(spec_path, key, spec.GetInfo(key))
                    except TypeError:  # a value type without a Python converter (read in C++ all the same)
                        pass
                if spec_path.IsPropertyPath():
                    for t in layer.ListTimeSamplesForPath(spec_path):
                        measure(spec_path, "timeSamples", layer.QueryTimeSample(spec_path, t))
            layer.Traverse(Sdf.Path.absoluteRootPath, visit)
            bound = decoded_bound(os.path.getsize(path))
            if big or total[0] > bound:
                why = big[0] if big else f"arrays decode to {total[0]} bytes > {bound} (bound for a {os.path.getsize(path)}-byte file)"
                return {"ok": False, "code": "ARRAY_TOO_LARGE", "detail": why[:300]}
            # never compose arcs to other files here: the parent checks their paths, and a v0.1 asset has none
            stage = Usd.Stage.Open(strip_external(layer) if has_external(layer) else layer, Usd.Stage.LoadAll)
            if stage is None:
                return {"ok": False, "detail": "the stage does not compose"}
            for prim in stage.TraverseAll():
                prim.GetAttributes()
        except Exception as exc:
            return {"ok": False, "detail": (str(exc).strip().splitlines() or [type(exc).__name__])[-1][:300]}
    return {"ok": True, "detail": ""}
out = main(sys.argv[1], sys.argv[2])
sys.stdout.write("\n@@probe@@" + json.dumps(out) + "\n")
sys.stdout.flush()
"""


PR_SET_PDEATHSIG = 1


def _prctl():
    try:
        import ctypes

        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):  # pragma: no cover - not Linux
        return None


def _limit_child(max_as: int):
    prctl = _prctl()  # looked up before fork: the child only calls it

    def apply():  # runs in the child between fork and exec
        if prctl is not None:  # die with the parent, even when it is SIGKILLed (Linux)
            prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        try:
            import resource

            resource.setrlimit(resource.RLIMIT_AS, (max_as, max_as))
            resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        except (ValueError, OSError):  # pragma: no cover - platform without the limit
            pass

    return apply


def probe(path: str | os.PathLike, *, level: str = "full", timeout: float = DEFAULT_TIMEOUT_S) -> ProbeResult:
    """Open ``path`` with USD in a child process; never raises for a bad file."""
    if level not in LEVELS:
        raise error("USAGE", f"probe level must be one of {LEVELS}, got {level!r}")
    p = Path(path)
    size = p.stat().st_size if p.is_file() else 0
    max_as = ADDRESS_SPACE_BASE + 4 * size
    env = dict(os.environ)
    env.setdefault("PXR_WORK_THREAD_LIMIT", "1")
    run = run_bounded([sys.executable, "-c", _CHILD, str(p), level], max_as=max_as, timeout=timeout, env=env)
    if run.status == "spawn-failed":
        return ProbeResult(False, "spawn-failed", run.stderr.decode("utf-8", "replace"), None, run.seconds)
    if run.status == "timeout":
        return ProbeResult(False, "timeout", f"{timeout:g} s", None, run.seconds)
    out, err, seconds = run.stdout, run.stderr, run.seconds
    if _out_of_memory(run.returncode, err):
        return ProbeResult(False, "memory", f"{max_as >> 20} MiB", run.returncode, seconds, "ARRAY_TOO_LARGE")
    text = out.decode("utf-8", "replace")
    marker = text.rfind("@@probe@@")
    if run.returncode != 0 or marker < 0:
        rc = run.returncode
        if rc is not None and rc < 0:
            try:
                detail = signal.Signals(-rc).name
            except ValueError:
                detail = f"signal {-rc}"
        else:
            tail = err.decode("utf-8", "replace").strip().splitlines()
            detail = f"exit status {rc}" + (f": {tail[-1][:200]}" if tail else "")
        return ProbeResult(False, "crashed", detail, rc, seconds)
    try:
        result = json.loads(text[marker + len("@@probe@@"):].strip().splitlines()[0])
    except (ValueError, IndexError):
        return ProbeResult(False, "crashed", "unreadable probe output", run.returncode, seconds)
    return ProbeResult(bool(result.get("ok")), "ok" if result.get("ok") else "error", str(result.get("detail", "")),
                       run.returncode, seconds, str(result.get("code") or "FILE_UNREADABLE"))


def _kill_group(proc) -> None:
    """SIGKILL the probe child's process group (it runs in a session of its own) and reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except OSError:  # already gone
        try:
            proc.kill()
        except OSError:  # pragma: no cover
            pass
    try:
        proc.wait(timeout=10)
    except Exception:  # noqa: BLE001 - best effort while unwinding
        pass


def _out_of_memory(returncode, err: bytes) -> bool:
    """The child died on its address-space bound (bad_alloc abort or MemoryError)."""
    if returncode in (0, None):
        return False
    tail = err[-4000:].decode("utf-8", "replace")
    return "bad_alloc" in tail or "MemoryError" in tail


def ensure_readable(path: str | os.PathLike, *, level: str = "full", timeout: float = DEFAULT_TIMEOUT_S) -> ProbeResult:
    """Raise ``FILE_NOT_FOUND`` / ``FILE_UNREADABLE`` unless the probe of ``path`` passes."""
    p = Path(path)
    if not p.is_file():
        raise error("FILE_NOT_FOUND", "no such file", file=str(p))
    result = probe(p, level=level, timeout=timeout)
    if not result.ok:
        raise error(result.code, result.message(), file=str(p))
    return result


@dataclass(frozen=True)
class ChildRun:
    """How a bounded child ended: status "ok" (exit 0), "failed" (non-zero exit), "crashed" (signal),
    "timeout" or "spawn-failed"; stdout/stderr as bytes."""

    status: str
    returncode: int | None
    stdout: bytes
    stderr: bytes
    seconds: float


def run_bounded(argv: list[str], *, stdin: bytes = b"", max_as: int, timeout: float, env: dict | None = None) -> ChildRun:
    """Run ``argv`` in its own session under RLIMIT_AS ``max_as`` bytes and a wall clock ``timeout``;
    the whole process group is killed on timeout, and when this process is interrupted (the child also
    dies with its parent: PR_SET_PDEATHSIG). Never raises for what the child does."""
    t0 = time.perf_counter()
    try:
        proc = subprocess.Popen(argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                env=env, preexec_fn=_limit_child(max_as), start_new_session=True)
    except OSError as exc:
        return ChildRun("spawn-failed", None, b"", str(exc).encode(), time.perf_counter() - t0)
    try:
        out, err = proc.communicate(stdin, timeout=timeout)
    except subprocess.TimeoutExpired:
        _kill_group(proc)
        out, err = proc.communicate()
        return ChildRun("timeout", None, out, err, time.perf_counter() - t0)
    except BaseException:  # KeyboardInterrupt, SystemExit from a signal handler: never leave the child running
        _kill_group(proc)
        raise
    rc = proc.returncode
    status = "ok" if rc == 0 else ("crashed" if rc < 0 else "failed")
    return ChildRun(status, rc, out, err, time.perf_counter() - t0)
