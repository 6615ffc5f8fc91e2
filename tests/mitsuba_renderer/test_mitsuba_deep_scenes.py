"""The Mitsuba implementation reads a scene nested thousands deep in time linear in its prims (as
tests/renderer/test_deep_scenes.py for the reference renderer). Counted, never timed."""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")
from nasset_mitsuba_renderer.usdscene import read_scene  # noqa: E402
from tests.stage_scenes import AncestorVisits, nested_scene  # noqa: E402


def _visits(tmp_path, monkeypatch, depth, **kw) -> int:
    path = nested_scene(tmp_path / f"nested{depth}.usda", depth, **kw)
    with monkeypatch.context() as m:
        visits = AncestorVisits(m)
        scene = read_scene(path)
    assert len(scene.meshes) == 2 + (depth if kw.get("mesh_every") == 1 else 0)  # the floor, the bottom's, the leaves
    return visits.count


def test_visibility_and_purpose_of_a_deep_chain_cost_linear_time(tmp_path, monkeypatch):
    small, large = (_visits(tmp_path, monkeypatch, n) for n in (200, 400))
    assert large <= 2.2 * small, (small, large)  # each prim's ancestors walked again: 4x


def test_transforms_primvars_and_materials_of_meshes_at_every_depth_cost_linear_time(tmp_path, monkeypatch):
    small, large = (_visits(tmp_path, monkeypatch, n, mesh_every=1) for n in (200, 400))
    assert large <= 2.2 * small, (small, large)  # each mesh's ancestors walked again: 4x
