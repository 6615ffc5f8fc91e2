"""Small USD stages that both renderers' stage-reading tests build (tests/renderer/test_usd_stages.py and
tests/mitsuba_renderer/test_mitsuba_stages.py): a diffuse floor seen from above under a delta DistantLight of
irradiance E at angle THETA, whose radiance is ``albedo E cos(THETA) / pi``."""

from __future__ import annotations

import numpy as np

from nasset_reference_renderer.testscenes import SceneBuilder

E, THETA = 3.0, np.radians(35)
RED = (0.9, 0.2, 0.1)


def floor_scene(albedo=(0.6, 0.6, 0.6)):
    """(SceneBuilder, the floor prim): camera /World/Camera above the floor, the sun /World/Sun."""
    b = SceneBuilder()
    b.camera((0, 3, 0.01), (0, 0, 0), focal=50)
    floor = b.quad("Floor", (0, 0, 0), 10.0, diffuse=albedo)
    b.distant("Sun", (np.sin(THETA), np.cos(THETA), 0), E)
    return b, floor.GetPrim()


def two_camera_scene():
    """Two cameras; ``Top`` (first in traversal) sees the lit floor, ``Below`` its unlit underside."""
    b, _ = floor_scene()
    b.camera((0, 3, 0.01), (0, 0, 0), focal=50, name="Top")
    b.camera((0, -3, 0.01), (0, 0, 0), focal=50, name="Below")
    b.stage.RemovePrim("/World/Camera")
    return b


def render_settings(b, path, camera=None, resolution=(8, 8), **attrs):
    """A UsdRender.Settings prim at ``path`` with ``resolution``, its ``camera`` rel, and schema attributes ``attrs``."""
    from pxr import Gf, UsdRender

    s = UsdRender.Settings.Define(b.stage, path)
    s.CreateResolutionAttr(Gf.Vec2i(*resolution))
    if camera:
        s.CreateCameraRel().SetTargets([camera])
    for name, value in attrs.items():
        s.GetPrim().GetAttribute(name).Set(value)
    return s


def check_gaussian_pixel_filter(render, tmp_path, spp: int = 256) -> None:
    """``render(scene, spp, seed=)`` [H, W, 3] of an emissive (radiance 1) half plane x < 0 whose edge projects onto the
    image's centre line, with ``nasset:pixelFilter = "gaussian"`` (stddev 0.5 px) in its render settings: each column is
    the filter's mass left of the edge, the truncated Gaussian's CDF (H x spp Bernoulli samples: within 5 sigma); the
    same scene without the filter gives the box filter's 0 / 1 step."""
    from pxr import Sdf

    def edge(name, **attrs):
        b = SceneBuilder()
        b.camera((0, 0, 0), (0, 0, -1))
        b.mesh("Half", [(-50, -50, -1), (0, -50, -1), (0, 50, -1), (-50, 50, -1)], [(0, 1, 2, 3)], diffuse=(0, 0, 0),
               specular=(0, 0, 0), emission=(1, 1, 1))
        st = render_settings(b, "/Render/Settings", resolution=(8, 4))
        for key, (kind, value) in attrs.items():
            st.GetPrim().CreateAttribute(key, kind).Set(value)
        return b.write(tmp_path / name)

    s = 0.5
    img = render(edge("gauss.usda", **{"nasset:pixelFilter": (Sdf.ValueTypeNames.Token, "gaussian"),
                                       "nasset:pixelFilterStddev": (Sdf.ValueTypeNames.Float, s)}), spp, seed=5)
    assert img.shape == (4, 8, 3)
    x = np.linspace(-4 * s, 4 * s, 200001)
    density = np.exp(-x * x / (2 * s * s)) - np.exp(-8.0)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (density[1:] + density[:-1]) * np.diff(x))])
    cdf /= cdf[-1]
    expect = np.interp(4.0 - (np.arange(8) + 0.5), x, cdf)  # a sample of column j lands left of the edge
    n = 4 * spp
    got = img[..., 0].mean(0)
    sigma = np.maximum(np.sqrt(expect * (1 - expect) / n), 1.0 / n)
    assert np.all(np.abs(got - expect) <= 5 * sigma), (got, expect)
    assert 0.05 < got[4] < 0.3 and 0.7 < got[3] < 0.95  # neither the box's 0 / 1 step
    # a sample on the pixel border may land on either side
    np.testing.assert_allclose(render(edge("box.usda"), spp, seed=5)[..., 0].mean(0), [1, 1, 1, 1, 0, 0, 0, 0], atol=2.0 / n)


def check_settings_max_depth(render, tmp_path, spp: int = 4) -> None:
    """``render(scene, spp, seed=, max_depth=)``: ``nasset:maxDepth`` of the render settings is the bounce limit when the
    caller gives none, and a caller's limit wins (a floor under a ceiling, lit by a bulb out of view)."""
    from pxr import Sdf

    def scene(name, depth=None):
        b, _ = floor_scene()
        b.quad("Ceiling", (0, 5, 0), 10.0, normal=(0, -1, 0), diffuse=(0.8, 0.8, 0.8))
        b.sphere_light("Bulb", (2, 1.5, 0), 0.2, 20.0)  # outside the view
        b.stage.RemovePrim("/World/Sun")
        st = render_settings(b, "/Render/Settings", resolution=(8, 8))
        if depth is not None:
            st.GetPrim().CreateAttribute("nasset:maxDepth", Sdf.ValueTypeNames.Int).Set(depth)
        return b.write(tmp_path / name)

    plain, one = scene("plain.usda"), scene("one.usda", 1)
    direct = render(plain, spp, seed=2, max_depth=1)
    np.testing.assert_array_equal(render(one, spp, seed=2), direct)
    assert render(plain, spp, seed=2).mean() > 1.01 * direct.mean()  # the ceiling's bounce
    np.testing.assert_array_equal(render(one, spp, seed=2, max_depth=5), render(plain, spp, seed=2))


def product_camera_scene():
    """:func:`two_camera_scene` whose settings name ``Top`` and whose render product names ``Below`` (the product's
    camera is the one rendered)."""
    from pxr import UsdRender

    b = two_camera_scene()
    settings = render_settings(b, "/Render/Settings", "/World/Top")
    product = UsdRender.Product.Define(b.stage, "/Render/Product")
    product.CreateCameraRel().SetTargets(["/World/Below"])
    settings.CreateProductsRel().SetTargets([product.GetPath()])
    return b


def hidden_camera_scene(hide: str):
    """(builder, camera path): :func:`floor_scene` with its camera made invisible (``hide`` "visibility") or moved
    under a guide-purpose Xform (``hide`` "purpose"); a render still looks through it."""
    from pxr import Sdf, UsdGeom

    b, _ = floor_scene()
    where = "/World/Camera"
    if hide == "visibility":
        UsdGeom.Imageable(b.stage.GetPrimAtPath(where)).CreateVisibilityAttr(UsdGeom.Tokens.invisible)
        return b, where
    UsdGeom.Xform.Define(b.stage, "/World/Rig").CreatePurposeAttr(UsdGeom.Tokens.guide)
    Sdf.CopySpec(b.stage.GetRootLayer(), where, b.stage.GetRootLayer(), "/World/Rig/Camera")
    b.stage.RemovePrim(where)
    return b, "/World/Rig/Camera"


def plain_geometry_layer(path, *, untyped: bool = True):
    """A layer whose default prim ``World`` (untyped, or the builder's Xform) holds the lit floor of
    :func:`floor_scene` and its material (no camera, no light)."""
    b, _ = floor_scene()
    for child in ("Camera", "Sun"):
        b.stage.RemovePrim(f"/World/{child}")
    if untyped:
        b.stage.GetPrimAtPath("/World").SetTypeName("")
    b.stage.SetDefaultPrim(b.stage.GetPrimAtPath("/World"))
    return b.write(path)


def nested_scene(path, depth: int, *, mesh_every: int = 0) -> str:
    """The lit floor of :func:`floor_scene` under ``depth`` nested Xforms (``/World/Chain/X/X/...``), a small triangle
    at the bottom and, with ``mesh_every``, one beside every ``mesh_every``-th Xform of the chain."""
    from pxr import Sdf

    b, _ = floor_scene()
    layer = b.stage.GetRootLayer()

    def triangle(where):
        spec = Sdf.CreatePrimInLayer(layer, where)
        spec.specifier, spec.typeName = Sdf.SpecifierDef, "Mesh"
        for name, kind, value in (("points", Sdf.ValueTypeNames.Point3fArray, [(-1, 1, -1), (1, 1, -1), (0, 1, 1)]),
                                  ("faceVertexCounts", Sdf.ValueTypeNames.IntArray, [3]),
                                  ("faceVertexIndices", Sdf.ValueTypeNames.IntArray, [0, 1, 2])):
            Sdf.AttributeSpec(spec, name, kind).default = value

    with Sdf.ChangeBlock():
        where = Sdf.Path("/World/Chain")
        for level in range(depth):
            spec = Sdf.CreatePrimInLayer(layer, where)
            spec.specifier, spec.typeName = Sdf.SpecifierDef, "Xform"
            if mesh_every and level % mesh_every == 0:
                triangle(where.AppendChild("Leaf"))
            where = where.AppendChild("X")
        triangle(where.GetParentPath().AppendChild("Bottom"))
    return b.write(path)


class AncestorVisits:
    """Counts the ancestors that USD's per-prim inherited-state queries walk while a scene loads (USD methods wrapped
    to count, USD still answering): each ``ComputeVisibility`` / ``ComputePurpose`` / parentless
    ``ComputePurposeInfo`` / ``ComputeLocalToWorldTransform`` / ``FindPrimvarWithInheritance(name)`` /
    ``ComputeBoundMaterial`` call walks the prim's ancestors (its depth counted); the same queries given the
    parent's answer count 1. A traversal whose count grows faster than its prims is quadratic in depth."""

    def __init__(self, monkeypatch):
        from pxr import UsdGeom, UsdShade

        self.count = 0
        for owner, name in ((UsdGeom.Imageable, "ComputeVisibility"), (UsdGeom.Imageable, "ComputePurpose"),
                            (UsdGeom.Imageable, "ComputePurposeInfo"), (UsdGeom.Imageable, "ComputeLocalToWorldTransform"),
                            (UsdGeom.PrimvarsAPI, "FindPrimvarWithInheritance"),
                            (UsdShade.MaterialBindingAPI, "ComputeBoundMaterial")):
            monkeypatch.setattr(owner, name, self._counted(getattr(owner, name), name))

    def _counted(self, method, name):
        given_parent = {"ComputePurposeInfo": 0, "FindPrimvarWithInheritance": 1}.get(name)

        def counted(schema, *args):
            walks = given_parent is None or len(args) <= given_parent
            self.count += schema.GetPrim().GetPath().pathElementCount if walks else 1
            return method(schema, *args)
        return counted


def ancestor_visits_ratio(tmp_path, monkeypatch, read, **kw) -> tuple[int, int]:
    """(visits at depth 200, visits at depth 400) of USD's ancestor-walking calls while ``read(path)`` loads
    :func:`nested_scene` (``kw``: its options). Linear cost doubles them; a walk per prim quadruples them."""
    counts = []
    for depth in (200, 400):
        path = nested_scene(tmp_path / f"nested{depth}.usda", depth, **kw)
        with monkeypatch.context() as m:
            visits = AncestorVisits(m)
            read(path, depth)
        counts.append(visits.count)
    return counts[0], counts[1]
