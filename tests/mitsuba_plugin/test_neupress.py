"""Kind ``neupress`` in the Mitsuba JIT plugin: Dr.Jit evaluation (and PRT shading) against the SDK evaluator,
the Dr.Jit lobe sampler against its pdf (chi-squared), the lobe technique against the uniform sphere under a non-uniformly
scaled instance (its world Jacobian), and typed errors for a neupress asset missing what the plugin needs."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.neupress import GaussianLobe, NeupressJit, SigmaTable  # noqa: E402
from nasset_mitsuba_plugin.plugins import register  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_sdk.asset import Asset  # noqa: E402
from nasset_sdk.errors import NassetError  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from nasset_sdk.kinds.neupress import gaussian_lobe_pdf, gaussian_lobe_sample  # noqa: E402
from tests.mitsuba_plugin.test_plugin import _asset_without  # noqa: E402
from tests.stats import SIGNIFICANCE, sphere_chi2  # noqa: E402


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    register(mi)
    return mi


def _vec(mi, a):
    return mi.Vector3f(*[mi.Float(np.ascontiguousarray(a[:, k], np.float32)) for k in range(3)])


def _np3(v):
    return np.asarray(v.numpy(), np.float64).reshape(3, -1).T


@pytest.mark.parametrize("size", ["tiny", pytest.param("small", marks=pytest.mark.slow)])
def test_neupress_matches_sdk_evaluator(mi, tmp_path, rng, size):
    """S (appearance network on Fourier features), f_r |n.wi| (GGX boundary), sigma (sampling network), and
    the lobe's samples from the same u and its pdf (with the lobe's own, tabulated sigma) equal the SDK on random inputs
    (points up to 20 % outside the encoding box, unnormalised and zero directions). Tolerances: S 5e-4 abs +
    1e-3 rel (float32 Fourier phases of up to ~100 cycles: ~1e-4 measured); f_r, sigma and pdfs 1e-3 rel;
    sampled directions 1e-3 abs (float32 against the SDK's float64)."""
    path = tmp_path / f"np_{size}.usdc"
    example_builder("neupress", size=size, seed=int(rng.integers(1 << 30))).write(path)
    sdk = Asset.open(path, load="all").evaluator()
    jit = NeupressJit(mi, str(path))
    lo, hi = (np.asarray(v) for v in Asset.open(path).domain)
    n = 3000
    x = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (n, 3))
    nrm, wo, wi = (rng.normal(size=(n, 3)) * rng.uniform(0.1, 10, (n, 1)) for _ in range(3))
    wo[:3] = 0.0  # safe_normalize's fallback (+z)
    wi[3:6] = 0.0
    xj, nj, woj, wij = mi.Point3f(_vec(mi, x)), _vec(mi, nrm), _vec(mi, wo), _vec(mi, wi)

    s_ref = sdk.evaluate(x, nrm, wo, wi)
    assert s_ref.max() > 0.3 and (s_ref > 0).mean() > 0.2  # the comparison sees real outputs
    un, sh = jit.transport(xj, nj, woj, wij)
    np.testing.assert_allclose(_np3(sh), s_ref, atol=5e-4, rtol=1e-3)
    fr_ref = sdk.surface_reflection(nrm, wo, wi)
    assert fr_ref.max() > 0.5
    np.testing.assert_allclose(_np3(un) - _np3(sh), fr_ref, atol=1e-5, rtol=1e-3)

    np.testing.assert_allclose(jit.sigma(xj, woj).numpy(), sdk.sigma(x, wo), rtol=1e-3)
    lobe = jit.technique(xj, nj, woj)
    sigma = np.asarray(lobe.sigma.numpy(), np.float64)
    np.testing.assert_allclose(sigma, jit.sigma_table(jit.to_unit_box(xj), woj).numpy(), rtol=1e-6)
    # the lobe with the plugin's own sigma (its table's; only the variance depends on it)
    u = rng.random((n, 2))
    w_ref, p_ref = gaussian_lobe_sample(nrm, sigma, u)
    w, p = lobe.sample(mi.Point2f(*[mi.Float(u[:, k].astype(np.float32)) for k in range(2)]))
    np.testing.assert_allclose(_np3(w), w_ref, atol=1e-3)
    np.testing.assert_allclose(p.numpy(), p_ref, rtol=1e-3, atol=1e-6)
    np.testing.assert_allclose(lobe.pdf(wij).numpy(), gaussian_lobe_pdf(nrm, sigma, wi), rtol=1e-3, atol=1e-6)


def test_prt_radiance_matches_sdk(mi, tmp_path, rng):
    """PRT shading (gathers of the [V, T, P, 9, 3] coefficients in the w_o bin of the vertex normal's frame,
    dotted with lighting SH b) equals the SDK's prt_radiance on random vertices, normals and directions
    (above and below the surface). Tolerance 1e-4 rel + 1e-6 abs (float32 sums)."""
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=int(rng.integers(1 << 30))).write(path)  # 2 x 4 w_o bins
    sdk = Asset.open(path, load="all").evaluator()
    jit = NeupressJit(mi, str(path))
    n = 4000
    v = rng.integers(0, sdk.prt_coefficients().shape[0], n)
    nrm, wo = (rng.normal(size=(n, 3)) for _ in range(2))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    b = rng.normal(size=(9, 3))
    ref = sdk.prt_radiance(b, v, nrm, wo)
    out = _np3(jit.prt_radiance(b, mi.UInt32(v.astype(np.uint32)), _vec(mi, nrm), _vec(mi, wo)))
    assert np.abs(ref).max() > 0.1
    np.testing.assert_allclose(out, ref, rtol=1e-4, atol=1e-6)


def _cols(mi, a: np.ndarray) -> list:
    return [mi.Float(np.ascontiguousarray(c).astype(np.float32)) for c in a.T]


def test_sigma_table_interpolates_trilinear_in_x_nearest_in_w_o(mi, rng):
    """SigmaTable of a function linear in xn plus a function of the w_o bin: trilinear interpolation reproduces
    the linear part exactly anywhere in the box, and the direction part is that of the bin holding w_o (equal-angle
    theta, phi bins), computed here independently; points outside the box clamp to it; the poles, a zero
    direction and NaN inputs give finite widths."""
    a = np.array([0.7, -0.4, 0.25])

    def dir_part(t, p):  # t = theta / pi, p = phi / (2 pi) at the bin centres
        return 0.3 * np.cos(2 * np.pi * p) * np.sin(np.pi * t) - 0.5 * t

    def log_sigma(cols):
        x, y, z, t, p = (np.asarray(c, np.float64) for c in cols)
        return (a[0] * x + a[1] * y + a[2] * z + dir_part(t, p)).astype(np.float32)

    nt, npb = 5, 7
    table = SigmaTable(mi, log_sigma, res=(6, nt, npb))
    n = 5000
    xn = rng.uniform(-1.3, 1.3, (n, 3))
    wo = rng.normal(size=(n, 3)) * rng.uniform(0.01, 10, (n, 1))
    got = np.log(np.asarray(table(mi.Vector3f(*_cols(mi, xn)), mi.Vector3f(*_cols(mi, wo))).numpy(), np.float64))
    w = wo / np.linalg.norm(wo, axis=1, keepdims=True)
    theta, phi = np.arctan2(np.hypot(w[:, 0], w[:, 1]), w[:, 2]), np.arctan2(w[:, 1], w[:, 0])
    it = np.minimum((theta / np.pi * nt).astype(int), nt - 1)
    ip = np.minimum(((phi + np.pi) / (2 * np.pi) * npb).astype(int), npb - 1)
    want = np.clip(xn, -1, 1) @ a + dir_part((it + 0.5) / nt, (ip + 0.5) / npb - 0.5)
    np.testing.assert_allclose(got, want, atol=2e-5)
    odd_x = np.array([[np.nan, 0, 0], [0, np.inf, 0], [0.2, 0.1, -0.3], [0.2, 0.1, -0.3], [0.2, 0.1, -0.3]])
    odd_w = np.array([[0, 0, 1], [0, 0, -1], [0, 0, 0], [np.nan, 1, 0], [1e-30, 0, -1]])
    s = np.asarray(table(mi.Vector3f(*_cols(mi, odd_x)), mi.Vector3f(*_cols(mi, odd_w))).numpy())
    assert np.isfinite(s).all() and (s > 0).all()


def test_sigma_table_holds_the_network_at_its_nodes(mi, tmp_path):
    """NeupressJit's table holds the ``sampling`` network's width at its box nodes and w_o bin centres (a tiny
    random asset, whose widths vary over two orders of magnitude; between the nodes the table interpolates,
    which only changes the variance)."""
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=3).write(path)
    jit = NeupressJit(mi, str(path))
    r, nt, npb = jit.sigma_table.r, jit.sigma_table.nt, jit.sigma_table.np
    g = np.linspace(-1, 1, r)
    rng = np.random.default_rng(1)
    n = 2000
    xn = g[rng.integers(0, r, (n, 3))]
    it, ip = rng.integers(0, nt, n), rng.integers(0, npb, n)
    theta, phi = (it + 0.5) / nt * np.pi, ((ip + 0.5) / npb - 0.5) * 2 * np.pi
    wo = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    x = jit.lo + (xn + 1) * 0.5 * jit.span
    want = jit.sigma(mi.Point3f(*_cols(mi, x)), mi.Vector3f(*_cols(mi, wo))).numpy()
    got = jit.sigma_table(mi.Vector3f(*_cols(mi, xn)), mi.Vector3f(*_cols(mi, wo))).numpy()
    assert np.ptp(np.log(want)) > 0.5  # the widths vary
    np.testing.assert_allclose(got, want, rtol=2e-3)


@pytest.mark.parametrize("sigma", [0.3, 2.0])
def test_lobe_sampler_matches_its_pdf(mi, sigma):
    """The Dr.Jit Gaussian lobe (around a tilted normal) against its own pdf: chi-squared over the sphere."""
    nrm = np.array([0.3, -0.5, 0.81])
    nrm /= np.linalg.norm(nrm)

    def lobe(k):
        return GaussianLobe(mi, mi.Vector3f(*[mi.Float(np.full(k, c, np.float32)) for c in nrm]), mi.Float(np.full(k, sigma, np.float32)))

    def sample(u):
        w, _ = lobe(len(u)).sample(mi.Point2f(*[mi.Float(u[:, k].astype(np.float32)) for k in range(2)]))
        return _np3(w)

    def pdf(v):
        return np.asarray(lobe(len(v)).pdf(_vec(mi, v)).numpy(), np.float64)

    p, dof, integral = sphere_chi2(sample, pdf, pdf_total=1.0)
    assert p > SIGNIFICANCE, (p, dof, integral)
    assert integral == pytest.approx(1.0, abs=2e-3)


def _scaled_instance_image(mi, path, lobe: bool, seed: int) -> np.ndarray:
    """A neupress instance, rotated and scaled by (1.3, 0.25, 1.6), filling most of the frame, under a constant
    environment (radiance 1), rendered with the lobe technique or the uniform sphere (48 x 48, 128 spp)."""
    t = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 30, "to_world": t().look_at(origin=[0, 0.3, 2.2], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 48, "height": 48, "rfilter": {"type": "box"}}},
        "asset": asset_shape(path, t().rotate([1, 1, 0], 35).scale([1.3, 0.25, 1.6]), mi=mi),
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    })
    integ = mi.load_dict({"type": "nasset_path", "max_depth": 2, "lobe": lobe})
    return np.asarray(mi.render(scene, integrator=integ, spp=128, seed=seed), np.float64)


def test_lobe_technique_is_unbiased_under_nonuniform_scale(mi, tmp_path):
    """The lobe (object-space density times J = |det B| / |B w|^3, in the continuation's weight and in both MIS
    weights) and the uniform world sphere estimate the same image. z = sum(d) / sqrt(sum(d^2)) over the pixels
    of the difference image d (independent, zero-mean under the null) is ~N(0, 1); the test asks |z| < 4.5."""
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=11).write(path)
    a = _scaled_instance_image(mi, str(path), True, 1)
    b = _scaled_instance_image(mi, str(path), False, 2)
    assert np.isfinite(a).all() and np.isfinite(b).all()
    d = (a - b).sum(-1)
    on = d != 0  # background pixels (the environment seen directly) are equal in both
    assert on.sum() > 200
    z = d[on].sum() / np.sqrt(np.square(d[on]).sum())
    assert abs(z) < 4.5, (z, a.mean(), b.mean())


def test_asset_without_the_appearance_network(mi, tmp_path):
    """A neupress asset whose core component lost its appearance network: the SDK's NETWORK_MISSING naming it."""
    with pytest.raises(NassetError) as exc:
        asset_shape(_asset_without(tmp_path, "neupress", "appearance"), mi=mi)
    assert exc.value.code == "NETWORK_MISSING" and "appearance" in exc.value.message


def test_sigma_table_is_built_on_first_use(mi, tmp_path):
    """Loading an asset builds no table (renders with ``lobe`` false or PRT never read it); the first lobe builds it
    once; an asset without the ``sampling`` component has none to build: COMPONENT_MISSING naming the prim."""
    path = tmp_path / "np.usdc"
    example_builder("neupress", size="tiny", seed=5).write(path)
    jit = NeupressJit(mi, str(path))
    assert jit._sigma_table is None
    n = mi.Vector3f(0.0, 0.0, 1.0)
    jit.technique(mi.Point3f(0.0, 0.0, 0.0), n, n)
    table = jit._sigma_table
    assert isinstance(table, SigmaTable)
    jit.technique(mi.Point3f(0.1, 0.0, 0.0), n, n)
    assert jit._sigma_table is table

    bare = NeupressJit(mi, str(_asset_without(tmp_path, "neupress", "sampling")))
    assert bare.technique(mi.Point3f(0.0, 0.0, 0.0), n, n) is None
    with pytest.raises(NassetError) as exc:
        _ = bare.sigma_table
    assert exc.value.code == "COMPONENT_MISSING" and "sampling" in str(exc.value)
