"""The render settings of a USD scene in the plugin (spec/renderer.md#render-settings): ``nasset:maxDepth`` is the
bounce limit when the caller gives none, ``nasset:pixelFilter = "gaussian"`` filters the film. The plugin used 5
bounces and a box filter whatever the scene said (Blender's converted scenes author both). The checks are the second
implementation's (tests/stage_scenes.py)."""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from tests.stage_scenes import check_gaussian_pixel_filter, check_settings_max_depth  # noqa: E402


def test_gaussian_pixel_filter_of_the_settings_is_applied(tmp_path):
    """Mitsuba's gaussian filter (the spec's, radius 4 s) splats the edge as the truncated Gaussian's CDF says."""
    check_gaussian_pixel_filter(render, tmp_path)


def test_max_depth_of_the_settings_is_the_default(tmp_path):
    check_settings_max_depth(render, tmp_path, spp=16)
