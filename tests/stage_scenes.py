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
