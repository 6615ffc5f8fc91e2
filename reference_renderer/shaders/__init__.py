"""Neural-asset shading: one shader module per kind (``rna_surface``, ``rna_fiber``, ``neupress``,
``eightdna``), each registered in :mod:`.registry`, and the per-asset dispatch over them.

:class:`KindShading` is used by :class:`nasset_reference_renderer.integrator.PathIntegrator` only when the
scene holds an asset of a kind other than rna; scenes of rna assets keep the integrator's own
single-call path.
"""

from __future__ import annotations

import numpy as np

from . import eightdna, neupress, rna_fiber, rna_surface  # noqa: F401  (importing a shader module registers it)
from .registry import SHADERS, register_shader, shader_class

__all__ = ["SHADERS", "KindShading", "register_shader", "shader_class", "variant_of"]


def variant_of(data) -> str:
    """The shader variant of a scene asset: ``fiber`` for rna fiber assets, else ``surface``."""
    return "fiber" if data.fiber is not None else "surface"


class KindShading:
    def __init__(self, integ) -> None:
        from ..plan import asset_mode

        self.integ = integ
        scene = integ.scene
        modes = list(integ.plan.asset_modes)
        has_dome = any(type(light).__name__ == "DomeLight" for light in scene.lights)
        for data in scene.assets[len(modes):]:  # a plan built without kind modes: the defaults
            modes.append(asset_mode(data, "auto", False, "mis", has_dome)[0])
        self.modes = modes
        built: dict[type, object] = {}
        self.shaders = []  # per asset file
        for data in scene.assets:
            cls = shader_class(data.asset.kind, variant_of(data))
            if cls not in built:
                built[cls] = cls(integ)
            self.shaders.append(built[cls])

    def vertices(self, neural, idx, x, d, beta, prim, bu, bv, inst, L, rng) -> list:
        integ = self.integ
        out = []
        asset_id = np.where(neural, integ.inst_asset[inst], -1)
        for a in np.unique(asset_id[neural]):
            r = np.nonzero(asset_id == a)[0]
            out.append(self.shaders[a].vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng, int(a), self.modes[a]))
        return out
