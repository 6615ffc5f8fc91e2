"""Render-level stress: extreme lights, degenerate cameras and scales; images finite, >= 0, and closed forms where known."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render, write_exr
from nasset_reference_renderer.testscenes import SceneBuilder, random_rna_asset

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")


@pytest.fixture(scope="module")
def rna_file(tmp_path_factory):
    return random_rna_asset(tmp_path_factory.mktemp("stress_render") / "rna.usdc", seed=2)


def _ok(img):
    assert np.isfinite(img).all(), "image holds NaN/Inf"
    assert (img >= 0).all(), "image holds negative radiance"


def _render(b, path, **kw):
    kw = {"width": 10, "height": 8, "spp": 2, "max_depth": 3, **kw}
    return render(load_scene(b.write(path)), RenderSettings(**kw)).image


def _mixed_scene(intensity, rna_file, *, scale=1.0, dome_texture=None, dome=0.0):
    s = scale
    b = SceneBuilder()
    b.camera((0, 1.2 * s, 3 * s), (0, 0.3 * s, 0), focal=30)
    b.quad("Floor", (0, 0, 0), 6.0 * s, diffuse=(0.6, 0.6, 0.6), specular=(0.04, 0.04, 0.04), roughness=0.3)
    b.sphere_mesh("Ball", (-0.7 * s, 0.4 * s, 0), 0.4 * s, subdivisions=1, diffuse=(0.3, 0.5, 0.7), specular=(0.2, 0.2, 0.2), roughness=0.05)
    m = np.eye(4) * s
    m[3] = (0.6 * s, 0.5 * s, 0, 1)
    b.asset("Obj", rna_file, m)
    b.sphere_light("Lamp", (1.0 * s, 2.0 * s, 1.0 * s), 0.2 * s, intensity)
    b.rect_light("Panel", (-1.0 * s, 2.0 * s, 0.5 * s), 0.5 * s, 0.5 * s, (0, -1, 0), intensity)
    b.distant("Sun", (0.3, 1.0, 0.2), intensity, angle=0.53)
    if dome or dome_texture is not None:
        b.dome("Sky", dome * intensity if dome else intensity, texture=dome_texture)
    return b


def test_intensity_linearity(tmp_path, rna_file):
    """Same seed: image(I) = I * image(1) for I = 1e6 and 1e-6 (sampling does not depend on the scale of the lights)."""
    imgs = {}
    for i in (1.0, 1e6, 1e-6):
        imgs[i] = _render(_mixed_scene(i, rna_file, dome=0.1), tmp_path / f"lin{i:g}.usda", max_depth=4, rr_depth=1)
        _ok(imgs[i])
    assert imgs[1.0].max() > 0
    for i in (1e6, 1e-6):
        np.testing.assert_allclose(imgs[i], i * imgs[1.0], rtol=2e-7, atol=1e-12 * i * imgs[1.0].max())  # light intensities are float32 attributes


def test_dome_hot_pixel(tmp_path):
    """A dark lat-long EXR with one 1e6 texel over a diffuse floor: finite, and the mean matches the closed form."""
    h, w, row, col, a, lhot = 8, 16, 2, 5, 0.5, 1e6
    tex = np.zeros((h, w, 3), np.float32)
    tex[row, col] = lhot
    exr = tmp_path / "hot.exr"
    write_exr(exr, tex)
    b = SceneBuilder()
    b.camera((0, 3, 0.001), (0, 0, 0), focal=200)  # looks straight down at the middle of the floor
    b.quad("Floor", (0, 0, 0), 40.0, diffuse=(a, a, a))
    b.dome("Sky", 1.0, texture=str(exr))
    res = render(load_scene(b.write(tmp_path / "hot.usda")), RenderSettings(width=8, height=8, spp=16, max_depth=1))
    img = res.image
    _ok(img)
    # texel (row, col) spans theta in [row, row + 1] pi / h from +Y, phi width 2 pi / w; its irradiance on an
    # upward floor is L dphi (sin^2 theta1 - sin^2 theta0) / 2, and the floor reflects a / pi of it
    t0, t1 = row * np.pi / h, (row + 1) * np.pi / h
    expect = a / np.pi * lhot * (2 * np.pi / w) * (np.sin(t1) ** 2 - np.sin(t0) ** 2) / 2
    mean = img.mean((0, 1))
    se = np.sqrt(res.variance.sum((0, 1))) / img[..., 0].size
    assert np.all(np.abs(mean - expect) < 5 * se + 1e-3 * expect), (mean, expect, se)


def test_asset_behind_camera(tmp_path, rna_file):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 6), focal=35)  # looks away from the asset at the origin
    b.asset("Obj", rna_file)
    b.distant("Sun", (0.3, 1.0, 0.5), 1e6)
    img = _render(b, tmp_path / "behind.usda")
    _ok(img)
    assert (img == 0).all()  # nothing visible; a delta distant light is never seen directly


@pytest.mark.parametrize("depth", [0, 1, 4])
def test_camera_inside_asset(tmp_path, rna_file, depth):
    b = SceneBuilder()
    b.camera((0.05, 0.02, 0.0), (1, 0.2, 0.3), focal=18)
    b.asset("Obj", rna_file)
    b.sphere_light("Lamp", (0.1, 0.1, 0.1), 0.05, 1e6)  # also inside the asset
    b.dome("Sky", 1.0)
    img = _render(b, tmp_path / f"inside{depth}.usda", max_depth=depth)
    _ok(img)


@pytest.mark.parametrize("scale", [1e-4, 1e4])
def test_scene_scale(tmp_path, rna_file, scale):
    """Scene (asset, meshes, camera, lights) scaled by 1e-4 / 1e4 with radiance-preserving lights: the same image."""
    kw = dict(width=12, height=10, spp=2, max_depth=1)
    ref = _render(_mixed_scene(1.0, rna_file), tmp_path / "ref.usda", **kw)
    img = _render(_mixed_scene(1.0, rna_file, scale=scale), tmp_path / f"s{scale:g}.usda", **kw)
    _ok(ref)
    _ok(img)
    assert ref.max() > 0
    # direct lighting only: the same random numbers give the same paths (float32 geometry: small differences)
    np.testing.assert_allclose(img, ref, rtol=1e-3, atol=1e-3 * ref.max())


def test_grazing_plane(tmp_path):
    """Camera almost in the plane of a large floor lit by a distant light: finite, >= 0, and lit pixels at the closed form."""
    a, E, theta = 0.6, 1e6, np.radians(89.9)
    b = SceneBuilder()
    b.camera((0, 1e-4, 0), (-1, 0, 0), focal=20)  # rays skim the floor at up to a few degrees
    b.quad("Floor", (0, 0, 0), 1e4, diffuse=(a, a, a))
    b.distant("Sun", (np.sin(theta), np.cos(theta), 0), E)
    img = _render(b, tmp_path / "grazing.usda", width=16, height=16, spp=2, max_depth=1)
    _ok(img)
    lit = img[..., 0] > 0
    assert lit.any()
    np.testing.assert_allclose(img[lit], a * E * np.cos(theta) / np.pi, rtol=1e-3)


#: in view, behind the other objects (at (0, 1.5, -1) the ball was outside the 10 x 8 frame: nothing was compared)
GLOW_AT = (0.0, 0.9, -1.0)


@pytest.mark.parametrize("depth", [0, 1])
def test_max_depth_zero_and_one(tmp_path, rna_file, depth):
    b = _mixed_scene(1e6, rna_file, dome=1e-6)
    b.sphere_mesh("Glow", GLOW_AT, 0.35, subdivisions=1, emission=(5.0, 5.0, 5.0))
    img = _render(b, tmp_path / f"d{depth}.usda", max_depth=depth)
    _ok(img)
    if depth == 0:
        # camera rays only: emitters seen directly (lamp, panel, glowing ball, dome); nothing reflected
        b0 = SceneBuilder()
        b0.camera((0, 1.2, 3), (0, 0.3, 0), focal=30)
        b0.sphere_mesh("Glow", GLOW_AT, 0.35, subdivisions=1, emission=(5.0, 5.0, 5.0))
        glow = _render(b0, tmp_path / "glow.usda", max_depth=0)
        seen = glow[..., 0] == 5.0  # pixels whose samples all hit the glowing ball
        assert seen.sum() >= 3, "the glowing ball covers no whole pixel: the comparison below would be empty"
        np.testing.assert_allclose(img[seen], 5.0, rtol=1e-6)
