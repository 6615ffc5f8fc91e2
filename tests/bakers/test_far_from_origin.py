"""Assets far from the origin for their size (spec/bake.md#far-from-the-origin): the Mitsuba bakers render them moved
to the origin, so their training targets are those of the same asset at the origin, and every stored position stays
in the scene's frame."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="bake tests need mitsuba (pip install 'nasset-sdk[mitsuba]')")
pytest.importorskip("torch", reason="bake tests need torch (pip install torch==2.13.0)")

import nasset_converters.mitsuba as cm  # noqa: E402
from nasset_converters.mitsuba import scene as msc  # noqa: E402

#: a two-part asset 0.6 units across (a block 0.01 above a plate: the block shadows the plate, light bounces between
#: them)
TWO_PART = """<scene version="3.0.0">
<bsdf type="diffuse" id="w"><rgb name="reflectance" value="0.8"/></bsdf>
<shape type="cube" id="plate"><ref id="w"/><transform name="to_world"><scale x="{s}" y="{sy}" z="{s}"/>{place}</transform></shape>
<shape type="cube" id="block"><ref id="w"/><transform name="to_world"><scale value="{b}"/><translate y="{by}"/>{place}</transform>
</shape></scene>"""
#: a translucent slab 0.6 x 0.06 x 0.6 units (rough dielectric around a homogeneous medium): neupress's subsurface
#: transport
TRANSLUCENT = """<scene version="3.0.0">
<medium type="homogeneous" id="m"><rgb name="albedo" value="0.9, 0.8, 0.6"/><float name="sigma_t" value="{st}"/></medium>
<shape type="cube" id="c"><bsdf type="roughdielectric"><string name="distribution" value="ggx"/>
<float name="alpha" value="0.2"/><float name="int_ior" value="1.4"/></bsdf><ref name="interior" id="m"/>
<transform name="to_world"><scale x="{s}" y="{sy}" z="{s}"/>{place}</transform></shape></scene>"""
#: (unit, offset): the 0.6-unit asset 800 units out (Mitsuba's offset 0.071 units, 16 % of its radius: past the gap and
#: through the slab; farther out than 1000 x its size the bake refuses it, below), and the same asset in centimetres
#: (9.6 cm) 5000 cm out (offset 0.45 cm, 6 %)
PLACEMENTS = [(1.0, 800.0), (16.0, 5000.0)]


def _scene(tmp_path, kind: str, unit: float, offset: float):
    place = f'<translate x="{offset}" y="{offset / 4}" z="{-offset}"/>' if offset else ""
    text = (TWO_PART.format(s=0.3 * unit, sy=0.03 * unit, b=0.1 * unit, by=0.14 * unit, place=place)
            if kind == "rna" else TRANSLUCENT.format(st=5.0 / unit, s=0.3 * unit, sy=0.03 * unit, place=place))
    path = tmp_path / f"{kind}_{offset:g}.xml"
    path.write_text(text)
    return path


def _held_out(tmp_path, kind: str, unit: float, offset: float, views: int = 4):
    """(held-out views, geometry) of the baker's own view renderer (``tiny`` preset)."""
    mi = cm.load_mitsuba()
    path = _scene(tmp_path, kind, unit, offset)
    if kind == "rna":
        from nasset_bakers.mitsuba.rna import DATA_PRESETS, _view_renderer
        from nasset_converters.mitsuba import dataset as ds

        shapes = msc.pick_shapes(msc.load_scene(mi, path), ["plate", "block"])
        geo = msc.mesh_geometry(mi, shapes)
        c, r = msc.bounding_sphere(geo)
        dset = replace(ds.DataSettings(), **{**DATA_PRESETS["tiny"], "val_views": views})
        render = _view_renderer(mi, shapes, geo, c, r, dset)
    else:
        from nasset_bakers.mitsuba.neupress import DATA_PRESETS, _view_renderer
        from nasset_converters.mitsuba import neupress_dataset as nd

        shapes = msc.pick_shapes(msc.load_scene(mi, path), ["c"])
        bshapes, _, _ = nd.boundary_of(mi, shapes)
        geo = msc.mesh_geometry(mi, bshapes)
        c, r = msc.bounding_sphere(geo)
        dset = replace(nd.NeupressDataSettings(), **{**DATA_PRESETS["tiny"], "val_views": views})
        render = _view_renderer(mi, shapes, bshapes, c, r, dset)
    return [render("val", i) for i in range(views)], geo


@pytest.mark.parametrize("kind", ["rna", "neupress"])
@pytest.mark.parametrize("unit, offset", PLACEMENTS)
def test_held_out_targets_far_from_the_origin_are_those_at_the_origin(tmp_path, kind, unit, offset):
    """The held-out targets (unclamped, two independent halves) of the asset far out agree with those at the origin:
    the energy over the pixels both cover differs by less than 4 standard errors of the two estimates (each pixel's
    variance from its halves, |a - b|^2 / 4, pixels independent; the two placements share seeds, which only makes the
    bound looser) plus 0.1 % for the float32 rounding of the far surface; and the hit points stored are the origin's
    moved by the offset, to float32 precision there. Before, Mitsuba's own ray offset crossed the asset far out
    (4 held-out views of 24^2 pixels, tiny; energy at the origin -> far out, 4 standard errors): rna 800 units out
    47.72 -> 49.22 (+3.1 %, bound 0.14), 5000 cm out 47.72 -> 48.91 (+2.5 %, bound 0.12); neupress (the slab) 800 units
    out 50.5 / 48.4 / 44.8 -> 2.5 / 2.2 / 1.8 (-95 %), 5000 cm out 50.7 / 48.5 / 45.0 -> 56.1 / 54.5 / 51.8 (bound
    6.0 / 5.8 / 5.4); now the two agree to 0.01 %."""
    near, geo0 = _held_out(tmp_path, kind, unit, 0.0)
    far, geo1 = _held_out(tmp_path, kind, unit, offset)
    move = np.array([offset, offset / 4, -offset])
    np.testing.assert_array_equal(geo1.faces, geo0.faces)
    np.testing.assert_allclose(geo1.points - move, geo0.points, atol=4 * np.spacing(np.float32(offset)))
    e0 = e1 = var = 0.0
    for a, b in zip(near, far, strict=True):
        common, ia, ib = np.intersect1d(a["pix"], b["pix"], return_indices=True)
        assert len(common) >= 0.98 * max(len(a["pix"]), len(b["pix"])) > 0
        np.testing.assert_allclose(b["x"][ib] - move, a["x"][ia], atol=4 * float(np.spacing(np.float32(offset))) + 1e-3 * unit)
        e0 = e0 + a["rgb"][ia].astype(np.float64).sum(0)
        e1 = e1 + b["rgb"][ib].astype(np.float64).sum(0)
        for v, i in ((a, ia), (b, ib)):
            var = var + (((v["rgb_a"][i] - v["rgb_b"][i]).astype(np.float64) ** 2) / 4).sum(0)
    bound = 4 * np.sqrt(var) + 0.001 * e0
    assert np.all(np.abs(e1 - e0) <= bound), (e0, e1, bound)


def test_the_moved_shapes_are_the_same_float32_surface(tmp_path):
    """move_to_origin moves by an exact float32 translation: the moved vertices plus c are the scene's vertices bit
    for bit, the vertex normals are the file's (Mitsuba recomputes them when positions change), and the geometry the
    asset stores is read before, in the scene's frame; a second placement near the origin is left where it is."""
    mi = cm.load_mitsuba()
    path = tmp_path / "s.xml"
    path.write_text('<scene version="3.0.0"><shape type="sphere" id="s"><float name="radius" value="4.7"/>'
                    '<point name="center" x="5000.3" y="-12.9" z="3001.7"/></shape></scene>')
    shapes = msc.pick_shapes(msc.load_scene(mi, path), ["s"])
    geo = msc.mesh_geometry(mi, shapes)
    params = mi.traverse(shapes[0])
    before = np.array(params["vertex_positions"], np.float32).reshape(-1, 3)
    normals = np.array(params["vertex_normals"], np.float32)
    c = msc.move_to_origin(mi, shapes)
    assert c[0] != 0 and c[2] != 0 and np.abs(c - [5000.3, -12.9, 3001.7]).max() < 1e-2
    params = mi.traverse(shapes[0])
    after = np.array(params["vertex_positions"], np.float32).reshape(-1, 3)
    np.testing.assert_array_equal((after.astype(np.float64) + c).astype(np.float32), before)
    np.testing.assert_array_equal(np.array(params["vertex_normals"], np.float32), normals)
    np.testing.assert_array_equal(geo.points, before)
    assert np.abs(np.asarray(shapes[0].bbox().min)).max() < 10
    assert msc.far_for_bake(mi, shapes) is None
    np.testing.assert_array_equal(msc.move_to_origin(mi, shapes), np.zeros(3))  # now near: stays


def test_curves_move_exactly(tmp_path):
    """Mitsuba curves (rna fiber bakes) move by their control points: exact, radii unchanged."""
    mi = cm.load_mitsuba()
    pts = np.array([[0, 0, 0, 0.01], [0.1, 0.3, 0, 0.01], [0.2, 0.5, 0.1, 0.008]]) + [7000.1, 20.2, -3000.3, 0]
    (tmp_path / "h.txt").write_text("\n".join(" ".join(f"{v:.6f}" for v in p) for p in pts) + "\n")
    (tmp_path / "s.xml").write_text('<scene version="3.0.0"><shape type="linearcurve" id="h">'
                                    '<string name="filename" value="h.txt"/></shape></scene>')
    shapes = msc.pick_shapes(msc.load_scene(mi, tmp_path / "s.xml"), ["h"], curves=True)
    before = np.array(mi.traverse(shapes[0])["control_points"], np.float32).reshape(-1, 4)
    c = msc.move_to_origin(mi, shapes)
    after = np.array(mi.traverse(shapes[0])["control_points"], np.float32).reshape(-1, 4)
    assert np.abs(c).max() > 1000
    np.testing.assert_array_equal((after[:, :3].astype(np.float64) + c).astype(np.float32), before[:, :3])
    np.testing.assert_array_equal(after[:, 3], before[:, 3])


def test_a_grid_medium_far_out_stays_and_is_warned(tmp_path):
    """A heterogeneous medium is placed in world space and cannot be moved with its shape: the shapes stay where they
    are and the bake warns that their targets miss their own shadows (the bench's warning is unchanged)."""
    mi = cm.load_mitsuba()
    mi.VolumeGrid(np.ones((4, 4, 4, 1), np.float32)).write(str(tmp_path / "d.vol"))
    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><medium type="heterogeneous" id="m"><volume type="gridvolume" name="sigma_t">'
        '<string name="filename" value="d.vol"/><transform name="to_world"><translate value="-1, -1, -1"/>'
        '<scale value="2"/><translate x="10000"/></transform></volume></medium>'
        '<shape type="cube" id="c"><bsdf type="roughdielectric"/><ref name="interior" id="m"/>'
        '<transform name="to_world"><scale value="0.3"/><translate x="10000"/></transform></shape></scene>')
    shapes = msc.pick_shapes(msc.load_scene(mi, tmp_path / "s.xml"), ["c"])
    msg = msc.far_for_bake(mi, shapes)
    assert msg and "'c'" in msg and "heterogeneous" in msg and "training targets" in msg
    assert msc.far_from_origin(mi, shapes)
    np.testing.assert_array_equal(msc.move_to_origin(mi, shapes), np.zeros(3))
    assert float(shapes[0].bbox().min[0]) > 9000


def test_fibers_far_out_keep_mitsubas_curves_on_the_prisms(tmp_path):
    """An rna fiber bake far out: Mitsuba's moved curves and the prisms the inputs are cast on (scene frame) cover the
    same pixels, the hit points are Mitsuba's within a fibre width, and the targets see light."""
    from nasset_bakers.mitsuba.rna import _view_renderer
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba.hair_example import write_example_scene

    mi = cm.load_mitsuba()
    xml = write_example_scene(tmp_path / "ex", "tiny")
    text = xml.read_text().replace('<string name="filename" value="curves/hair.txt"/>',
                                   '<string name="filename" value="curves/hair.txt"/><transform name="to_world">'
                                   '<translate x="5000" z="-5000"/></transform>')
    xml.write_text(text)
    shapes = msc.pick_shapes(msc.load_scene(mi, xml), ["hair"], curves=True)
    assert msc.far_from_origin(mi, shapes) and msc.far_for_bake(mi, shapes) is None
    _, geo = msc.asset_geometry(mi, shapes)
    center, radius = msc.bounding_sphere(geo)
    v = _view_renderer(mi, shapes, geo, center, radius, ds.DataSettings(views=1, val_views=1, res=48, spp=4))("train", 0)
    assert len(v["pix"]) > 50 and 0 <= int(v["disagree"]) < 0.1 * int(v["covered"])
    assert np.abs(np.asarray(shapes[0].bbox().min)).max() < 100 and np.abs(v["x"]).max() > 4000
    assert np.isfinite(v["rgb"]).all() and v["rgb"].mean() > 0


@pytest.mark.parametrize("kind", ["rna", "neupress", "8dna"])
def test_an_asset_beyond_float32_rendering_is_refused_before_rendering(tmp_path, kind):
    """The asset's object space is the scene's: 10^4 units out, a 0.6-unit object's geometry fails the validator's
    GEOMETRY_SCALE (diagonal >= 1e-3 x the largest coordinate; a float32 renderer loses it). Before, rna and neupress
    rendered, trained and wrote an asset `nasset validate` refuses; 8dna refused it only after training
    (CONVERT_TRAINING). Now every Mitsuba bake stops in its first stage, naming the shapes, before any view."""
    import nasset_bakers.mitsuba.eightdna  # noqa: F401 - each baker module registers itself
    import nasset_bakers.mitsuba.neupress  # noqa: F401
    import nasset_bakers.mitsuba.rna  # noqa: F401
    from nasset_bakers.registry import baker_for
    from nasset_sdk.errors import NassetError

    scene = _scene(tmp_path, "rna" if kind == "rna" else "neupress", 1.0, 1e4)
    ids = ["plate", "block"] if kind == "rna" else ["c"]
    with pytest.raises(NassetError) as exc:
        baker_for(kind, scene, None)(scene, ids, tmp_path / "a.usdc", size="tiny", quiet=True)
    assert exc.value.code == "GEOMETRY_SCALE" and repr(ids[0]) in str(exc.value) and "origin" in str(exc.value)
    assert not (tmp_path / "a.usdc").exists() and not (tmp_path / "a.usdc.bake" / "train").exists()


def test_a_dataset_folder_rendered_in_place_is_not_resumed_moved(tmp_path):
    """A far asset's views are rendered moved to the origin: a work folder from before (its views rendered in place,
    its meta.json without ``render_origin``) is refused on resume (CONVERT_DATASET naming the key), not mixed in."""
    import json

    from nasset_bakers.mitsuba.rna import bake
    from nasset_sdk.errors import NassetError

    scene = _scene(tmp_path, "rna", 16.0, 5000.0)
    out = tmp_path / "a.usdc"
    bake(scene, ["plate", "block"], out, size="tiny", views=1, res=8, epochs=1, quiet=True)
    meta_path = tmp_path / "a.usdc.bake" / "meta.json"
    meta = json.loads(meta_path.read_text())
    assert np.abs(np.array(meta.pop("render_origin")) - [5000, 1250, -5000]).max() < 5
    meta_path.write_text(json.dumps(meta))
    with pytest.raises(NassetError) as exc:
        bake(scene, ["plate", "block"], out, size="tiny", views=1, res=8, epochs=1, quiet=True)
    assert exc.value.code == "CONVERT_DATASET" and "render_origin" in str(exc.value)
