"""rna fiber assets baked from Mitsuba curve shapes (spec/bake.md#mitsuba-curves)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")

import nasset_converters.mitsuba as cm  # noqa: E402
from nasset_converters.mitsuba import scene as msc  # noqa: E402
from nasset_converters.mitsuba.examples import write_ply  # noqa: E402
from nasset_sdk.errors import SceneError  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    m = cm.load_mitsuba(None)
    m.set_log_level(m.LogLevel.Error)
    return m


def _scene(mi, tmp_path, curve_rows: list[np.ndarray], kind: str = "linearcurve"):
    """A scene with a curve shape ``hair`` (one curve per array of ``x y z radius`` rows) and a mesh ``m``."""
    text = "\n\n".join("\n".join(" ".join(f"{v:.9g}" for v in row) for row in c) for c in curve_rows)
    (tmp_path / "c.txt").write_text(text + "\n")
    write_ply(tmp_path / "m.ply", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32),
              np.array([[0, 1, 2], [0, 3, 1], [1, 3, 2], [2, 3, 0]], np.int64))
    xml = tmp_path / "s.xml"
    xml.write_text(f'<scene version="3.0.0"><shape type="{kind}" id="hair"><string name="filename" value="c.txt"/></shape>'
                   '<shape type="ply" id="m"><string name="filename" value="m.ply"/></shape></scene>')
    return xml, msc.load_scene(mi, xml)


def test_linear_curves_are_taken_as_written(mi, tmp_path):
    rng = np.random.default_rng(1)
    curves = [np.c_[rng.normal(size=(3, 3)), [0.01, 0.02, 0.015]], np.c_[rng.normal(size=(4, 3)), [0.03] * 4]]
    _, scene = _scene(mi, tmp_path, curves)
    shapes = msc.pick_shapes(scene, ["hair"], curves=True)
    variant, geo = msc.asset_geometry(mi, shapes)
    assert variant == "fiber"
    assert geo.counts.tolist() == [3, 4]
    rows = np.concatenate(curves)
    np.testing.assert_allclose(geo.points, rows[:, :3], atol=1e-6)
    np.testing.assert_allclose(geo.widths, 2.0 * rows[:, 3], rtol=1e-6)  # USD widths are diameters


def test_curves_take_their_to_world_and_keep_their_radius(mi, tmp_path):
    """Mitsuba moves the control points by ``to_world`` and keeps the radius as written: so does the asset."""
    rows = np.array([[0.0, 0.0, 0.0, 0.02], [0.0, 1.0, 0.0, 0.02], [0.5, 1.5, 0.0, 0.01]])
    (tmp_path / "c.txt").write_text("\n".join(" ".join(f"{v:g}" for v in r) for r in rows) + "\n")
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><shape type="linearcurve" id="hair"><string name="filename" value="c.txt"/>'
                   '<transform name="to_world"><scale value="2"/><translate x="1"/></transform></shape></scene>')
    scene = msc.load_scene(mi, xml)
    geo = msc.curves_geometry(mi, msc.pick_shapes(scene, ["hair"], curves=True))
    np.testing.assert_allclose(geo.points, 2.0 * rows[:, :3] + [1.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(geo.widths, 2.0 * rows[:, 3], rtol=1e-6)
    # Mitsuba's tube there has that radius: a ray down the z axis onto the first segment's middle meets it at z = r
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(1.0, 1.0, 1.0), mi.Vector3f(0.0, 0.0, -1.0)))
    assert bool(si.is_valid()[0]) and abs(float(si.p.z[0]) - 0.02) < 1e-3


def test_bspline_becomes_the_polyline_through_its_span_ends(mi, tmp_path):
    # a uniform cubic B-spline reproduces straight lines: control points at x = 0..5 give span ends at x = 1..4
    cp = np.c_[np.arange(6.0), np.zeros(6), np.zeros(6), np.full(6, 0.05)]
    _, scene = _scene(mi, tmp_path, [cp], kind="bsplinecurve")
    geo = msc.curves_geometry(mi, msc.pick_shapes(scene, ["hair"], curves=True))
    assert geo.counts.tolist() == [4]
    np.testing.assert_allclose(geo.points[:, 0], [1.0, 2.0, 3.0, 4.0], atol=1e-6)
    np.testing.assert_allclose(geo.points[:, 1:], 0.0, atol=1e-6)
    # and Mitsuba's own curve passes there: a ray down onto x = 2.5 meets the tube at y = its radius
    si = scene.ray_intersect(mi.Ray3f(mi.Point3f(2.5, 1.0, 0.0), mi.Vector3f(0.0, -1.0, 0.0)))
    assert bool(si.is_valid()[0]) and abs(float(si.p.y[0]) - 0.05) < 2e-3


def test_curves_need_the_fiber_kind_and_are_not_mixed_with_meshes(mi, tmp_path):
    _, scene = _scene(mi, tmp_path, [np.c_[np.eye(3), [0.01] * 3]])
    with pytest.raises(SceneError) as e:
        msc.pick_shapes(scene, ["hair"], file="s.xml")  # neupress and 8dna pick surfaces only
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "rna" in str(e.value) and "'hair'" in str(e.value)
    with pytest.raises(SceneError) as e:
        msc.pick_shapes(scene, ["hair", "m"], curves=True)
    assert e.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "mix" in str(e.value)


def test_fiber_views_take_their_inputs_where_mitsuba_hits_the_curves(mi, tmp_path):
    """The prisms' hit points lie on Mitsuba's round tubes (within a width), the frames are valid."""
    from nasset_converters.caster import Caster
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.hair_example import write_example_scene

    xml = write_example_scene(tmp_path / "ex", "tiny")
    shapes = msc.pick_shapes(msc.load_scene(mi, xml), ["hair"], curves=True)
    _, geo = msc.asset_geometry(mi, shapes)
    center, radius = msc.bounding_sphere(geo)
    s = ds.DataSettings(views=1, val_views=1, res=48, spp=4, val_spp=4)
    iso = msc.IsolatedAsset(mi, shapes, center, radius)
    renderer = ds.Renderer(mi, iso, s, caster=Caster("fiber", geo))
    v = ds.render_view(renderer, center, radius, 0, validation=False)
    assert len(v["pix"]) > 50
    assert 0 <= int(v["disagree"]) < 0.1 * int(v["covered"])
    # Mitsuba's own hits along the same pixel-centre rays
    rng, eye = np.random.default_rng([s.seed, 0, 0]), None
    cam = ds.unit_sphere(rng, 1, s.upper_hemisphere)[0]
    eye = center + s.distance * radius * cam
    half_fov = float(np.arcsin(1.0 / s.distance)) * 1.04
    o, d = ds.camera_rays(eye, center, half_fov, s.res)
    mask, x_mi, _ = renderer.hits(o, d)
    assert mask[v["pix"]].all()
    gap = np.linalg.norm(x_mi[v["pix"]] - v["x"], axis=1)
    assert np.median(gap) < float(geo.widths.max()) and np.quantile(gap, 0.9) < 4.0 * float(geo.widths.max())
    np.testing.assert_allclose(np.linalg.norm(v["n"], axis=1), 1.0, atol=1e-4)  # tangents
    assert (np.abs(v["h"]) <= 1.0 + 1e-6).all() and np.ptp(v["h"]) > 1.0
    assert np.isfinite(v["rgb"]).all() and (v["rgb"] >= 0).all() and v["rgb"].mean() > 0


def test_tiny_hair_bake_writes_a_fiber_asset(tmp_path):
    pytest.importorskip("torch", reason="bake tests need torch (pip install torch==2.13.0)")
    from nasset_bakers.mitsuba.rna import bake
    from nasset_sdk.asset import Asset

    s = bake(None, None, tmp_path / "hair.usdc", size="tiny", example="hair-dense", quiet=True, epochs=2)
    assert s["asset_variant"] == "fiber" and 0.0 <= s["mask_disagreement"] < 0.1
    a = Asset.open(tmp_path / "hair.usdc")
    assert a.kind == "rna" and a.variant == "fiber"
    assert len(a.geometry().counts) == 1000
    assert a.provenance["data"]["mask_disagreement"] == pytest.approx(s["mask_disagreement"])


def test_scene_conversion_writes_unreplaced_curves_as_tubes_and_says_how_to_bake_them(mi, tmp_path):
    """Curves that no asset replaces become BasisCurves (the renderer's tubes, spec/renderer.md#curves-and-points) of
    the control points and twice their radii; the warning says a hair is better baked."""
    from pxr import Usd, UsdGeom

    from nasset_converters.mitsuba.usd_export import convert_scene

    xml, _ = _scene(mi, tmp_path, [np.c_[np.eye(3), [0.01] * 3]])
    res = convert_scene(xml, tmp_path / "out.usda", check_usd=False)
    text = "\n".join(res.warnings)
    assert "shape hair: LinearCurve of 1 curves written as BasisCurves" in text and "--kind rna --asset hair" in text
    stage = Usd.Stage.Open(str(res.output))
    curves = [UsdGeom.BasisCurves(p) for p in stage.Traverse() if p.GetTypeName() == "BasisCurves"]
    assert len(curves) == 1
    np.testing.assert_allclose(np.asarray(curves[0].GetPointsAttr().Get()), np.eye(3), atol=1e-6)
    np.testing.assert_allclose(np.asarray(curves[0].GetWidthsAttr().Get()), [0.02] * 3, atol=1e-7)
