"""The shader registry: one shading-vertex class per asset kind (and variant), registered where it is defined.

A shader is built once per render as ``cls(integrator)`` and shades, per wavefront, the rows that hit
instances of one asset file::

    vertex(r, idx, x, d, beta, prim, bu, bv, inst, L, rng, asset, mode) -> continuation rows or None

``r``: the rows of the wavefront; ``idx``: pixel-sample index per row (into the radiance ``L``, which
the vertex adds its light-sampled terms to); ``x``, ``d``: world hit point and ray direction; ``beta``:
path throughput; ``prim``, ``bu``, ``bv``, ``inst``: hit triangle, barycentrics and instance; ``asset``:
the asset file's index in the scene and ``mode`` the plan's per-asset settings (spec/renderer.md).
Shaders use the integrator's public helpers only (``trace``, ``occluded``, ``to_object``). A shader class
may set ``evaluator_options`` (a dict): keyword arguments of its assets' evaluators (``Asset.evaluator``).
"""

from __future__ import annotations

#: (kind, variant) -> shader class; variant None: every variant of the kind
SHADERS: dict[tuple[str, str | None], type] = {}


def register_shader(kind: str, variant: str | None = None):
    """Class decorator: the shader of ``kind`` assets (of ``variant`` only, when given)."""

    def deco(cls):
        SHADERS[(kind, variant)] = cls
        return cls

    return deco


def shader_class(kind: str, variant: str | None) -> type:
    """The registered shader of an asset of this kind and variant (KeyError when there is none)."""
    return SHADERS[(kind, variant)] if (kind, variant) in SHADERS else SHADERS[(kind, None)]
