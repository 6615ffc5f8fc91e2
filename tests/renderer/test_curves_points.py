"""Plain BasisCurves and Points (spec/renderer.md#curves-and-points): tubes and spheres of their widths. Before, a
scene holding either was SCENE_UNSUPPORTED as a whole."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.curves import polylines
from nasset_sdk.errors import SceneError

P = np.array([[0.0, 0.0, 0.0], [1.0, 2.0, 0.0], [3.0, 2.0, 1.0], [4.0, 0.0, 0.0]])


def test_cubic_bases_evaluate_their_curves():
    """Bezier: through its end points, (P0 + 3 P1 + 3 P2 + P3) / 8 at the middle; B-spline: (P0 + 4 P1 + P2) / 6 at its
    start; Catmull-Rom: through its inner control points; linear: the points themselves; widths alike."""
    w = np.array([1.0, 2.0, 3.0, 4.0])
    p, c, wid = polylines(P, [4], w, "cubic", "bezier")
    assert c.tolist() == [5]
    np.testing.assert_allclose(p[[0, -1]], P[[0, 3]], atol=1e-12)
    np.testing.assert_allclose(p[2], (P[0] + 3 * P[1] + 3 * P[2] + P[3]) / 8, atol=1e-12)
    np.testing.assert_allclose(wid[2], (1 + 6 + 9 + 4) / 8, atol=1e-12)
    p, _, _ = polylines(P, [4], w, "cubic", "bspline")
    np.testing.assert_allclose(p[0], (P[0] + 4 * P[1] + P[2]) / 6, atol=1e-12)
    p, _, _ = polylines(P, [4], w, "cubic", "catmullRom")
    np.testing.assert_allclose(p[[0, -1]], P[[1, 2]], atol=1e-12)
    p, c, _ = polylines(P, [4], w, "cubic", "catmullRom", "pinned")  # pinned: through every control point
    assert c.tolist() == [13]
    np.testing.assert_allclose(p[::4], P, atol=1e-12)
    p, c, _ = polylines(P, [2, 2], w)
    np.testing.assert_array_equal(p, P)
    np.testing.assert_array_equal(c, [2, 2])


def _scene(tmp_path, tname, name, **attrs):
    """An emitting prim (radiance 1) seen head-on by an orthographic camera 4 units wide, a black background."""
    from pxr import UsdGeom, UsdShade

    b = SceneBuilder()
    cam = b.camera((0, 0, 5), (0, 0, 0), aperture=40.0)
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    prim = (UsdGeom.BasisCurves if tname == "BasisCurves" else UsdGeom.Points).Define(b.stage, "/World/Geo")
    for k, v in attrs.items():
        if k == "widths_interp":
            prim.SetWidthsInterpolation(v)
            continue
        attr = prim.GetPrim().GetAttribute(k)
        attr.Set(v)
    mat = b.material("Glow", diffuse=(0, 0, 0), specular=(0, 0, 0), emission=(1, 1, 1))
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(mat)
    return b.write(tmp_path / f"{name}.usda")


def test_a_linear_curve_renders_a_band_of_its_width(tmp_path):
    """A straight linear curve from x = -1.5 to 1.5 of width 0.4 covers 3 x 0.4 of the 4 x 4 view: 7.5 %; the
    octagonal tube's projected width lies within cos(22.5 deg) of its diameter."""
    path = _scene(tmp_path, "BasisCurves", "line", points=[(-1.5, 0, 0), (1.5, 0, 0)], curveVertexCounts=[2],
                  type="linear", widths=[0.4], widths_interp="constant")
    img = render(load_scene(path), RenderSettings(spp=16, width=64, height=64, max_depth=1)).image[..., 0]
    assert 0.075 * np.cos(np.radians(22.5)) - 0.003 < img.mean() < 0.075 + 0.003
    rows = np.flatnonzero(img[:, 32] > 0.5)
    assert rows.min() >= 32 - 4 and rows.max() <= 31 + 4  # centred: 0.4 units are 6.4 pixels


def test_points_render_spheres_of_their_width(tmp_path):
    """Two points of widths 1 and 0.5 cover pi (0.25 + 0.0625) of the 16-unit view (the 80-triangle icospheres'
    silhouettes are within 10 % of the circles')."""
    path = _scene(tmp_path, "Points", "pts", points=[(-1, 0, 0), (1, 0, 0)], widths=[1.0, 0.5])
    img = render(load_scene(path), RenderSettings(spp=16, width=64, height=64, max_depth=1)).image[..., 0]
    expect = np.pi * (0.25 + 0.0625) / 16
    assert 0.88 * expect < img.mean() < 1.01 * expect


@pytest.mark.parametrize("attrs, code", [
    ({"points": [(0, 0, 0), (1, 0, 0), (2, 0, 0)], "curveVertexCounts": [2], "type": "linear"}, "SCENE_INVALID"),
    ({"points": [(0, 0, 0), (1, 0, 0), (2, 0, 0), (3, 0, 0), (4, 0, 0)], "curveVertexCounts": [5], "type": "cubic",
      "basis": "bezier"}, "SCENE_INVALID"),
    ({"points": [(0, 0, 0), (1, 0, 0)], "curveVertexCounts": [2], "type": "linear", "widths": [float("nan")]},
     "SCENE_INVALID"),
])
def test_curves_that_do_not_fit_are_scene_errors(tmp_path, attrs, code):
    with pytest.raises(SceneError) as exc:
        load_scene(_scene(tmp_path, "BasisCurves", "bad", **attrs))
    assert exc.value.code == code and "/World/Geo" in str(exc.value)


def test_curves_beyond_the_triangle_budget_are_refused_before_evaluation(tmp_path):
    """One cubic B-spline of 2^18 points: about 2^20 evaluated segments of 28 triangles, over the 2^24 budget
    (spec/renderer.md#limits): SCENE_INVALID from the counts alone."""
    n = 1 << 18
    pts = np.zeros((n, 3), np.float32)
    pts[:, 0] = np.linspace(0.0, 1.0, n)
    path = _scene(tmp_path, "BasisCurves", "huge", points=pts, curveVertexCounts=[n], type="cubic", basis="bspline",
                  widths=[0.01], widths_interp="constant")
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.code == "SCENE_INVALID" and "triangles" in str(exc.value)
