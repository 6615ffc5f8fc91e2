"""Mitsuba's ``bumpmap`` converted to a tangent-space normal map (converters/mitsuba/bump.py, spec/bake.md#materials).

The independent check is Mitsuba itself: the same shape rendered with the bump map and with Mitsuba's ``normalmap``
of the converted texels (its frame is the renderer's, spec/renderer.md#normal-maps) must agree to the renders' noise,
while the unbumped shape must not. Measured when written (64², 64 spp, direct light): squared differences 1e-6 to
3e-5 against 6e-4 to 3e-3 for the flat shape; a sphere whose texture repeats (``to_uv`` scaling) cannot be one normal
map and is only approximate (2.5e-4 against 1.8e-3), so it is not held to the noise.
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")
pytest.importorskip("scipy")

from nasset_converters.mitsuba import analytic, bump, load_mitsuba  # noqa: E402
from nasset_converters.mitsuba.usd_export import latlong_sphere  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    return load_mitsuba(None)


def _height(folder):
    from nasset_sdk.images import write_png

    y, x = np.mgrid[0:64, 0:64] / 64.0
    h = 0.5 + 0.25 * np.sin(6 * np.pi * x) * np.cos(4 * np.pi * y)
    path = folder / "height.png"
    write_png(path, np.repeat(np.round(255 * h).astype(np.uint8)[..., None], 3, -1))
    return str(path)


def _render(mi, shape: dict, bsdf: dict, seed: int) -> np.ndarray:
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 40,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 2.5, 3.5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}}},
        "obj": dict(shape, bsdf=bsdf),
        "sun": {"type": "directional", "direction": [-0.4, -0.8, -0.45], "irradiance": {"type": "rgb", "value": [2.5, 2.4, 2.2]}},
    })
    return np.asarray(mi.render(scene, spp=64, seed=seed), np.float64)


def _world_mesh(mi, shape):
    """The shape's triangles in uv as the converter writes them (points, faces, uv, normals)."""
    cls = analytic.shape_class(shape)
    p = mi.traverse(shape)
    if "vertex_positions" in p:
        return (np.asarray(p["vertex_positions"]).reshape(-1, 3), np.asarray(p["faces"]).reshape(-1, 3),
                np.asarray(p["vertex_texcoords"]).reshape(-1, 2), np.asarray(p["vertex_normals"]).reshape(-1, 3))
    m = np.asarray(analytic.drawn_to_world(mi, shape), np.float64)
    if cls == "Sphere":
        pts, faces, uv = latlong_sphere()
        nrm = pts
    else:
        pts, faces, nrm, uv = analytic.local_mesh(cls)
    return pts @ m[:3, :3].T + m[:3, 3], faces, uv, nrm @ np.linalg.inv(m[:3, :3])


SHAPES = {
    "rectangle": {"type": "rectangle", "to_world": [("rotate", [1, 0, 0], -90), ("scale", [1.5, 1.0, 1.0])]},
    "sphere": {"type": "sphere", "radius": 1.0},
    "cube": {"type": "cube", "to_world": [("rotate", [0, 1, 0], 30), ("scale", [0.8, 0.8, 0.8])]},
}


def _shape(mi, name):
    d = dict(SHAPES[name])
    if "to_world" in d:
        t = mi.ScalarTransform4f()
        for op, *args in d["to_world"]:
            t = t.rotate(*args) if op == "rotate" else t.scale(args[0])
        d["to_world"] = t
    return d


@pytest.mark.parametrize("name,tiled", [("rectangle", False), ("rectangle", True), ("sphere", False), ("cube", True)])
def test_converted_normal_map_renders_like_mitsubas_bump_map(mi, tmp_path, name, tiled):
    shape = _shape(mi, name)
    height = {"type": "bitmap", "filename": _height(tmp_path)}
    to_uv = mi.ScalarTransform4f().scale([2, 3, 1]).rotate([0, 0, 1], 20) if tiled else None
    if to_uv is not None:
        height["to_uv"] = to_uv
    bumped = {"type": "bumpmap", "tex": height, "scale": 0.3, "bsdf": {"type": "diffuse"}}
    ref, ref2 = (_render(mi, shape, bumped, seed) for seed in (1, 2))
    loaded = mi.load_dict(dict(shape, bsdf=bumped))
    to_uv3 = None if to_uv is None else np.asarray(to_uv.matrix, np.float64)[[0, 1, 3]][:, [0, 1, 3]]
    metric = bump.uv_metric(*_world_mesh(mi, loaded))
    assert (metric.k is None) == (name == "sphere")  # a sphere's strength varies with latitude; the others are uniform
    texture = mi.traverse(loaded.bsdf()).properties["nested_texture.data"][2]
    texels = bump.bump_normal_texels(mi, texture, bump.normal_map_size((64, 64), 1 << 22), 0.3, metric, to_uv3)
    assert texels.shape == (128, 128, 3) and np.all(np.isfinite(texels))
    normal_map = {"type": "bitmap", "bitmap": mi.Bitmap(texels.astype(np.float32)), "raw": True}
    if to_uv is not None:
        normal_map["to_uv"] = to_uv
    mapped = _render(mi, shape, {"type": "normalmap", "normalmap": normal_map, "bsdf": {"type": "diffuse"}}, 1)
    flat = _render(mi, shape, {"type": "diffuse"}, 1)
    noise = np.mean((ref - ref2) ** 2)  # two seeds: twice one render's variance
    err, err_flat = np.mean((mapped - ref) ** 2), np.mean((flat - ref) ** 2)
    assert err_flat > 20 * noise, (err_flat, noise)  # the bump shows
    assert err < 3 * noise, (err, noise, err_flat)  # same seed as ref: only the conversion differs
    assert abs(mapped.mean() / ref.mean() - 1.0) < 0.01


def test_strength_follows_the_uv_layout(mi):
    """On a rectangle the normal tilts by scale x gradient / |dP/du|: a rectangle twice as long in u (the same uv)
    bends half as much; a height rising along u tilts the normal towards -s."""
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)
    k1 = bump.uv_metric(quad, faces, uv).k
    k2 = bump.uv_metric(quad * [2, 1, 1], faces, uv).k
    np.testing.assert_allclose(k1, [-1.0, 0.0, -1.0], atol=1e-12)  # dP/dv = +t: hv tilts towards -t
    np.testing.assert_allclose(k2, [-0.5, 0.0, -1.0], atol=1e-12)
    flipped = bump.uv_metric(quad, faces, uv * [1, -1]).k  # v runs along -t (Mitsuba's flip to the geometric side)
    np.testing.assert_allclose(flipped, [-1.0, 0.0, 1.0], atol=1e-12)


def test_degenerate_layouts_give_no_metric_and_no_nan():
    quad = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float64)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    assert bump.uv_metric(quad, faces, np.zeros((4, 2))) is None  # every uv the same point
    assert bump.uv_metric(np.zeros((4, 3)), faces, np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)) is None
    huge, tiny = bump.uv_metric(quad * 1e12, faces, np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64)), \
        bump.uv_metric(quad * 1e-9, faces, np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float64))
    assert np.all(np.isfinite(huge.k)) and np.all(np.isfinite(tiny.k))


def test_converted_scene_writes_one_normal_map_per_uv_layout(tmp_path):
    """A bump BSDF shared by rectangles of two sizes becomes two materials (the same size shares one); a procedural
    height and a disk (written without uv) keep their notes and no normal input."""
    from pxr import Usd, UsdShade

    from nasset_converters.mitsuba.usd_export import convert_scene

    _height(tmp_path)
    rect = ('<shape type="rectangle" id="{id}"><transform name="to_world"><scale x="{s}" y="1" z="1"/>'
            '<translate x="{x}"/></transform><ref id="bumpy"/></shape>')
    xml = tmp_path / "scene.xml"
    xml.write_text(
        '<scene version="3.0.0"><integrator type="path"/>'
        '<sensor type="perspective"><film type="hdrfilm"><integer name="width" value="8"/>'
        '<integer name="height" value="8"/></film></sensor>'
        '<bsdf type="bumpmap" id="bumpy"><texture type="bitmap"><string name="filename" value="height.png"/></texture>'
        '<float name="scale" value="0.2"/><bsdf type="diffuse"/></bsdf>'
        + rect.format(id="a", s=1, x=0) + rect.format(id="b", s=1, x=3) + rect.format(id="c", s=2, x=-4)
        + '<shape type="disk" id="d"><ref id="bumpy"/></shape>'
        '<shape type="rectangle" id="e"><bsdf type="bumpmap"><texture type="checkerboard"/><bsdf type="diffuse"/>'
        '</bsdf></shape><emitter type="constant"/></scene>')
    res = convert_scene(xml, tmp_path / "scene.usda", check_usd=False)
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))

    def normal_file(sid):
        prim = next(p for p in stage.Traverse() if p.GetName() == sid)
        mat = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        surface = UsdShade.Shader(stage.GetPrimAtPath(mat.GetPath().AppendChild("PreviewSurface")))
        src = surface.GetInput("normal")
        if not src or not src.HasConnectedSource():
            return mat.GetPath(), None
        tex = UsdShade.Shader(src.GetConnectedSource()[0].GetPrim())
        return mat.GetPath(), tex.GetInput("file").Get().path

    (ma, fa), (mb, fb), (mc, fc), (md, fd), (me, fe) = (normal_file(s) for s in "abcde")
    assert ma == mb and fa == fb and fa is not None
    assert mc != ma and fc is not None and fc != fa
    assert fd is None and fe is None
    notes = " ".join(res.warnings)
    assert "shape d: bumpmap on a Disk written without usable texture coordinates: dropped" in notes
    assert "shape e: BumpMap: the nested BSDF is converted, its bump map is dropped" in notes


def test_normal_map_size_doubles_small_heights_and_bounds_large_ones():
    assert bump.normal_map_size((64, 32), 1 << 22) == (128, 64)
    big = bump.normal_map_size((8192, 4096), 1 << 22)
    assert big[0] * big[1] <= 1 << 22 and abs(big[0] / big[1] - 2.0) < 0.01
