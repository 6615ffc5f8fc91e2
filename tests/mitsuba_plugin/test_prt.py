"""PRT mode of the Mitsuba JIT plugin (``nasset_path`` with ``prt``, ``--prt`` of the render command;
spec/renderer.md#neupress, PRT mode): per-lane PRT shading against the SDK evaluator, the dome's SH projection
per instance against an independent quadrature of the plugin's own dome, an asset pixel against the exact
integral, a whole render against the reference renderer's ``--prt`` render within noise, and usage errors."""

from __future__ import annotations

import math

import drjit as dr
import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin import prt as prt_mode  # noqa: E402
from nasset_mitsuba_plugin.neupress import NeupressJit  # noqa: E402
from nasset_mitsuba_plugin.plugins import _instance_tables, register  # noqa: E402
from nasset_mitsuba_plugin.render import load_scene, main, render  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.testscenes import SceneBuilder  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.errors import UsageError  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from nasset_sdk.kinds.encodings import sh9  # noqa: E402
from tests.mitsuba_plugin.test_neupress import _np3, _vec  # noqa: E402
from tests.renderer.render_stats import assert_renders_agree, render_finite  # noqa: E402
from tests.renderer.test_render_neupress import _gradient_dome, _wi_only_asset  # noqa: E402

Z_MEAN = 4.5  # |difference of image means| / its standard error, per channel
Z_PIXEL, PIXEL_FRACTION = 3.5, 0.05  # at most 5 % of pixels may differ by more than 3.5 sigma
CHI2_PIXEL = 1.6  # mean over pixels of (a - b)^2 / (var_a + var_b): ~1.1 for two correct renders (see the test)


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    register(mi)
    return mi


def _rotation(axis, degrees) -> np.ndarray:
    """3x3 rotation (row-vector convention: v @ R) by ``degrees`` about ``axis`` (Rodrigues)."""
    k = np.asarray(axis, np.float64) / np.linalg.norm(axis)
    a = math.radians(degrees)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return (np.eye(3) + math.sin(a) * kx + (1 - math.cos(a)) * kx @ kx).T


def _matrix(m3, t=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 row-vector (USD) matrix of linear part m3 [3, 3] and translation t."""
    m = np.eye(4)
    m[:3, :3], m[3, :3] = m3, t
    return m


def _scene(tmp_path, assets, *, dome_tex=None, dome_rot=None, floor=False, sun=False, dome=True, name="s.usda"):
    """Camera looking at the origin; ``assets`` [(file, 4x4 row-vector matrix or None)]; a dome (optionally
    textured and rotated), a floor and a sun on request."""
    from pxr import Gf, UsdGeom

    b = SceneBuilder()
    b.camera((0, 0.4, 3.0), (0, 0, 0), focal=55)
    if dome:
        b.dome("Dome", 0.6, texture=dome_tex, color=(1.0, 0.8, 0.6))
        if dome_rot is not None:
            UsdGeom.Xformable(b.stage.GetPrimAtPath("/World/Dome")).AddTransformOp().Set(
                Gf.Matrix4d(*_matrix(dome_rot).ravel().tolist()))
    else:
        b.distant("Sun", (0.3, 1.0, 0.2), 1.5)
    if floor:
        b.quad("Floor", (0, -0.6, 0), 6.0, diffuse=(0.5, 0.5, 0.5))
    if sun and dome:
        b.distant("Sun", (0.3, 1.0, -0.4), 1.5)
    for j, (file, m) in enumerate(assets):
        b.asset(f"Obj{j}", file, m)
    return b.write(tmp_path / name)


def test_prt_radiance_with_per_lane_lighting_matches_sdk(mi, tmp_path, rng):
    """PRT shading with lighting coefficients that differ per lane (27 Floats, b[k, c] at 3 k + c: the
    integrator's per-instance SH) equals the SDK's prt_radiance with each lane's b, on random vertices,
    normals and directions. Tolerance 1e-4 rel + 1e-6 abs (float32 sums against float64)."""
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=int(rng.integers(1 << 30))).write(path)
    sdk = Asset.open(path, load="all").evaluator()
    jit = NeupressJit(mi, str(path))
    n, groups = 3000, 4
    v = rng.integers(0, sdk.prt_coefficients().shape[0], n)
    nrm, wo = (rng.normal(size=(n, 3)) for _ in range(2))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    b = rng.normal(size=(groups, 9, 3))
    g = rng.integers(0, groups, n)
    ref = np.zeros((n, 3))
    for j in range(groups):
        m = g == j
        ref[m] = sdk.prt_radiance(b[j], v[m], nrm[m], wo[m])
    lanes = b[g].reshape(n, 27)
    out = _np3(jit.prt_radiance([mi.Float(lanes[:, i].astype(np.float32)) for i in range(27)],
                                mi.UInt32(v.astype(np.uint32)), _vec(mi, nrm), _vec(mi, wo)))
    assert np.abs(ref).max() > 0.1
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-6)
    with pytest.raises(UsageError):
        jit.prt_radiance([mi.Float(0.0)] * 26, mi.UInt32(0), _vec(mi, nrm[:1]), _vec(mi, wo[:1]))


def test_dome_sh_projection_per_instance(mi, tmp_path, rng):
    """b_k of each instance (the plugin's tables) = sum over a fine equal-area grid of world directions d of
    L(d) Y_k(normalize(d M3^-1)) d omega, with L the plugin dome's own radiance (Dr.Jit emitter, rotated,
    textured) and M3 the instance's linear part (rotated and non-uniformly scaled; a second instance is
    the identity). The grid (512 x 1024 cells) cuts texel edges: tolerance 4e-3 of max |b| (measured ~1e-3)."""
    asset = example_builder("neupress", size="tiny", seed=3).write(tmp_path / "np.usdc")
    tex = _gradient_dome(tmp_path / "dome.exr", hot=3.0)
    m3 = _rotation((1, 2, 0.5), 40) @ np.diag([1.3, 0.6, 1.0])
    r_dome = _rotation((0.2, 1, 0.3), 70)
    path = _scene(tmp_path, [(asset, _matrix(m3, (0.4, 0, 0))), (asset, _matrix(np.eye(3), (-0.4, 0, 0)))],
                  dome_tex=tex, dome_rot=r_dome)
    scene = load_scene(path, 8, 8, mi=mi)
    assets, _, tab = _instance_tables(mi, scene)
    tables = prt_mode.tables(mi, scene, assets, tab)
    got = np.asarray(tables.light.numpy(), np.float64).reshape(-1, 9, 3)
    # instance order is Mitsuba's shape order: tell the two apart by their world-to-object maps
    inv = np.asarray(tab["inv"].numpy(), np.float64).reshape(-1, 3, 4)[:, :, :3]
    which_m3 = [m3 if np.abs(m - np.eye(3)).max() > 0.1 else np.eye(3) for m in inv]
    assert len(which_m3) == 2 and np.abs(which_m3[0] - which_m3[1]).max() > 0.1
    nz, nphi = 512, 1024
    z = 1 - (np.arange(nz) + 0.5) / nz * 2
    phi = (np.arange(nphi) + 0.5) / nphi * 2 * np.pi
    zz, pp = np.meshgrid(z, phi, indexing="ij")
    r = np.sqrt(1 - zz ** 2)
    d = np.stack([r * np.cos(pp), r * np.sin(pp), zz], -1).reshape(-1, 3)
    si = dr.zeros(mi.SurfaceInteraction3f, len(d))
    si.wi = -_vec(mi, d)
    (dome,) = [e for e in scene.emitters() if type(e).__name__ == "DomeLight"]
    le = _np3(dome.eval(si))
    assert np.ptp(le[:, 0]) > 1.0  # the dome varies
    for i, m in enumerate(which_m3):
        d_obj = d @ np.linalg.inv(m)
        d_obj /= np.linalg.norm(d_obj, axis=1, keepdims=True)
        want = (sh9(d_obj)[:, :, None] * le[:, None, :]).sum(0) * (4 * np.pi / len(d))
        np.testing.assert_allclose(got[i], want, atol=4e-3 * np.abs(want).max())
    assert np.abs(got[0] - got[1]).max() > 0.1 * np.abs(got[1]).max()  # the instance transform matters


def test_prt_pixel_is_the_exact_integral(mi, tmp_path):
    """An asset whose S depends on w_i only, with PRT coefficients a_k = integral S Y_k by quadrature (so
    vertices and w_o bins all hold the same a), under a gradient dome L = c0 + c1 cos(theta) (SH degree 1:
    exact in SH2 but for the dome's texel rows), instance rotated: an asset pixel shows
    integral S(w_obj) L(w_world) dw within 1 % (the texel quantisation), and is constant over the asset."""
    asset, S, dirs, dw = _wi_only_asset(tmp_path)
    c0, c1, rows = 1.0, 0.8, 64
    tex = _gradient_dome(tmp_path / "grad.exr", c0, c1, rows=rows)
    rot = _rotation((1, 0, 1), 60)
    path = _scene(tmp_path, [(asset, _matrix(rot))], dome_tex=tex, name="prt.usda")
    img = render(path, 4, width=16, height=16, seed=1, prt=True, max_depth=1)
    d_world = dirs @ rot  # the grid is in object space
    theta = np.arccos(np.clip(d_world[:, 1], -1, 1))
    row = np.minimum((theta / np.pi * rows).astype(int), rows - 1)
    lum = 0.6 * (c0 + c1 * np.cos((row + 0.5) / rows * np.pi))[:, None] * np.array([1.0, 0.8, 0.6])
    exact = (S * lum).sum(0) * dw
    np.testing.assert_allclose(img[8, 8], exact, rtol=0.01)
    assert np.ptp(img[6:10, 6:10], axis=(0, 1)).max() < 1e-3 * img[8, 8].max()


class _Image:
    """A render as the film statistics of tests.renderer.render_stats use it: image and variance of the mean."""

    def __init__(self, image, variance) -> None:
        self.image, self.variance = image, variance


def test_prt_render_matches_reference_renderer(mi, tmp_path):
    """A neupress instance (rotated, non-uniformly scaled) and an rna instance (path mode: PRT concerns neupress)
    on a diffuse floor under a rotated textured dome (with a bright patch) and a sun, PRT mode, 24 x 24,
    max_depth 3: the plugin (16 renders of 16 spp, variance of the mean from their spread) against the
    reference renderer's --prt render (64 spp, its film variance; per-pixel noise ~16 % of the mean, the
    image mean's standard error ~1 %). Per-channel image means within 4.5 standard errors (measured |z|
    0.0-2.9 over six seed sets; at 8x the samples |z| <= 1.5 at standard errors of 0.2-0.4 %); at most 5 %
    of pixels beyond 3.5 sigma (measured 0-0.3 %); mean over pixels of (a - b)^2 / (var_a + var_b) (the
    per-pixel squared error in units of the two renders' noise) below 1.6: ~1.1 expected for two correct
    renders (the plugin's variance is estimated from 16 renders), 1.02-1.11 measured. The rna instance
    stands next to the neupress one, so that rna -> neupress paths are common. Pixels that see a single dome texel have no noise: their
    variance gets a float32 rounding floor (1e-5 relative), so they must agree to ~1e-5."""
    asset = example_builder("neupress", size="tiny", seed=21).write(tmp_path / "np.usdc")
    rna = example_builder("rna", size="tiny", seed=22).write(tmp_path / "rna.usdc")
    tex = _gradient_dome(tmp_path / "dome.exr", hot=10.0)
    m3 = _rotation((0, 1, 0.3), 35) @ np.diag([1.2, 0.8, 1.0])
    path = _scene(tmp_path, [(asset, _matrix(m3, (-0.25, 0, 0))), (rna, _matrix(0.9 * np.eye(3), (0.55, -0.1, 0.2)))],
                  dome_tex=tex, dome_rot=_rotation((0, 1, 0), 50), floor=True, sun=True)
    ref = render_finite(path, width=24, height=24, spp=64, seed=7, prt=True, max_depth=3)
    runs = np.stack([render(path, 16, width=24, height=24, seed=100 + s, prt=True, max_depth=3) for s in range(16)])
    assert np.isfinite(runs).all()
    # pixels that see one dome texel only have no noise: a floor of float32 rounding (1e-5 relative) on the variance
    floor = np.square(1e-5 * np.maximum(np.abs(ref.image), 1e-3))
    ours = _Image(runs.mean(0), runs.var(0, ddof=1) / len(runs) + floor)
    assert np.abs(ref.image).max() > 0.1
    assert_renders_agree(ours, ref, z_mean=Z_MEAN, z_pixel=Z_PIXEL, pixel_fraction=PIXEL_FRACTION)
    den = ours.variance + ref.variance
    noisy = den > 100 * floor
    assert noisy.mean() > 0.5
    chi2 = float((np.square(ours.image - ref.image)[noisy] / den[noisy]).mean())
    assert chi2 < CHI2_PIXEL, chi2


def test_prt_usage_errors(mi, tmp_path, capsys):
    """--prt with a neupress asset without ``prt``, or a scene without a DomeLight: the reference renderer's
    usage errors (UsageError naming the asset file; exit code 2 from the render command), not a Dr.Jit
    error. A scene with only rna assets needs neither (PRT concerns neupress)."""
    b = example_builder("neupress", size="tiny", seed=4)
    del b.components["prt"]
    noprt = b.write(tmp_path / "noprt.usdc")
    asset = example_builder("neupress", size="tiny", seed=4).write(tmp_path / "np.usdc")
    path = _scene(tmp_path, [(noprt, None)], name="noprt.usda")
    with pytest.raises(UsageError) as exc:
        render(path, 1, width=4, height=4, prt=True)
    assert "prt" in exc.value.message and exc.value.file and "noprt.usdc" in str(exc.value.file)
    assert np.isfinite(render(path, 1, width=4, height=4)).all()  # path mode does not need it
    nodome = _scene(tmp_path, [(asset, None)], dome=False, name="nodome.usda")
    with pytest.raises(UsageError, match="DomeLight"):
        render(nodome, 1, width=4, height=4, prt=True)
    assert main([nodome, str(tmp_path / "o.exr"), "--spp", "1", "--width", "4", "--height", "4", "--prt"]) == 2
    assert "[USAGE]" in capsys.readouterr().err and not (tmp_path / "o.exr").exists()
    rna = example_builder("rna", size="tiny", seed=4).write(tmp_path / "rna.usdc")
    assert np.isfinite(render(_scene(tmp_path, [(rna, None)], dome=False, name="rna.usda"), 1, width=4, height=4, prt=True)).all()
