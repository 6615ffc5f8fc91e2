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
``"compose"`` compose the stage with its arcs to other files followed and all payloads loaded (a tree of
             layers that each passed ``"full"``: arcs between them can repeat subtrees without bound).
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

LEVELS = ("layer", "full", "compose")
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
    measured: bool = False  # the child measured a bound (detail says which field); USD itself read the file
    asset_bounds: bool = False  # the child held the layer to the asset structure bounds (and it passed them)

    def message(self) -> str:
        if self.measured:
            return self.detail
        if self.status == "memory":
            return (f"reading it needs more memory than its bound ({self.detail}): arrays decompress, or arcs repeat subtrees, "
                    "beyond the format bounds")
        if self.status == "crashed":
            return f"USD crashed while reading it ({self.detail})"
        if self.status == "timeout":
            return f"USD did not finish reading it within {self.detail}"
        return f"USD cannot open it: {self.detail}"


_CHILD = r"""
import json, os, sys
def _why(exc):  # USD's own messages (the parser's file:line:column and prim), without its source locations
    from nasset_sdk.errors import usd_reason
    return (usd_reason(exc) or type(exc).__name__)[:300]
def main(path, level, asset, search):
    from pxr import Ar, Sdf, Tf, Usd
    import nasset_sdk  # registers the schema so the stage composes as in the parent
    try:
        layer = Sdf.Layer.FindOrOpen(path)
    except Exception as exc:
        return {"ok": False, "detail": _why(exc)}
    if layer is None:
        return {"ok": False, "detail": "not a USD layer"}
    if level == "full":
        from nasset_sdk.paths import has_external, outer_file, strip_external
        from nasset_sdk.safeopen import composition_problem, is_asset_layer, measure_layer, structure_problem
        try:
            # an asset's structure first: counting stops at its bound, the walks below visit every spec
            as_asset = asset == "asset" or is_asset_layer(layer)
            why = (structure_problem(layer) or composition_problem(strip_external(layer))) if as_asset else None
            if why:
                return {"ok": False, "code": "ARRAY_TOO_LARGE", "detail": why[:300]}
            over = measure_layer(layer, os.path.getsize(outer_file(path)))
            if over:
                return {"ok": False, "code": over[0], "detail": over[1][:300]}
            # never compose arcs to other files here: the parent checks their paths, and a v0.1 asset has none
            stage = Usd.Stage.Open(strip_external(layer) if has_external(layer) else layer, Usd.Stage.LoadAll)
            if stage is None:
                return {"ok": False, "detail": "the stage does not compose"}
            for prim in stage.TraverseAll():
                prim.GetAttributes()
        except Exception as exc:
            return {"ok": False, "detail": _why(exc)}
        return {"ok": True, "detail": "", "asset": as_asset}
    if level == "compose":
        from nasset_sdk.limits import MAX_ASSET_SPECS
        folders = json.loads(search)
        context = Ar.DefaultResolverContext(folders) if folders else Ar.GetResolver().CreateDefaultContextForAsset(path)
        try:
            stage = Usd.Stage.Open(layer, context, Usd.Stage.LoadAll)
            if stage is None:
                return {"ok": False, "detail": "the stage does not compose"}
            n = 0
            for prim in stage.TraverseAll() if asset == "asset" else ():
                n += 1
                if n > MAX_ASSET_SPECS:
                    return {"ok": False, "code": "ARRAY_TOO_LARGE", "detail": "its layers compose to more than "
                            f"{MAX_ASSET_SPECS} prims, the bound of an asset"}
        except Exception as exc:
            return {"ok": False, "detail": _why(exc)}
    return {"ok": True, "detail": ""}
out = main(sys.argv[1], sys.argv[2], sys.argv[3], sys.argv[4])
sys.stdout.write("\n@@probe@@" + json.dumps(out) + "\n")
sys.stdout.flush()
"""


#: Bytes one decoded ``std::string`` costs besides its characters (libstdc++), and one token or pointer.
_STRING_BYTES = 32
_POINTER_BYTES = 8
_LIST_OP_PARTS = ("explicitItems", "addedItems", "prependedItems", "appendedItems", "deletedItems", "orderedItems")


class _TooDeep(Exception):
    pass


def _text_bytes(s: str) -> int:
    return _STRING_BYTES + (len(s) if s.isascii() else len(s.encode("utf-8", "surrogatepass")))


_SCALAR_BYTES = {"Bool": 1, "UChar": 1, "Half": 2, "Int": 4, "UInt": 4, "Float": 4}
_LETTER_BYTES = {"h": 2, "f": 4, "i": 4, "d": 8}


def _item_bytes(type_name: str) -> int:
    """Bytes of one element of a numeric ``Vt`` array type (``Vec3fArray`` -> 12, ``QuatdArray`` -> 32,
    ``Matrix4dArray`` -> 128, ``HalfArray`` -> 2); 8 for any other (``Int64``, ``Double``, ``TimeCode``, ...)."""
    base = type_name[: -len("Array")]
    letter = _LETTER_BYTES.get(base[-1:], 8)
    if base.startswith("Vec") and base[3:4].isdigit():
        return int(base[3]) * letter
    if base.startswith("Quat"):
        return 4 * letter
    if base.startswith("Matrix") and base[6:7].isdigit():
        return int(base[6]) ** 2 * letter
    return _SCALAR_BYTES.get(base, 8)


def decoded_bytes(value, depth: int = 0) -> int:
    """Bytes usd-core holds for a field ``value`` once decoded.

    A crate file stores each distinct string once (in a compressed table) and refers to it by index,
    so every element of a string array, every list-op item and every dictionary entry that names it
    holds a copy of its own: strings count their length plus a ``std::string`` wherever they occur.
    Numeric arrays count their element width; tokens (interned) a pointer each. Raises
    :class:`_TooDeep` for dictionaries or lists nested deeper than ``limits.MAX_VALUE_DEPTH``."""
    from .limits import MAX_VALUE_DEPTH

    if depth > MAX_VALUE_DEPTH:
        raise _TooDeep
    if isinstance(value, str):
        return _text_bytes(value)
    if isinstance(value, (bytes, bytearray)):
        return len(value)
    if isinstance(value, dict):
        return sum(_text_bytes(str(k)) + decoded_bytes(v, depth + 1) for k, v in value.items())
    if isinstance(value, (list, tuple)):
        return sum(_POINTER_BYTES + decoded_bytes(v, depth + 1) for v in value)
    name = type(value).__name__
    if name == "StringArray":
        return sum(_text_bytes(s) for s in value)
    if name == "TokenArray":
        return _POINTER_BYTES * len(value)
    if name == "AssetPathArray":  # authored, evaluated and resolved path strings
        return sum(2 * _STRING_BYTES + _text_bytes(a.path) for a in value)
    if name == "AssetPath":
        return 2 * _STRING_BYTES + _text_bytes(value.path)
    if name.endswith("ListOp"):
        return sum(decoded_bytes(list(getattr(value, part)), depth + 1) for part in _LIST_OP_PARTS)
    if name in ("Reference", "Payload"):
        return _text_bytes(value.assetPath) + _text_bytes(str(value.primPath))
    if name.endswith("Array"):
        return len(value) * _item_bytes(name)
    return _POINTER_BYTES


def measure_layer(layer, file_bytes: int) -> tuple[str, str] | None:
    """(code, why) when a field of ``layer`` (every spec, every variant, every time sample) is an array above its
    bound, nests deeper than ``MAX_VALUE_DEPTH``, or all fields decode to more than ``decoded_bound(file_bytes)``
    bytes; None when it is within the bounds. Reads every value: run it in the probe child only."""
    from pxr import Sdf

    from .limits import MAX_VALUE_DEPTH, array_bound, decoded_bound

    total = 0
    largest = (0, None, "")
    problems: list[tuple[str, str]] = []

    def where(spec_path, key) -> str:  # spelled only for a message: a path's text costs its depth
        return f"{spec_path.StripAllVariantSelections()} {key}"

    def measure(spec_path, key, value):
        nonlocal total, largest
        name = type(value).__name__
        if name.endswith("Array"):
            n = len(value)
            bound = array_bound(spec_path.name if spec_path.IsPropertyPath() else key, key)
            if n > bound:
                problems.append(("ARRAY_TOO_LARGE", f"{where(spec_path, key)}: {n} elements > {bound}"))
                return
        try:
            size = decoded_bytes(value)
        except _TooDeep:
            problems.append(("FILE_UNREADABLE", f"{where(spec_path, key)}: dictionaries or lists nested more than {MAX_VALUE_DEPTH} levels deep"))
            return
        total += size
        if size > largest[0]:
            largest = (size, spec_path, key)

    def visit(spec_path):
        spec = layer.GetObjectAtPath(spec_path)
        if spec is None or problems:
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
    if problems:
        return problems[0]
    bound = decoded_bound(file_bytes)
    if total > bound:
        return ("ARRAY_TOO_LARGE", f"arrays and strings decode to {total} bytes > {bound} (bound for a {file_bytes}-byte file); "
                f"largest: {where(largest[1], largest[2])}, {largest[0]} bytes")
    return None


def is_asset_layer(layer) -> bool:
    """True when ``layer``'s defaultPrim is a NeuralAsset (an asset file, not a scene)."""
    name = layer.defaultPrim
    spec = layer.GetPrimAtPath("/" + name) if name else None
    return spec is not None and spec.typeName == "NeuralAsset"


def _list_op_items(proxy) -> int:
    return sum(len(getattr(proxy, part)) for part in _LIST_OP_PARTS)


def structure_problem(layer, max_specs: int | None = None, max_depth: int | None = None) -> str | None:
    """Why ``layer`` is over an asset's structure bounds (``limits.MAX_ASSET_SPECS`` specs and time samples,
    ``limits.MAX_ASSET_DEPTH`` nested prims); None within them. Walks the prims breadth first and counts a
    prim's children and properties from their lists before visiting any of them, so it stops after at most
    ``max_specs`` visits whatever the file holds."""
    from collections import deque

    from .limits import MAX_ASSET_DEPTH, MAX_ASSET_SPECS

    max_specs = MAX_ASSET_SPECS if max_specs is None else max_specs
    max_depth = MAX_ASSET_DEPTH if max_depth is None else max_depth
    count = 0
    queue = deque([(layer.pseudoRoot, 0)])

    def over() -> str:
        return (f"holds at least {count} specs and time samples (prims, variants, properties, relationship targets, "
                f"connections, time samples) > {max_specs}, the bound of an asset layer")

    while queue:
        prim, depth = queue.popleft()
        children, properties = prim.nameChildren, prim.properties
        count += len(children) + len(properties)
        if count > max_specs:
            return over()
        if children and depth + 1 > max_depth:
            return f"nests prims more than {max_depth} deep, the bound of an asset layer (under {prim.path})"
        for prop in properties:
            count += layer.GetNumTimeSamplesForPath(prop.path)
            count += _list_op_items(prop.targetPathList if hasattr(prop, "targetPathList") else prop.connectionPathList)
            if count > max_specs:
                return over()
        queue.extend((child, depth + 1) for child in children)
        for vset in prim.variantSets:
            variants = vset.variants
            count += 1 + len(variants)
            if count > max_specs:
                return over()
            queue.extend((v.primSpec, depth) for v in variants.values())
    return None


class _Over(Exception):
    pass


def _internal_targets(spec) -> list:
    """Prim paths this prim spec's internal arcs (references and payloads without an asset path, inherits,
    specializes) name; arcs to other files are not composed by the probe."""
    out = []
    if spec.path.IsAbsoluteRootPath():
        return out
    for proxy in (spec.referenceList, spec.payloadList):
        for part in _LIST_OP_PARTS[:4]:
            out.extend(arc.primPath for arc in getattr(proxy, part) if not arc.assetPath and arc.primPath)
    for proxy in (spec.inheritPathList, spec.specializesList):
        for part in _LIST_OP_PARTS[:4]:
            out.extend(getattr(proxy, part))
    return [t.MakeAbsolutePath(spec.path) if not t.IsAbsolutePath() else t for t in out]


def composition_problem(layer, max_prims: int | None = None, max_depth: int | None = None) -> str | None:
    """Why composing ``layer`` could give an asset more than ``limits.MAX_ASSET_SPECS`` prims; None when it cannot.

    Internal arcs repeat a subtree wherever they point to it: ten prims each referencing a class of ten prims that
    each reference the next class, six levels deep, is a 13 KB file that composes to 10^6 prims (validate: 88 s,
    1.8 GB; one level more runs into the probe's time bound). This bounds the composed prims from the specs alone,
    before composing: a prim counts 1, plus its children, plus what every arc and every variant of it brings
    (summed: an upper bound). Arcs nested deeper than ``limits.MAX_ASSET_DEPTH`` are over the bound too."""
    from .limits import MAX_ASSET_DEPTH, MAX_ASSET_SPECS

    max_prims = MAX_ASSET_SPECS if max_prims is None else max_prims
    max_depth = MAX_ASSET_DEPTH if max_depth is None else max_depth
    memo: dict = {}

    def size(spec, depth: int) -> int:
        key = spec.path
        if key in memo:
            return memo[key]
        if depth > max_depth:
            raise _Over(f"nests prims and arcs more than {max_depth} deep, the bound of an asset (at {key})")
        memo[key] = 0  # an arc cycle adds nothing (composition refuses it)
        n = 1 + sum(size(child, depth + 1) for child in spec.nameChildren)
        for target in _internal_targets(spec):
            found = layer.GetPrimAtPath(target)
            if found is not None:
                n += size(found, depth + 1) - 1
        for vset in spec.variantSets:
            n += sum(size(v.primSpec, depth + 1) - 1 for v in vset.variants.values())
        if n > max_prims:
            raise _Over(f"composes to more than {max_prims} prims, the bound of an asset (arcs repeat {key}: "
                        f"at least {n} prims)")
        memo[key] = n
        return n

    try:
        size(layer.pseudoRoot, 0)
    except _Over as over:
        return str(over)
    return None


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


def probe(path: str | os.PathLike, *, level: str = "full", timeout: float = DEFAULT_TIMEOUT_S,
          asset: bool = False, search_paths: list[str] | None = None) -> ProbeResult:
    """Open ``path`` with USD in a child process; never raises for a bad file. At level 'full' a layer that is an
    asset (defaultPrim a NeuralAsset), or any layer when ``asset`` (the caller reads it as an asset), is held to
    the asset structure bounds (:func:`structure_problem`) before anything else reads it. ``search_paths``: the
    folders of the resolver context the caller composes with (level 'compose')."""
    if level not in LEVELS:
        raise error("USAGE", f"probe level must be one of {LEVELS}, got {level!r}")
    from .paths import outer_file

    p = Path(path)
    outer = outer_file(os.fspath(p))
    size = os.path.getsize(outer) if os.path.isfile(outer) else 0
    max_as = ADDRESS_SPACE_BASE + 4 * size
    env = dict(os.environ)
    env.setdefault("PXR_WORK_THREAD_LIMIT", "1")
    # crate's default zero-copy mapping: an uncompressed array's length comes from its header and none of its
    # bytes is read (with USDC_USE_PREAD every array would be read whole: a reader that loads only the
    # required components would pay for the optional ones in its probe)
    env.pop("USDC_USE_PREAD", None)
    run = run_bounded([sys.executable, "-c", _CHILD, str(p), level, "asset" if asset else "any",
                       json.dumps(list(search_paths or []))], max_as=max_as, timeout=timeout, env=env)
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
                       run.returncode, seconds, str(result.get("code") or "FILE_UNREADABLE"), "code" in result,
                       bool(result.get("asset")))


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


def ensure_readable(path: str | os.PathLike, *, level: str = "full", timeout: float = DEFAULT_TIMEOUT_S,
                    asset: bool = False, search_paths: list[str] | None = None) -> ProbeResult:
    """Raise ``FILE_NOT_FOUND`` / ``FILE_UNREADABLE`` / ``ARRAY_TOO_LARGE`` unless the probe of ``path`` passes
    (a file, or a layer inside a package: ``a.usdz[b.usdc]``); ``asset``: held to the asset bounds (:func:`probe`)."""
    from .paths import outer_file

    p = Path(path)
    if not os.path.isfile(outer_file(os.fspath(p))):
        raise error("FILE_NOT_FOUND", "no such file", file=str(p))
    result = probe(p, level=level, timeout=timeout, asset=asset, search_paths=search_paths)
    if not result.ok:
        raise error(result.code, result.message(), file=str(p))
    return result


#: Identities of the files this process wrote, or whose full probe passed: opened again without a probe. The value
#: says whether the file is known to be within the asset structure bounds (written here, or probed as an asset).
_SAFE: dict[tuple, bool] = {}
#: Identities of the files this process wrote (their networks came from this process: no runtime probe).
_WRITTEN: set[tuple] = set()


def file_identity(path: str | os.PathLike) -> tuple | None:
    """(device, inode, size, mtime, ctime, inner path) of the file behind ``path``; None if it cannot be stat'ed.
    Any change to the file (a rewrite, a replacement, a different link target) changes it."""
    from .paths import outer_file

    s = os.fspath(path)
    outer = outer_file(s)
    try:
        st = os.stat(outer)
    except OSError:
        return None
    return (st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns, s[len(outer):])


def trust(path: str | os.PathLike) -> None:
    """Record that this process just wrote ``path``: :func:`ensure_safe` opens it without a probe while it is unchanged."""
    key = file_identity(path)
    if key is not None:
        _SAFE[key] = True
        _WRITTEN.add(key)


def written_here(path: str | os.PathLike) -> bool:
    """True when this process wrote ``path`` (:func:`trust`) and it is unchanged since."""
    key = file_identity(path)
    return key is not None and key in _WRITTEN


def ensure_safe(path: str | os.PathLike, *, timeout: float = DEFAULT_TIMEOUT_S, asset: bool = False) -> None:
    """Probe ``path`` at level ``full`` (:func:`ensure_readable`) before it is opened in this process, unless this
    process wrote it (:func:`trust`) or already probed it (as an asset when ``asset``), unchanged since. Every reader
    of an untrusted layer calls this first (spec/security.md#bounds)."""
    key = file_identity(path)
    if key is not None and key in _SAFE and (_SAFE[key] or not asset):
        return
    result = ensure_readable(path, level="full", timeout=timeout, asset=asset)
    if key is not None:
        _SAFE[key] = asset or result.asset_bounds


#: Trees of layers whose whole composition passed its probe: (asset, search paths, identities of every file).
_COMPOSED: set[tuple] = set()


def ensure_composes(root: str | os.PathLike, files, *, asset: bool, search_paths: list[str]) -> None:
    """Compose the tree of layer ``files`` rooted at ``root`` in a probe child (level ``compose``) unless this process
    already did, every file unchanged since; raises as :func:`ensure_readable`."""
    key = (asset, tuple(search_paths), tuple(sorted(map(str, (file_identity(f) for f in files)))))
    if key in _COMPOSED:
        return
    ensure_readable(root, level="compose", asset=asset, search_paths=search_paths)
    _COMPOSED.add(key)


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
