"""The render plan: what a scene needs, decided before any ray is traced (``--explain`` prints it).

* Lights that cannot reach any geometry (zero power; a RectLight with every scene point behind
  it) get no shadow rays; they stay visible to rays that hit them.
* A vertex continues its path only when something else in the scene could reflect light back
  to it: another object, or a non-planar mesh (which can reflect onto itself). A lone neural
  asset has all of its own interreflection baked in, so it gets next-event estimation only
  (light-sampling weight 1; unbiased because every reachable light is sampled).
* Each asset file loads only the components the renderer evaluates (the kind's required ones);
  optional components (importance sampling networks, PRT, other quality levels) stay unloaded.
* The rna decoder returns both branches from one evaluation; the branch is picked by the shadow
  ray, and light samples blocked by another object are not evaluated at all.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .lights import RectLight


@dataclass
class RenderPlan:
    width: int
    height: int
    spp: int
    max_depth: int
    tile: int
    batch: int
    spp_per_pass: int
    light_nee: list
    light_notes: list
    instance_indirect: np.ndarray
    instance_notes: list
    components: dict = field(default_factory=dict)  # asset file -> (loaded, skipped)
    notes: list = field(default_factory=list)

    def explain(self) -> str:
        lines = [f"render plan: {self.width}x{self.height}, {self.spp} spp, max depth {self.max_depth}",
                 f"  tiles {self.tile}x{self.tile}, {self.spp_per_pass} spp per pass (<= {self.batch} camera rays in flight)",
                 "  lights:"]
        lines += [f"    {n}" for n in self.light_notes] or ["    (none)"]
        lines.append("  objects:")
        lines += [f"    {n}" for n in self.instance_notes] or ["    (none)"]
        if self.components:
            lines.append("  neural asset components:")
            for f, (loaded, skipped) in self.components.items():
                lines.append(f"    {f}: load {loaded or '[]'}; skip {skipped or '[]'}")
        lines += [f"  {n}" for n in self.notes]
        return "\n".join(lines)


def make_plan(scene, *, width, height, spp, max_depth, tile, batch) -> RenderPlan:
    lo, hi = scene.bounds
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    has_geo = len(scene.triangles) > 0
    light_nee, light_notes = [], []
    for light in scene.lights:
        name = f"{type(light).__name__} {light.prim}"
        if light.power_is_zero():
            light_nee.append(False)
            light_notes.append(f"{name}: zero power, no shadow rays")
        elif not has_geo:
            light_nee.append(False)
            light_notes.append(f"{name}: no geometry to light, no shadow rays")
        elif isinstance(light, RectLight) and ((corners - light.c) @ light.n <= 0).all():
            light_nee.append(False)
            light_notes.append(f"{name}: every object is behind it, no shadow rays")
        else:
            light_nee.append(True)
            kind = "delta" if light.delta else "sampled + MIS with BSDF"
            light_notes.append(f"{name}: shadow rays ({kind})")
    n_inst = len(scene.instances)
    indirect = np.zeros(n_inst, bool)
    inst_notes = []
    for i, inst in enumerate(scene.instances):
        others = n_inst > 1
        if inst.kind == "neural":
            indirect[i] = others and max_depth > 1
            why = "other objects present" if others else "nothing else can reflect light back: NEE only"
            inst_notes.append(f"neural {inst.prim} ({scene.assets[inst.asset].path.name}): "
                              f"{'indirect on' if indirect[i] else 'indirect off'} ({why})")
        else:
            indirect[i] = (others or not inst.planar) and max_depth > 1
            why = "other objects present" if others else ("non-planar, may reflect onto itself" if not inst.planar
                                                            else "lone planar mesh: NEE only")
            inst_notes.append(f"mesh {inst.prim} ({inst.n_tri} tris): {'indirect on' if indirect[i] else 'indirect off'}"
                              f" ({why})")
    comps = {}
    for data in scene.assets:
        a = data.asset
        required = list(a.contract.required_components(a.variant))
        skipped = [n for n in a.components() if n not in required]
        comps[str(data.path)] = (required, skipped)
    spp_pass = max(1, min(spp, batch // max(1, tile * tile)))
    notes = []
    if scene.assets:
        notes.append("rna: one decoder evaluation yields both branches; shadow-ray visibility picks one; "
                     "light samples blocked by other objects are not evaluated")
    return RenderPlan(width, height, spp, max_depth, tile, batch, spp_pass, light_nee, light_notes, indirect, inst_notes,
                      comps, notes)
