"""rna fiber assets in the reference renderer (spec/renderer.md#fibers): curve prisms, the fiber
quantities t and h at hits, branch choice by other fibers, exact closed forms."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.integrator import PathIntegrator
from nasset_reference_renderer.plan import make_plan
from nasset_reference_renderer.shaders.rna_fiber import TUBE_SIDES, fiber_frame, tessellate
from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_fiber_asset

UNSH, SH = (1.0, 0.5, 0.25), (0.1, 0.2, 0.3)


def _load(path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(str(path))


def _render(path, spp=4, size=32, seed=3, max_depth=5):
    return render(_load(path), RenderSettings(spp=spp, width=size, height=size, seed=seed, max_depth=max_depth)).image


def _integrator(scene):
    plan = make_plan(scene, width=8, height=8, spp=1, max_depth=1, tile=8, batch=64)
    return PathIntegrator(scene, plan, RenderSettings())


def _fiber_hits(path, o, d):
    """(hit mask, t [n,3], h [n]) of world rays against the fiber instance, through the renderer's own code."""
    scene = _load(path)
    integ = _integrator(scene)
    hits = integ.accel.trace(o, d)
    m = hits.prim >= 0
    x = o[m] + d[m] * hits.t[m][:, None]
    inst = scene.tri_inst[hits.prim[m]]
    x_obj = integ.to_object(x, inst, point=True)
    wo_obj = integ.to_object(-d[m], inst)
    wo_obj /= np.linalg.norm(wo_obj, axis=1, keepdims=True)
    t, h, _, _ = integ.shading.fibers.hit_frame(x_obj, wo_obj, hits.prim[m], integ.inst_asset[inst])
    return m, t, h


def test_tessellation_is_closed_prisms():
    pts = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 1, 0]])  # second segment has zero length
    tubes = tessellate(pts, [4], [0.2, 0.2, 0.2, 0.4])
    per = 4 * TUBE_SIDES - 4  # 2N sides + 2 (N - 2) cap triangles
    assert len(tubes.faces) == 2 * per and len(tubes.p0) == 3
    assert (tubes.tri_seg == np.repeat([0, 2], per)).all()
    # every edge of a closed prism is shared by exactly two triangles
    f = tubes.faces[:per]
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), 1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert (counts == 2).all()
    # ring vertices lie on the circles of radius width / 2 around the end points
    v = tubes.points.reshape(3, 2, TUBE_SIDES, 3)
    assert np.allclose(np.linalg.norm(v[2, 1] - pts[3], axis=1), 0.2)
    assert np.allclose(np.linalg.norm(v[0, 0] - pts[0], axis=1), 0.1)
    # a segment and its neighbours in the curve are exempt from self hits
    assert tubes.exempt.tolist() == [[0, per], [0, 2 * per], [per, 2 * per]]


@pytest.mark.parametrize("transformed", [False, True])
def test_h_equals_the_analytic_offset(tmp_path, transformed):
    """A straight tapered fiber along x (radius 0.1 at x=-1 to 0.2 at x=1); rays along -z at known
    offsets y: h = -y / r(x), t = +x (t x wo = -y), in object space under any instance transform."""
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", [[[-1.0, 0, 0], [1.0, 0, 0]]], [0.2, 0.4])
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 0, 1), 1.0)
    M = np.eye(4)
    if transformed:  # rotation about z by 30 degrees, uniform scale 1.5, translation
        c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
        M[:3, :3] = 1.5 * np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
        M[3, :3] = (0.3, -0.2, 0.1)
    b.asset("A", asset, M)
    scene = b.write(tmp_path / "scene.usda")
    xs = np.array([-0.8, -0.2, 0.3, 0.3, 0.3, 0.9])
    ys = np.array([0.05, -0.12, 0.0, 0.1, -0.15, 0.17])
    o_obj = np.stack([xs, ys, np.full_like(xs, 4.0)], 1)
    d_obj = np.tile([0.0, 0, -1], (len(xs), 1))
    o = o_obj @ M[:3, :3] + M[3, :3]
    d = d_obj @ M[:3, :3]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    m, t, h = _fiber_hits(scene, o, d)
    assert m.all()
    r = 0.1 + 0.1 * (xs + 1) / 2
    assert np.allclose(h, -ys / r, atol=1e-5)
    assert np.allclose(t, [1.0, 0, 0], atol=1e-6)
    # fiber_frame alone, at points off the ray's hit: h depends on the ray, not on where it met the prism
    tubes = tessellate([[-1.0, 0, 0], [1.0, 0, 0]], [2], [0.2, 0.4])
    x = np.array([[0.3, 0.05, 0.1], [0.3, 0.05, -0.1]])
    _, h2 = fiber_frame(tubes, np.zeros(2, np.int64), x, np.array([[0.0, 0, 1], [0.0, 0, 1]]))
    assert np.allclose(h2, -0.05 / 0.165)


def test_h_is_bounded_and_symmetric(tmp_path):
    """Rays uniformly across a fiber seen head-on (several view angles about its axis): h in [-1, 1],
    mean ~0, reaching close to +-1 at the silhouettes, and monotonic in the ray's offset."""
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", [[[-1.0, 0, 0], [0.0, 0.02, 0], [1.0, 0, 0]]], 0.2)
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", (0, 0, 1), 1.0)
    b.asset("A", asset)
    scene = b.write(tmp_path / "scene.usda")
    rng = np.random.default_rng(0)
    for ang in (0.0, 0.2, 0.7, 1.3):
        n = 4000
        off = np.sort(rng.uniform(-0.15, 0.15, n))
        view = np.array([0.0, np.sin(ang), np.cos(ang)])  # toward the viewer, perpendicular to the axis
        side = np.cross([1.0, 0, 0], view)  # t x wo
        o = 4.0 * view + off[:, None] * side + np.array([0.5, 0.0, 0.0])
        d = np.tile(-view, (n, 1))
        m, _, h = _fiber_hits(scene, o, d)
        assert m.sum() > 0.5 * n
        assert h.min() >= -1.0 and h.max() <= 1.0
        assert abs(h.mean()) < 0.05
        assert h.max() > 0.9 and h.min() < -0.9
        assert (np.diff(h) >= -1e-9).all()  # offsets sorted along t x wo: h increases


def _fiber_scene(tmp_path, asset, toward_light, e=2.0, floor=False):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    b.distant("Sun", toward_light, e)
    if floor:
        b.quad("Floor", (0, -0.8, 0), 4, diffuse=(0.5, 0.5, 0.5))
    b.asset("A", asset)
    return b.write(tmp_path / "scene.usda")


@pytest.mark.parametrize("toward_light", [(0, 0, 1), (0, 0, -1), (0.3, 0.2, 1.0)])
def test_constant_fiber_closed_form(tmp_path, toward_light):
    """Lone fibers (straight and gently bent), delta DistantLight of irradiance E: every covered pixel
    shows T_unshadowed E exactly, whether the light is in front of or behind them (a fiber's own
    cross-section is part of its transport: it never shadows itself)."""
    curves = [[[-1.0, 0.45, 0], [1.0, 0.45, 0]], [[-1.0, -0.1, 0], [-0.3, 0.0, 0.05], [0.4, -0.05, 0], [1.0, 0.05, -0.05]],
              [[-1.0, -0.55, 0], [1.0, -0.55, 0]]]
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", curves, 0.3, unshadowed=UNSH, shadowed=SH)
    e = 2.0
    img = _render(_fiber_scene(tmp_path, asset, toward_light, e))
    assert np.isfinite(img).all()
    cover = img / (e * np.asarray(UNSH))
    assert np.allclose(cover, cover[..., :1], atol=1e-5), "pixels are not multiples of T E"
    assert cover.max() == pytest.approx(1.0, abs=1e-5) and cover.min() >= 0.0
    assert (cover[..., 0] > 1 - 1e-5).sum() >= 60


@pytest.mark.parametrize("same_asset", [True, False])
def test_fiber_shadowed_by_another_fiber(tmp_path, same_asset):
    """Light from above: fiber A (y=0) lies in the shadow of the thicker fiber B (y=0.5). Same asset:
    A picks the shadowed branch (T_s E), B the unshadowed one. B in another instance: A gets 0."""
    fa, fb = [[-1.0, 0.0, 0], [1.0, 0.0, 0]], [[-1.2, 0.5, 0], [1.2, 0.5, 0]]
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0))
    e = 2.0
    b.distant("Sun", (0, 1, 0), e)
    if same_asset:
        b.asset("A", constant_rna_fiber_asset(tmp_path / "ab.usda", [fa, fb], [[0.2, 0.2], [0.4, 0.4]], unshadowed=UNSH,
                                              shadowed=SH))
    else:
        b.asset("A", constant_rna_fiber_asset(tmp_path / "a.usda", [fa], 0.2, unshadowed=UNSH, shadowed=SH))
        b.asset("B", constant_rna_fiber_asset(tmp_path / "b.usda", [fb], 0.4, unshadowed=UNSH, shadowed=SH))
    img = _render(b.write(tmp_path / "scene.usda"), max_depth=1)  # direct light only: two instances would continue paths
    assert np.isfinite(img).all()
    rows_a = img[14:18]  # fiber A crosses the image centre
    rows_b = img[:12]
    full_b = rows_b[..., 0] > 0
    cb = rows_b[full_b] / (e * np.asarray(UNSH))
    assert np.allclose(cb, cb[:, :1], atol=1e-5) and cb.max() == pytest.approx(1.0, abs=1e-5)
    lit_a = rows_a[..., 2] > 0
    if same_asset:
        ca = rows_a[lit_a] / (e * np.asarray(SH))
        assert np.allclose(ca, ca[:, :1], atol=1e-5), "fiber A is not on the shadowed branch"
        assert ca.max() == pytest.approx(1.0, abs=1e-5) and lit_a.sum() >= 40
    else:
        assert not lit_a.any()


def test_h_reaches_the_network(tmp_path):
    """Decoder affine in h (R = 1 + h, G = 1 - h): lit head-on, the fiber's lower half (h > 0, t x wo
    points down the image) is redder, the upper half greener, and the two balance."""
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", [[[-1.5, 0, 0], [1.5, 0, 0]]], 0.6, h_probe=True)
    img = _render(_fiber_scene(tmp_path, asset, (0, 0, 1), 1.0), spp=8)
    lit = img[..., 2] > 0
    assert lit.sum() > 100
    assert np.allclose((img[..., 0] + img[..., 1])[lit], 2 * img[..., 2][lit], atol=1e-5)
    ys = np.nonzero(lit.any(1))[0]
    top, bottom = img[ys[: len(ys) // 2]], img[ys[len(ys) - len(ys) // 2:]]
    assert top[..., 1].sum() > 1.3 * top[..., 0].sum() and bottom[..., 0].sum() > 1.3 * bottom[..., 1].sum()
    assert img[..., 0].sum() == pytest.approx(img[..., 1].sum(), rel=0.03)


def test_example_fiber_asset_renders(tmp_path):
    """The SDK's random fiber example on a floor (continuation rays on) and in a mixed scene with a
    surface asset: finite, non-negative images with the fibers visible."""
    from nasset_sdk.examples import example_builder

    fiber = example_builder("rna", variant="fiber", size="tiny", seed=0).write(tmp_path / "fiber.usdc")
    surf = example_builder("rna", size="tiny", seed=1).write(tmp_path / "surf.usdc")
    b = SceneBuilder()
    b.camera((0, 0.6, 2.2), (0, 0.4, 0))
    b.distant("Sun", (0.5, 1.0, 0.35), 3.0)
    b.sphere_light("Bulb", (1.0, 1.5, 1.0), 0.2, 5.0)
    b.quad("Floor", (0, 0, 0), 4, diffuse=(0.5, 0.5, 0.5))
    b.asset("Hair", fiber)
    M = np.eye(4)
    M[3, :3] = (0.8, 0.3, -0.3)
    b.asset("Ball", surf, M)
    img = _render(b.write(tmp_path / "scene.usda"), spp=4, size=40, max_depth=3)
    assert np.isfinite(img).all() and img.min() >= 0.0 and img.max() > 0.0


def test_fibre_prisms_need_no_face_normals(tmp_path):
    """The loader stores zero geometric normals for fibre prisms (the work of 8.4 M cross products on a dense groom):
    no renderer path reads them. The same scene with their true normals (and a mirrored surface asset beside, whose
    normals are read) renders bit for bit the same image; its surface asset's normals are the true ones."""
    from nasset_reference_renderer.sampling import face_normals
    from nasset_sdk.examples import example_builder

    fiber = example_builder("rna", variant="fiber", size="tiny", seed=0).write(tmp_path / "fiber.usdc")
    surf = example_builder("rna", size="tiny", seed=1).write(tmp_path / "surf.usdc")
    b = SceneBuilder()
    b.camera((0, 0.6, 2.2), (0, 0.4, 0))
    b.sphere_light("Bulb", (1.0, 1.5, 1.0), 0.2, 5.0)
    b.quad("Floor", (0, 0, 0), 4, diffuse=(0.5, 0.5, 0.5))
    b.asset("Hair", fiber)
    M = np.diag([-1.0, 1.0, 1.0, 1.0])
    M[3, :3] = (0.8, 0.3, -0.3)
    b.asset("Ball", surf, M)
    path = b.write(tmp_path / "scene.usda")
    settings = RenderSettings(spp=2, width=24, height=24, seed=4, max_depth=3)
    zero, true = _load(path), _load(path)
    hair, ball = (next(i for i in zero.instances if i.prim.endswith(name)) for name in ("Hair", "Ball"))
    rows = slice(hair.first_tri, hair.first_tri + hair.n_tri)
    assert hair.n_tri > 0 and not zero.tri_ng[rows].any()
    own = slice(ball.first_tri, ball.first_tri + ball.n_tri)
    np.testing.assert_array_equal(zero.tri_ng[own], face_normals(zero.triangles[own]))
    true.tri_ng[rows] = face_normals(true.triangles[rows])
    a, c = render(zero, settings), render(true, settings)
    assert a.image.max() > 0.0 and a.stats.rays == c.stats.rays
    np.testing.assert_array_equal(a.image, c.image)


def test_ray_structures_built_once_per_scene(tmp_path):
    """Renders of one scene share its ray-casting structures (built at the first render): the same image as a
    freshly loaded scene, each render counting only its own rays. The fibre asset's structure is in Embree's
    fast (non-robust) mode, the floor's robust; another backend gets structures of its own."""
    from nasset_reference_renderer.accel import NumpyBackend

    curves = [[[-1.0, 0.2, 0], [0.0, 0.3, 0.1], [1.0, 0.2, 0]], [[-1.0, -0.3, 0.2], [1.0, -0.2, -0.1]]]
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", curves, 0.3, unshadowed=UNSH, shadowed=SH)
    path = _fiber_scene(tmp_path, asset, (0.3, 1.0, 0.4), floor=True)
    settings = RenderSettings(spp=2, width=16, height=16, seed=5, max_depth=3)
    scene = _load(path)
    first = render(scene, settings)
    (acc, _), = scene.accel_cache.values()
    second = render(scene, settings)
    assert next(iter(scene.accel_cache.values()))[0] is acc
    fresh = render(_load(path), settings)
    assert first.stats.rays > 0 and second.stats.rays == first.stats.rays == fresh.stats.rays
    np.testing.assert_array_equal(second.image, first.image)
    np.testing.assert_array_equal(fresh.image, first.image)
    fiber_inst = [i for i, inst in enumerate(scene.instances) if inst.kind == "neural"]
    assert {p.inst: p.backend.robust for p in acc.parts} == {fiber_inst[0]: False, -1: True}
    render(scene, RenderSettings(spp=1, width=4, height=4, backend="numpy", max_depth=1))
    (other, _), = scene.accel_cache.values()
    assert other is not acc and all(isinstance(p.backend, NumpyBackend) for p in other.parts)



@pytest.mark.parametrize("transformed,continuation", [(False, "lobes"), (True, "lobes"), (True, "uniform")])
def test_fiber_continuation_is_unbiased_under_a_constant_sky(tmp_path, transformed, continuation):
    """A lone straight fiber of constant transport T under a constant sky of radiance Le: a covered pixel's
    expectation is 4 pi T Le times its coverage, whatever density the continuation samples, as long as the MIS
    weights of the sky's light samples and the continuation's weights use the same density
    (:func:`~tests.renderer.test_render_neural.continuation_against_light_sampling`). Under a rotated,
    non-uniformly scaled instance the density is still per world steradian."""
    from tests.renderer.test_render_neural import continuation_against_light_sampling

    asset = constant_rna_fiber_asset(tmp_path / "f.usda", [[[-1.0, 0.0, 0], [1.0, 0.0, 0]]], 0.3, unshadowed=UNSH, shadowed=SH)
    M = None
    if transformed:
        c, s = np.cos(0.5), np.sin(0.5)
        M = np.eye(4)
        M[:3, :3] = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]) @ np.diag([1.0, 1.0, 0.6])
    _, direct = continuation_against_light_sampling(tmp_path, asset, M, continuation, spp=128, size=24)
    expected = 4 * np.pi * 0.5 * UNSH[0]
    assert direct.image[..., 0].max() == pytest.approx(expected, rel=1e-6)  # a fully covered pixel, exactly
    assert (direct.image[..., 0] > 0.99 * expected).sum() >= 20


def test_rna_continuation_setting_is_checked(tmp_path):
    asset = constant_rna_fiber_asset(tmp_path / "f.usda", [[[-1.0, 0.0, 0], [1.0, 0.0, 0]]], 0.3)
    from nasset_sdk.errors import UsageError

    with pytest.raises(UsageError, match="rna continuation must be one of"):
        render(_load(_fiber_scene(tmp_path, asset, (0, 0, 1))), RenderSettings(spp=1, width=4, height=4,
                                                                             rna_continuation="cosine"))
