"""The Mitsuba implementation reads a scene nested thousands deep in time linear in its prims (as
tests/renderer/test_deep_scenes.py for the reference renderer). Counted, never timed."""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")
from nasset_mitsuba_renderer.usdscene import read_scene  # noqa: E402
from tests.stage_scenes import ancestor_visits_ratio  # noqa: E402


@pytest.mark.parametrize("mesh_every", [0, 1], ids=["visibility-and-purpose", "transforms-primvars-materials"])
def test_a_deep_chain_loads_in_linear_time(tmp_path, monkeypatch, mesh_every):
    def read(path, depth):  # the floor, the bottom's mesh, and with mesh_every one beside every Xform
        assert len(read_scene(path).meshes) == 2 + (depth if mesh_every else 0)

    small, large = ancestor_visits_ratio(tmp_path, monkeypatch, read, mesh_every=mesh_every)
    assert large <= 2.2 * small, (small, large)  # each prim's (mesh's) ancestors walked again: 4x
