"""Lens shift (spec/renderer.md#cameras): ``horizontalApertureOffset`` / ``verticalApertureOffset`` move the
image window by offset / focalLength in the image plane at distance 1."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import load_scene
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError


def _scene(tmp_path, h_off, v_off):
    b = SceneBuilder()
    cam = b.camera((0, 0, 5), (0, 0, 0), focal=35.0, aperture=20.0)  # looks down -Z, +Y up, +X to the right
    if h_off is not None:
        cam.CreateHorizontalApertureOffsetAttr(h_off)
        cam.CreateVerticalApertureOffsetAttr(v_off)
    b.quad("Floor", (0, 0, 0), 1.0, normal=(0, 0, 1))
    return load_scene(b.write(tmp_path / "s.usda"))


def test_offsets_move_the_window_by_offset_over_focal_length(tmp_path):
    scene = _scene(tmp_path, 3.5, -7.0)
    _, d = scene.camera.generate_rays(np.array([32.0]), np.array([16.0]), 64, 32)  # the image centre
    np.testing.assert_allclose(d[0] / -d[0, 2], [3.5 / 35.0, -7.0 / 35.0, -1.0], atol=1e-12)
    _, d0 = _scene(tmp_path, None, None).camera.generate_rays(np.array([0.0, 64.0]), np.array([0.0, 32.0]), 64, 32)
    _, d1 = scene.camera.generate_rays(np.array([0.0, 64.0]), np.array([0.0, 32.0]), 64, 32)
    # the corners shift alike: the field of view keeps its size, the window moves
    np.testing.assert_allclose(d1[:, :2] / -d1[:, 2:] - d0[:, :2] / -d0[:, 2:], [[0.1, -0.2]] * 2, atol=1e-12)


@pytest.mark.parametrize("value", [float("nan"), 1e12])
def test_offsets_that_are_not_finite_or_beyond_the_bound_are_scene_errors(tmp_path, value):
    with pytest.raises(SceneError) as exc:
        _scene(tmp_path, value, 0.0)
    assert "horizontalApertureOffset" in str(exc.value)
