"""Shadow rays from an offset origin toward a light sample (spec/renderer.md#ray-offsets).

Shared by the mesh vertex of :mod:`nasset_reference_renderer.integrator` and the neural-asset shaders.
"""

from __future__ import annotations

import numpy as np

from .sampling import dot


def aim_shadow(x, xo, wi, dist, eps):
    """Shadow ray from the offset origin ``xo`` [n,3] toward the light sample at ``x + wi dist`` (``x`` the
    shading point, ``dist`` [n], inf for lights at infinity): (direction [n,3], tmax [n]) per
    spec/renderer.md#ray-offsets. Aimed at the sample point itself, so that the ray meets an emitting mesh
    exactly at its end: along ``wi`` from ``xo`` it would meet the mesh's plane ``offset / cos`` early at grazing
    angles and be shadowed by the light itself. With ``xo == x`` the direction is ``wi``."""
    finite = np.isfinite(dist)
    q = x + wi * np.where(finite, dist, 0.0)[:, None]
    v = q - xo
    d2 = np.sqrt(np.maximum(dot(v, v), 1e-300))
    d = np.where(finite[:, None], v / d2[:, None], wi)
    return d, np.where(finite, d2 * (1 - 1e-7) - 2 * eps, np.inf)
