"""nasset_sdk.process: the heap settings of the ``nasset`` command (glibc's own counters, in fresh processes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

import pytest

import nasset_sdk.cli as cli
import nasset_sdk.process as process

# a fresh process: optionally tune, then allocate one 8 MiB array and report how many blocks glibc mmapped for it
PROBE = """
import ctypes, json, sys
import numpy as np
from nasset_sdk.process import tune_allocator

class MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = MallInfo2
tuned = tune_allocator() if sys.argv[1] == "tune" else None
before = libc.mallinfo2().hblks
a = np.ones(1 << 20)  # 8 MiB
after = libc.mallinfo2().hblks
print(json.dumps({"tuned": tuned, "mmapped": after - before, "sum": float(a.sum())}))
"""


def _probe(mode: str, **env) -> dict:
    clean = {k: v for k, v in os.environ.items() if k not in process.USER_SETTINGS}
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True,
                         env={**clean, **env}, timeout=60)
    return json.loads(out.stdout)


def test_glibc_defaults_mmap_a_fresh_8_mib_array():
    """The baseline the setting changes: without it, a new 8 MiB array gets its own mmapped pages."""
    assert _probe("plain") == {"tuned": None, "mmapped": 1, "sum": float(1 << 20)}


def test_tuned_process_serves_8_mib_from_the_heap():
    assert _probe("tune") == {"tuned": True, "mmapped": 0, "sum": float(1 << 20)}


def test_user_setting_wins():
    """A user who set glibc's thresholds through the environment keeps them: nothing is changed."""
    r = _probe("tune", MALLOC_TRIM_THRESHOLD_="1000000")
    assert r["tuned"] is False and r["mmapped"] == 1


def test_console_script_tunes_then_runs_main(monkeypatch, capsys):
    calls = []
    monkeypatch.setattr(process, "tune_allocator", lambda: calls.append("tune") or True)
    monkeypatch.setattr(sys, "argv", ["nasset"])
    assert cli.console_main() == 2  # no verb: help, usage exit code
    assert calls == ["tune"] and "usage" in capsys.readouterr().out


def _blas_counts() -> list[int]:
    return [get() for get, _ in process._loaded_openblas()]


@pytest.fixture
def blas_two_threads():
    """numpy's OpenBLAS at 2 threads for the test (the renderers' setting must show as 1), its count restored after."""
    libs = process._loaded_openblas()
    if sys.platform.startswith("linux"):
        assert libs, "numpy's wheel bundles OpenBLAS on Linux: /proc/self/maps should list it"
    if (os.cpu_count() or 1) < 2:
        pytest.skip("OpenBLAS caps its threads at the cores: one core cannot show the difference")
    before = _blas_counts()
    for _, put in libs:
        put(2)
    assert set(_blas_counts()) == {2}
    yield
    for (_, put), n in zip(libs, before, strict=True):
        put(n)


def test_single_threaded_blas_nests_and_restores(blas_two_threads):
    with process.single_threaded_blas():
        assert set(_blas_counts()) == {1}
        with process.single_threaded_blas():
            assert set(_blas_counts()) == {1}
        assert set(_blas_counts()) == {1}  # the outer block still runs
    assert set(_blas_counts()) == {2}
    with pytest.raises(RuntimeError), process.single_threaded_blas():
        raise RuntimeError("restored on the way out")
    assert set(_blas_counts()) == {2}


def test_single_threaded_blas_concurrent_blocks(blas_two_threads):
    """Two threads' blocks overlapping (A enters, B enters, A leaves, B leaves): one thread until B leaves."""
    a_in, b_in, a_out = threading.Event(), threading.Event(), threading.Event()
    seen = {}

    def a():
        with process.single_threaded_blas():
            a_in.set()
            b_in.wait(10)
        a_out.set()

    def b():
        a_in.wait(10)
        with process.single_threaded_blas():
            b_in.set()
            a_out.wait(10)
            seen["after A left"] = set(_blas_counts())

    threads = [threading.Thread(target=f) for f in (a, b)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(20)
    assert seen == {"after A left": {1}} and set(_blas_counts()) == {2}


def test_reference_renderer_loads_and_renders_on_one_blas_thread(blas_two_threads, monkeypatch):
    """load_scene and render run inside single_threaded_blas (docs/benchmarks.md#blas-threads); the count they see
    is read from OpenBLAS itself."""
    import nasset_reference_renderer.integrator as integrator
    import nasset_reference_renderer.scene as scene_module
    from nasset_reference_renderer import RenderSettings, load_scene, render

    case = Path(process.__file__).parent / "conformance_cases" / "rna_point_light" / "scene.usda"
    seen = []
    load, render_inner = scene_module._Loader.load, integrator._render
    monkeypatch.setattr(scene_module._Loader, "load", lambda self: seen.append(("load", _blas_counts())) or load(self))
    monkeypatch.setattr(integrator, "_render", lambda *a: seen.append(("render", _blas_counts())) or render_inner(*a))
    render(load_scene(case), RenderSettings(width=4, height=4, spp=1, progress=False))
    assert [(what, set(c)) for what, c in seen] == [("load", {1}), ("render", {1})]
    assert set(_blas_counts()) == {2}
