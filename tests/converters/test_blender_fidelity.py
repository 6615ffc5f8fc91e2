"""Conversion fidelity for Blender: each scene of ``nasset_converters.blender.fidelity`` rendered by Cycles and,
converted, by the reference renderer at 32x32 and 32 spp (and by the Mitsuba plugin at 64 spp; a scene whose means need
more samples sets its ``test_spp``: area_spread, 128 and 256) (the full-size table is docs/conversion-fidelity.md).

Bounds as in tests/converters/test_conversion_fidelity.py: the mean within 3 % per channel (2 % is the
target at full size) and the MSE against Cycles at most 1.4x what the two images' noise explains
(measured 0.6-1.2 here). Measured on the converter before this suite: textures ratio ~2 (linked
textures dropped), spot 0.88 (cone ignored), instances 1.04 (collection instances dropped), mesh_emitter
0 (Emission shader grey), hdri green 1.49 (mirrored dome), render_settings 1.20 (depth 5 instead of
max bounces + 1), area_lights 1.23 (light surfaces seen by the camera): each fails.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("bpy", reason="Blender tests need the bpy wheel (pip install bpy; CI installs it)")

from nasset_converters.blender.fidelity import SCENES, measure  # noqa: E402


@pytest.mark.parametrize("name", list(SCENES))
def test_converted_blender_scene_renders_like_cycles(tmp_path, name):
    r = measure(name, tmp_path, size=32, spp=SCENES[name].test_spp // 2)  # 32 but where a scene needs more
    assert np.all(np.abs(np.asarray(r["ratio"]) - 1.0) < 0.03), (name, r["ratio"])
    assert r["noise_ratio"] < 1.4, (name, r["noise_ratio"], r["psnr"], r["psnr_seed"])


@pytest.mark.parametrize("name", list(SCENES))
def test_converted_blender_scene_renders_like_cycles_in_the_mitsuba_plugin(tmp_path, name):
    """The converted stage rendered by the Mitsuba plugin, at 64 spp: the plugin picks one light per vertex, so its
    means need more samples than the reference renderer's (spot read 0.970 at 32 spp, 1.001 at 256). Its variance
    comes from a second seed, which undercounts rare bright samples: the MSE / noise bound is 2.5 (measured 0.8-2.1 at
    this size; shader_mixes, the highest, reads 1.34 at 64 x 64 x 512 spp, as the reference renderer's 1.36). Before
    2026-12-07 eleven scenes failed, MSE / noise 3.3-4700: every texture read as its input's own value (textures,
    procedural_textures, texture_ops, pixel_art, pbr_textures, emission_texture, node_links), colour attributes as their
    mean, normal maps and cut-outs ignored, smooth balls faceted (principled)."""
    r = measure(name, tmp_path, size=32, spp=SCENES[name].test_spp, renderer="plugin")  # 64 but where a scene needs more
    assert np.all(np.abs(np.asarray(r["ratio"]) - 1.0) < 0.03), (name, r["ratio"])
    assert r["noise_ratio"] < 2.5, (name, r["noise_ratio"], r["psnr"], r["psnr_seed"])


def test_area_lights_convert_exactly_without_warnings(tmp_path):
    """Rectangle and square area lights are RectLights, disk and ellipse ones DiskLights (before: equal-area
    rectangles, warned); none is approximated, so none is warned about."""
    from pxr import Usd

    r = measure("area_lights", tmp_path, size=8, spp=4)
    assert not [w for w in r["warnings"] if "light" in w], r["warnings"]
    stage = Usd.Stage.Open(str(tmp_path / "area_lights.usda"))
    types = {p.GetName(): str(p.GetTypeName()) for p in stage.Traverse() if p.GetTypeName().endswith("Light")}
    assert types == {"Rect": "RectLight", "Square": "RectLight", "Disk": "DiskLight", "Ellipse": "DiskLight"}, types
