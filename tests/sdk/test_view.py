"""Asset preview (nasset_sdk.view, ``nasset view``): shading, self-shadowing, triplane images, PNG output."""

from __future__ import annotations

import struct
import sys
import zlib

import numpy as np
import pytest

from nasset_sdk import view
from nasset_sdk.asset import Asset
from nasset_sdk.cli import main
from nasset_sdk.errors import UsageError
from nasset_sdk.examples import example_builder


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """Tiny example assets of every kind (and the rna fiber variant), written once."""
    d = tmp_path_factory.mktemp("view")
    out = {}
    for key, kind, variant in (("rna", "rna", "surface"), ("fiber", "rna", "fiber"), ("neupress", "neupress", "surface"),
                               ("8dna", "8dna", "surface")):
        path = d / f"{key}.usdc"
        example_builder(kind, variant=variant, size="tiny", seed=3).write(path)
        out[key] = path
    return out


def read_png(path) -> np.ndarray:
    """Decode the 8-bit RGB PNGs view.write_png writes (filter type 0 on every row) to [H, W, 3] uint8."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, idat, w, h = 8, b"", 0, 0
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        if tag == b"IHDR":
            w, h, depth, ctype = struct.unpack(">IIBB", body[:10])
            assert (depth, ctype) == (8, 2)
        elif tag == b"IDAT":
            idat += body
        pos += 12 + n
    rows = np.frombuffer(zlib.decompress(idat), np.uint8).reshape(h, 1 + 3 * w)
    assert (rows[:, 0] == 0).all()
    return rows[:, 1:].reshape(h, w, 3)


@pytest.mark.parametrize("key", ["rna", "fiber", "neupress", "8dna"])
@pytest.mark.parametrize("fallback", [False, True])
def test_shade_vertices_finite_nonnegative(assets, key, fallback):
    asset = Asset.open(assets[key])
    rgb = view.shade_vertices(asset, (0.3, 1.0, 0.2), (0.0, 0.2, 1.0), fallback=fallback)
    assert rgb.shape == (len(asset.geometry().points), 3)
    assert np.isfinite(rgb).all() and (rgb >= 0).all()
    assert rgb.max() > 0


def test_light_from_behind_convex_mesh_picks_shadowed_branch(assets):
    asset = Asset.open(assets["rna"])
    geo = asset.geometry()  # an icosphere: convex
    n = view.vertex_normals(geo)
    view_dir = np.array([0.0, 0.0, 1.0])
    light = -view_dir  # behind the sphere as seen from the camera
    shadowed = view.self_shadow_vertices(geo, light)
    cos = n @ light
    assert shadowed[cos < -0.2].all() and not shadowed[cos > 0.2].any()
    ev = asset.evaluator()
    x = np.asarray(geo.points, np.float32)
    wo = np.broadcast_to(view_dir, x.shape)
    wi = np.broadcast_to(light, x.shape)
    t_u, t_s = ev.evaluate(x, n.astype(np.float32), wo.astype(np.float32), wi.astype(np.float32))
    rgb = view.shade_vertices(asset, light, view_dir, evaluator=ev)
    facing_camera = (n @ view_dir) > 0.2  # the vertices the camera sees are all on the unlit side
    assert shadowed[facing_camera].all()
    np.testing.assert_allclose(rgb[facing_camera], t_s[facing_camera] * view.IRRADIANCE, rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(rgb[~shadowed], t_u[~shadowed] * view.IRRADIANCE, rtol=1e-5, atol=1e-6)
    # the fallback Lambert term is zero wherever the asset blocks the light
    fb = view.shade_vertices(asset, light, view_dir, fallback=True)
    assert (fb[shadowed] == 0).all()


def test_fiber_self_shadow_ignores_its_own_segments(assets):
    asset = Asset.open(assets["fiber"])
    geo = asset.geometry()
    # light straight up along the (mostly vertical) fibers: their own tubes must not count as occluders
    shadowed = view.self_shadow_vertices(geo, (1.0, 0.0, 0.0))
    assert shadowed.shape == (len(geo.points),)
    pts, faces, owner = view.tube_mesh(geo)
    assert faces.max() < len(pts) and owner.shape == (len(faces), 2)
    # two straight parallel fibres along z, B at x = 0.3 (width 0.05): a straight fibre never shadows itself, at any
    # light direction (its own tube, around every vertex, is skipped); light towards +x: B shadows A's inner vertices
    # (the end vertices graze B's tube ends), A never shadows B; towards -x the other way round
    from nasset_sdk.geometry import CurvesGeometry

    z = np.linspace(-0.5, 0.5, 6)
    two = CurvesGeometry(np.concatenate([np.stack([0 * z, 0 * z, z], 1), np.stack([0 * z + 0.3, 0 * z, z], 1)]),
                         np.array([6, 6]), np.full(12, 0.05))
    a, b = np.arange(12) < 6, np.arange(12) >= 6
    inner = np.isin(np.arange(12) % 6, [1, 2, 3, 4])
    for light in ((0, 1.0, 0), (0, 0.6, 0.8), (0, 0, 1.0)):
        assert not view.self_shadow_vertices(two, light).any(), light
    for light, front, back in (((1.0, 0, 0), b, a), ((-1.0, 0, 0), a, b)):
        shadowed = view.self_shadow_vertices(two, light)
        assert shadowed[back & inner].all() and not shadowed[front].any(), (light, shadowed)


def test_tube_mesh_and_tangents_curve_by_curve():
    """The tube mesh and tangents, built for all curves at once, against a construction curve by curve: np.gradient
    along each curve, two triangles per side between the rings of a segment's two points, owners the two points."""
    from nasset_sdk.geometry import CurvesGeometry

    rng = np.random.default_rng(4)
    counts = np.array([2, 5, 3, 2, 7, 4])
    n = counts.sum()
    geo = CurvesGeometry(rng.normal(size=(n, 3)), counts, rng.uniform(0.01, 0.05, n))
    p = np.asarray(geo.points, np.float64)
    want_t, want_faces, want_owner, start = [], [], [], 0
    k = np.arange(view.TUBE_SIDES)
    for c in counts:
        want_t.append(np.gradient(p[start:start + c], axis=0))
        for s in range(start, start + c - 1):
            i0, i1 = s * view.TUBE_SIDES + k, (s + 1) * view.TUBE_SIDES + (k + 1) % view.TUBE_SIDES
            j0, j1 = s * view.TUBE_SIDES + (k + 1) % view.TUBE_SIDES, (s + 1) * view.TUBE_SIDES + k
            want_faces += [np.stack([i0, j0, i1], 1), np.stack([i0, i1, j1], 1)]
            want_owner += [[s, s + 1]] * (2 * view.TUBE_SIDES)
        start += c
    want_t = np.concatenate(want_t)
    np.testing.assert_allclose(view.curve_tangents(geo), want_t / np.linalg.norm(want_t, axis=1, keepdims=True),
                               rtol=1e-12, atol=1e-15)
    pts, faces, owner = view.tube_mesh(geo)
    assert pts.shape == (n * view.TUBE_SIDES, 3)
    np.testing.assert_array_equal(faces, np.concatenate(want_faces))
    np.testing.assert_array_equal(owner, np.array(want_owner))
    ring = pts.reshape(n, view.TUBE_SIDES, 3) - p[:, None]  # each ring: the point's half width from it, across t
    radius = np.broadcast_to(0.5 * np.asarray(geo.widths, np.float64)[:, None], ring.shape[:2])
    np.testing.assert_allclose(np.linalg.norm(ring, axis=2), radius, rtol=1e-9)
    np.testing.assert_allclose((ring * view.curve_tangents(geo)[:, None]).sum(2), 0.0, atol=1e-12)


def test_triplane_channel_image_shape(assets):
    asset = Asset.open(assets["rna"])
    planes = np.asarray(asset.tensor("core", "triplane"), np.float32)
    _, r, _, c = planes.shape
    ch = view.triplane_channel(asset, c - 1)
    assert ch.shape == (3, r, r)
    np.testing.assert_array_equal(ch, planes[..., c - 1])
    img = view.channel_image(ch, min_size=64, gap=4)
    scale = -(-64 // r)
    assert img.shape == (r * scale, 3 * r * scale + 2 * 4, 3) and img.dtype == np.uint8
    # v grows upwards: the top-left texel of the image is plane XY's last row, first column
    lo, hi = ch.min(), ch.max()
    np.testing.assert_array_equal(img[0, 0], view.colormap(ch[0, -1, 0], lo, hi))
    with pytest.raises(UsageError):
        view.triplane_channel(asset, c)
    with pytest.raises(UsageError):
        view.triplane_channel(Asset.open(assets["neupress"]), 0)


def test_tonemap():
    x = np.array([0.0, 0.0031308, 0.5, 1.0, 4.0, np.nan])
    y = view.tonemap(x)
    assert y.tolist() == [0, 10, 188, 255, 255, 0]
    assert view.tonemap(0.25, exposure=1.0) == view.tonemap(0.5)
    for bad in (float("nan"), float("inf"), 65.0):  # NaN made every byte undefined; refused before any pixel
        with pytest.raises(UsageError, match="exposure"):
            view.tonemap(x, exposure=bad)


def test_per_pixel_png_without_pyvista(assets, tmp_path):
    out = tmp_path / "pp.png"
    assert main(["view", str(assets["rna"]), "--per-pixel", "--size", "64", "48", "--png", str(out)]) == 0
    img = read_png(out)
    assert img.shape == (48, 64, 3)
    bg = np.round(np.asarray(view.BACKGROUND) * 255)
    assert (img[24, 32] != bg).any() and (img[0, 0] == bg).all()  # the sphere in the middle, background at the corner
    assert main(["view", str(assets["fiber"]), "--per-pixel", "--png", str(out)]) == 2


def test_channel_png(assets, tmp_path):
    out = tmp_path / "ch.png"
    assert main(["view", str(assets["8dna"]), "--channel", "1", "--png", str(out)]) == 0
    img = read_png(out)
    assert img.shape[2] == 3 and img.shape[1] > 3 * img.shape[0]


def test_missing_pyvista_is_a_usage_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyvista", None)
    with pytest.raises(UsageError, match="pyvista"):
        view._pyvista()


@pytest.mark.parametrize("key", ["rna", "fiber"])
def test_offscreen_png_per_vertex(assets, tmp_path, key):
    try:
        import pyvista  # noqa: F401
    except ImportError:
        pytest.skip("pyvista is not installed (install the 'view' extra)")
    out = tmp_path / f"{key}.png"
    assert main(["view", str(assets[key]), "--size", "96", "72", "--png", str(out)]) == 0
    img = read_png(out)
    assert img.shape == (72, 96, 3)
    bg = np.round(np.asarray(view.BACKGROUND) * 255)
    drawn = (np.abs(img.astype(int) - bg).max(-1) > 2)
    assert drawn.any() and not drawn.all()
    if key == "rna":  # the rasterised mesh covers the same pixels as the ray-cast one (same camera)
        _, mask = view.shade_pixels(Asset.open(assets[key]), view.DEFAULT_LIGHT, view.DEFAULT_VIEW, (96, 72))
        iou = (drawn & mask).sum() / (drawn | mask).sum()
        assert iou > 0.9
