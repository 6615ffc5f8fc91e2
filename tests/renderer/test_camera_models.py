"""Camera models (spec/renderer.md#cameras): orthographic projection, the thin lens of ``fStop`` and
``focusDistance``, and the camera's exposure scale. Before, an orthographic camera was SCENE_UNSUPPORTED (the whole
scene refused) and fStop, focusDistance and exposure were ignored."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.testscenes import SceneBuilder
from nasset_sdk.errors import SceneError
from tests.stats import stat_seed

WHITE = {"diffuse": (0, 0, 0), "specular": (0, 0, 0), "emission": (1, 1, 1)}


def _ortho_scene(tmp_path, distance, *, offset=0.0):
    """A unit emitting square at the origin seen from +Z by an orthographic camera 4 units wide."""
    from pxr import UsdGeom

    b = SceneBuilder()
    cam = b.camera((0, 0, distance), (0, 0, 0), aperture=40.0)  # 40 tenths of a scene unit: 4 units
    cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
    if offset:
        cam.CreateHorizontalApertureOffsetAttr(offset)
    b.quad("Card", (0, 0, 0), 1.0, normal=(0, 0, 1), **WHITE)
    return load_scene(b.write(tmp_path / f"ortho{distance}.usda"))


def test_orthographic_camera_sees_sizes_independent_of_distance(tmp_path):
    """The unit square covers 16 of 64 columns and rows (4 units wide) at any distance; a perspective camera would
    shrink it 10x between distances 5 and 50."""
    images = [render(_ortho_scene(tmp_path, d), RenderSettings(spp=4, width=64, height=64, max_depth=1)).image[..., 0]
              for d in (5.0, 50.0)]
    for img in images:
        cols = np.flatnonzero(img[32] > 0.5)
        rows = np.flatnonzero(img[:, 32] > 0.5)
        assert cols.tolist() == list(range(24, 40)) and rows.tolist() == list(range(24, 40))
        assert img.mean() == pytest.approx(1 / 16, abs=1e-3)
    np.testing.assert_array_equal(images[0], images[1])


def test_orthographic_offset_moves_the_window_in_tenths_of_a_scene_unit(tmp_path):
    """horizontalApertureOffset 10 (1 scene unit) moves the window right: the square moves 16 columns left."""
    img = render(_ortho_scene(tmp_path, 5.0, offset=10.0), RenderSettings(spp=4, width=64, height=64, max_depth=1)).image
    assert np.flatnonzero(img[32, :, 0] > 0.5).tolist() == list(range(8, 24))


def _disk_fraction_beyond(s):
    """Fraction of the unit disk with x > s."""
    s = np.clip(s, -1.0, 1.0)
    return (np.arccos(s) - s * np.sqrt(1.0 - s * s)) / np.pi


def _lens_scene(tmp_path, depth, f_stop, focus=5.0):
    """An emitting half-plane x > 0 at ``depth`` in front of a 50 / 20 camera at the origin looking down -Z."""
    b = SceneBuilder()
    cam = b.camera((0, 0, 0), (0, 0, -1), focal=50.0, aperture=20.0)
    if f_stop:
        cam.CreateFStopAttr(f_stop)
        cam.CreateFocusDistanceAttr(focus)
    b.quad("HalfPlane", (100.0, 0, -depth), 200.0, normal=(0, 0, 1), **WHITE)
    return load_scene(b.write(tmp_path / f"lens{depth}_{f_stop}.usda"))


def test_thin_lens_blurs_an_edge_off_the_plane_of_focus_by_the_lens_disk(tmp_path):
    """Lens radius 0.1 x 50 / (2 x 10) = 0.25; focus 5. A ray through the pinhole ray's point x_f on the plane of focus
    from lens point l meets depth 10 at 2 x_f - l_x, so the pixel sees the half-plane with probability P(l_x < 2 x_f)
    = 1 - disk_fraction_beyond(2 x_f / 0.25), averaged over the pixel. At depth 5 the edge stays sharp."""
    w, spp = 64, 256
    scene = _lens_scene(tmp_path, 10.0, 10.0)
    assert scene.camera.lens_radius == pytest.approx(0.25)
    img = render(scene, RenderSettings(spp=spp, width=w, height=4, max_depth=1, seed=stat_seed(11))).image[..., 0]
    measured = img.mean(0)
    sub = (np.arange(w)[:, None] + (np.arange(256) + 0.5) / 256)  # columns x sub-pixel positions
    x_f = 5.0 * (2.0 * sub / w - 1.0) * 0.2  # tan(half field of view) = 20 / (2 x 50)
    expect = (1.0 - _disk_fraction_beyond(2.0 * x_f / 0.25)).mean(1)
    se = np.sqrt(np.maximum(expect * (1 - expect), 1e-4) / (spp * 4))
    assert np.all(np.abs(measured - expect) < 5 * se + 1e-3), np.c_[measured, expect][26:38]
    assert ((expect > 0.02) & (expect < 0.98)).sum() >= 6  # the blur spans several columns
    sharp = render(_lens_scene(tmp_path, 5.0, 10.0), RenderSettings(spp=64, width=w, height=4, max_depth=1)).image[..., 0]
    assert np.array_equal(sharp.mean(0), (np.arange(w) >= 32).astype(np.float32))  # in focus: the pinhole's step


def test_thin_lens_rays_leave_the_lens_disk_and_meet_at_the_point_in_focus(tmp_path):
    scene = _lens_scene(tmp_path, 10.0, 4.0, focus=3.0)
    cam = scene.camera
    rng = np.random.default_rng(stat_seed(12))
    n = 100_000
    px, py = np.full(n, 40.3), np.full(n, 7.9)
    o, d = cam.generate_rays(px, py, 64, 64, rng.random((n, 2)))
    r = 0.1 * 50.0 / (2 * 4.0)
    assert np.abs(o[:, 2]).max() == 0 and np.hypot(o[:, 0], o[:, 1]).max() <= r
    assert np.mean(o[:, 0] ** 2 + o[:, 1] ** 2) == pytest.approx(r * r / 2, rel=0.01)  # uniform on the disk
    t = -3.0 / d[:, 2]
    focus = o + t[:, None] * d
    _, d_pin = _lens_scene(tmp_path, 10.0, 0.0).camera.generate_rays(px[:1], py[:1], 64, 64)
    np.testing.assert_allclose(focus, np.broadcast_to(d_pin[0] * 3.0 / -d_pin[0, 2], focus.shape), atol=1e-9)


def test_exposure_scales_the_image_by_its_linear_scale(tmp_path):
    """exposure 1.5 and exposure:time 0.5 give 2^1.5 x 0.5 (UsdGeomCamera::ComputeLinearExposureScale); the same
    seed draws the same paths, so the image is that multiple of the unexposed one."""
    def scene(exposed):
        b = SceneBuilder()
        cam = b.camera((0, 1, 3), (0, 0, 0))
        if exposed:
            cam.CreateExposureAttr(1.5)
            cam.CreateExposureTimeAttr(0.5)
        b.quad("Floor", (0, 0, 0), 4.0, diffuse=(0.5, 0.5, 0.5))
        b.distant("Sun", (0.3, 1, 0.2), 2.0)
        return load_scene(b.write(tmp_path / f"exp{exposed}.usda"))

    s = RenderSettings(spp=4, width=16, height=16, max_depth=3)
    a, b = render(scene(False), s).image, render(scene(True), s).image
    assert a.mean() > 0
    np.testing.assert_allclose(b, a * (2 ** 1.5 * 0.5), rtol=1e-6)


def _camera_scene(tmp_path, **attrs):
    from pxr import Sdf

    b = SceneBuilder()
    cam = b.camera((0, 0, 5), (0, 0, 0))
    for name, value in attrs.items():
        name = name.replace("__", ":")
        attr = cam.GetPrim().GetAttribute(name)
        if attr:
            attr.Set(value)
        else:
            cam.GetPrim().CreateAttribute(name, Sdf.ValueTypeNames.Float).Set(value)
    b.quad("Card", (0, 0, 0), 1.0, normal=(0, 0, 1), **WHITE)
    return b.write(tmp_path / "c.usda")


@pytest.mark.parametrize("attrs, name", [
    ({"fStop": -2.0}, "fStop"),
    ({"fStop": 2.0, "focusDistance": float("nan")}, "focusDistance"),
    ({"exposure": float("inf")}, "exposure"),
    ({"exposure__time": -1.0}, "exposure"),
    ({"fStop": 1e-30, "focusDistance": 5.0}, "fStop"),  # a lens radius of 2.5e30: rays from beyond the world's bound
])
def test_invalid_lens_and_exposure_values_are_scene_errors(tmp_path, attrs, name):
    with pytest.raises(SceneError) as exc:
        load_scene(_camera_scene(tmp_path, **attrs))
    assert exc.value.code == "SCENE_INVALID" and name in str(exc.value)


def test_unknown_projection_is_unsupported_and_lens_without_focus_warns(tmp_path):
    from pxr import Usd

    path = _camera_scene(tmp_path, fStop=2.0)
    scene = load_scene(path)
    assert scene.camera.lens_radius == 0 and any("without a focusDistance" in w for w in scene.warnings)
    stage = Usd.Stage.Open(path)
    stage.GetPrimAtPath("/World/Camera").GetAttribute("projection").Set("fisheye")
    stage.GetRootLayer().Save()
    with pytest.raises(SceneError) as exc:
        load_scene(path)
    assert exc.value.code == "SCENE_UNSUPPORTED" and "projection" in str(exc.value)

