"""Mitsuba's analytic shapes as triangle meshes (converters/mitsuba/analytic.py, spec/bake.md#analytic-shapes):
the tessellation against Mitsuba's own analytic intersection, and bakes of an analytic shape."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba", reason="needs mitsuba (pip install 'nasset-sdk[mitsuba]')")

from nasset_converters.mitsuba import analytic  # noqa: E402
from nasset_converters.mitsuba import scene as msc  # noqa: E402

#: each class under a rotation and, where Mitsuba allows one, a non-uniform scale (rotation axes normalised: Mitsuba does
#: not normalise them, and its disk does not follow the sheared transform that results)
SHAPES = {
    "Sphere": '<shape type="sphere" id="s"><point name="center" x="0.3" y="-0.2" z="0.1"/><float name="radius" value="0.7"/>'
              '<bsdf type="roughdielectric"><float name="alpha" value="0.2"/></bsdf>'
              '<medium type="homogeneous" name="interior"><float name="sigma_t" value="3"/></medium></shape>',
    "Rectangle": '<shape type="rectangle" id="s"><transform name="to_world"><scale x="0.5" y="1.5" z="1"/>'
                 '<rotate x="0.70710678" y="0.70710678" z="0" angle="50"/><translate x="0.2" y="0" z="-0.3"/></transform></shape>',
    "Disk": '<shape type="disk" id="s"><transform name="to_world"><scale x="1.2" y="0.6" z="1"/>'
            '<rotate x="0" y="0.70710678" z="0.70710678" angle="-35"/></transform></shape>',
    "Cylinder": '<shape type="cylinder" id="s"><point name="p0" x="-0.4" y="-0.3" z="0.1"/>'
                '<point name="p1" x="0.5" y="0.6" z="-0.2"/><float name="radius" value="0.25"/></shape>',
}


@pytest.fixture(scope="module")
def mi():
    from nasset_converters.mitsuba import load_mitsuba

    m = load_mitsuba()
    m.set_log_level(m.LogLevel.Error)
    return m


def _scene(mi, tmp_path, cls):
    xml = tmp_path / f"{cls}.xml"
    xml.write_text(f'<scene version="3.0.0">{SHAPES[cls]}</scene>')
    return msc.load_scene(mi, xml)


def _cast(mi, scene, o, d):
    import drjit as dr

    ray = mi.Ray3f(mi.Point3f(*(o[:, k] for k in range(3))), mi.Vector3f(*(d[:, k] for k in range(3))))
    si = scene.ray_intersect(ray)
    valid = np.asarray(si.is_valid(), bool)
    t = np.asarray(dr.select(si.is_valid(), si.t, 0.0), np.float64)
    n = np.stack([np.asarray(si.n[k], np.float64) for k in range(3)], 1)
    return valid, t, n


@pytest.mark.parametrize("cls", list(SHAPES))
def test_tessellation_matches_mitsubas_analytic_intersection(mi, tmp_path, cls):
    """Rays from all around, aimed into the shape's box: Mitsuba's analytic hits and the tessellation's hits agree
    in coverage (up to silhouette rays), distance (the chord's sagitta) and normal (the face is a chord)."""
    scene = _scene(mi, tmp_path, cls)
    shape = scene.shapes()[0]
    assert msc.shape_class(shape) == cls
    mesh = analytic.as_mesh(mi, shape)
    assert mesh.is_mesh() and mesh.id() == "s"
    mesh_scene = mi.load_dict({"type": "scene", "m": mesh})
    bb = shape.bbox()
    lo, hi = np.array(bb.min, np.float64), np.array(bb.max, np.float64)
    size = float(np.linalg.norm(hi - lo))
    rng = np.random.default_rng(3)
    n = 20000
    dirs = rng.normal(size=(n, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    target = lo + rng.random((n, 3)) * (hi - lo)
    o = target - 3.0 * size * dirs
    va, ta, na = _cast(mi, scene, o, dirs)
    vm, tm, nm = _cast(mi, mesh_scene, o, dirs)
    assert va.mean() > 0.2
    both = va & vm
    assert (va != vm).mean() < 0.01  # rays through the sliver between chord and arc at the silhouette
    # a ray grazing the silhouette can cross the sliver and meet the tessellation on a far chord: a few rays
    assert np.quantile(np.abs(ta - tm)[both], 0.995) < 2e-3 * size
    assert np.median(np.abs(ta - tm)[both]) < 3e-4 * size
    # geometric normals: the mesh's face normal is a chord's, within pi / segments of the analytic one
    cos = np.abs(np.sum(na * nm, axis=1))[both]
    assert np.quantile(cos, 0.01) > np.cos(np.pi / 48)
    # the tessellation's points lie on the analytic surface
    pts, faces, nrm = analytic.world_mesh(mi, shape)
    assert np.isfinite(pts).all() and np.allclose(np.linalg.norm(nrm, axis=1), 1.0)
    tri = pts[faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    # faces are wound so that their normal points along the analytic normal (outward)
    assert (np.sum(face_n * nrm[faces].mean(1), axis=1) > 0).all()


def test_sphere_is_closed_and_cylinder_open():
    for cls, closed in (("Sphere", True), ("Cylinder", False), ("Disk", False), ("Rectangle", False)):
        _, faces, _, _ = analytic.local_mesh(cls)
        assert msc.is_closed(faces) == closed, cls
    pts, faces, nrm, uv = analytic.local_mesh("Sphere")
    assert np.allclose(np.linalg.norm(pts, axis=1), 1.0) and np.allclose(pts, nrm)
    assert len(np.unique(np.round(pts, 9), axis=0)) == len(pts)  # no duplicated seam or pole vertices
    assert uv.min() >= 0.0 and uv.max() <= 1.0
    with pytest.raises(ValueError):
        analytic.local_mesh("SDFGrid")


def test_pick_shapes_tessellates_and_keeps_material_and_medium(mi, tmp_path):
    scene = _scene(mi, tmp_path, "Sphere")
    [mesh] = msc.pick_shapes(scene, ["s"])
    assert mesh.is_mesh() and mesh.id() == "s"
    assert "RoughDielectric" in str(mesh.bsdf()) and mesh.interior_medium() is not None
    geo = msc.mesh_geometry(mi, [mesh])  # closed: no open-surface warning
    center, radius = msc.bounding_sphere(geo)
    assert np.allclose(center, [0.3, -0.2, 0.1], atol=1e-3) and abs(radius - 0.7) < 2e-3


def test_a_translucent_sphere_bakes_and_stands_in_for_itself(tmp_path):
    """A ``sphere`` with a dielectric boundary and a medium bakes to a closed asset whose bounds are the sphere's, and
    the accuracy bench takes it in place of the analytic shape (the bench's scene-asset check)."""
    pytest.importorskip("torch", reason="bakes need torch")
    from nasset_bakers.mitsuba.rna import bake
    from nasset_benchmarks.accuracy import check_asset_fits
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_sdk.asset import Asset

    xml = tmp_path / "ball.xml"
    xml.write_text('<scene version="3.0.0">' + SHAPES["Sphere"] + "</scene>")
    out = tmp_path / "ball.usdc"
    bake(xml, ["s"], out, size="tiny", views=4, epochs=2, quiet=True)
    asset = Asset.open(out)
    geo = asset.geometry()
    assert msc.is_closed(np.asarray(geo.faces))
    np.testing.assert_allclose(np.linalg.norm(geo.points - [0.3, -0.2, 0.1], axis=1), 0.7, atol=1e-5)
    mi = load_mitsuba()
    [fit] = check_asset_fits(mi, msc.load_scene(mi, xml), {"s": out})
    assert fit["bounds_offset"] < 1e-4
