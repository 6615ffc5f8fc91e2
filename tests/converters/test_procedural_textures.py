"""Mitsuba's checkerboard texture converted as an image of its values (spec/bake.md#materials).

Before 2026-12-07 a checkerboard reflectance was written as the mean of its two colours (a floor of 4 x 4 checks:
MSE / noise 35-43 at 32² / 64², 64 spp; 0.97 / 1.07 now), and a checkerboard roughness was taken for an absent
parameter (the conductor's default alpha 0.1 used, without a note). The texels are checked against Mitsuba's own
evaluation of the texture: ``eval`` for a colour, ``eval_1`` for a float (Mitsuba 3.9's checkerboard swaps its two
colours there, so the two differ).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")


def _surface_texture(stage, material: str, name: str):
    from pxr import UsdShade

    surface = UsdShade.Shader(stage.GetPrimAtPath(f"/World/Looks/{material}/PreviewSurface"))
    src = surface.GetInput(name)
    assert src and src.HasConnectedSource(), (material, name)
    tex = UsdShade.Shader(src.GetConnectedSource()[0].GetPrim())
    st = stage.GetPrimAtPath(f"/World/Looks/{material}/{name}_st_transform")
    return tex.GetInput("file").Get().resolvedPath, UsdShade.Shader(st).GetInput("scale").Get() if st else None


def test_checkerboards_become_images_of_mitsubas_values(tmp_path):
    from pxr import Usd

    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.usd_export import RASTERIZED_TEXELS, convert_scene
    from nasset_sdk.images import read_exr

    checker = ('<texture type="checkerboard" name="{n}"><rgb name="color0" value="{a}"/><rgb name="color1" '
               'value="{b}"/><transform name="to_uv"><scale x="4" y="2"/></transform></texture>')
    xml = tmp_path / "scene.xml"
    xml.write_text(
        '<scene version="3.0.0"><integrator type="path"/><sensor type="perspective"><film type="hdrfilm">'
        '<integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>'
        '<shape type="rectangle" id="floor"><bsdf type="diffuse" id="checked">'
        + checker.format(n="reflectance", a="0.1, 0.2, 0.3", b="0.8, 0.7, 0.6") + '</bsdf></shape>'
        '<shape type="rectangle" id="plate"><transform name="to_world"><translate x="3"/></transform>'
        '<bsdf type="roughconductor" id="metal"><string name="distribution" value="ggx"/>'
        + checker.format(n="alpha", a="0.04, 0.04, 0.04", b="0.36, 0.36, 0.36") + '</bsdf></shape>'
        '<emitter type="constant"/></scene>')
    res = convert_scene(xml, tmp_path / "scene.usda", check_usd=False)
    assert not any("procedural texture" in w for w in res.warnings), res.warnings
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))

    mi = load_mitsuba(None)
    tex = mi.load_dict({"type": "checkerboard", "color0": {"type": "rgb", "value": [0.1, 0.2, 0.3]},
                        "color1": {"type": "rgb", "value": [0.8, 0.7, 0.6]}})
    n = RASTERIZED_TEXELS
    g = (np.arange(n) + 0.5) / n
    v, u = np.meshgrid(g, g, indexing="ij")
    si = mi.SurfaceInteraction3f()
    si.uv = mi.Point2f(u.ravel().astype(np.float32), v.ravel().astype(np.float32))
    colour = np.stack([np.asarray(c) for c in tex.eval(si)], -1).reshape(n, n, 3)
    path, scale = _surface_texture(stage, "checked", "diffuseColor")
    np.testing.assert_allclose(read_exr(path)[..., :3], colour, atol=1e-6)
    assert tuple(scale) == (4.0, 2.0)  # the texture's to_uv, as for a bitmap

    alpha = mi.load_dict({"type": "checkerboard", "color0": {"type": "rgb", "value": [0.04] * 3},
                          "color1": {"type": "rgb", "value": [0.36] * 3}})
    float_value = np.asarray(alpha.eval_1(si)).reshape(n, n)
    path, _ = _surface_texture(stage, "metal", "roughness")
    np.testing.assert_allclose(read_exr(path)[..., 0], np.sqrt(float_value), atol=1e-6)  # roughness = sqrt(alpha)
    assert abs(float_value[0, 0] - 0.36) < 1e-6  # eval_1's colour, not eval's (0.04) at the first texel
