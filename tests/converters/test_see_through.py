"""Shapes that light crosses without scattering (a clear, thin or masked surface over at most a thin medium): rna
stores smooth transport, so what they show of the scene behind them is lost, and the rna bake says so
(spec/bake.md#see-through). Found on an unseen scene: a cube with a ``mask`` BSDF of opacity 0.5 baked silently and
read 47 / 65 / 62 % of its energy in the scene, the background it showed replaced by an opaque surface."""

import warnings

import numpy as np
import pytest

pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def mi():
    from nasset_converters.mitsuba import load_mitsuba

    return load_mitsuba()


def _medium(sigma_t: float) -> dict:
    return {"type": "homogeneous", "albedo": 0.9, "sigma_t": sigma_t}


CASES = {  # id: (shape, see-through)
    "mask": ({"type": "sphere", "bsdf": {"type": "mask", "opacity": 0.5, "nested": {"type": "diffuse"}}}, True),
    "null": ({"type": "sphere", "bsdf": {"type": "null"}}, True),
    "thin": ({"type": "sphere", "bsdf": {"type": "thindielectric"}}, True),
    "clear": ({"type": "sphere", "bsdf": {"type": "dielectric"}}, True),
    "blend": ({"type": "sphere", "bsdf": {"type": "blendbsdf", "weight": 0.3, "a": {"type": "diffuse"},
                                           "b": {"type": "dielectric"}}}, True),
    "milky": ({"type": "sphere", "bsdf": {"type": "dielectric"}, "interior": _medium(0.5)}, True),  # ~50 % crosses
    "dense": ({"type": "sphere", "bsdf": {"type": "dielectric"}, "interior": _medium(20.0)}, False),  # ~0.1 %
    "rough": ({"type": "sphere", "bsdf": {"type": "roughdielectric"}, "interior": _medium(0.1)}, False),  # no delta
    "diffuse": ({"type": "sphere"}, False),
}


def test_see_through_by_bsdf_and_medium(mi):
    from nasset_converters.mitsuba.scene import see_through

    shapes = list(mi.load_dict({"type": "scene", **{k: v[0] for k, v in CASES.items()}}).shapes())
    found = see_through(mi, shapes)
    assert sorted(found) == sorted(k for k, (_, clear) in CASES.items() if clear)
    assert sorted(s.id() for s in shapes) == sorted(CASES)  # the shapes keep their ids


@pytest.mark.parametrize("sigma_t", [0.2, 1.0, 3.0])
def test_straight_through_share_matches_an_independent_estimate(mi, sigma_t):
    """The share of light crossing a unit sphere of extinction sigma_t along the function's random chords (a point
    uniform in the bounding box, a uniform direction), against the same construction with analytic ray-sphere
    intersections in numpy, on other random numbers."""
    import drjit as dr

    from nasset_converters.mitsuba.scene import _straight_through

    [ball] = mi.load_dict({"type": "scene", "b": {"type": "sphere", "bsdf": {"type": "dielectric"},
                                                   "interior": _medium(sigma_t)}}).shapes()
    got = _straight_through(mi, dr, ball, ball.interior_medium(), np.random.default_rng(1), 8192, 4)

    rng = np.random.default_rng(2)
    d = rng.normal(size=(200_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = rng.uniform(-1.0, 1.0, (len(d), 3))
    b = np.sum(p * d, axis=1)
    disc = b * b - (np.sum(p * p, axis=1) - 1.0)
    chord = 2.0 * np.sqrt(disc[disc > 0])
    want = np.exp(-sigma_t * chord).mean()
    assert abs(got - want) < 0.02, (got, want)


def test_rna_bake_warns(mi, tmp_path, capsys):
    pytest.importorskip("torch", reason="bakes need torch")
    from nasset_bakers.mitsuba.rna import bake

    (tmp_path / "s.xml").write_text(
        '<scene version="3.0.0"><shape type="cube" id="glassy"><bsdf type="mask"><float name="opacity" value="0.5"/>'
        '<bsdf type="diffuse"/></bsdf></shape></scene>')
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        bake(tmp_path / "s.xml", ["glassy"], tmp_path / "a.usdc", size="tiny", views=2, epochs=1)
    err = capsys.readouterr().err
    assert "warning: shape(s) ['glassy'] let light through unscattered" in err, err
    said = err + "".join(str(w.message) for w in caught)
    assert "closed surface" not in said  # a cube's split vertices weld into a closed surface
