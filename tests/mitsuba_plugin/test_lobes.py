"""The rna continuation mixture in the Mitsuba JIT plugin (:mod:`nasset_mitsuba_plugin.lobes`): its sampler
against its own pdf (chi-squared), its pdf against the reference renderer's mixture, and its images against the
uniform world sphere under a rotated, non-uniformly scaled instance (surface and fiber)."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_mitsuba_plugin.lobes import RnaLobes  # noqa: E402
from nasset_mitsuba_plugin.plugins import register  # noqa: E402
from nasset_mitsuba_plugin.scene import asset_shape  # noqa: E402
from nasset_mitsuba_plugin.variant import jit_mitsuba  # noqa: E402
from nasset_reference_renderer.shaders.rna_fiber import FiberContinuation  # noqa: E402
from nasset_reference_renderer.shaders.rna_surface import SurfaceContinuation  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402
from tests.mitsuba_plugin.test_neupress import _np3, _vec  # noqa: E402
from tests.stats import SIGNIFICANCE, sphere_chi2  # noqa: E402

CASES = [  # (fiber, frame: normal or tangent, wo)
    (False, (0.3, -0.5, 0.81), (0.2, 0.4, 0.89)),
    (False, (0.0, 0.0, 1.0), (0.6, 0.0, -0.8)),  # wo below the normal: the lobes flip to wo's side
    (True, (0.0, 1.0, 0.0), (0.3, 0.5, 0.81)),
    (True, (0.0, 1.0, 0.0), (0.0, 0.96, 0.28)),  # grazing: the band is clipped at the pole
]


@pytest.fixture(scope="module")
def mi():
    mi = jit_mitsuba()
    register(mi)
    return mi


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _lobes(mi, fiber, frame, wo, k):
    rep = lambda v: mi.Vector3f(*[mi.Float(np.full(k, c, np.float32)) for c in _unit(v)])  # noqa: E731
    return RnaLobes(mi, fiber, rep(frame), rep(wo))


@pytest.mark.parametrize("fiber,frame,wo", CASES)
def test_sampler_matches_its_pdf(mi, fiber, frame, wo):
    def sample(u):
        w, _ = _lobes(mi, fiber, frame, wo, len(u)).sample(mi.Point2f(*[mi.Float(u[:, k].astype(np.float32)) for k in range(2)]))
        return _np3(w)

    def pdf(v):
        return np.asarray(_lobes(mi, fiber, frame, wo, len(v)).pdf(_vec(mi, v)).numpy(), np.float64)

    p, dof, integral = sphere_chi2(sample, pdf, n_theta=30, n_phi=40, pdf_total=1.0)
    assert p > SIGNIFICANCE, (p, dof, integral)
    assert integral == pytest.approx(1.0, abs=2e-2)


@pytest.mark.parametrize("fiber,frame,wo", CASES)
def test_pdf_is_the_reference_renderers(mi, rng, fiber, frame, wo):
    """Object space = world space here: the plugin's density is the reference renderer's (float32 tolerance)."""
    w = rng.normal(size=(2000, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    rows = np.zeros(len(w), np.int64)
    f, o = _unit(frame)[None], _unit(wo)[None]
    ref = (FiberContinuation(o, f) if fiber else SurfaceContinuation(o, f)).pdf(rows, w)
    got = np.asarray(_lobes(mi, fiber, frame, wo, len(w)).pdf(_vec(mi, w)).numpy(), np.float64)
    band_edge = np.zeros(len(w), bool)
    if fiber:  # float32 rounding may put a direction on the other side of the band's edge
        z, s_o = w @ f[0], o[0] @ f[0]
        band_edge = (np.abs(z + s_o - 0.2) < 1e-5) | (np.abs(z + s_o + 0.2) < 1e-5)
    np.testing.assert_allclose(got[~band_edge], ref[~band_edge], rtol=2e-4, atol=1e-6)


def _scaled_instance_image(mi, path, lobe: bool, seed: int) -> np.ndarray:
    """An rna instance, rotated and scaled by (1.3, 0.4, 1.6), under a constant environment (radiance 1) with a
    grey floor, rendered with the mixture or the uniform world sphere (40 x 40, 64 spp)."""
    t = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        "sensor": {"type": "perspective", "fov": 35, "to_world": t().look_at(origin=[0, 0.6, 2.4], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 40, "height": 40, "rfilter": {"type": "box"}}},
        "asset": asset_shape(path, t().rotate([1, 1, 0], 35).scale([1.3, 0.4, 1.6]), mi=mi),
        "floor": {"type": "rectangle", "to_world": t().translate([0, -0.6, 0]).rotate([1, 0, 0], -90).scale(3),
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 1.0}},
    })
    integ = mi.load_dict({"type": "nasset_path", "max_depth": 3, "lobe": lobe})
    return np.asarray(mi.render(scene, integrator=integ, spp=64, seed=seed), np.float64)


@pytest.mark.parametrize("variant", ["surface", "fiber"])
def test_mixture_is_unbiased_under_nonuniform_scale(mi, tmp_path, variant):
    """The mixture (object-space density times the world Jacobian, in the continuation's weight and in both MIS
    weights) and the uniform world sphere estimate the same image: z = sum(d) / sqrt(sum(d^2)) over the pixels
    of the difference image d is ~N(0, 1) under the null; the test asks |z| < 4.5."""
    path = tmp_path / "a.usdc"
    example_builder("rna", variant=variant, size="tiny", seed=5).write(path)
    a = _scaled_instance_image(mi, str(path), True, 1)
    b = _scaled_instance_image(mi, str(path), False, 2)
    assert np.isfinite(a).all() and np.isfinite(b).all()
    d = (a - b).sum(-1)
    on = d != 0
    assert on.sum() > 200
    z = d[on].sum() / np.sqrt(np.square(d[on]).sum())
    assert abs(z) < 4.5, (z, a.mean(), b.mean())
