"""nasset_sdk.process: the heap settings of the ``nasset`` command (glibc's own counters, in fresh processes)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

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
