"""Scenes nested thousands deep are untrusted input too: loading one costs time linear in its prims, not in their
number times their depth (docs/security-report.md, deep scenes). Counted, never timed."""

from __future__ import annotations

import pytest

from nasset_reference_renderer import load_scene
from tests.stage_scenes import ancestor_visits_ratio


def _read(path, depth) -> None:
    assert load_scene(path).camera.prim == "/World/Camera"


@pytest.mark.parametrize("mesh_every", [0, 1], ids=["visibility-and-purpose", "transforms-primvars-materials"])
def test_a_deep_chain_loads_in_linear_time(tmp_path, monkeypatch, mesh_every):
    small, large = ancestor_visits_ratio(tmp_path, monkeypatch, _read, mesh_every=mesh_every)
    assert large <= 2.2 * small, (small, large)  # each prim's (mesh's) ancestors walked again: 4x
