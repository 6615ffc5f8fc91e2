"""Near-field calibration of rna surface bakes (spec/bake.md#near-field): the fit, the sphere light's irradiance
against Mitsuba, and the bake's stage and option."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_converters.mitsuba.near_field import FETCH_GRID, fetch_fraction


def _linear(start: float, slope: float) -> np.ndarray:
    """Predicted energy [F,3] whose ratio to a unit reference falls linearly with f."""
    return np.repeat((start + slope * FETCH_GRID)[:, None], 3, 1) / 3.0


@pytest.mark.parametrize("start, slope, target, want", [
    (1.10, -0.20, 1.0, 0.5),  # crossing between grid points is interpolated
    (1.10, -0.20, 0.95, 0.75),  # the network's own distant-light bias is kept, not removed
    (1.02, -0.08, 1.0, 0.25),
    (0.97, -0.10, 1.0, 0.0),  # already too dark at f = 0
    (1.015, -0.10, 1.0, 0.0),  # within MIN_NEAR_FIELD_ERROR at f = 0: the distant-light rule is kept
    (1.30, -0.10, 1.0, 1.0),  # still too bright at f = 1
])
def test_fetch_fraction_is_where_the_ratio_meets_the_target(start, slope, target, want):
    f = fetch_fraction(_linear(start, slope), np.full(3, 1.0 / 3.0), [target] * 3)
    assert f == pytest.approx(want, abs=1e-9)


def test_fetch_fraction_without_reference_energy_is_zero():
    assert fetch_fraction(_linear(1.1, -0.2), np.zeros(3), [1.0] * 3) == 0.0
    assert fetch_fraction(_linear(1.1, -0.2), np.full(3, np.nan), [1.0] * 3) == 0.0


mitsuba = pytest.importorskip("mitsuba")


def test_a_diffuse_sphere_is_predicted_right_at_its_own_surface(tmp_path):
    """Mitsuba's diffuse sphere under the calibration's sphere light against its exact transport rho/pi max(0, n.wi)
    (shadowed branch 0): with the light fetched at x (f = 0) the energies agree, which pins the light's irradiance,
    the pixels' geometry and the branch test, and the fit finds no offset (an opaque surface's light enters where
    it leaves)."""
    from nasset_converters.caster import Caster
    from nasset_converters.mitsuba import dataset as ds
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.near_field import NearFieldSettings, calibrate

    mi = load_mitsuba(None)
    rho = (0.2, 0.5, 0.8)
    path = tmp_path / "s.xml"
    path.write_text('<scene version="3.0.0"><shape type="sphere" id="s"><float name="radius" value="0.7"/>'
                    '<point name="center" x="0.3" y="-0.2" z="0.1"/><bsdf type="diffuse"><rgb name="reflectance" '
                    f'value="{rho[0]}, {rho[1]}, {rho[2]}"/></bsdf></shape></scene>')
    shapes = msc.pick_shapes(msc.load_scene(mi, path), ["s"])
    geo = msc.mesh_geometry(mi, shapes)
    center, radius = msc.bounding_sphere(geo)
    iso = msc.IsolatedAsset(mi, shapes, center, radius, max_depth=8, origin=msc.move_to_origin(mi, shapes))
    renderer = ds.Renderer(mi, iso, ds.DataSettings(max_depth=8), shadows=Caster("surface", geo))

    def exact(x, n, wo, wi):
        cos = np.maximum(np.sum(n * wi, axis=1), 0.0)[:, None]
        return np.asarray(rho)[None] / np.pi * cos, np.zeros((len(x), 3))

    lo, hi = geo.bounds()
    out = calibrate(renderer, center, radius, NearFieldSettings(views=6, res=24, spp=64), exact, 0.5 * (lo + hi), [1.0] * 3)
    assert out["pixels"] > 1000
    np.testing.assert_allclose(out["energy_ratio_f0"], 1.0, atol=0.03)
    assert out["fetch"] == 0.0, out
