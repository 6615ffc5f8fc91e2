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


def test_warnings_name_what_is_approximated(tmp_path):
    """One warning per approximated object: the disk area light (and nothing for the exact rectangles)."""
    r = measure("area_lights", tmp_path, size=8, spp=4)
    assert [w for w in r["warnings"] if "Disk" in w] and not [w for w in r["warnings"] if "Rect" in w or "Square" in w]
