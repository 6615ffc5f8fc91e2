"""The evaluator interface every kind shares: Query -> radiance [N, 3] (spec/kinds/README.md#evaluator-interface)."""

from __future__ import annotations

import numpy as np
import pytest

import nasset_sdk as ns
from nasset_sdk.examples import example_builder
from tests.stats import stat_seed

KINDS = (("rna", "surface"), ("rna", "fiber"), ("neupress", "surface"), ("8dna", "surface"))


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    d = tmp_path_factory.mktemp("interface")
    return {(k, v): example_builder(k, variant=v, size="tiny", seed=3).write(d / f"{k}_{v}.usdc") for k, v in KINDS}


def _query(n, seed=0, **extra):
    rng = np.random.default_rng(stat_seed(seed))
    x = rng.uniform(-0.3, 0.3, (n, 3))
    nn, wo, wi = (rng.normal(size=(n, 3)) for _ in range(3))
    wo *= np.sign((wo * nn).sum(1))[:, None]  # viewer and light on the side of n
    wi *= np.sign((wi * nn).sum(1))[:, None]
    return ns.Query(x, nn, wo, wi, **extra)


@pytest.mark.parametrize("kind,variant", KINDS)
def test_radiance_shape_dtype_and_keyword_form(assets, kind, variant):
    ev = ns.Asset.open(assets[kind, variant]).evaluator(light_samples=4) if kind == "8dna" else \
        ns.Asset.open(assets[kind, variant]).evaluator()
    assert isinstance(ev, ns.Evaluator)
    q = _query(64)
    rgb = ev.radiance(q)
    assert rgb.shape == (64, 3) and rgb.dtype == np.float32
    assert np.isfinite(rgb).all() and (rgb >= 0).all() and rgb.max() > 0
    np.testing.assert_array_equal(ev.radiance(x=q.x, n=q.n, wo=q.wo, wi=q.wi), rgb)
    # one row evaluated alone equals the same row of the batch
    one = ev.radiance(ns.Query(q.x[5:6], q.n[5:6], q.wo[5:6], q.wi[5:6]))
    np.testing.assert_allclose(one, rgb[5:6], rtol=1e-6, atol=1e-7)
    if kind == "8dna":  # split into passes of 4 query rows (batch // light_samples): the same numbers
        chunked = ns.Asset.open(assets[kind, variant]).evaluator(light_samples=4, batch=16).radiance(q)
        np.testing.assert_allclose(chunked, rgb, rtol=1e-6, atol=1e-9)


def test_rna_radiance_picks_the_branch_named_by_shadowed(assets):
    ev = ns.Asset.open(assets["rna", "surface"]).evaluator()
    q = _query(200)
    unshadowed, shadowed = ev.evaluate(q.x, q.n, q.wo, q.wi)
    mask = np.arange(200) % 3 == 0
    got = ev.radiance(ns.Query(q.x, q.n, q.wo, q.wi, shadowed=mask))
    assert not np.allclose(unshadowed, shadowed)  # the two branches differ, so the pick is visible
    np.testing.assert_array_equal(got[mask], shadowed[mask])
    np.testing.assert_array_equal(got[~mask], unshadowed[~mask])


def test_rna_fiber_h_is_used_and_surface_refuses_it(assets):
    fib = ns.Asset.open(assets["rna", "fiber"]).evaluator()
    q = _query(50)
    h = np.linspace(-1, 1, 50)
    with_h = fib.radiance(ns.Query(q.x, q.n, q.wo, q.wi, h=h))
    np.testing.assert_array_equal(with_h, fib.evaluate(q.x, q.n, q.wo, q.wi, h)[0])
    assert not np.array_equal(with_h, fib.radiance(q))  # default h = 0
    for key in (("rna", "surface"), ("neupress", "surface")):
        with pytest.raises(ns.UsageError, match="'h' applies to rna fiber"):
            ns.Asset.open(assets[key]).evaluator().radiance(ns.Query(q.x, q.n, q.wo, q.wi, h=h))


def test_neupress_radiance_is_subsurface_plus_unshadowed_reflection(assets):
    ev = ns.Asset.open(assets["neupress", "surface"]).evaluator()
    q = _query(100)
    s = ev.evaluate(q.x, q.n, q.wo, q.wi)
    f = ev.surface_reflection(q.n, q.wo, q.wi)
    assert f.max() > 0
    lit = ev.radiance(q)
    dark = ev.radiance(ns.Query(q.x, q.n, q.wo, q.wi, shadowed=np.ones(100, bool)))
    np.testing.assert_allclose(lit, s + f, rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(dark, s.astype(np.float32))


def _box_faces(lo, hi, m, rng):
    """m points uniform on the surface of the box [lo, hi]: (u [m,3], outward normal [m,3], total area)."""
    ext = hi - lo
    areas = np.array([ext[1] * ext[2], ext[0] * ext[2], ext[0] * ext[1]] * 2)
    face = rng.choice(6, m, p=areas / areas.sum())
    u = lo + rng.random((m, 3)) * ext
    axis, side = face % 3, face // 3  # side 0: the lo face, 1: the hi face
    u[np.arange(m), axis] = np.where(side == 1, hi[axis], lo[axis])
    normal = np.zeros((m, 3))
    normal[np.arange(m), axis] = np.where(side == 1, 1.0, -1.0)
    return u, normal, areas.sum()


def test_8dna_distant_density_matches_uniform_box_quadrature(assets):
    """alpha * E_{u ~ p(u)}[p(w|u)] (the flow estimator in radiance) against A * E_{u uniform}[p(u, w)]:
    the same integral over the box, estimated independently; within 5 combined standard errors."""
    asset = ns.Asset.open(assets["8dna", "surface"])
    m_flow = 2048
    ev = asset.evaluator(light_samples=m_flow)
    rng = np.random.default_rng(stat_seed(7))
    lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
    q = _query(3, seed=11)
    got = ev.distant_density(q.x, q.wo, q.wi)
    wi = q.wi / np.linalg.norm(q.wi, axis=1, keepdims=True)
    m = 20000
    for r in range(3):
        u, nu, area = _box_faces(lo, hi, m, rng)
        rep = lambda a, k, r=r: np.repeat(a[r:r + 1], k, 0)  # noqa: E731
        gate = (nu * wi[r]).sum(1) > 0
        for c in range(3):
            p = ev.pdf(rep(q.x, m), rep(q.wo, m), u, rep(wi, m), np.full(m, c)) * gate * area
            ref, se_ref = p.mean(), p.std(ddof=1) / np.sqrt(m)
            # iid version of the flow estimator: its standard error bounds the stratified one's
            ui, _, _ = ev.sample(rep(q.x, m_flow), rep(q.wo, m_flow), np.full(m_flow, c), rng)
            rel = (ui - ev.box.center) / ev.box.half
            ax = np.argmax(np.abs(rel), 1)
            enters = np.sign(rel[np.arange(m_flow), ax]) * wi[r][ax] > 0
            pf = ev.pdf_direction(rep(q.x, m_flow), rep(q.wo, m_flow), ui, rep(wi, m_flow), np.full(m_flow, c)) * enters
            se_flow = pf.std(ddof=1) / np.sqrt(m_flow)
            assert ref > 0
            assert abs(got[r, c] - ref) < 5 * np.hypot(se_ref, se_flow) + 1e-9, (r, c, got[r, c], ref, se_ref, se_flow)
    # and radiance = direct lobe (unshadowed only) + albedo * that density
    lit, dark = ev.radiance(q), ev.radiance(ns.Query(q.x, q.n, q.wo, q.wi, shadowed=np.ones(3, bool)))
    np.testing.assert_allclose(dark, ev.albedo(q.x, q.wo) * got, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(lit - dark, ev.direct_eval(q.n, q.wo, q.wi), rtol=1e-4, atol=1e-7)


@pytest.mark.parametrize("kind,variant", KINDS)
def test_bad_queries_raise_usage_errors_naming_the_field(assets, kind, variant):
    asset = ns.Asset.open(assets[kind, variant])
    ev = asset.evaluator()
    q = _query(10)
    bad_cases = [
        (dict(wo=q.wo[0]), r"'wo': expected shape \[N, 3\] with N = 10.*got \(3,\)"),
        (dict(wi=q.wi[:9]), r"'wi': expected shape \[N, 3\] with N = 10"),
        (dict(x=q.x[:, :2]), r"'x': expected shape \[N, 3\], got \(10, 2\)"),
        (dict(n=np.where(np.arange(10)[:, None] == 4, np.nan, q.n)), "'n' .* NaN or Inf"),
        (dict(wi=np.zeros((10, 3))), "'wi' .* zero vector"),
        (dict(wo=q.wo.astype(complex)), "'wo': expected a real number array"),
        (dict(shadowed=np.zeros(10)), "'shadowed': expected dtype bool"),
        (dict(shadowed=np.zeros(9, bool)), r"'shadowed': expected shape \[N\] with N = 10"),
    ]
    for change, pattern in bad_cases:
        fields = {"x": q.x, "n": q.n, "wo": q.wo, "wi": q.wi, **change}
        with pytest.raises(ns.UsageError, match=pattern) as info:
            ev.radiance(ns.Query(**fields))
        assert info.value.file == str(asset.path)
    with pytest.raises(ns.UsageError, match="takes a nasset_sdk.Query"):
        ev.radiance((q.x, q.n, q.wo, q.wi))


def test_rna_evaluate_refuses_a_single_direction_for_many_rows(assets):
    """The old per-kind method checks shapes too: a (3,) direction used to broadcast up to 8192 rows, then fail
    with a bare numpy ValueError."""
    ev = ns.Asset.open(assets["rna", "surface"]).evaluator()
    q = _query(10000)
    with pytest.raises(ns.UsageError, match=r"'wo': expected shape \[N, 3\] with N = 10000"):
        ev.evaluate(q.x, q.n, q.wo[0], q.wi)
    with pytest.raises(ns.UsageError, match=r"'h': expected shape \[N\]"):
        ns.Asset.open(assets["rna", "fiber"]).evaluator().evaluate(q.x, q.n, q.wo, q.wi, np.zeros(3))


@pytest.mark.parametrize("bad", [[["a", "b", "c"]] * 3, np.zeros((3, 3), complex), np.zeros((3, 3), bool), np.full((3, 3), None)])
def test_per_kind_methods_refuse_arrays_that_hold_no_real_numbers(assets, bad):
    """The per-kind methods (rna and neupress ``evaluate``, 8dna ``albedo`` / ``sample``) name the argument as
    USAGE for strings, complex numbers, booleans and objects; strings used to fail as a bare numpy ValueError."""
    q = _query(3)
    rna = ns.Asset.open(assets["rna", "surface"]).evaluator()
    with pytest.raises(ns.UsageError, match="'x': expected a real number array"):
        rna.evaluate(bad, q.n, q.wo, q.wi)
    with pytest.raises(ns.UsageError, match="real number arrays"):
        ns.Asset.open(assets["neupress", "surface"]).evaluator().evaluate(q.x, q.n, bad, q.wi)
    e8 = ns.Asset.open(assets["8dna", "surface"]).evaluator()
    with pytest.raises(ns.UsageError, match="real number arrays"):
        e8.albedo(bad, q.wo)
    with pytest.raises(ns.UsageError, match="real number arrays"):
        e8.sample(q.x, bad, 0)
    assert np.isfinite(rna.evaluate(q.x.astype(np.float32), q.n, q.wo.astype(np.int64) + 1, q.wi)[0]).all()  # real dtypes pass
