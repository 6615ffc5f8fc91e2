"""Opacity as presence (spec/renderer.md#cutouts): UsdPreviewSurface ``opacity`` with ``opacityThreshold`` > 0 cuts a
surface out where the opacity is below the threshold; with threshold 0 the surface is there with probability
``opacity``. Camera, continuation and shadow rays all pass where it is absent. Before, opacity was ignored (every
surface opaque, warned)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from tests.stats import stat_seed


def _set(b, mat, **inputs):
    from pxr import Sdf, UsdShade

    surf = UsdShade.Shader(b.stage.GetPrimAtPath(f"/World/Looks/{mat}/PreviewSurface"))
    for name, value in inputs.items():
        surf.CreateInput(name, Sdf.ValueTypeNames.Float).Set(float(value))
    return surf


def _cards(tmp_path, n_cards, name="cards", **opacity):
    """``n_cards`` emitting cards (radiance 1) stacked in front of an emitting wall (radiance 3), seen head-on."""
    b = SceneBuilder()
    b.camera((0, 0, 5), (0, 0, 0), focal=50.0, aperture=10.0)  # sees a 1-unit square at the origin
    b.quad("Wall", (0, 0, -2), 10.0, normal=(0, 0, 1), diffuse=(0, 0, 0), specular=(0, 0, 0), emission=(3, 3, 3))
    for k in range(n_cards):
        b.quad(f"Card{k}", (0, 0, 0.2 * k), 4.0, normal=(0, 0, 1), diffuse=(0, 0, 0), specular=(0, 0, 0),
               emission=(1, 1, 1))
        _set(b, f"Card{k}Mat", **opacity)
    return load_scene(b.write(tmp_path / f"{name}.usda"))


def test_fractional_opacity_is_the_probability_of_the_surface_being_there(tmp_path):
    """Three stacked cards of opacity 0.5 before a wall of radiance 3: a camera ray meets the first card with
    probability 0.5 (radiance 1), ..., the wall with probability 0.125: 0.875 x 1 + 0.125 x 3 = 1.25."""
    scene = _cards(tmp_path, 3, opacity=0.5)
    img = render(scene, RenderSettings(spp=64, width=16, height=16, max_depth=1, seed=stat_seed(21))).image
    n = img[..., 0].size * 64
    se = np.sqrt(0.875 * 0.125 * 4.0 / n)  # the sample's values 1 and 3
    assert abs(img[..., 0].mean() - 1.25) < 5 * se, (img[..., 0].mean(), se)


@pytest.mark.parametrize("opacity, expect", [(0.4, 3.0), (0.6, 1.0)])
def test_threshold_cuts_out_below_and_keeps_above(tmp_path, opacity, expect):
    """opacityThreshold 0.5: opacity 0.4 removes the card (the wall shows), 0.6 keeps it whole."""
    scene = _cards(tmp_path, 1, name=f"t{opacity}", opacity=opacity, opacityThreshold=0.5)
    img = render(scene, RenderSettings(spp=4, width=8, height=8, max_depth=1)).image
    np.testing.assert_allclose(img[..., 0], expect, rtol=1e-5)


def _alpha_card(tmp_path, alpha_output="a"):
    """A card whose opacity is a 2 x 1 RGBA PNG's alpha (left texel 0, right 255; colour 255 everywhere) through
    ``alpha_output``, nearest-texel sized: its left half is cut out (threshold 0.5) before the wall."""
    from PIL import Image

    Image.fromarray(np.array([[[255, 255, 255, 0], [255, 255, 255, 255]]], np.uint8), "RGBA").save(tmp_path / "a.png")
    b = SceneBuilder()
    b.camera((0, 0, 5), (0, 0, 0), focal=50.0, aperture=10.0)
    b.quad("Wall", (0, 0, -2), 10.0, normal=(0, 0, 1), diffuse=(0, 0, 0), specular=(0, 0, 0), emission=(3, 3, 3))
    card = b.quad("Card", (0, 0, 0), 1.0, normal=(0, 0, 1), diffuse=(0, 0, 0), specular=(0, 0, 0), emission=(1, 1, 1))
    pts = np.asarray(card.GetPointsAttr().Get())
    _set(b, "CardMat", opacityThreshold=0.5)
    b.texture("CardMat", {"opacity": alpha_output}, "a.png", st=pts[:, :2] + 0.5, mesh=card)  # st 0 .. 1 across the card
    return load_scene(b.write(tmp_path / f"alpha_{alpha_output}.usda"))


def test_texture_alpha_cuts_out_where_it_is_below_the_threshold(tmp_path):
    """Bilinear alpha runs 0 -> 1 across the card's middle (texel centres at s = 0.25, 0.75): below 0.5 for
    s < 0.5, so the left half of the card shows the wall and the right half the card."""
    img = render(_alpha_card(tmp_path), RenderSettings(spp=16, width=16, height=16, max_depth=1)).image[..., 0]
    np.testing.assert_allclose(img[:, :8], 3.0, rtol=1e-5)  # the card spans exactly the view (1 unit at distance 5)
    np.testing.assert_allclose(img[:, 8:], 1.0, rtol=1e-5)
    rgb = render(_alpha_card(tmp_path, "r"), RenderSettings(spp=4, width=16, height=16, max_depth=1)).image[..., 0]
    np.testing.assert_allclose(rgb, 1.0, rtol=1e-5)  # its red channel is 1 everywhere: opaque


def test_shadows_pass_through_in_proportion_to_the_opacity(tmp_path):
    """A floor under a sun straight above, shaded by a card of opacity 0.25 (threshold 0) between them: the floor's
    radiance is 0.75 of the unshadowed kd / pi x E, by shadow rays that pass with probability 0.75."""
    def floor(with_card):
        b = SceneBuilder()
        b.camera((0, 0.3, 0.001), (0, 0, 0), focal=200.0)  # under the card
        b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
        if with_card:
            b.quad("Card", (0, 0.5, 0), 4.0, normal=(0, -1, 0), diffuse=(0, 0, 0), specular=(0, 0, 0))
            _set(b, "CardMat", opacity=0.25)
        b.distant("Sun", (0.0, 1.0, 0.0), 2.0)
        return load_scene(b.write(tmp_path / f"floor{with_card}.usda"))

    expect = 0.5 / np.pi * 2.0
    r = render(floor(True), RenderSettings(spp=256, width=4, height=4, max_depth=1, seed=stat_seed(22)))
    free = render(floor(False), RenderSettings(spp=4, width=4, height=4, max_depth=1)).image
    np.testing.assert_allclose(free, expect, rtol=1e-5)  # the premise: the floor alone is the closed form
    se = np.sqrt(0.75 * 0.25 / (16 * 256)) * expect
    assert abs(r.image.mean() - 0.75 * expect) < 5 * se, (r.image.mean(), 0.75 * expect, se)


def test_readers_keep_alpha_on_request(tmp_path):
    """PNG (RGBA, palette with transparency, RGB) and OpenEXR (with and without A): alpha as a fourth channel, 1 where
    the file has none; without the request the images stay RGB."""
    import OpenEXR
    from PIL import Image

    from nasset_sdk.images import read_exr, read_png_jpeg

    rgba = np.array([[[10, 20, 30, 0], [40, 50, 60, 255]], [[70, 80, 90, 51], [1, 2, 3, 102]]], np.uint8)
    Image.fromarray(rgba, "RGBA").save(tmp_path / "a.png")
    img, bits = read_png_jpeg(tmp_path / "a.png", alpha=True)
    assert bits == 8 and img.shape == (2, 2, 4)
    np.testing.assert_allclose(img * 255, rgba, atol=1e-4)  # straight alpha: colours kept where alpha is 0
    assert read_png_jpeg(tmp_path / "a.png")[0].shape == (2, 2, 3)
    pal = Image.fromarray(np.array([[0, 1]], np.uint8), "P")
    pal.putpalette([255, 0, 0, 0, 255, 0])
    pal.save(tmp_path / "p.png", transparency=0)
    np.testing.assert_allclose(read_png_jpeg(tmp_path / "p.png", alpha=True)[0][0, :, 3], [0.0, 1.0])
    Image.fromarray(rgba[..., :3], "RGB").save(tmp_path / "rgb.png")
    np.testing.assert_array_equal(read_png_jpeg(tmp_path / "rgb.png", alpha=True)[0][..., 3], 1.0)
    for chans, expect in (("RGBA", [[0.25, 0.5], [0.75, 1.0]]), ("RGB", [[1.0, 1.0], [1.0, 1.0]])):
        px = {k: np.full((2, 2), 0.5, np.float32) for k in "RGB"}
        if chans == "RGBA":
            px["A"] = np.array(expect, np.float32)
        with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, px) as f:
            f.write(str(tmp_path / f"{chans}.exr"))
        out = read_exr(tmp_path / f"{chans}.exr", alpha=True)
        assert out.shape == (2, 2, 4)
        np.testing.assert_allclose(out[..., 3], expect)
        assert read_exr(tmp_path / f"{chans}.exr").shape == (2, 2, 3)
