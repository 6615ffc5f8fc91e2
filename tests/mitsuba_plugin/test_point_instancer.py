"""A PointInstancer rendered by the plugin as the reference renderer renders it (it was SCENE_UNSUPPORTED); the reader's
placements are tested in tests/mitsuba_renderer/test_point_instancer.py."""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from tests.stage_scenes import check_point_instancer  # noqa: E402


def test_instances_render_as_in_the_reference_renderer(tmp_path):
    check_point_instancer(render, tmp_path)
