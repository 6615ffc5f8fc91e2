"""Scenes nested thousands deep are untrusted input too: loading one costs time linear in its prims, not in their
number times their depth (docs/security-report.md, deep scenes). Counted, never timed."""

from __future__ import annotations

from nasset_reference_renderer import load_scene
from tests.stage_scenes import AncestorVisits, nested_scene


def _visits(tmp_path, monkeypatch, depth, **kw) -> int:
    path = nested_scene(tmp_path / f"nested{depth}.usda", depth, **kw)
    with monkeypatch.context() as m:
        visits = AncestorVisits(m)
        scene = load_scene(path)
    assert scene.camera.prim == "/World/Camera"
    return visits.count


def test_visibility_and_purpose_of_a_deep_chain_cost_linear_time(tmp_path, monkeypatch):
    small, large = (_visits(tmp_path, monkeypatch, n) for n in (200, 400))
    assert large <= 2.2 * small, (small, large)  # each prim's ancestors walked again: 4x


def test_transforms_primvars_and_materials_of_meshes_at_every_depth_cost_linear_time(tmp_path, monkeypatch):
    small, large = (_visits(tmp_path, monkeypatch, n, mesh_every=1) for n in (200, 400))
    assert large <= 2.2 * small, (small, large)  # each mesh's ancestors walked again: 4x
