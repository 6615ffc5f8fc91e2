"""Neural-asset shading: one shader module per kind (``rna_surface``, ``rna_fiber``, ``neupress``,
``eightdna``), each registered in :mod:`.registry`, and the per-asset dispatch over them.

:class:`NeuralShading` is what :class:`nasset_reference_renderer.integrator.PathIntegrator` calls: per asset
file through :class:`KindShading` when the scene holds an asset of a kind other than rna; in scenes of
rna assets only, one rna surface call over every surface instance and one fiber call.
"""

from __future__ import annotations

import numpy as np

from . import eightdna, neupress, rna_fiber, rna_surface  # noqa: F401  (importing a shader module registers it)
from .registry import SHADERS, register_shader, shader_class
from .rna_fiber import FiberShading
from .rna_surface import RnaSurfaceShader

__all__ = ["SHADERS", "KindShading", "NeuralShading", "register_shader", "shader_class", "variant_of"]


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


class NeuralShading:
    """The shading vertices of every neural-asset hit of a wavefront."""

    def __init__(self, integ) -> None:
        scene = integ.scene
        insts = scene.instances
        self.kinds = None  # neupress / 8dna instances (spec/renderer.md#neupress, #8dna); None: rna only
        if any(data.asset.kind != "rna" for data in scene.assets):
            self.kinds = KindShading(integ)
        self.surface = RnaSurfaceShader(integ)
        self.fibers = None  # rna fiber instances (spec/renderer.md#fibers); None: no fiber asset in the scene
        self.inst_fiber = np.zeros(len(insts), bool)
        if any(data.fiber is not None for data in scene.assets):
            self.fibers = FiberShading(integ)
            self.inst_fiber = np.array([i.kind == "neural" and scene.assets[i.asset].fiber is not None for i in insts], bool)

    def vertices(self, neural, idx, x, d, beta, prim, bu, bv, inst, L, rng) -> list:
        """Continuation rows (or None) of each shader call over the rows where ``neural``."""
        if self.kinds is not None:
            return self.kinds.vertices(neural, idx, x, d, beta, prim, bu, bv, inst, L, rng)
        if self.fibers is None:
            return [self.surface.vertex(np.nonzero(neural)[0], idx, x, d, beta, prim, bu, bv, inst, L, rng)]
        out = []
        fib = neural & self.inst_fiber[inst]
        if (neural & ~fib).any():
            out.append(self.surface.vertex(np.nonzero(neural & ~fib)[0], idx, x, d, beta, prim, bu, bv, inst, L, rng))
        if fib.any():
            out.append(self.fibers.vertex(np.nonzero(fib)[0], idx, x, d, beta, prim, bu, bv, inst, L, rng))
        return out
