"""Conversion fidelity for Blender: each scene of ``nasset_converters.blender.fidelity`` rendered by Cycles and,
converted, by the reference renderer, at 32x32 and 32 spp (the full-size table is docs/conversion-fidelity.md).

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
    r = measure(name, tmp_path, size=32, spp=32)
    assert np.all(np.abs(np.asarray(r["ratio"]) - 1.0) < 0.03), (name, r["ratio"])
    assert r["noise_ratio"] < 1.4, (name, r["noise_ratio"], r["psnr"], r["psnr_seed"])


def test_area_lights_convert_exactly_without_warnings(tmp_path):
    """Rectangle and square area lights are RectLights, disk and ellipse ones DiskLights (before: equal-area
    rectangles, warned); none is approximated, so none is warned about."""
    from pxr import Usd

    r = measure("area_lights", tmp_path, size=8, spp=4)
    assert not [w for w in r["warnings"] if "light" in w], r["warnings"]
    stage = Usd.Stage.Open(str(tmp_path / "area_lights.usda"))
    types = {p.GetName(): str(p.GetTypeName()) for p in stage.Traverse() if p.GetTypeName().endswith("Light")}
    assert types == {"Rect": "RectLight", "Square": "RectLight", "Disk": "DiskLight", "Ellipse": "DiskLight"}, types
