"""Runtime probe of embedded networks, bounded in time and memory (spec/security.md#networks).

The static check (:func:`nasset_sdk.networks.check_model_bytes`) proves what it can from the graph;
this probe runs every network of an asset once, in one short-lived child process under an
address-space limit and a wall-clock timeout (:func:`nasset_sdk.safeopen.run_bounded`), on probe
inputs shaped like the evaluator's: uniform values in [-1, 1] per column, with the columns a kind
declares as unit directions drawn as unit vectors. For each network it checks

* the session loads and runs at every batch size of :data:`BATCH_SIZES` (``NETWORK_RUNTIME``);
* every output is ``[n, declared width]`` for an ``n``-row batch (``NETWORK_RUNTIME``);
* every output value is finite and ``|y| <= limits.MAX_NETWORK_OUTPUT`` (``NETWORK_OUTPUT``);
* rows are independent: each row of a batch equals that row evaluated alone, and the first rows
  of a batch do not change when the other rows are replaced (``NETWORK_OUTPUT``).

A child that crashes, exceeds its memory or outlives its timeout fails every network it was
probing with ``NETWORK_RUNTIME``.
"""

from __future__ import annotations

import json
import os
import struct
import sys
from dataclasses import dataclass

import numpy as np

#: batch sizes every network is run at (1 and an odd size catch fixed or assumed batch dimensions)
BATCH_SIZES = (1, 7, 256)
#: rows of the largest batch that are also evaluated alone
SINGLE_ROWS = 5
#: |batched - alone| <= ROW_ATOL + ROW_RTOL |alone| (kernels may differ by batch size)
ROW_RTOL = 1e-3
ROW_ATOL = 1e-4
#: wall clock of the whole child (all networks of one asset)
PROBE_TIMEOUT_S = 30.0
#: address-space cap of the child on top of 16x the model bytes; onnxruntime + numpy start at ~1.2 GiB of VM
ADDRESS_SPACE_BASE = 4 << 30
_MARKER = "@@netprobe@@"


@dataclass(frozen=True)
class ProbeJob:
    """One network to probe. ``unit_columns[i]``: first columns of the 3-wide unit vectors of input i."""

    key: str
    data: bytes
    input_names: tuple[str, ...]
    input_widths: tuple[int, ...]
    output_names: tuple[str, ...]
    output_widths: tuple[int, ...]
    unit_columns: tuple[tuple[int, ...], ...] = ()


def probe_inputs(widths, unit_columns, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """One float32 [n, w] array per input: uniform in [-1, 1], unit vectors at ``unit_columns``."""
    out = []
    for i, w in enumerate(widths):
        x = rng.uniform(-1.0, 1.0, (n, int(w)))
        for c in (unit_columns[i] if i < len(unit_columns) else ()):
            if 0 <= c and c + 3 <= w:
                v = rng.normal(size=(n, 3))
                x[:, c:c + 3] = v / np.maximum(np.linalg.norm(v, axis=1, keepdims=True), 1e-12)
        out.append(x.astype(np.float32))
    return out


def check_outputs(run, job: ProbeJob, seed: int = 0, max_output: float | None = None) -> list[tuple[str, str]]:
    """Probe one network through ``run(feeds: dict) -> list[np.ndarray]``; return (code, message) findings.

    Stops at the first finding. ``run`` may raise: that is a ``NETWORK_RUNTIME`` finding.
    """
    if max_output is None:
        from . import limits

        max_output = limits.MAX_NETWORK_OUTPUT
    rng = np.random.default_rng(seed)
    big = max(BATCH_SIZES)
    xs = probe_inputs(job.input_widths, job.unit_columns, big, rng)
    declared = tuple(int(w) for w in job.output_widths)

    def call(arrays, what):
        feeds = {name: np.ascontiguousarray(a) for name, a in zip(job.input_names, arrays, strict=True)}
        try:
            outs = run(feeds)
        except Exception as exc:  # onnxruntime raises its own exception types
            return None, ("NETWORK_RUNTIME", f"onnxruntime cannot run it ({what}): {(str(exc).strip() or type(exc).__name__)[:200]}")
        n = len(arrays[0])
        got = tuple(tuple(np.shape(o)) for o in outs)
        if got != tuple((n, w) for w in declared):
            return None, ("NETWORK_RUNTIME", f"{what}: outputs have shapes {got}, declared {[(n, w) for w in declared]}")
        outs = [np.asarray(o, np.float64) for o in outs]
        for name, o in zip(job.output_names, outs, strict=True):
            finite = np.isfinite(o)
            if not finite.all():
                return None, ("NETWORK_OUTPUT", f"{what}: output {name!r} has {int(o.size - finite.sum())} NaN/Inf values")
            peak = float(np.abs(o).max(initial=0.0))
            if peak > max_output:
                return None, ("NETWORK_OUTPUT", f"{what}: output {name!r} reaches |y| = {peak:.3g} > bound {max_output:.3g}")
        return outs, None

    results = {}
    for n in BATCH_SIZES:
        outs, bad = call([x[:n] for x in xs], f"batch of {n}")
        if bad:
            return [bad]
        results[n] = outs
    ref = results[big]

    def differs(a_list, b_list):
        for a, b in zip(a_list, b_list, strict=True):
            if (np.abs(a - b) > ROW_ATOL + ROW_RTOL * np.abs(b)).any():
                return True
        return False

    for n in BATCH_SIZES:  # the first n rows of the big batch against the n-row batch
        if differs([o[:n] for o in ref], results[n]):
            return [("NETWORK_OUTPUT", f"rows depend on the batch: the first {n} rows differ between a {n}-row and a {big}-row batch")]
    for i in rng.choice(big, size=min(SINGLE_ROWS, big), replace=False):
        alone, bad = call([x[i:i + 1] for x in xs], f"row {int(i)} alone")
        if bad:
            return [bad]
        if differs([o[i:i + 1] for o in ref], alone):
            return [("NETWORK_OUTPUT", f"rows depend on each other: row {int(i)} of a {big}-row batch differs from the row alone")]
    others = probe_inputs(job.input_widths, job.unit_columns, big, rng)
    for x, o in zip(xs, others, strict=True):
        o[: big // 2] = x[: big // 2]
    mixed, bad = call(others, f"batch of {big}, second half replaced")
    if bad:
        return [bad]
    if differs([o[: big // 2] for o in mixed], [o[: big // 2] for o in ref]):
        return [("NETWORK_OUTPUT", "rows depend on each other: replacing the second half of a batch changes the first half")]
    # the largest run a reader makes (limits.MAX_NETWORK_ROWS), under this child's memory bound: a graph whose
    # activations take megabytes per row passes at 256 rows and exhausts a renderer's memory at thousands
    from . import limits

    _, bad = call(probe_inputs(job.input_widths, job.unit_columns, limits.MAX_NETWORK_ROWS, rng),
                  f"batch of {limits.MAX_NETWORK_ROWS}")
    return [bad] if bad else []


def run_jobs_here(jobs: list[ProbeJob], seed: int = 0) -> dict[str, list[tuple[str, str]]]:
    """Probe ``jobs`` in this process (the child's work; tests call it directly)."""
    from .networks import make_session

    found: dict[str, list[tuple[str, str]]] = {}
    for job in jobs:
        try:
            session = make_session(job.data, intra_threads=1)
        except Exception as exc:  # onnxruntime raises its own exception types
            found[job.key] = [("NETWORK_RUNTIME", f"onnxruntime cannot load it: {(str(exc).strip() or type(exc).__name__)[:200]}")]
            continue
        found[job.key] = check_outputs(lambda feeds, s=session, j=job: s.run(list(j.output_names), feeds), job, seed)
    return found


def _encode(jobs: list[ProbeJob]) -> bytes:
    """Header JSON (length-prefixed) then the model bytes of each job, in order."""
    head = json.dumps([{"key": j.key, "size": len(j.data), "input_names": list(j.input_names),
                        "input_widths": [int(w) for w in j.input_widths], "output_names": list(j.output_names),
                        "output_widths": [int(w) for w in j.output_widths],
                        "unit_columns": [list(map(int, c)) for c in j.unit_columns]} for j in jobs]).encode()
    return struct.pack("<Q", len(head)) + head + b"".join(j.data for j in jobs)


def _decode(blob: bytes) -> list[ProbeJob]:
    (n,) = struct.unpack_from("<Q", blob)
    head = json.loads(blob[8:8 + n])
    jobs, at = [], 8 + n
    for h in head:
        data = blob[at:at + h["size"]]
        at += h["size"]
        jobs.append(ProbeJob(h["key"], data, tuple(h["input_names"]), tuple(h["input_widths"]), tuple(h["output_names"]),
                             tuple(h["output_widths"]), tuple(tuple(c) for c in h["unit_columns"])))
    return jobs


def child_main() -> None:
    """Entry point of the probe child: jobs on stdin, findings as JSON after a marker on stdout."""
    timeout = float(sys.argv[1]) if len(sys.argv) > 1 else PROBE_TIMEOUT_S
    try:  # an orphaned child (the parent was killed) still ends
        import resource
        import signal

        cpu = int(timeout) + 5
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu))
        signal.alarm(int(timeout) + 5)
    except (ImportError, ValueError, OSError):  # pragma: no cover - platform without the limits
        pass
    jobs = _decode(sys.stdin.buffer.read())
    found = run_jobs_here(jobs)
    sys.stdout.write("\n" + _MARKER + json.dumps(found) + "\n")
    sys.stdout.flush()


def make_job(data: bytes, info, unit_columns: tuple[tuple[int, ...], ...] = ()) -> ProbeJob:
    """The probe job of model ``data`` declared by ``info`` (a :class:`~nasset_sdk.networks.NetworkInfo`); its key
    names the bytes and the declared interface, so equal networks are probed once."""
    from .networks import sha256_hex

    key = f"{sha256_hex(data)}:{tuple(info.input_names)}:{tuple(info.input_widths)}:{tuple(info.output_names)}:{tuple(info.output_widths)}"
    return ProbeJob(key, bytes(data), tuple(info.input_names), tuple(int(w) for w in info.input_widths),
                    tuple(info.output_names), tuple(int(w) for w in info.output_widths), tuple(unit_columns))


#: job key -> findings of the probes this process ran for readers ([] when the network passed)
_READER_RESULTS: dict[str, list[tuple[str, str]]] = {}


def probe_once(jobs: list[ProbeJob], *, timeout: float | None = None) -> dict[str, list[tuple[str, str]]]:
    """:func:`probe_networks` for a reader (``timeout`` default :data:`PROBE_TIMEOUT_S`): ``jobs`` this process has
    not probed yet run in one bounded child, the others answer from that earlier probe; key -> findings."""
    todo = [j for j in jobs if j.key not in _READER_RESULTS]
    if todo:
        _READER_RESULTS.update(probe_networks(todo, timeout=PROBE_TIMEOUT_S if timeout is None else timeout))
    return {j.key: _READER_RESULTS[j.key] for j in jobs}


def probe_networks(jobs: list[ProbeJob], *, timeout: float = PROBE_TIMEOUT_S) -> dict[str, list[tuple[str, str]]]:
    """Probe all ``jobs`` in one bounded child; key -> findings ([] when the network passed)."""
    from .safeopen import run_bounded

    if not jobs:
        return {}
    total = sum(len(j.data) for j in jobs)
    env = dict(os.environ)
    env["OMP_NUM_THREADS"] = "1"
    argv = [sys.executable, "-P", "-c", "from nasset_sdk.netprobe import child_main; child_main()", str(float(timeout))]
    run = run_bounded(argv, stdin=_encode(jobs), max_as=ADDRESS_SPACE_BASE + 16 * total, timeout=timeout, env=env)
    text = run.stdout.decode("utf-8", "replace")
    marker = text.rfind(_MARKER)
    if run.status == "ok" and marker >= 0:
        try:
            found = json.loads(text[marker + len(_MARKER):].strip().splitlines()[0])
            return {j.key: [tuple(f) for f in found.get(j.key, [])] for j in jobs}
        except (ValueError, IndexError):
            pass
    if run.status == "timeout":
        why = f"the network probe did not finish within {timeout:g} s"
    elif run.status == "crashed":
        why = f"the network probe crashed (signal {-(run.returncode or 0)})"
    else:
        tail = run.stderr.decode("utf-8", "replace").strip().splitlines()
        why = f"the network probe failed ({run.status}" + (f": {tail[-1][:200]}" if tail else "") + ")"
        if (tail and "MemoryError" in tail[-1]) or "bad_alloc" in run.stderr.decode("utf-8", "replace"):
            why = "the network probe ran out of its memory bound"
    return {j.key: [("NETWORK_RUNTIME", why)] for j in jobs}
