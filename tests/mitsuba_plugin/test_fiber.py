"""rna fiber assets in the Mitsuba JIT plugin: the decoder and the hit frame (tangent, h, exempt range)
against independent implementations, and the fiber conformance cases."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.plugins import register  # noqa: E402
from nasset_mitsuba_plugin.rna import RnaJit  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.shaders.rna_fiber import fiber_frame, tessellate  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from nasset_sdk.geometry import CurvesGeometry  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _run_case, _vec  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    register(mi)
    return mi


@pytest.fixture
def fiber_asset(tmp_path, rng):
    path = tmp_path / "fiber.usdc"
    example_builder("rna", variant="fiber", size="small", seed=int(rng.integers(1 << 30))).write(path)
    return path


def test_fiber_transport_matches_sdk_evaluator(mi, fiber_asset, rng):
    """Dr.Jit decoder row [zeta, xn, t, h, wo, wi] + traced network = the SDK's numpy + onnxruntime
    evaluator on random inputs: points in and around the box, unnormalised and zero directions, h
    inside and outside [-1, 1] and NaN. Tolerance 2e-4 abs + 2e-4 rel (float32 texture fractions,
    as for surfaces)."""
    sdk = Asset.open(fiber_asset).evaluator()
    jit = RnaJit(mi, str(fiber_asset))
    assert jit.fiber
    lo, hi = (np.asarray(v) for v in Asset.open(fiber_asset).domain)
    n = 3000
    x = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (n, 3))
    t, wo, wi = (rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, (n, 1)) for _ in range(3))
    t[:5] = 0.0
    h = rng.uniform(-1.5, 1.5, n)
    h[5:10] = np.nan
    u_ref, s_ref = sdk.evaluate(x, t, wo, wi, h)
    u, s = jit.transport(mi.Point3f(_vec(mi, x)), _vec(mi, t), _vec(mi, wo), _vec(mi, wi), mi.Float(h.astype(np.float32)))
    u, s = np.asarray(u.numpy()).T, np.asarray(s.numpy()).T
    assert np.abs(u_ref).max() > 0.1 and np.abs(s_ref).max() > 0.1
    # h is an input that matters: the same rows with h = 0 differ
    u0, _ = sdk.evaluate(x, t, wo, wi, np.zeros(n))
    assert np.abs(u0 - u_ref).max() > 1e-2
    np.testing.assert_allclose(u, u_ref, atol=2e-4, rtol=2e-4)
    np.testing.assert_allclose(s, s_ref, atol=2e-4, rtol=2e-4)


def test_fiber_frame_matches_reference_renderer(mi, fiber_asset, rng):
    """The prisms Mitsuba traces are the reference renderer's (same vertices, triangles, order), and at
    points on random prism triangles the plugin's tangent, h (|h| <= 1, clamped at the silhouette) and
    exempt triangle range equal the reference renderer's numpy ``fiber_frame`` (tolerance 1e-4 on t
    and h: float32 against float64)."""
    g = Asset.open(fiber_asset).geometry()
    assert isinstance(g, CurvesGeometry)
    jit = RnaJit(mi, str(fiber_asset))
    ref = tessellate(g.points, g.counts, g.widths)
    np.testing.assert_array_equal(jit.geometry.faces, ref.faces)
    np.testing.assert_allclose(jit.geometry.points, ref.points, atol=1e-6)
    n = 4000
    prim = rng.integers(0, len(ref.faces), n)
    bary = rng.dirichlet(np.ones(3), n)
    x = np.einsum("nk,nkj->nj", bary, ref.points[ref.faces[prim]])
    wo = rng.normal(size=(n, 3))
    wo /= np.linalg.norm(wo, axis=1, keepdims=True)
    seg = ref.tri_seg[prim]
    wo[:20] = ref.p1[seg[:20]] - ref.p0[seg[:20]]  # along the axis: h = 0
    wo[:20] /= np.linalg.norm(wo[:20], axis=1, keepdims=True)
    t_ref, h_ref = fiber_frame(ref, seg, x, wo)
    t, h, lo, hi = jit.fiber_frame(mi.UInt32(prim.astype(np.uint32)), mi.Point3f(_vec(mi, x)), _vec(mi, wo))
    np.testing.assert_allclose(np.asarray(t.numpy()).T, t_ref, atol=1e-4)
    np.testing.assert_allclose(np.asarray(h.numpy()), h_ref, atol=1e-4)
    assert np.abs(h_ref).max() > 0.9 and (h_ref > 0.5).any() and (h_ref < -0.5).any()  # both sides of the axis
    np.testing.assert_array_equal(np.stack([lo.numpy(), hi.numpy()], 1), ref.exempt[seg])


def test_fiber_without_segments(mi, tmp_path):
    """Curves whose every segment has zero length: GEOMETRY_INVALID naming the file, not a Mitsuba error."""
    b = example_builder("rna", variant="fiber", size="tiny", seed=4)
    b.geometry = CurvesGeometry(np.zeros((4, 3), np.float32), np.array([2, 2], np.int32), np.full(4, 0.01, np.float32))
    path = tmp_path / "degenerate.usdc"
    b.write(path)
    with pytest.raises(NassetError) as exc:
        RnaJit(mi, str(path))
    assert exc.value.code == "GEOMETRY_INVALID" and "degenerate.usdc" in str(exc.value)


def test_scene_with_fiber_and_surface_assets(mi, fiber_asset, tmp_path):
    """A dict scene with a floor, a fiber asset and a surface asset (two different assets, each evaluated
    on its own lanes): finite, the far floor at rho E cos / pi (5 %), both assets lit, and the fibres
    casting a shadow (the floor in front of them darker than in the same scene without them)."""
    surface = tmp_path / "rna.usdc"
    example_builder("rna", size="tiny", seed=5).write(surface)
    t = mi.ScalarTransform4f
    lo, hi = (np.asarray(v, np.float64) for v in Asset.open(fiber_asset).domain)
    fit = t().translate([-0.7, 0, 0]).scale(float(1.0 / (hi - lo).max())).translate((-0.5 * (lo + hi)).tolist())

    def scene(with_hair: bool):
        d = {"type": "scene",
             "sensor": {"type": "perspective", "fov": 45, "to_world": t().look_at(origin=[0, 2.5, 4], target=[0, 0, 0], up=[0, 1, 0]),
                        "film": {"type": "hdrfilm", "width": 48, "height": 32, "rfilter": {"type": "box"}}},
             "floor": {"type": "rectangle", "to_world": t().translate([0, -0.6, 0]).rotate([1, 0, 0], -90).scale(4),
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
             "blob": asset_shape(surface, t().translate([0.9, 0, 0]), mi=mi),
             "sun": {"type": "directional", "direction": [0, -1, 0.8], "irradiance": {"type": "rgb", "value": 3.0}}}
        if with_hair:
            d["hair"] = asset_shape(fiber_asset, fit, mi=mi)
        integ = mi.load_dict({"type": "nasset_path", "max_depth": 4})
        return np.asarray(mi.render(mi.load_dict(d), integrator=integ, spp=16, seed=1)).mean(-1)

    lum, bare = scene(True), scene(False)
    assert lum.shape == (32, 48) and np.isfinite(lum).all()
    floor = np.median(lum[8:12])  # far floor: cos = 1 / sqrt(1.64)
    assert floor == pytest.approx(0.5 * 3.0 / np.pi / np.sqrt(1.64), rel=0.05)
    assert lum[12:20, 10:20].max() > 2 * floor and lum[12:20, 29:40].max() > 2 * floor  # both assets lit
    assert lum[25:31, 11:19].mean() < 0.95 * bare[25:31, 11:19].mean()  # the fibres' shadow, cast toward the camera


@pytest.mark.parametrize("case", ["rna_fiber_dense", pytest.param("rna_fiber_closeup", marks=pytest.mark.slow),
                                  pytest.param("rna_fiber_distant", marks=pytest.mark.slow)])
def test_fiber_conformance_cases(tmp_path, case):
    """Fiber conformance cases through the ``nasset conformance`` machinery (reference renderer at the
    case's ref_spp; tolerance from its measured noise). ``rna_fiber_dense``: rays crossing tens of
    fibres of their own asset, own and neighbouring segments exempt."""
    row = _run_case(case, tmp_path)
    assert row["passed"], row
