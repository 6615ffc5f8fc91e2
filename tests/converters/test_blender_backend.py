"""Without Blender's module every Blender entry point fails with a typed CONVERT_BACKEND error
(runs whether or not bpy is installed: the import is blocked for the test)."""

from __future__ import annotations

import sys

import pytest

from nasset_sdk.errors import NassetError


def test_missing_bpy_is_a_typed_error(monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "bpy", None)  # makes `import bpy` raise ImportError
    from nasset_converters.blender import load_bpy
    from nasset_converters.blender.usd_export import convert_scene

    with pytest.raises(NassetError) as e:
        load_bpy()
    assert e.value.code == "CONVERT_BACKEND" and "pip install bpy" in str(e.value)
    with pytest.raises(NassetError) as e:
        convert_scene(None, tmp_path / "s.usda", example="blender-hair")
    assert e.value.code == "CONVERT_BACKEND"


HEAVY = ("bpy", "torch", "mitsuba", "drjit")

CHILD_HELP = """
import contextlib, io, sys
from nasset_sdk.cli import build_parser
p = build_parser()
with contextlib.redirect_stdout(io.StringIO()) as out:
    try:
        p.parse_args(["bench", "blender", "--help"])
    except SystemExit:
        pass
args = p.parse_args(["bench", "blender", "--quick", "--examples", "blender-hair"])
assert args.quick and args.examples == "blender-hair"
print("--quick" in out.getvalue(), sorted(m for m in %r if m in sys.modules))
"""


def test_bench_cli_help_does_not_import_heavy_modules():
    """``nasset bench blender --help`` (and parsing its options) in a fresh interpreter imports no heavy module."""
    import subprocess

    r = subprocess.run([sys.executable, "-c", CHILD_HELP % (HEAVY,)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == ["True", "[]"], r.stdout
