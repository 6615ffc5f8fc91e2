"""Small USD stages that several renderers' tests build (tests/renderer/test_usd_stages.py and
tests/mitsuba_renderer/test_mitsuba_stages.py): a diffuse floor seen from above under a delta DistantLight of
irradiance E at angle THETA, whose radiance is ``albedo E cos(THETA) / pi``; scenes of many lights
(tests/renderer/test_light_selection.py and tests/mitsuba_plugin/test_light_selection.py)."""

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


def check_light_surfaces_occlude_nothing(render, tmp_path, spp: int = 64) -> None:
    """``render(scene, spp, seed=, max_depth=, width=, height=)``: light surfaces occlude nothing
    (spec/renderer.md#light-surfaces). (1) A camera ray through a RectLight's emitting side sees its radiance plus the
    dome behind it, exactly; through its back the dome alone; an opaque one (``nasset:opaqueSurface``) ends the ray on
    its emitting side. (2) A zero-power RectLight hidden from the camera, 0.5
    over a floor lit by a constant dome, with a box beside (so that the floor's BSDF rays are traced), leaves the image
    as it is without it, as in Cycles: before, the floor's BSDF rays ended on it and the floor under it read 48 %."""
    from pxr import Sdf

    def panel_in_view(name, facing, opaque=False):
        b = SceneBuilder()
        b.camera((0, 0, 3.0), (0, 0, 0), focal=50)
        b.dome("Sky", 0.25)
        light = b.rect_light("Panel", (0, 0, 0), 4.0, 4.0, facing, 2.0)
        if opaque:
            light.GetPrim().CreateAttribute("nasset:opaqueSurface", Sdf.ValueTypeNames.Bool, custom=True).Set(True)
        return b.write(tmp_path / f"{name}.usda")

    def seen(name, facing, opaque=False):
        return render(panel_in_view(name, facing, opaque), 4, seed=1, max_depth=1, width=8, height=8)

    np.testing.assert_allclose(seen("front", (0, 0, 1)), 2.25, rtol=1e-4)  # 2 + 0.25: before, 2 (the ray ended there)
    np.testing.assert_allclose(seen("back", (0, 0, -1)), 0.25, rtol=1e-4)
    # nasset:opaqueSurface (Mitsuba's emitter shapes): the ray ends on its emitting side, passes its back
    np.testing.assert_allclose(seen("opaque_front", (0, 0, 1), True), 2.0, rtol=1e-4)
    np.testing.assert_allclose(seen("opaque_back", (0, 0, -1), True), 0.25, rtol=1e-4)

    def floor(name, panel):
        b = SceneBuilder()
        b.camera((0, 1.6, 2.4), (0, 0, 0), focal=35)
        b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.7, 0.7, 0.7))
        b.mesh("Box", [(1.2, 0, 0.6), (1.6, 0, 0.6), (1.6, 0.4, 0.6), (1.2, 0.4, 0.6)], [(0, 1, 2, 3)], diffuse=(0.5, 0.5, 0.5))
        b.dome("Sky", 1.0)
        if panel:
            light = b.rect_light("Panel", (0, 0.5, 0), 1.2, 1.2, (0, -1, 0), 1e-9)
            light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool, custom=True).Set(False)
        return b.write(tmp_path / f"{name}.usda")

    size = dict(width=16, height=16)
    with_panel = render(floor("with", True), spp, seed=2, max_depth=2, **size)
    without = render(floor("without", False), spp, seed=3, max_depth=2, **size)
    under = (slice(6, 11), slice(5, 11))
    assert abs(with_panel[under].mean() / without[under].mean() - 1.0) < 0.03, (with_panel[under].mean(), without[under].mean())
    assert abs(with_panel.mean() / without.mean() - 1.0) < 0.02, (with_panel.mean(), without.mean())


def check_shading_normals(render, tmp_path, spp: int = 4) -> None:
    """``render(scene, spp, seed=, max_depth=)``: a diffuse floor (geometric normal +Y) under the delta sun of
    :func:`floor_scene`, its four corners carrying one authored normal ``ns``, seen from above with direct light only, is
    ``albedo E max(0, ns . l) / pi`` everywhere (spec/renderer.md#shading-normals): a normal tilted toward the sun is
    brighter than the flat floor, one tilted away darker, one past the sun's horizon black; zero normals shade with the
    geometric normal; a leftHanded prim wound the other way round reads its normals on its front as well."""
    from pxr import Gf, UsdGeom

    albedo = 0.6

    def scene(name, tilt_deg, *, left_handed=False):
        b, floor = floor_scene((albedo,) * 3)
        mesh = UsdGeom.Mesh(floor)
        if left_handed:  # the same surface, its front still up: USD reads the reversed winding as leftHanded
            mesh.GetFaceVertexIndicesAttr().Set([3, 2, 1, 0])
            mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
        t = np.radians(tilt_deg) if tilt_deg is not None else None
        n = (0.0, 0.0, 0.0) if t is None else (float(np.sin(t)), float(np.cos(t)), 0.0)  # in the sun's plane (x, y)
        mesh.CreateNormalsAttr([Gf.Vec3f(*n)] * 4)
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        return b.write(tmp_path / f"{name}.usda")

    def expect(cos):
        return albedo * E * max(cos, 0.0) / np.pi

    cases = {"toward": (20.0, {}, np.cos(THETA - np.radians(20))), "away": (-20.0, {}, np.cos(THETA + np.radians(20))),
             "past_horizon": (-70.0, {}, 0.0), "zero": (None, {}, np.cos(THETA)),
             "left_handed": (20.0, {"left_handed": True}, np.cos(THETA - np.radians(20)))}
    for name, (tilt, kw, cos) in cases.items():
        img = render(scene(name, tilt, **kw), spp, seed=1, max_depth=1)
        np.testing.assert_allclose(img, expect(cos), rtol=2e-3, atol=1e-5, err_msg=name)


def check_cage_normals(render, tmp_path, spp: int = 64) -> None:
    """``render(scene, spp, seed=, max_depth=)``: a cube without normals whose ``subdivisionScheme`` is the schema's
    fallback (catmullClark) shades with its cage's smooth normals (the normalised diagonals at the corners), as the
    reference renderer renders it (direct light under a delta sun: the same values up to pixel jitter): a face seen
    head-on under a sun behind the camera reads cos(ns, l) < 1 away from its centre, the faceted cube (scheme none) 1."""
    from pxr import UsdGeom

    from nasset_reference_renderer import RenderSettings, load_scene
    from nasset_reference_renderer import render as reference

    def cube(scheme):
        b = SceneBuilder()
        b.camera((0, 0, 5), (0, 0, 0), focal=50)
        b.distant("Sun", (0, 0, 1), 1.0)
        pts = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
        faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        m = b.mesh("Cube", pts, faces, diffuse=(0.5, 0.5, 0.5), specular=(0.0, 0.0, 0.0))
        if scheme is None:
            m.GetSubdivisionSchemeAttr().Clear()
        return b.write(tmp_path / f"cube_{scheme}.usda")

    size = dict(width=24, height=24)  # the front face fills the image
    smooth = render(cube(None), spp, seed=1, max_depth=1, **size)
    ref = reference(load_scene(cube(None)), RenderSettings(spp=spp, max_depth=1, seed=1, **size)).image[..., :3]
    flat = render(cube(UsdGeom.Tokens.none), spp, seed=1, max_depth=1, **size)
    np.testing.assert_allclose(flat, 0.5 / np.pi, rtol=2e-3)  # faceted: the face's own normal
    assert smooth.mean() < 0.9 * flat.mean() and smooth[0, 0].mean() < 0.75 * flat[0, 0].mean()
    np.testing.assert_allclose(smooth, ref, rtol=1e-2)


def check_implicit_prims_and_curves(render, tmp_path, spp: int = 256) -> None:
    """``render(scene, spp, seed=, max_depth=, width=, height=)``: implicit prims (a Sphere, a leftHanded Sphere seen
    from inside-out shading, a Cube, a Capsule along X) and plain curves and points (linear and cubic BasisCurves, a
    Points cloud) render as the reference renderer renders them, with the SDK's tessellations (spec/renderer.md#implicit-
    prims, #curves-and-points): direct light from a delta sun, relative RMSE within 8 % at 32 x 32 (the two renders
    sample pixels at other points) and means within 2 %. Both Mitsuba implementations refused these prims."""
    from pxr import Gf, UsdGeom

    b = SceneBuilder()
    b.camera((0, 2.5, 4.0), (0, 0.3, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.5, 0.5, 0.5))

    def place(prim, at, scale=1.0):
        xf = UsdGeom.Xformable(prim)
        xf.AddTranslateOp().Set(Gf.Vec3d(*at))
        xf.AddScaleOp().Set(Gf.Vec3f(scale, scale, scale))
        UsdShadeBind(prim, b.material(prim.GetName() + "Mat", diffuse=(0.8, 0.5, 0.3), specular=(0.04,) * 3, roughness=0.4))

    def UsdShadeBind(prim, mat):
        from pxr import UsdShade

        UsdShade.MaterialBindingAPI.Apply(prim).Bind(mat)

    place(UsdGeom.Sphere.Define(b.stage, "/World/Ball").GetPrim(), (-1.0, 0.5, 0.0), 0.5)
    inside = UsdGeom.Sphere.Define(b.stage, "/World/Inside")
    inside.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    place(inside.GetPrim(), (1.0, 0.4, -0.5), 0.4)
    place(UsdGeom.Cube.Define(b.stage, "/World/Box").GetPrim(), (0.2, 0.25, -1.0), 0.25)
    capsule = UsdGeom.Capsule.Define(b.stage, "/World/Pill")
    capsule.CreateAxisAttr(UsdGeom.Tokens.x)
    place(capsule.GetPrim(), (0.0, 0.3, 1.0), 0.3)
    arcs = UsdGeom.BasisCurves.Define(b.stage, "/World/Arcs")
    t = np.linspace(0, np.pi, 9)
    pts = np.concatenate([np.stack([np.cos(t) * 0.6 - 0.5, np.sin(t) * 0.6 + 0.05, 0.8 + 0 * t], 1),
                          np.stack([np.cos(t) * 0.4 + 0.9, np.sin(t) * 0.4 + 0.05, 0.6 + 0 * t], 1)])
    arcs.CreatePointsAttr([Gf.Vec3f(*map(float, q)) for q in pts])
    arcs.CreateCurveVertexCountsAttr([9, 9])
    arcs.CreateTypeAttr(UsdGeom.Tokens.linear)
    arcs.CreateWidthsAttr([0.08])
    arcs.SetWidthsInterpolation(UsdGeom.Tokens.constant)
    loop = UsdGeom.BasisCurves.Define(b.stage, "/World/Loop")
    ring = [(0.5 * np.cos(a) + 0.3, 0.9, 0.5 * np.sin(a) - 0.2) for a in np.linspace(0, 2 * np.pi, 8, endpoint=False)]
    loop.CreatePointsAttr([Gf.Vec3f(*map(float, q)) for q in ring])
    loop.CreateCurveVertexCountsAttr([8])
    loop.CreateTypeAttr(UsdGeom.Tokens.cubic)
    loop.CreateBasisAttr(UsdGeom.Tokens.bspline)
    loop.CreateWrapAttr(UsdGeom.Tokens.periodic)
    loop.CreateWidthsAttr([0.06] * 8)
    dots = UsdGeom.Points.Define(b.stage, "/World/Dots")
    dots.CreatePointsAttr([Gf.Vec3f(-0.3 + 0.2 * k, 0.08, 1.6) for k in range(5)])
    dots.CreateWidthsAttr([0.12] * 5)
    b.distant("Sun", (0.4, 0.8, 0.45), 3.0)
    scene = b.write(tmp_path / "prims.usda")
    check_direct_light_like_the_reference(render, scene, spp)


def point_instancer_scene(tmp_path) -> str:
    """A floor under a sun, and a PointInstancer of two prototypes: a "Rock" Xform (its own transform, part of every
    instance) holding a pyramid Mesh with authored faceVarying normals and a Sphere child, and a Points cloud. Six
    instances: rotated, scaled unevenly, one mirrored (scale -1 in x), one masked by ``invisibleIds``."""
    from pxr import Gf, UsdGeom, Vt

    b = SceneBuilder()
    b.camera((0, 3.0, 3.5), (0, 0.2, 0), focal=28)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.5, 0.5, 0.5))
    pi = UsdGeom.PointInstancer.Define(b.stage, "/World/Scatter")
    UsdGeom.Xformable(pi).AddTranslateOp().Set(Gf.Vec3d(0.1, 0.0, -0.2))
    b.stage.DefinePrim("/World/Scatter/Prototypes", "Scope")
    rock = UsdGeom.Xform.Define(b.stage, "/World/Scatter/Prototypes/Rock")
    UsdGeom.Xformable(rock).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.05, 0.0))
    apex, base = (0.0, 0.5, 0.0), [(-0.3, 0.0, -0.3), (0.3, 0.0, -0.3), (0.3, 0.0, 0.3), (-0.3, 0.0, 0.3)]
    pyramid = b.mesh("Scatter/Prototypes/Rock/Pyramid", [apex] + base, [[0, 2, 1], [0, 3, 2], [0, 4, 3], [0, 1, 4]],
                     diffuse=(0.8, 0.4, 0.2), specular=(0.04,) * 3, roughness=0.5)
    normals = []
    for a, c in ((2, 1), (3, 2), (4, 3), (1, 4)):  # per face corner: the face normal tilted toward the vertex
        p = [np.array(apex), np.array(base[a - 1]), np.array(base[c - 1])]
        n = np.cross(p[1] - p[0], p[2] - p[0])
        n /= np.linalg.norm(n)
        normals += [Gf.Vec3f(*map(float, n + 0.3 * (q - p[0]))) for q in p]
    mesh = UsdGeom.Mesh(pyramid)
    mesh.CreateNormalsAttr(Vt.Vec3fArray(normals))
    mesh.SetNormalsInterpolation(UsdGeom.Tokens.faceVarying)
    ball = UsdGeom.Sphere.Define(b.stage, "/World/Scatter/Prototypes/Rock/Ball")
    ball.CreateRadiusAttr(0.15)
    UsdGeom.Xformable(ball).AddTranslateOp().Set(Gf.Vec3d(0.0, 0.6, 0.0))
    dots = UsdGeom.Points.Define(b.stage, "/World/Scatter/Prototypes/Dots")
    dots.CreatePointsAttr([Gf.Vec3f(0.15 * k, 0.1, 0.0) for k in range(-2, 3)])
    dots.CreateWidthsAttr([0.12] * 5)
    pi.CreatePrototypesRel().SetTargets([rock.GetPath(), dots.GetPath()])
    pi.CreateProtoIndicesAttr(Vt.IntArray([0, 0, 0, 1, 0, 1]))
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(*q) for q in
                                          ((-1.2, 0, 0), (0.0, 0, 0.3), (1.1, 0, -0.2), (0.0, 0, 1.2), (0.6, 0, 1.0), (-0.9, 0, -1.3))]))
    half = np.sqrt(0.5)
    pi.CreateOrientationsAttr(Vt.QuathArray([Gf.Quath(1, 0, 0, 0), Gf.Quath(half, 0, half, 0), Gf.Quath(0.9, 0.1, 0.3, 0.3),
                                             Gf.Quath(1, 0, 0, 0), Gf.Quath(1, 0, 0, 0), Gf.Quath(1, 0, 0, 0)]))
    pi.CreateScalesAttr(Vt.Vec3fArray([Gf.Vec3f(*q) for q in
                                       ((1, 1, 1), (1.5, 0.7, 1.0), (-1.0, 1.2, 1.0), (1, 1, 1), (1.3, 1, 1), (1, 1, 1))]))
    pi.CreateInvisibleIdsAttr(Vt.Int64Array([4]))
    b.distant("Sun", (0.4, 0.8, 0.45), 3.0)
    return b.write(tmp_path / "instancer.usda")


def instancer_with_prototype(tmp_path, define=None, *, n: int = 2, proto_indices=None, position=None) -> str:
    """A PointInstancer over a lit floor, of one prototype Xform ``/World/Scatter/Prototypes/Lamp`` under which
    ``define(stage, path)`` puts the child ``Part`` (default: a Cube of size 0.5); ``n`` instances at (i, 2, 0), or all at
    ``position``; ``proto_indices``: instead of n zeros."""
    from pxr import Gf, UsdGeom, Vt

    b = SceneBuilder()
    b.camera((0, 6, 0.001), (0, 0, 0), focal=20)
    b.quad("Floor", (0, 0, 0), 10.0)
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    pi = UsdGeom.PointInstancer.Define(b.stage, "/World/Scatter")
    root = UsdGeom.Xform.Define(b.stage, "/World/Scatter/Prototypes/Lamp")
    part = "/World/Scatter/Prototypes/Lamp/Part"
    if define is None:
        UsdGeom.Cube.Define(b.stage, part).CreateSizeAttr(0.5)
    else:
        define(b.stage, part)
    pi.CreatePrototypesRel().SetTargets([root.GetPath()])
    pi.CreateProtoIndicesAttr(Vt.IntArray(list(proto_indices) if proto_indices is not None else [0] * n))
    points = [position] * n if position is not None else [(float(i), 2.0, 0.0) for i in range(n)]
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(*q) for q in points]))
    return b.write(tmp_path / "s.usda")


def singular_transforms_scene(tmp_path, *, collapsed: bool = True) -> str:
    """Transforms that USD allows and that have no inverse (spec/renderer.md#shading-normals): a Cube flattened by a
    scale of 0 along y (it draws as a square, its top and bottom faces' normals +-y), and, with
    ``collapsed``, a Sphere and a PointInstancer instance scaled to 0 in every axis (they draw nothing), beside a Cube
    instance of scale 1, over a lit floor."""
    from pxr import Gf, UsdGeom, Vt

    b = SceneBuilder()
    b.camera((0, 3.0, 3.0), (0, 0.2, 0), focal=28)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.5, 0.5, 0.5))
    flat = UsdGeom.Cube.Define(b.stage, "/World/Flat")
    xf = UsdGeom.Xformable(flat)
    xf.AddTranslateOp().Set(Gf.Vec3d(-0.8, 0.6, 0.0))
    xf.AddScaleOp().Set(Gf.Vec3f(0.5, 0.0, 0.5))
    pi = UsdGeom.PointInstancer.Define(b.stage, "/World/Scatter")
    box = UsdGeom.Cube.Define(b.stage, "/World/Scatter/Prototypes/Box")
    box.CreateSizeAttr(0.5)
    pi.CreatePrototypesRel().SetTargets([box.GetPath()])
    pi.CreateProtoIndicesAttr(Vt.IntArray([0, 0] if collapsed else [0]))
    pi.CreatePositionsAttr(Vt.Vec3fArray([Gf.Vec3f(0.8, 0.25, 0.0), Gf.Vec3f(0.0, 0.25, 1.0)][:2 if collapsed else 1]))
    pi.CreateScalesAttr(Vt.Vec3fArray([Gf.Vec3f(1, 1, 1), Gf.Vec3f(0, 0, 0)][:2 if collapsed else 1]))
    if collapsed:
        gone = UsdGeom.Sphere.Define(b.stage, "/World/Gone")
        UsdGeom.Xformable(gone).AddScaleOp().Set(Gf.Vec3f(0.0, 0.0, 0.0))
    b.distant("Sun", (0.4, 0.8, 0.45), 3.0)
    return b.write(tmp_path / ("singular.usda" if collapsed else "regular.usda"))


def check_singular_transforms(render, tmp_path, spp: int = 256) -> None:
    """``render(scene, spp, seed=, max_depth=, width=, height=)``: :func:`singular_transforms_scene` renders as the
    reference renderer renders it (direct light: relative RMSE within 8 %, means within 2 %), and as the same scene
    without the collapsed prims (means within 2 %). Both renderers failed on such a scene: numpy's inverse of a singular
    matrix (the reference renderer's SCENE_INVALID "wrong type or shape", the Mitsuba reader's LinAlgError)."""
    with_collapsed = check_direct_light_like_the_reference(render, singular_transforms_scene(tmp_path), spp)
    without = render(singular_transforms_scene(tmp_path, collapsed=False), spp, seed=4, max_depth=1, width=32, height=32)
    np.testing.assert_allclose(with_collapsed.mean((0, 1)), without.mean((0, 1)), rtol=0.02)


def check_rewritten_asset_is_read_again(render, tmp_path) -> None:
    """``render(scene, spp, width, height) -> [H, W, 3]`` of a scene whose asset file is rewritten in place (a bake to
    the same path) while another stage in the process still composes it: the second render shows the new asset. The
    reference renderer composed the layer USD kept (the old content) and the plugin its cached asset: the old image,
    without a word. An asset of constant transport T under a sun facing the camera: the image mean scales with T."""
    from nasset_reference_renderer.testscenes import constant_rna_asset

    constant_rna_asset(tmp_path / "a.usdc", unshadowed=(1.0, 1.0, 1.0))
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0), focal=45)
    b.distant("Sun", (0, 0, 1), 2.0)
    b.asset("A", "./a.usdc", np.eye(4), typed="Xform")
    scene = b.write(tmp_path / "rewritten.usda")
    from pxr import Usd

    holder = Usd.Stage.Open(scene)  # another stage of the process composes the asset
    assert holder.GetPrimAtPath("/World/A")
    first = float(np.mean(render(scene, 4, 16, 16)))
    constant_rna_asset(tmp_path / "a.usdc", unshadowed=(0.2, 0.2, 0.2))
    second = float(np.mean(render(scene, 4, 16, 16)))
    assert first > 0.1 and abs(second / first - 0.2) < 0.02, (first, second)


def check_point_instancer(render, tmp_path, spp: int = 256) -> None:
    """``render(scene, spp, seed=, max_depth=, width=, height=)``: the instances of :func:`point_instancer_scene` render
    as the reference renderer renders them (spec/renderer.md#geometry): direct light from a delta sun, relative RMSE
    within 8 % at 32 x 32 and means within 2 %. Both Mitsuba implementations refused a PointInstancer."""
    check_direct_light_like_the_reference(render, point_instancer_scene(tmp_path), spp)


def check_direct_light_like_the_reference(render, scene, spp: int) -> np.ndarray:
    """``render``'s image of ``scene`` with direct light only (max_depth 1) against the reference renderer's, 32 x 32 at
    ``spp``: relative RMSE within 8 % (the two renders sample pixels at other points) and means within 2 %. Returns
    ``render``'s image (seed 4)."""
    import warnings

    from nasset_reference_renderer import RenderSettings, load_scene
    from nasset_reference_renderer import render as reference

    size = dict(width=32, height=32)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "tessellated into N triangles"
        want = reference(load_scene(scene), RenderSettings(spp=spp, max_depth=1, seed=3, **size)).image[..., :3]
        got = render(scene, spp, seed=4, max_depth=1, **size)
    rel = float(np.sqrt(np.mean((got - want) ** 2)) / want.mean())
    assert rel < 0.08, rel
    np.testing.assert_allclose(got.mean((0, 1)), want.mean((0, 1)), rtol=0.02)
    return got


#: the per-hit inputs :func:`textured_scene` builds (spec/renderer.md#textures, #primvar-colors)
TEXTURED_VARIANTS = ("repeat", "mirror", "clamp", "black", "exr", "channels", "transform2d", "face_varying", "primvar_color",
                     "display_color", "missing_file")


def textured_scene(tmp_path, variant: str) -> str:
    """A 2 x 2 quad seen from above on a dark ground under a delta sun, its UsdPreviewSurface fed per hit as ``variant``
    says (one of :data:`TEXTURED_VARIANTS`): a 24 x 16 8-bit sRGB checker-and-ramps PNG on diffuseColor read at st from
    -0.7 to 1.7 with each wrap mode; a linear OpenEXR of ramps (mirror); roughness and metallic from the g and b channels
    of a raw PNG; a UsdTransform2d between the primvar reader and the texture, with scale and bias; faceVarying st; a
    UsdPrimvarReader_float3 colour; an unbound mesh's varying displayColor; a missing file with an authored fallback."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade

    from nasset_sdk.images import write_exr, write_png

    yy, xx = np.mgrid[:16, :24]
    checker = np.stack([np.where((xx // 4 + yy // 4) % 2 == 0, 230, 30), xx * 10, yy * 15], -1).astype(np.uint8)
    write_png(tmp_path / "checker.png", checker)
    ramps = np.zeros((8, 8, 3), np.uint8)
    ramps[..., 1], ramps[..., 2] = np.linspace(0, 255, 8)[None, :], np.linspace(0, 255, 8)[:, None]
    write_png(tmp_path / "ramps.png", ramps)
    write_exr(tmp_path / "ramps.exr", np.stack([xx / 24.0, yy / 16.0, 0.5 + 0.0 * xx], -1).astype(np.float32))

    b = SceneBuilder()
    b.camera((0, 4, 0.01), (0, 0, 0), focal=35)
    b.quad("Ground", (0, -0.01, 0), 8, diffuse=(0.2, 0.2, 0.2))
    st = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32) * 2.4 - 0.7
    q = b.quad("Quad", (0, 0, 0), 2.0, diffuse=(0.5, 0.5, 0.5), specular=(0.04,) * 3)
    looks = "/World/Looks/QuadMat"
    if variant in ("repeat", "mirror", "clamp", "black"):
        b.texture("QuadMat", {"diffuseColor": "rgb"}, "checker.png", wrap=variant, st=st, mesh=q)
    elif variant == "exr":
        b.texture("QuadMat", {"diffuseColor": "rgb"}, "ramps.exr", wrap="mirror", st=st, mesh=q)
    elif variant == "channels":
        UsdShade.MaterialBindingAPI(q.GetPrim()).Bind(b.material("Metal", diffuse=(0.6, 0.4, 0.2), metallic=0.0))
        b.texture("Metal", {"roughness": "g", "metallic": "b"}, "ramps.png", wrap="clamp", space="raw", st=st, mesh=q)
    elif variant == "transform2d":
        node = b.texture("QuadMat", {"diffuseColor": "rgb"}, "checker.png", wrap="repeat", st=st, mesh=q,
                         scale=(1.5, 0.8, 1.0, 1.0), bias=(0.05, 0.1, 0.0, 0.0))
        xf = UsdShade.Shader.Define(b.stage, f"{looks}/Transform")
        xf.CreateIdAttr("UsdTransform2d")
        xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(1.7, 0.6))
        xf.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(30.0)
        xf.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(0.2, -0.3))
        reader = UsdShade.Shader(b.stage.GetPrimAtPath(f"{looks}/st"))
        xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        node.GetInput("st").ConnectToSource(xf.ConnectableAPI(), "result")
    elif variant == "face_varying":
        b.texture("QuadMat", {"diffuseColor": "rgb"}, "checker.png", wrap="repeat")
        pv = UsdGeom.PrimvarsAPI(q).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
        pv.Set(np.array([[0, 0], [2, 0], [1.5, 1.3], [0, 1]], np.float32))
    elif variant == "primvar_color":
        surface = UsdShade.Shader(b.stage.GetPrimAtPath(f"{looks}/PreviewSurface"))
        reader = UsdShade.Shader.Define(b.stage, f"{looks}/Tint")
        reader.CreateIdAttr("UsdPrimvarReader_float3")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("tint")
        surface.GetInput("diffuseColor").ConnectToSource(reader.ConnectableAPI(), "result")
        pv = UsdGeom.PrimvarsAPI(q).CreatePrimvar("tint", Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.vertex)
        pv.Set(np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0.2]], np.float32))
    elif variant == "display_color":
        m = UsdGeom.Mesh.Define(b.stage, "/World/Unbound")
        m.CreatePointsAttr([(-1, 0.01, -1), (1, 0.01, -1), (1, 0.01, 1), (-1, 0.01, 1)])
        m.CreateFaceVertexCountsAttr([4])
        m.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
        m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        m.CreateDisplayColorPrimvar(UsdGeom.Tokens.vertex).Set([(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 1)])
    elif variant == "missing_file":
        node = b.texture("QuadMat", {"diffuseColor": "rgb"}, "nowhere.png", wrap="repeat", st=st, mesh=q)
        node.CreateInput("fallback", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(0.9, 0.1, 0.3, 1.0))
    else:
        raise ValueError(variant)
    b.distant("Sun", (0.3, 0.9, 0.2), 3.0)
    return b.write(tmp_path / f"{variant}.usda")


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


def add_many_lights(b, rng, spheres: int, points: int, *, spread: float = 3.0) -> None:
    """``spheres`` small sphere lights (radius 0.1-0.3, 0.6-1.5 up, random colours) and ``points`` point lights (0.5-2
    up) scattered over +-``spread`` in x and z: more of each kind than a vertex samples one by one
    (spec/renderer.md#light-selection)."""
    for i in range(spheres):
        p = (rng.uniform(-spread, spread), rng.uniform(0.6, 1.5), rng.uniform(-spread, spread))
        b.sphere_light(f"S{i}", p, rng.uniform(0.1, 0.3), rng.uniform(0.5, 3.0), color=tuple(rng.uniform(0.3, 1, 3)))
    for i in range(points):
        p = (rng.uniform(-spread, spread), rng.uniform(0.5, 2.0), rng.uniform(-spread, spread))
        b.sphere_light(f"P{i}", p, 0.0, rng.uniform(0.2, 3.0))


def glossy_floor_many_lights(path) -> str:
    """64 sphere lights and 12 point lights over a glossy floor beside a ball: the floor reflects the sphere lights
    through both light samples and BSDF samples, so MIS with many lights shows in its image."""
    b = SceneBuilder()
    b.camera((0, 2.5, 5), (0, 0, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 12.0, diffuse=(0.05, 0.05, 0.05), specular=(0.9, 0.9, 0.9), roughness=0.3)
    b.sphere_mesh("Ball", (0.5, 0.5, -1), 0.5, diffuse=(0.5, 0.5, 0.5))
    add_many_lights(b, np.random.default_rng(1), 64, 12)
    return b.write(path)


def asset_among_many_lights(path, asset: str, seed: int = 2) -> str:
    """The neural ``asset`` on a diffuse floor among 12 sphere lights and 10 point lights within 1.5 of it, placed by
    ``seed``."""
    b = SceneBuilder()
    b.camera((0, 0.6, 3.0), (0, 0, 0), focal=45)
    b.quad("Floor", (0, -0.6, 0), 6.0, diffuse=(0.5, 0.5, 0.5))
    b.asset("Obj", asset)
    add_many_lights(b, np.random.default_rng(seed), 12, 10, spread=1.5)
    return b.write(path)


def cone_lights_scene(path) -> str:
    """A floor under two soft boxes (RectLights with nasset:spread 0.9 and 0.6 rad, each a pool of light), a spot (a
    point light with ShapingAPI, 25 degrees), a spot with a radius (a SphereLight of radius 0.15, 30 degrees) and a
    faint dome: most of the floor lies outside most of the cones."""
    from pxr import Gf, Sdf, UsdGeom, UsdLux

    from nasset_reference_renderer.testscenes import _frame_matrix

    b = SceneBuilder()
    b.camera((0, 4.5, 4.5), (0, 0, 0), focal=28)
    b.quad("Floor", (0, 0, 0), 8.0, diffuse=(0.6, 0.6, 0.6))
    for name, centre, aim, spread in (("BoxA", (-1.5, 1.2, 0.5), (0.3, -1.0, 0.0), 0.9),
                                      ("BoxB", (1.6, 1.0, -0.8), (-0.2, -1.0, 0.3), 0.6)):
        lt = b.rect_light(name, centre, 0.6, 0.4, aim, 10.0)
        lt.GetPrim().CreateAttribute("nasset:spread", Sdf.ValueTypeNames.Float, custom=True).Set(spread)
    for name, position, aim, radius, cone in (("Spot", (0.0, 2.5, -1.5), (0.1, -1.0, 0.6), 0.0, 25.0),
                                               ("Ball", (-0.5, 2.0, 2.0), (0.6, -1.0, -0.2), 0.15, 30.0)):
        lt = b.sphere_light(name, position, radius, 30.0)
        m = _frame_matrix(-np.asarray(aim, np.float64), position)
        UsdGeom.Xformable(lt.GetPrim()).GetOrderedXformOps()[0].Set(Gf.Matrix4d(*np.asarray(m, np.float64).ravel().tolist()))
        UsdLux.ShapingAPI.Apply(lt.GetPrim()).CreateShapingConeAngleAttr(cone)
    b.dome("Sky", 0.05)
    return b.write(path)


def spot_stage_scene(path, n: int = 12, seed: int = 3) -> str:
    """A floor under ``n`` spots (point lights with ShapingAPI, cones of 12-22 degrees) hung at random over it, each
    aimed at a random point of the floor: a stage of pools of light, most of the floor outside most of the cones."""
    from pxr import Gf, UsdGeom, UsdLux

    from nasset_reference_renderer.testscenes import _frame_matrix

    rng = np.random.default_rng(seed)
    b = SceneBuilder()
    b.camera((0, 5.0, 4.0), (0, 0, 0), focal=26)
    b.quad("Floor", (0, 0, 0), 8.0, diffuse=(0.6, 0.6, 0.6))
    for i in range(n):
        pos = np.array([rng.uniform(-3, 3), 2.2, rng.uniform(-3, 3)])
        aim = np.array([rng.uniform(-3, 3), 0.0, rng.uniform(-3, 3)]) - pos
        lt = b.sphere_light(f"Spot{i}", pos, 0.0, 20.0)
        m = _frame_matrix(-aim / np.linalg.norm(aim), pos)
        UsdGeom.Xformable(lt.GetPrim()).GetOrderedXformOps()[0].Set(Gf.Matrix4d(*np.asarray(m, np.float64).ravel().tolist()))
        UsdLux.ShapingAPI.Apply(lt.GetPrim()).CreateShapingConeAngleAttr(float(rng.uniform(12, 22)))
    return b.write(path)
