"""Mitsuba's to_uv as a UsdTransform2d on USD's st (spec/bake.md#materials)."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_converters.mitsuba.usd_export import st_transform
from nasset_reference_renderer.textures import transform2d


@pytest.mark.parametrize("scale, angle, offset", [((2.0, 1.5), 20.0, (0.1, 0.3)), ((1.0, 1.0), 0.0, (0.5, 0.0)),
                                                  ((3.0, -2.0), -75.0, (-1.0, 2.0))])
def test_st_transform_maps_st_as_to_uv_maps_uv(scale, angle, offset):
    c, s = np.cos(np.radians(angle)), np.sin(np.radians(angle))
    to_uv = np.array([[1, 0, offset[0]], [0, 1, offset[1]], [0, 0, 1]]) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) \
        @ np.diag([scale[0], scale[1], 1.0])
    uv = np.random.default_rng(2).random((20, 2))
    mitsuba = (np.concatenate([uv, np.ones((20, 1))], 1) @ to_uv.T)[:, :2]  # what Mitsuba looks up
    sc, rot, tr = st_transform(to_uv)
    st = np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1)  # USD's coordinates of the same points
    usd = st @ transform2d(sc, rot, tr)[:, :2].T + np.asarray(tr)
    np.testing.assert_allclose(usd, np.stack([mitsuba[:, 0], 1.0 - mitsuba[:, 1]], 1), atol=1e-9)


def test_a_shearing_to_uv_has_no_transform2d():
    assert st_transform(np.array([[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0, 0, 1]])) is None
