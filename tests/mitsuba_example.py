"""The built-in Mitsuba example's asset, isolated as the bakes see it (tests of ground-truth data)."""

from __future__ import annotations

import pytest


def isolated_example(folder):
    """(mi, IsolatedAsset, centre [3], radius) of the example scene written into ``folder``; skips on a scalar
    Mitsuba variant (per-pixel lights need a JIT variant)."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.examples import EXAMPLE_ASSET_IDS, write_example_scene

    mi = load_mitsuba()
    if mi.variant().startswith("scalar"):
        pytest.skip("per-pixel lights need a JIT variant")
    mi.set_log_level(mi.LogLevel.Error)
    xml = write_example_scene(folder)
    shapes = msc.pick_shapes(msc.load_scene(mi, xml), list(EXAMPLE_ASSET_IDS))
    center, radius = msc.bounding_sphere(msc.mesh_geometry(mi, shapes))
    return mi, msc.IsolatedAsset(mi, shapes, center, radius), center, radius
