"""Shading vertex of rna surface assets (spec/renderer.md#neural-assets).

The vertex itself is :meth:`nasset_reference_renderer.integrator.PathIntegrator.rna_surface_vertex`: scenes
holding only rna assets call it directly, in one batch over every rna instance; this shader puts it
behind the common interface for scenes that mix kinds.
"""

from __future__ import annotations

from .registry import register_shader


@register_shader("rna", "surface")
class RnaSurfaceShader:
    def __init__(self, integ) -> None:
        self.integ = integ

    def vertex(self, r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset: int | None = None, mode: dict | None = None):
        return self.integ.rna_surface_vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng)
