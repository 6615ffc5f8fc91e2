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


def test_bench_cli_help_does_not_import_heavy_modules():
    import argparse

    from nasset_benchmarks import blender as bench

    p = argparse.ArgumentParser()
    bench.add_args(p)
    args = p.parse_args(["--quick", "--examples", "blender-hair"])
    assert args.quick and args.examples == "blender-hair"
