"""``nasset render`` on hostile arguments and scenes (issue 13, classes 7-9): exit codes and typed error codes.

Exit 2 and ``[USAGE]`` for bad arguments (checked before anything is allocated), exit 1 and the typed
code for scene and file problems, never a traceback; no output overwrites an input; no Inf/NaN in a file.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.corpus.gen_render import make_cases

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    return {c.name: c.path for c in make_cases(tmp_path_factory.mktemp("render_cases"))}


def nasset(*args, cwd=None, timeout=120):
    r = subprocess.run([sys.executable, "-m", "nasset_sdk.cli", *map(str, args)], capture_output=True, text=True,
                       timeout=timeout, cwd=cwd)
    assert "Traceback" not in r.stderr, r.stderr
    return r


def _render(scene, out, *extra):
    return nasset("render", scene, "-o", out, "--width", 16, "--height", 16, "--spp", 2, "--quiet", *extra)


@pytest.mark.parametrize("args", [("--width", 0), ("--width", -3), ("--height", 0), ("--width", 100_000_000, "--height", 100_000),
                                  ("--width", 70_000, "--height", 1), ("--spp", 0), ("--spp", -1), ("--spp", 10**12),
                                  ("--width", 8192, "--height", 8192, "--spp", 1 << 20), ("--max-depth", -2), ("--tile", 0),
                                  ("--batch", 1 << 30), ("--threads", -1)])
def test_bad_sizes_are_usage_errors_before_allocating(cases, tmp_path, args):
    r = nasset("render", cases["r9_geometry_offset_300"], "-o", tmp_path / "o.exr", "--quiet", *args, timeout=60)
    assert r.returncode == 2 and "[USAGE]" in r.stderr, r.stderr
    assert not (tmp_path / "o.exr").exists()


@pytest.mark.parametrize("target", ["missing_dir/o.exr", "/proc/o.exr", "dir.exr"])
def test_unwritable_output_is_write_failed(cases, tmp_path, target):
    (tmp_path / "dir.exr").mkdir()
    out = target if target.startswith("/") else tmp_path / target
    r = _render(cases["r9_scene_control"], out)
    assert r.returncode == 1 and "[WRITE_FAILED]" in r.stderr, r.stderr


def test_asset_write_to_unwritable_folder_is_typed(tmp_path):
    r = nasset("example", "-o", "/proc/x.usdc", "--size", "tiny")
    assert r.returncode == 1 and "[WRITE_FAILED]" in r.stderr, r.stderr


def test_outputs_never_overwrite_inputs(cases, tmp_path):
    asset = tmp_path / "a.usdc"
    asset.write_bytes(Path(cases["r9_geometry_offset_300"]).read_bytes())
    before = asset.read_bytes()
    os.symlink(asset, tmp_path / "link.png")
    for extra in (("--png", asset), ("--png", tmp_path / "link.png"), ("--variance", asset)):
        r = _render(asset, tmp_path / "o.exr", *extra)
        assert r.returncode == 2 and "[USAGE]" in r.stderr and "overwrite" in r.stderr, r.stderr
    # a scene's referenced asset is an input too
    scene = Path(cases["r9_scene_control"])
    ref = scene.parent / "_scene_asset.usdc"
    ref_bytes = ref.read_bytes()
    r = _render(scene, tmp_path / "o.exr", "--png", ref)
    assert r.returncode == 2 and "overwrite" in r.stderr, r.stderr
    r = _render(scene, tmp_path / "o.exr", "--png", tmp_path / "o.exr")
    assert r.returncode == 2 and "same file" in r.stderr, r.stderr
    assert asset.read_bytes() == before and ref.read_bytes() == ref_bytes


@pytest.mark.parametrize("name,code,where", [
    ("r9_camera_focal_zero", "SCENE_INVALID", "/World/Camera.focalLength"),
    ("r9_camera_aperture_huge", "SCENE_INVALID", "/World/Camera.horizontalAperture"),
    ("r9_transform_asset_nan", "SCENE_INVALID", "/World/Asset.xformOpOrder"),
    ("r9_transform_asset_scale_1e37", "SCENE_INVALID", "/World/Asset.xformOpOrder"),
    ("r9_transform_asset_scale_2e-4_vs_ground", "SCENE_INVALID", "/World/Asset.xformOpOrder"),
    ("r8_light_exposure_1e6", "SCENE_INVALID", "/World/Key.inputs:exposure"),
    ("r8_dome_huge_header", "IMAGE_INVALID", "/World/Dome.inputs:texture:file"),
    ("r8_dome_truncated", "IMAGE_INVALID", "/World/Dome.inputs:texture:file"),
    ("r8_8dna_spline_minimums_width_sum", "KIND_CONTRACT", "splineMinimums.values"),
])
def test_scene_mistakes_are_typed_errors_naming_prim_and_attribute(cases, tmp_path, name, code, where):
    r = _render(cases[name], tmp_path / "o.exr")
    assert r.returncode == 1 and f"[{code}]" in r.stderr and where in r.stderr, r.stderr
    assert not (tmp_path / "o.exr").exists()


def test_huge_radiance_stays_finite_in_every_file(cases, tmp_path):
    from nasset_reference_renderer.film import SAMPLE_RADIANCE_MAX, read_exr

    r = _render(cases["r7_scene_key_1e30_asset_1e8"], tmp_path / "o.exr", "--variance", tmp_path / "v.exr", "--png", tmp_path / "o.png")
    assert r.returncode == 0, r.stderr
    img, var = read_exr(tmp_path / "o.exr"), read_exr(tmp_path / "v.exr")
    assert np.isfinite(img).all() and np.isfinite(var).all()
    assert img.max() > 1e20 and img.max() <= SAMPLE_RADIANCE_MAX * (1 + 1e-6)  # huge, clamped per sample, not Inf
    assert (tmp_path / "o.png").stat().st_size > 0


def test_assets_at_the_size_bounds_do_not_vanish(cases, tmp_path):
    """Validated extremes (diagonal 3e-8, coordinates 2.5e9) render like the unit asset: the studio frames the asset
    and the rna transport sees object space through the encoding box, so the pictures agree within their noise
    (the same random numbers do not give the same paths: a continuation lobe's tangent frame flips where a normal
    crosses z = 0, and rounding decides on which side). An asset 300 diagonals off its origin is still drawn (its
    centre pixels are not the background)."""
    from nasset_reference_renderer.film import read_exr
    from nasset_sdk.validate import validate_file

    names = ("r9_geometry_small_2e-8", "r9_geometry_large_5e9", "r9_geometry_offset_300")
    paths = {n: cases[n] for n in names}
    paths["unit"] = Path(cases["r9_scene_control"]).parent / "_scene_asset.usdc"
    imgs = {}
    for name, path in paths.items():
        assert validate_file(path, probe=False).ok
        r = _render(path, tmp_path / f"{name}.exr", "--spp", 16, "--variance", tmp_path / f"{name}_var.exr")
        assert r.returncode == 0, r.stderr
        imgs[name] = read_exr(tmp_path / f"{name}.exr"), read_exr(tmp_path / f"{name}_var.exr")
    ref, ref_var = imgs["unit"]
    assert ref.mean() > 0.1
    for name in names[:2]:
        img, var = imgs[name]
        se = np.sqrt((var + ref_var).sum()) / img.size  # standard error of the difference of the image means
        assert abs(img.mean() - ref.mean()) < 4 * se + 1e-3 * ref.mean(), (name, img.mean(), ref.mean(), se)
        z = np.abs(img - ref) / np.sqrt(var + ref_var + 1e-12)
        assert (z > 5).mean() < 0.02, name
    centre = imgs["r9_geometry_offset_300"][0][6:10, 6:10]
    assert (centre > 1.5 * imgs["r9_geometry_offset_300"][0][0, 0]).mean() > 0.5
