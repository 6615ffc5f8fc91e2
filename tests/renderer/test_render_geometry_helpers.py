"""The column-wise geometry helpers of the renderer's setup equal numpy's reductions bit for bit."""

import numpy as np
import pytest

from nasset_reference_renderer.sampling import box3, cross3, face_normals, normalize


@pytest.mark.parametrize("scale", [1e-30, 1.0, 1e30])
def test_cross3_and_box3_equal_numpy(scale):
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 1000, 3)) * scale
    a[:5] = 0.0  # zero rows
    a[5:10] = b[5:10]  # parallel rows
    np.testing.assert_array_equal(cross3(a, b), np.cross(a, b))
    lo, hi = box3(a)
    np.testing.assert_array_equal(lo, a.min(0))
    np.testing.assert_array_equal(hi, a.max(0))


def test_face_normals_are_unit_and_zero_for_degenerate_triangles():
    rng = np.random.default_rng(1)
    tri = rng.normal(size=(200, 3, 3))
    tri[:3, 2] = tri[:3, 1]  # degenerate: two equal corners
    n = face_normals(tri)
    np.testing.assert_array_equal(n, normalize(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])))
    assert not n[:3].any()
    np.testing.assert_allclose(np.linalg.norm(n[3:], axis=1), 1.0, rtol=1e-15)
    # perpendicular to both edges, right-handed from corner 0
    np.testing.assert_allclose(np.einsum("ij,ij->i", n, tri[:, 1] - tri[:, 0]), 0.0, atol=1e-12)
    assert (np.einsum("ij,ij->i", np.cross(tri[3:, 1] - tri[3:, 0], tri[3:, 2] - tri[3:, 0]), n[3:]) > 0).all()


def test_subdivision_cage_without_normals_shades_smooth(tmp_path):
    """A catmullClark mesh (the schema's fallback scheme) without normals gets area-weighted vertex normals, as
    usdview draws its cage; with scheme none it stays faceted. Checked on a cube: each corner's normal is the
    normalised diagonal (its three faces have equal area), and a face-centre hit then interpolates them."""
    from pxr import UsdGeom

    from nasset_reference_renderer import load_scene
    from nasset_reference_renderer.testscenes import SceneBuilder

    def cube(scheme):
        b = SceneBuilder()
        b.camera((0, 0, 5), (0, 0, 0))
        b.distant("Sun", (0, 0, 1), 1.0)
        pts = [(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]
        faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
        m = b.mesh("Cube", pts, faces)
        if scheme is None:
            m.GetSubdivisionSchemeAttr().Clear()
        else:
            m.GetSubdivisionSchemeAttr().Set(scheme)
        return load_scene(b.write(tmp_path / f"cube_{scheme}.usda")), np.array(pts, np.float64)

    for scheme in (None, UsdGeom.Tokens.catmullClark, UsdGeom.Tokens.loop):
        scene, pts = cube(scheme)
        n = scene.tri_normals.reshape(-1, 3)
        corners = scene.triangles.reshape(-1, 3)
        np.testing.assert_allclose(n, corners / np.sqrt(3.0), atol=1e-12)  # outward diagonals at every corner
        assert any("control cage" in w for w in scene.warnings)
    flat, _ = cube(UsdGeom.Tokens.none)
    ng = np.repeat(flat.tri_ng[:, None], 3, 1).reshape(-1, 3)
    np.testing.assert_allclose(np.abs(flat.tri_normals.reshape(-1, 3)), np.abs(ng), atol=1e-12)


def test_singular_transforms_flatten_or_collapse_geometry(tmp_path):
    """A Cube flattened by a scale of 0 along y draws as a square; a Sphere and a PointInstancer instance scaled to 0
    draw nothing (tests/stage_scenes.py::check_singular_transforms). The scene was SCENE_INVALID ("a value of the wrong
    type or shape (LinAlgError: Singular matrix)"): every instance's inverse and the normals' inverse transpose."""
    import warnings

    from nasset_reference_renderer import RenderSettings, load_scene, render
    from tests.stage_scenes import check_singular_transforms

    def reference(scene, spp, seed=0, max_depth=None, width=None, height=None):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # "tessellated into N triangles"
            settings = RenderSettings(spp=spp, seed=seed, max_depth=max_depth, width=width, height=height)
            return render(load_scene(scene), settings).image[..., :3]

    check_singular_transforms(reference, tmp_path, spp=64)
