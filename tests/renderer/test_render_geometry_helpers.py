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
