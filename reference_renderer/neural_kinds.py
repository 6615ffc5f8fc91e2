"""Per-kind dispatch of neural-asset shading vertices (rna, neupress, 8dna).

Used by :class:`nasset_reference_renderer.integrator.PathIntegrator` only when the scene holds an asset of
a kind other than rna; scenes of rna assets keep the integrator's own single-call path.
"""

from __future__ import annotations

import numpy as np


class KindShading:
    def __init__(self, integ) -> None:
        from .neural_8dna import EightdnaShader
        from .neural_neupress import NeupressShader
        from .plan import asset_mode

        self.integ = integ
        scene = integ.scene
        modes = list(integ.plan.asset_modes)
        has_dome = any(type(light).__name__ == "DomeLight" for light in scene.lights)
        for data in scene.assets[len(modes):]:  # a plan built without kind modes: the defaults
            modes.append(asset_mode(data, "auto", False, "mis", has_dome)[0])
        self.modes = modes
        self.asset_kind = np.array([data.asset.kind for data in scene.assets])
        self.shaders = {}
        if "neupress" in self.asset_kind:
            self.shaders["neupress"] = NeupressShader(integ)
        if "8dna" in self.asset_kind:
            self.shaders["8dna"] = EightdnaShader(integ)

    def vertices(self, neural, idx, x, d, beta, prim, bu, bv, inst, L, rng) -> list:
        integ = self.integ
        out = []
        asset_id = np.where(neural, integ.inst_asset[inst], -1)
        for a in np.unique(asset_id[neural]):
            r = np.nonzero(asset_id == a)[0]
            kind = self.asset_kind[a]
            if kind == "rna" and integ.scene.assets[a].fiber is not None:
                out.append(integ.fibers.vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng))
            elif kind == "rna":
                out.append(integ._neural_vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng))
            else:
                out.append(self.shaders[kind].vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng, int(a), self.modes[a]))
        return out
