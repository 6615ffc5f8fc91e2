"""Primvar colours (spec/renderer.md#primvar-colors): an unbound mesh's varying ``displayColor`` and a
``UsdPrimvarReader_float3`` feeding ``diffuseColor`` are interpolated over each triangle. Before, an unbound mesh took
the mean of its displayColor and a primvar reader's input used its own value (warned)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder

COLORS = np.array([[0.9, 0.1, 0.1], [0.1, 0.8, 0.1], [0.1, 0.2, 0.9], [0.7, 0.7, 0.2]])


def _quad(tmp_path, colors, *, bound: bool, interpolation="vertex", name="q"):
    """A 2 x 2 quad facing +Z under a delta sun along its normal, seen by an orthographic camera 2 units wide."""
    from pxr import Sdf, UsdGeom, UsdShade

    b = SceneBuilder()
    cam = b.camera((0, 0, 5), (0, 0, 0), aperture=20.0)
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    pts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
    mesh = UsdGeom.Mesh.Define(b.stage, "/World/Quad")
    mesh.CreatePointsAttr([tuple(p) for p in pts])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("displayColor", Sdf.ValueTypeNames.Color3fArray, interpolation)
    pv.Set([tuple(c) for c in np.atleast_2d(colors)])
    if bound:
        mat = b.material("Painted", diffuse=(0.3, 0.3, 0.3), roughness=0.5)
        surf = UsdShade.Shader(b.stage.GetPrimAtPath("/World/Looks/Painted/PreviewSurface"))
        reader = UsdShade.Shader.Define(b.stage, "/World/Looks/Painted/color")
        reader.CreateIdAttr("UsdPrimvarReader_float3")
        reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set("displayColor")
        surf.GetInput("diffuseColor").ConnectToSource(reader.ConnectableAPI(), "result")
        UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim()).Bind(mat)
    b.distant("Sun", (0, 0, 1), np.pi, angle=0.0)
    return load_scene(b.write(tmp_path / f"{name}.usda")), pts


def _barycentric_colors(w):
    """The fan triangulation's (0, 1, 2), (0, 2, 3) interpolation of COLORS at the pixel centres of a w x w image."""
    c = (np.arange(w) + 0.5) / w * 2 - 1
    x, y = np.meshgrid(c, -c)  # row 0 at the top
    out = np.zeros((w, w, 3))
    p0, p1, p2, p3 = np.array([-1, -1]), np.array([1, -1]), np.array([1, 1]), np.array([-1, 1])
    for (a, b, cc), (ia, ib, ic) in (((p0, p1, p2), (0, 1, 2)), ((p0, p2, p3), (0, 2, 3))):
        m = np.array([b - a, cc - a]).T
        uv = np.linalg.solve(m, np.stack([x - a[0], y - a[1]], -1)[..., None])[..., 0]
        inside = (uv[..., 0] >= -1e-12) & (uv[..., 1] >= -1e-12) & (uv.sum(-1) <= 1 + 1e-12)
        col = COLORS[ia] * (1 - uv.sum(-1))[..., None] + COLORS[ib] * uv[..., 0:1] + COLORS[ic] * uv[..., 1:2]
        out[inside] = col[inside]
    return out


@pytest.mark.parametrize("bound", [False, True])
def test_vertex_colors_are_interpolated_over_each_triangle(tmp_path, bound):
    """The difference to the same quad in one grey (same seed: the same paths, so the specular lobe cancels) is
    (kd - grey) x E / pi with kd the barycentric interpolation of the vertex colours at each pixel (an orthographic view
    is affine: a pixel's expected value is its centre's). The jittered samples leave each pixel a standard deviation
    of about (colour change across a pixel, <= 0.07) / sqrt(12 x 64) = 0.0025."""
    w = 16
    s_ = RenderSettings(spp=64, width=w, height=w, max_depth=1, seed=3)
    img = render(_quad(tmp_path, COLORS, bound=bound)[0], s_).image
    grey = render(_quad(tmp_path, [0.5, 0.5, 0.5], bound=bound, interpolation="constant", name="grey")[0], s_).image
    expect = _barycentric_colors(w) - 0.5
    off_diagonal = np.abs(np.add.outer(np.arange(w), np.arange(w)) - (w - 1)) > 1  # pixels inside one triangle
    err = (img - grey)[off_diagonal] - expect[off_diagonal]
    assert np.abs(err).max() < 0.0125 and abs(err.mean()) < 0.001, (np.abs(err).max(), err.mean())
    assert np.ptp(img[..., 0]) > 0.5  # the colours vary across the quad


def test_missing_primvar_uses_the_reader_fallback_with_a_warning(tmp_path):
    from pxr import Sdf, Usd, UsdShade

    scene, _ = _quad(tmp_path, COLORS, bound=True, name="fb")
    stage = Usd.Stage.Open(scene.file)
    reader = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/Painted/color"))
    reader.GetInput("varname").Set("paint")
    reader.CreateInput("fallback", Sdf.ValueTypeNames.Float3).Set((0.2, 0.4, 0.6))
    stage.GetRootLayer().Save()
    scene = load_scene(scene.file)
    assert any("'paint'" in w and "fallback" in w for w in scene.warnings)
    np.testing.assert_allclose(scene.tri_color[0, 0], [0.2, 0.4, 0.6])
