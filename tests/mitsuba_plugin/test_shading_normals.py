"""Shading normals of plain meshes in the plugin (spec/renderer.md#shading-normals): authored normals of any
interpolation, a subdivision cage's smooth normals, the flip with the front side's geometric normal, zero normals. The
plugin shaded every mesh of a USD scene with its triangles' normals, so smooth meshes (nearly every converted Blender
object) rendered faceted. The checks are the second implementation's (tests/stage_scenes.py)."""

from __future__ import annotations

import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.render import render  # noqa: E402
from tests.stage_scenes import check_cage_normals, check_shading_normals  # noqa: E402


def test_authored_normals_shade_the_surface(tmp_path):
    check_shading_normals(render, tmp_path)


def test_a_subdivision_cage_shades_smooth(tmp_path):
    check_cage_normals(render, tmp_path)


def test_implicit_prims_and_curves_render(tmp_path):
    """Implicit prims, BasisCurves and Points, tessellated as the reference renderer does (they were SCENE_UNSUPPORTED:
    the converter writes Mitsuba's spheres as UsdGeom.Sphere, so most converted Mitsuba scenes did not load)."""
    from tests.stage_scenes import check_implicit_prims_and_curves

    check_implicit_prims_and_curves(render, tmp_path)


def test_singular_transforms_flatten_or_collapse_geometry(tmp_path):
    """Zero scales (tests/stage_scenes.py::check_singular_transforms): the scene reader raised numpy's LinAlgError."""
    from tests.stage_scenes import check_singular_transforms

    check_singular_transforms(render, tmp_path)
