"""Image textures (UsdUVTexture through UsdPrimvarReader_float2) and one-sided surfaces (doubleSided = false)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_reference_renderer.textures import ImageTexture, srgb_to_linear
from nasset_sdk.images import write_exr


def test_srgb_decode_matches_the_standard_formula():
    # IEC 61966-2-1 values: 0.5 -> 0.214041, 0.04045 (the knee) -> 0.04045 / 12.92, 1 -> 1
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0.0, 0.04045 / 12.92, 0.2140411, 1.0], rtol=1e-6)


def test_bilinear_lookup_reproduces_a_linear_image_and_wraps():
    h, w = 6, 8
    y, x = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.stack([x, y, 2 * x + 3 * y], -1)  # linear in the texel indices
    tex = ImageTexture(img, "repeat", "repeat")
    rng = np.random.default_rng(1)
    # st whose texel coordinates stay between texel centres (no wrap involved)
    px, py = rng.uniform(0, w - 1, 200), rng.uniform(0, h - 1, 200)
    st = np.stack([(px + 0.5) / w, 1.0 - (py + 0.5) / h], 1)  # t = 0 is the bottom row
    np.testing.assert_allclose(tex.sample(st), np.stack([px, py, 2 * px + 3 * py], 1), atol=1e-9)
    np.testing.assert_allclose(tex.sample(st + [3.0, -2.0]), tex.sample(st), atol=1e-9)  # repeat is periodic
    mirror = ImageTexture(img, "mirror", "mirror")
    np.testing.assert_allclose(mirror.sample(np.array([[-0.2, 0.4]])), mirror.sample(np.array([[0.2, 0.4]])), atol=1e-9)
    black = ImageTexture(img + 1.0, "black", "black")
    assert np.all(black.sample(np.array([[-0.5, 0.5], [0.5, 1.5]])) == 0.0)
    clamp = ImageTexture(img, "clamp", "clamp")
    np.testing.assert_allclose(clamp.sample(np.array([[5.0, 0.5]]))[0, 0], w - 1)
    scaled = ImageTexture(img, scale=[2, 2, 2], bias=[1, 1, 1])
    np.testing.assert_allclose(scaled.sample(st), 2 * tex.sample(st) + 1, atol=1e-9)


def _textured_quad_scene(tmp_path, space: str, file: str = "t.exr"):
    """A 4 x 4 floor under a distant light, seen from above; its diffuseColor is a 2 x 1 texture (left texel 0.5,
    right texel (0.9, 0.2, 0.1)) with clamp wrap, st running 0 .. 1 across the floor. Another ``file`` (written by
    the caller) replaces the texture."""
    from pxr import Sdf, UsdGeom, UsdShade

    if file == "t.exr":
        write_exr(tmp_path / "t.exr", np.array([[[0.5, 0.5, 0.5], [0.9, 0.2, 0.1]]], np.float32))
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=14)  # the floor fills the view, with a margin
    quad = b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0, 0, 0), specular=(0, 0, 0), roughness=1.0)
    pts = np.asarray(quad.GetPointsAttr().Get())
    b.distant("Sun", (0.3, 1.0, 0.2), 2.0)
    st = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    UsdGeom.PrimvarsAPI(quad).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(st)
    surf = UsdShade.Shader(b.stage.GetPrimAtPath("/World/Looks/FloorMat/PreviewSurface"))
    reader = UsdShade.Shader.Define(b.stage, "/World/Looks/FloorMat/st")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    node = UsdShade.Shader.Define(b.stage, "/World/Looks/FloorMat/tex")
    node.CreateIdAttr("UsdUVTexture")
    node.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{file}")
    node.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
    for k in ("wrapS", "wrapT"):
        node.CreateInput(k, Sdf.ValueTypeNames.Token).Set("clamp")
    node.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    surf.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(node.ConnectableAPI(), "rgb")
    return b.write(tmp_path / f"s_{file}.usda"), pts


@pytest.mark.parametrize("space", ["auto", "sRGB", "raw"])
def test_png_texture_renders_like_an_openexr_of_its_decoded_values(tmp_path, space):
    """An 8-bit PNG texture is its values / 255, decoded from sRGB under ``sRGB`` and ``auto`` (UsdPreviewSurface:
    auto is sRGB for 8-bit images), as stored under ``raw``. Before, a PNG was ignored (the input's own value,
    black here, with a warning)."""
    from nasset_sdk.images import write_png

    u8 = np.array([[[128, 128, 128], [230, 51, 26]]], np.uint8)
    write_png(tmp_path / "t.png", u8)
    linear = u8 / 255.0 if space == "raw" else srgb_to_linear(u8 / 255.0)
    write_exr(tmp_path / "lin.exr", linear.astype(np.float32))
    png, _ = _textured_quad_scene(tmp_path, space, "t.png")
    exr, _ = _textured_quad_scene(tmp_path, "raw", "lin.exr")
    settings = RenderSettings(spp=4, width=12, height=12, max_depth=1)
    a, b = render(load_scene(png), settings).image, render(load_scene(exr), settings).image
    assert a.mean() > 0.05
    np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-7)


def test_png_texture_beyond_the_image_bounds_is_refused_before_decoding(tmp_path):
    """A PNG whose header claims 40000 x 1 pixels (a side over MAX_TEXTURE_SIDE): IMAGE_INVALID from the header."""
    import struct
    import zlib

    from nasset_sdk.errors import NassetError

    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", 40000, 1, 8, 2, 0, 0, 0)
    (tmp_path / "big.png").write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))
    path, _ = _textured_quad_scene(tmp_path, "auto", "big.png")
    with pytest.raises(NassetError) as exc:
        load_scene(path)
    assert exc.value.code == "IMAGE_INVALID" and "40000" in str(exc.value)


@pytest.mark.parametrize("space, left, right", [("raw", 0.5, (0.9, 0.2, 0.1)),
                                                ("sRGB", 0.2140411, (0.787412, 0.0331048, 0.0100228))])
def test_textured_floor_shows_each_texel_where_its_st_falls(tmp_path, space, left, right):
    path, pts = _textured_quad_scene(tmp_path, space)
    scene = load_scene(path)
    assert scene.materials.textured
    w = h = 24
    img = render(scene, RenderSettings(spp=4, width=w, height=h, max_depth=1)).image
    # s of each pixel centre from the camera ray's hit on the floor plane y = 0 (independent of the renderer's lookup)
    ys, xs = np.mgrid[0:h, 0:w]
    o, d = scene.camera.generate_rays(xs.ravel() + 0.5, ys.ravel() + 0.5, w, h)
    hit = o + d * (-o[:, 1] / d[:, 1])[:, None]
    e0, e1 = pts[1] - pts[0], pts[3] - pts[0]
    s = (hit - pts[0]) @ e0 / (e0 @ e0)
    t = (hit - pts[0]) @ e1 / (e1 @ e1)
    light = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])
    shade = 2.0 * light[1] / np.pi  # E cos / pi
    px = img.reshape(-1, 3)
    # pixel footprints on the floor (one pixel is ~0.04 in s) and away from the blend between the texel centres
    inside = (t > 0.06) & (t < 0.94)
    lo, hi = inside & (s > 0.06) & (s < 0.18), inside & (s > 0.82) & (s < 0.94)
    assert lo.sum() > 20 and hi.sum() > 20
    np.testing.assert_allclose(px[lo], np.full((lo.sum(), 3), left * shade), rtol=2e-3)
    np.testing.assert_allclose(px[hi], np.tile(np.asarray(right) * shade, (hi.sum(), 1)), rtol=2e-3)


@pytest.mark.parametrize("authored, normal_up, lit", [(None, False, True), (False, False, False), (False, True, True),
                                                      (True, False, True)])
def test_one_sided_surface_is_black_from_behind(tmp_path, authored, normal_up, lit):
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=200)
    quad = b.quad("Floor", (0, 0, 0), 4.0, normal=(0, 1, 0) if normal_up else (0, -1, 0), diffuse=(0.5, 0.5, 0.5))
    if authored is not None:
        quad.CreateDoubleSidedAttr(authored)
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    img = render(load_scene(b.write(tmp_path / "s.usda")), RenderSettings(spp=1, width=4, height=4, max_depth=2)).image
    assert (img.mean() > 0.1) == lit, img.mean()


@pytest.mark.parametrize("left_handed, mirror, lit", [(False, False, False), (True, False, True), (False, True, True),
                                                      (True, True, False)])
def test_front_side_follows_usd_orientation_and_mirroring(tmp_path, left_handed, mirror, lit):
    """A one-sided quad wound to face down, seen from above: black, unless its effective orientation flips
    (``orientation = leftHanded``, or a world transform with det < 0; both cancel), as USD defines the front side.
    Before, the front was the world winding's right-hand side whatever the prim said."""
    from pxr import Gf, UsdGeom

    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=200)
    quad = b.quad("Floor", (0, 0, 0), 4.0, normal=(0, -1, 0), diffuse=(0.5, 0.5, 0.5))
    quad.CreateDoubleSidedAttr(False)
    if left_handed:
        quad.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    if mirror:  # a mirror through the quad's plane y = 0: the world points and winding stay, the orientation flips
        UsdGeom.Xformable(quad).AddTransformOp().Set(Gf.Matrix4d(1, 0, 0, 0, 0, -1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1))
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    img = render(load_scene(b.write(tmp_path / "s.usda")), RenderSettings(spp=1, width=4, height=4, max_depth=2)).image
    assert (img.mean() > 0.1) == lit, img.mean()


@pytest.mark.parametrize("left_handed, mirror, lit", [(False, False, True), (True, False, False), (False, True, True)])
def test_one_sided_implicit_sphere_front_is_outside_unless_left_handed(tmp_path, left_handed, mirror, lit):
    """A one-sided UsdGeom.Sphere seen from outside: lit whatever its transform (a mirror keeps its outside the
    front), black when ``orientation = leftHanded`` (its front is the inside)."""
    import warnings

    from pxr import Gf, UsdGeom

    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=60)
    sph = UsdGeom.Sphere.Define(b.stage, "/World/Ball")
    sph.CreateRadiusAttr(0.5)
    sph.CreateDoubleSidedAttr(False)
    if left_handed:
        sph.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    if mirror:
        UsdGeom.Xformable(sph).AddTransformOp().Set(Gf.Matrix4d(-1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1))
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the sphere is tessellated
        scene = load_scene(b.write(tmp_path / "s.usda"))
    img = render(scene, RenderSettings(spp=1, width=4, height=4, max_depth=2)).image
    assert (img.mean() > 0.01) == lit and (lit or img.mean() == 0.0), img.mean()


def test_geom_subsets_bind_materials_per_face_and_holes_are_left_out(tmp_path):
    """A floor of three faces: the left one in a ``materialBind`` GeomSubset bound to a red material, the middle one
    a hole, the right one with the mesh's own (green) binding. Seen from above under a sun: red, black, green.
    Before, the whole mesh took the mesh's material and the hole rendered."""
    from pxr import UsdGeom, UsdShade

    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=12)
    pts = [(x, 0.0, z) for x in (-1.5, -0.5, 0.5, 1.5) for z in (-0.5, 0.5)]  # columns of 2 points, +x to the right
    faces = [[2 * i, 2 * i + 1, 2 * i + 3, 2 * i + 2] for i in range(3)]
    mesh = b.mesh("Floor", pts, faces, diffuse=(0.1, 0.8, 0.1), specular=(0, 0, 0), roughness=1.0)
    red = b.material("Red", diffuse=(0.8, 0.1, 0.1), specular=(0, 0, 0), roughness=1.0)
    subset = UsdShade.MaterialBindingAPI(mesh.GetPrim()).CreateMaterialBindSubset("left", [0], UsdGeom.Tokens.face)
    UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(red)
    mesh.CreateHoleIndicesAttr([1])
    b.distant("Sun", (0.0, 1.0, 0.0), 1.0)
    img = render(load_scene(b.write(tmp_path / "s.usda")), RenderSettings(spp=4, width=30, height=10, max_depth=1)).image
    left, middle, right = img[4:6, 3:7].mean((0, 1)), img[4:6, 13:17].mean((0, 1)), img[4:6, 23:27].mean((0, 1))
    assert left[0] > 4 * left[1] and right[1] > 4 * right[0], (left, right)
    assert not middle.any(), middle


def test_spot_falloff_hand_values():
    from nasset_reference_renderer.lights import spot_falloff

    c = np.cos(np.radians([0.0, 14.9, 18.5, 21.9, 22.1, 90.0]))
    # cone 22 deg, softness 7/22: beam 15 deg, then linear in angle to 0 at 22 deg (Mitsuba's spot)
    np.testing.assert_allclose(spot_falloff(c, 22.0, 7.0 / 22.0), [1, 1, 0.5, 0.1 / 7, 0, 0], atol=1e-9)


def test_spot_smoothstep_falloff_hand_values():
    """Cycles' profile: smoothstep((cos t - cos c) / ((1 - cos c) s)); x = 1/4 of the span gives 0.25^2 (3 - 0.5)."""
    from nasset_reference_renderer.lights import spot_falloff

    cc, s = np.cos(np.radians(25.0)), 0.3
    span = (1.0 - cc) * s
    c = np.array([1.0, cc + span * 1.01, cc + 0.5 * span, cc + 0.25 * span, cc - 1e-4, -1.0])
    np.testing.assert_allclose(spot_falloff(c, 25.0, s, "smoothstep"), [1, 1, 0.5, 0.15625, 0, 0], atol=1e-9)
    hard = np.cos(np.radians([0.0, 24.9, 25.1]))
    np.testing.assert_allclose(spot_falloff(hard, 25.0, 0.0, "smoothstep"), [1, 1, 0])  # softness 0: a step


def _smoothstep_ramp(theta, cone, soft):
    """Hand-written Cycles spot ramp at angles ``theta`` (degrees) for the render test below."""
    x = np.clip((np.cos(np.radians(theta)) - np.cos(np.radians(cone))) / ((1 - np.cos(np.radians(cone))) * soft), 0, 1)
    return x * x * (3 - 2 * x)


@pytest.mark.parametrize("falloff", [None, "smoothstep"])
def test_spot_light_lights_its_cone_only(tmp_path, falloff):
    from pxr import Sdf, UsdLux

    h, a, intensity, cone, soft = 2.0, 0.5, 4.0, 20.0, 0.25 if falloff is None else 0.6
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=14)
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(a, a, a), specular=(0, 0, 0), roughness=1.0)
    lt = b.sphere_light("Spot", (0, h, 0), 0.0, intensity)
    lt.CreateTreatAsPointAttr(True)
    from pxr import Gf, UsdGeom

    op = UsdGeom.Xformable(lt.GetPrim()).GetOrderedXformOps()[0]  # local -Z -> world down
    op.Set(Gf.Matrix4d(1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, h, 0, 1))
    shaping = UsdLux.ShapingAPI.Apply(lt.GetPrim())
    shaping.CreateShapingConeAngleAttr(cone)
    shaping.CreateShapingConeSoftnessAttr(soft)
    if falloff is not None:
        lt.GetPrim().CreateAttribute("nasset:shaping:falloff", Sdf.ValueTypeNames.Token, custom=True).Set(falloff)
    scene = load_scene(b.write(tmp_path / "s.usda"))
    w = 32
    img = render(scene, RenderSettings(spp=32, width=w, height=w, max_depth=1)).image.reshape(-1, 3)[:, 0]
    ys, xs = np.mgrid[0:w, 0:w]
    o, d = scene.camera.generate_rays(xs.ravel() + 0.5, ys.ravel() + 0.5, w, w)
    hit = o + d * (-o[:, 1] / d[:, 1])[:, None]
    theta = np.degrees(np.arctan(np.hypot(hit[:, 0], hit[:, 2]) / h))
    cos = np.cos(np.radians(theta))
    full = a / np.pi * intensity * cos ** 3 / h ** 2  # E = I cos / d^2 with d = h / cos
    if falloff is None:
        beam, ramp_of = cone * (1 - soft), lambda t: (cone - t) / (cone - cone * (1 - soft))
    else:  # full strength where cos t >= cos c + (1 - cos c) s
        beam = np.degrees(np.arccos(np.cos(np.radians(cone)) + (1 - np.cos(np.radians(cone))) * soft))
        ramp_of = lambda t: _smoothstep_ramp(t, cone, soft)  # noqa: E731
    inner, outer = theta < beam - 3.5, theta > cone + 3.5  # pixel footprints span up to ~3.4 degrees here
    assert inner.sum() > 10 and outer.sum() > 10
    np.testing.assert_allclose(img[inner], full[inner], rtol=1e-2)  # pixel-footprint means of a concave cos^3: a bit low
    assert np.all(img[outer] == 0.0)
    ramp = (theta > beam + 1.7) & (theta < cone - 1.7)
    # in the ramp single pixels straddle its ends: compare the mean over the ramp's pixels
    assert ramp.sum() > 10
    assert img[ramp].mean() == pytest.approx((full[ramp] * ramp_of(theta[ramp])).mean(), rel=0.05)


def test_light_hidden_from_camera_still_lights_the_scene(tmp_path):
    """``nasset:cameraVisibility = false``: camera rays pass through the RectLight (black background there) and the
    light still lights the floor as before (pixels that do not see the panel keep their mean)."""
    from pxr import Sdf, Usd

    b = SceneBuilder()
    b.camera((0, 0.55, 3.0), (0, 0.55, 0), focal=20)  # rays through the panel rise into the black background
    b.quad("Floor", (0, 0, 0), 6.0, diffuse=(0.3, 0.3, 0.3), specular=(0.5, 0.5, 0.5), roughness=0.05)
    b.rect_light("Panel", (0, 1.0, 0), 0.8, 0.8, (0.0, -0.3, 1.0), 5.0)
    path = b.write(tmp_path / "s.usda")
    shown = render(load_scene(path), RenderSettings(spp=64, width=24, height=24, max_depth=2, seed=3)).image
    stage = Usd.Stage.Open(path)
    stage.GetPrimAtPath("/World/Panel").CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool,
                                                         custom=True).Set(False)
    stage.GetRootLayer().Save()
    hidden = render(load_scene(path), RenderSettings(spp=64, width=24, height=24, max_depth=2, seed=3)).image
    scene = load_scene(path)
    ys, xs = np.mgrid[0:24, 0:24]
    touches, panel = np.zeros(24 * 24, bool), np.ones(24 * 24, bool)  # corners or centre on the panel; all of them
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1), (0.5, 0.5)):
        o, d = scene.camera.generate_rays(xs.ravel() + dx, ys.ravel() + dy, 24, 24)
        on = np.isfinite(scene.lights[0].intersect(o, d)[0])
        touches, panel = touches | on, panel & on
    touches, panel = touches.reshape(24, 24), panel.reshape(24, 24)
    assert panel.sum() > 5
    np.testing.assert_allclose(shown[panel], 5.0)  # the panel's radiance, seen directly
    assert np.all(hidden[panel] == 0.0)  # through it: the black background
    assert (~touches).sum() > 100
    assert hidden[~touches].mean() == pytest.approx(shown[~touches].mean(), rel=0.03)


def test_dome_hidden_from_camera_is_black_behind_and_still_lights_the_scene(tmp_path):
    """``nasset:cameraVisibility = false`` on a DomeLight (Mitsuba's ``hide_emitters``, Cycles' transparent film): camera rays that escape see
    black, and the dome still lights the floor, seen directly and through a mirror-like reflection, as before."""
    from pxr import Sdf, Usd

    b = SceneBuilder()
    b.camera((0, 1.0, 3.0), (0, 0.6, 0), focal=20)  # the upper half of the image is sky
    b.quad("Floor", (0, 0, 0), 400.0, diffuse=(0.3, 0.3, 0.3), specular=(0.5, 0.5, 0.5), roughness=0.05)
    b.dome("Sky", 0.8, color=(0.5, 0.7, 1.0))
    path = b.write(tmp_path / "s.usda")
    settings = RenderSettings(spp=32, width=24, height=24, max_depth=2, seed=3)
    shown = render(load_scene(path), settings).image
    stage = Usd.Stage.Open(path)
    stage.GetPrimAtPath("/World/Sky").CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool,
                                                       custom=True).Set(False)
    stage.GetRootLayer().Save()
    hidden = render(load_scene(path), settings).image
    scene = load_scene(path)
    ys, xs = np.mgrid[0:24, 0:24]
    o, d = scene.camera.generate_rays(xs.ravel() + 0.5, ys.ravel() + 0.5, 24, 24)
    sky = (d[:, 1] > 0.05).reshape(24, 24)  # rising rays: they miss the floor
    floor = (d[:, 1] < -0.05).reshape(24, 24)  # they meet the (400 wide) floor
    assert sky.sum() > 50 and floor.sum() > 50
    np.testing.assert_allclose(shown[sky], np.broadcast_to([0.4, 0.56, 0.8], shown[sky].shape), rtol=1e-5)
    assert np.all(hidden[sky] == 0.0)
    np.testing.assert_allclose(hidden[floor].mean(0), shown[floor].mean(0), rtol=0.03)


@pytest.mark.parametrize("file, code", [("https://example.com/t.exr", "SCENE_INVALID"), ("./bad.exr", "IMAGE_INVALID")])
def test_texture_files_are_checked_like_other_asset_paths(tmp_path, file, code):
    from pxr import Sdf, Usd, UsdShade

    from nasset_sdk.errors import NassetError

    path, _ = _textured_quad_scene(tmp_path, "raw")
    (tmp_path / "bad.exr").write_bytes(b"not an OpenEXR file")
    stage = Usd.Stage.Open(path)
    UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/tex")).GetInput("file").Set(Sdf.AssetPath(file))
    stage.GetRootLayer().Save()
    with pytest.raises(NassetError) as exc:
        load_scene(path)
    assert exc.value.code == code, exc.value


def test_transform2d_hand_value():
    from nasset_reference_renderer.textures import transform2d

    m = transform2d((2.0, 3.0), 90.0, (0.5, 0.0))  # scale, then rotate counter-clockwise, then translate
    np.testing.assert_allclose(m @ [1.0, 1.0, 1.0], [-2.5, 2.0], atol=1e-12)


def test_st_through_a_usd_transform2d_is_the_textures_uv_map(tmp_path):
    """A UsdTransform2d (scale, rotation, translation) between the primvar reader and the texture: the loaded texture
    looks up ``transform2d(...) st`` (checked against a lookup at the hand-transformed coordinates). Before, the
    transform was not followed (a warning, primvar st used as is)."""
    import warnings

    from pxr import Sdf, Usd, UsdShade

    from nasset_reference_renderer.textures import transform2d

    plain, _ = _textured_quad_scene(tmp_path, "raw")
    stage = Usd.Stage.Open(plain)
    tex = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/tex"))
    xf = UsdShade.Shader.Define(stage, "/World/Looks/FloorMat/tile")
    xf.CreateIdAttr("UsdTransform2d")
    xf.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set((3.0, 2.0))
    xf.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(30.0)
    xf.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set((0.25, -0.5))
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(
        UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/st")).ConnectableAPI(), "result")
    tex.GetInput("st").ConnectToSource(xf.ConnectableAPI(), "result")
    stage.GetRootLayer().Export(str(tmp_path / "tiled.usda"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the chain is followed: no "primvar st used" warning
        scene = load_scene(str(tmp_path / "tiled.usda"))
    texture = next(t for t in scene.materials.textures if t is not None).diffuse
    np.testing.assert_allclose(texture.uv_matrix, transform2d((3.0, 2.0), 30.0, (0.25, -0.5)))
    st = np.random.default_rng(3).random((50, 2))
    moved = st @ texture.uv_matrix[:, :2].T + texture.uv_matrix[:, 2]
    plain_lookup = ImageTexture(texture.image, texture.wrap_s, texture.wrap_t)
    np.testing.assert_allclose(texture.sample(st), plain_lookup.sample(moved))


def test_textures_inside_a_usdz_package_are_read(tmp_path):
    """A usdz holding the scene and its PNG texture renders like the loose files (the texture resolves to
    ``scene.usdz[t.png]``, read through USD's resolver). Before, the packaged texture was not found."""
    from pxr import Sdf, UsdUtils

    from nasset_sdk.images import write_png

    write_png(tmp_path / "t.png", np.array([[[128, 128, 128], [230, 51, 26]]], np.uint8))
    loose, _ = _textured_quad_scene(tmp_path, "auto", "t.png")
    package = tmp_path / "scene.usdz"
    assert UsdUtils.CreateNewUsdzPackage(Sdf.AssetPath(str(loose)), str(package))
    settings = RenderSettings(spp=2, width=12, height=12, max_depth=1)
    b = render(load_scene(loose), settings).image
    (tmp_path / "t.png").unlink()  # only the packaged copy is left
    a = render(load_scene(str(package)), settings).image
    assert a.mean() > 0.05
    np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-7)


def test_inputs_connected_to_the_materials_interface_take_its_values(tmp_path):
    """USD's own UsdPreviewSurface example: the primvar reader's varname is connected to the material's interface
    input (``inputs:frame:stPrimvarName``), and a value input may be too. The floor with its primvar renamed "UVs"
    and read that way renders like the plain one; a roughness fed by the interface is used. Before, a connected
    varname read as unset ("st": no texture coordinates) and connected values were dropped."""
    import warnings

    from pxr import Sdf, Usd, UsdGeom, UsdShade

    plain, _ = _textured_quad_scene(tmp_path, "raw")
    settings = RenderSettings(spp=2, width=12, height=12, max_depth=1)
    want = render(load_scene(plain), settings).image
    stage = Usd.Stage.Open(plain)
    mat = UsdShade.Material(stage.GetPrimAtPath("/World/Looks/FloorMat"))
    floor = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath("/World/Floor"))
    st = floor.GetPrimvar("st").Get()
    floor.RemovePrimvar("st")
    floor.CreatePrimvar("UVs", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(st)
    name_in = mat.CreateInput("frame:stPrimvarName", Sdf.ValueTypeNames.Token)
    name_in.Set("UVs")
    UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/st")).GetInput("varname").ConnectToSource(name_in)
    surface = UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/PreviewSurface"))
    rough_in = mat.CreateInput("roughness", Sdf.ValueTypeNames.Float)
    rough_in.Set(float(surface.GetInput("roughness").Get()))
    surface.GetInput("roughness").ConnectToSource(rough_in)
    surface.GetInput("roughness").GetAttr().Clear()  # the value now lives only on the material's interface
    stage.GetRootLayer().Export(str(tmp_path / "interface.usda"))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing dropped, nothing defaulted
        scene = load_scene(str(tmp_path / "interface.usda"))
    np.testing.assert_allclose(render(scene, settings).image, want, rtol=1e-6, atol=1e-7)


@pytest.mark.parametrize("name, value_type, value", [("scale", "String", "big"), ("rotation", "Float", float("inf")),
                                                     ("translation", "Float2", (1e12, 0.0))])
def test_a_bad_transform2d_value_is_a_scene_error(tmp_path, name, value_type, value):
    from pxr import Sdf, Usd, UsdShade

    from nasset_sdk.errors import SceneError

    plain, _ = _textured_quad_scene(tmp_path, "raw")
    stage = Usd.Stage.Open(plain)
    xf = UsdShade.Shader.Define(stage, "/World/Looks/FloorMat/tile")
    xf.CreateIdAttr("UsdTransform2d")
    xf.CreateInput(name, getattr(Sdf.ValueTypeNames, value_type)).Set(value)
    xf.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(
        UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/st")).ConnectableAPI(), "result")
    UsdShade.Shader(stage.GetPrimAtPath("/World/Looks/FloorMat/tex")).GetInput("st").ConnectToSource(xf.ConnectableAPI(),
                                                                                                  "result")
    stage.GetRootLayer().Export(str(tmp_path / "bad.usda"))
    with pytest.raises(SceneError) as exc:
        load_scene(str(tmp_path / "bad.usda"))
    assert exc.value.code == "SCENE_INVALID" and f"inputs:{name}" in str(exc.value)


def _orm_floor(tmp_path, textured: bool, rough=0.5, metal=0.0):
    """A glossy floor under a sun and a sky seen at an angle (the specular lobe shows). ``textured``: roughness from the
    ``g`` and metallic from the ``b`` output of one 2 x 1 OpenEXR (glTF's occlusion-roughness-metallic packing): left
    texel (1, 0.2, 0), right texel (1, 0.9, 1), clamp wrap; else the constants ``rough``, ``metal``."""
    from pxr import Sdf, UsdGeom

    b = SceneBuilder()
    b.camera((0, 1.2, 3.0), (0, 0, 0), focal=24)
    quad = b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.6, 0.4, 0.2), roughness=rough, metallic=metal)
    pts = np.asarray(quad.GetPointsAttr().Get())
    b.distant("Sun", (0.0, 0.5, -1.0), 3.0, angle=5.0)
    b.dome("Sky", 0.3)
    # a second object, out of view: every variant keeps its continuation rays (a lone planar mesh of a sharp lobe keeps
    # them, a rough one does not: spec/renderer.md#plan), so the three renders draw the same paths
    b.quad("Far", (0, 0, 40), 0.1)
    st = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    UsdGeom.PrimvarsAPI(quad).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(st)
    if textured:
        write_exr(tmp_path / "orm.exr", np.array([[[1.0, 0.2, 0.0], [1.0, 0.9, 1.0]]], np.float32))
        b.texture("FloorMat", {"roughness": "g", "metallic": "b"}, "orm.exr")
    return load_scene(b.write(tmp_path / f"orm_{textured}_{rough}_{metal}.usda")), pts


def test_roughness_and_metallic_textures_shade_each_hit_like_their_constants(tmp_path):
    """Where st reads only the left texel the textured floor renders as the constant material (roughness 0.2,
    metallic 0), where it reads only the right one as (0.9, 1): same seed, same paths, same pixels. Before, a
    connected roughness or metallic used the input's own value (warned)."""
    w = h = 32
    s_ = RenderSettings(spp=8, width=w, height=h, max_depth=2, seed=4)
    scene, pts = _orm_floor(tmp_path, True)
    img = render(scene, s_).image.reshape(-1, 3)
    left = render(_orm_floor(tmp_path, False, 0.2, 0.0)[0], s_).image.reshape(-1, 3)
    right = render(_orm_floor(tmp_path, False, 0.9, 1.0)[0], s_).image.reshape(-1, 3)
    ys, xs = np.mgrid[0:h, 0:w]
    o, d = scene.camera.generate_rays(xs.ravel() + 0.5, ys.ravel() + 0.5, w, h)
    hit = o + d * (-o[:, 1] / np.minimum(d[:, 1], -1e-9))[:, None]
    e0, e1 = pts[1] - pts[0], pts[3] - pts[0]
    s = (hit - pts[0]) @ e0 / (e0 @ e0)
    t = (hit - pts[0]) @ e1 / (e1 @ e1)
    inside = (d[:, 1] < 0) & (t > 0.05) & (t < 0.95)
    lo, hi = inside & (s > 0.03) & (s < 0.2), inside & (s > 0.8) & (s < 0.97)
    assert lo.sum() > 20 and hi.sum() > 20
    assert np.abs(left[lo] - right[lo]).max() > 0.05  # the two materials differ in the view
    np.testing.assert_allclose(img[lo], left[lo], rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(img[hi], right[hi], rtol=1e-6, atol=1e-9)


def _normal_mapped_floor(tmp_path, toward, tilt_deg=20.0, mapped=True):
    """A diffuse floor whose normal map (one texel, stored (n + 1) / 2 with UsdUVTexture scale 2, bias -1) tilts the
    normal by ``tilt_deg`` toward +dP/ds, under a delta sun ``toward`` (unit)."""
    from pxr import Sdf, UsdGeom

    t = np.radians(tilt_deg)
    write_exr(tmp_path / "n.exr", ((np.array([[[np.sin(t), 0.0, np.cos(t)]]]) + 1) / 2).astype(np.float32))
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=60)
    quad = b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    pts = np.asarray(quad.GetPointsAttr().Get(), np.float64)
    b.distant("Sun", tuple(toward), 2.0, angle=0.0)
    st = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    UsdGeom.PrimvarsAPI(quad).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex).Set(st)
    if mapped:
        b.texture("FloorMat", {"normal": "rgb"}, "n.exr", wrap="repeat", space="raw", scale=(2, 2, 2, 1),
                  bias=(-1, -1, -1, 0))
    return load_scene(b.write(tmp_path / f"nmap_{mapped}_{np.round(toward, 3).tolist()}.usda")), pts


@pytest.mark.parametrize("side, expect_cos", [(1.0, 1.0), (-1.0, np.cos(np.radians(40.0)))])
def test_normal_map_turns_the_shading_normal_toward_dp_ds(tmp_path, side, expect_cos):
    """The map tilts the normal 20 deg toward +dP/ds (tangent space x). A sun tilted 20 deg the same way meets it
    head-on (cos 1); tilted the other way, at 40 deg. A diffuse floor shows kd / pi x E x that cosine x the
    bump-terminator term G = 2 / (1 + sqrt(1 + a2 tan^2 20)), a2 = tan^2 20 / 8 (the sun is 20 deg off the unmapped
    normal either way), where without the map both suns give cos 20 deg. Before, the normal input was ignored."""
    probe, pts = _normal_mapped_floor(tmp_path, (0.0, 1.0, 0.0), mapped=False)
    tangent = (pts[1] - pts[0]) / np.linalg.norm(pts[1] - pts[0])  # st's s grows along the floor's first edge
    t = np.radians(20.0)
    toward = np.cos(t) * np.array([0.0, 1.0, 0.0]) + side * np.sin(t) * tangent
    s_ = RenderSettings(spp=4, width=8, height=8, max_depth=1)
    img = render(_normal_mapped_floor(tmp_path, toward)[0], s_).image
    tan2 = np.tan(t) ** 2
    g = 2.0 / (1.0 + np.sqrt(1.0 + tan2 / 8.0 * tan2))
    np.testing.assert_allclose(img, 0.5 / np.pi * 2.0 * expect_cos * g, rtol=1e-5)
    plain = render(_normal_mapped_floor(tmp_path, toward, mapped=False)[0], s_).image
    np.testing.assert_allclose(plain, 0.5 / np.pi * 2.0 * np.cos(t), rtol=1e-5)
