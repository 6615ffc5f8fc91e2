"""The render plan: what a scene needs, decided before any ray is traced (``--explain`` prints it).

* Lights that cannot reach any geometry (zero power; a RectLight with every scene point behind
  it) get no shadow rays; they stay visible to rays that hit them.
* A vertex continues its path only when something else in the scene could reflect light back
  to it: another object, or a non-planar mesh (which can reflect onto itself); a lone planar mesh too when its
  material transmits or has a sharp lobe (GGX alpha below SHARP_ALPHA), which light samples rarely meet. A lone neural
  asset has all of its own interreflection baked in, so it gets next-event estimation only
  (light-sampling weight 1; unbiased because every reachable light is sampled).
* Each asset file loads only the components the renderer evaluates (the kind's required ones);
  optional components (importance sampling networks, PRT, other quality levels) stay unloaded.
* The rna decoder returns both branches from one evaluation; the branch is picked by the shadow
  ray, and light samples blocked by another object are not evaluated at all.
* neupress: the ``sampling`` component is loaded only when the lobe technique is used
  (``neupress_sampling`` lobe or mis), ``prt`` only in PRT mode. 8dna: ``core`` only.
  (spec/renderer.md#neupress, spec/renderer.md#8dna)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nasset_sdk.errors import UsageError

from .lights import DomeLight, RectLight

#: GGX alpha below which a lone planar mesh keeps its continuation rays: light samples rarely fall in so narrow a lobe
#: (a mirror floor under a dome, NEE only, showed almost none of the dome it reflects)
SHARP_ALPHA = 0.1
NEUPRESS_SAMPLING = ("auto", "dome", "lobe", "mis")
EIGHTDNA_SAMPLING = ("light", "flow", "mis")
#: rna continuation densities (spec/renderer.md#neural-assets): the uniform sphere, or the kind's mixture of it with
#: lobes (surfaces: cosine and mirror lobes; fibers: forward lobe and specular-cone band)
RNA_CONTINUATION = ("uniform", "lobes")


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
    asset_modes: list = field(default_factory=list)  # per scene.assets entry: kind-specific rendering choices

    @property
    def nee(self) -> list[int]:
        """Indices of the scene's lights sampled at shading vertices (``light_nee``)."""
        return [k for k, on in enumerate(self.light_nee) if on]

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


def asset_mode(data, neupress_sampling: str, prt: bool, eightdna_sampling: str, has_dome: bool,
               rna_continuation: str = "lobes") -> tuple[dict, list, str]:
    """(mode, extra components to load, explain note) for one asset file."""
    a = data.asset
    present = a.components()
    if a.kind == "neupress":
        if prt:
            if "prt" not in present:
                raise UsageError(f"--prt: asset {data.path} has no 'prt' component")
            if not has_dome:
                raise UsageError("--prt needs a DomeLight in the scene (the PRT lighting is the dome's SH projection)")
            return ({"kind": "neupress", "prt": True, "sampling": None, "lobe": False}, ["prt"],
                    f"neupress {data.path.name}: PRT (SH2 transport . dome SH projection; other lights and shadow rays unused"
                    + ("; near-field fetch unused: a dome is the same from every point)" if data.near_field_fetch > 0 else ")"))
        mode = neupress_sampling
        has_s = "sampling" in present
        if mode == "auto":
            mode = "mis" if has_s else "dome"
        lobe = mode in ("lobe", "mis") and has_s
        tech = "Gaussian lobe (sampling network)" if lobe else "uniform sphere"
        what = {"dome": "light sampling only", "lobe": f"{tech} sampling only (delta lights light-sampled)",
                "mis": f"light sampling + {tech} sampling, power heuristic"}[mode]
        fetch = data.near_field_fetch
        near = (f"; light fetched at x + {fetch:g} (c_w - x), S, f_r, lobe and asset-visibility at x (near-field "
                "fetch, kinds/neupress.md)" if fetch > 0 else "")
        return ({"kind": "neupress", "prt": False, "sampling": mode, "lobe": lobe}, ["sampling"] if lobe else [],
                f"neupress {data.path.name}: far-field transport, {what}; shadow rays ignore the asset (surface "
                f"reflection: asset-visibility from the same ray){near}")
    if a.kind == "8dna":
        what = {"light": "emitter sampling only", "flow": "GGX lobe / flow direction sampling only (delta lights emitter-sampled)",
                "mis": "emitter sampling + GGX lobe / flow direction sampling, power heuristic"}[eightdna_sampling]
        return ({"kind": "8dna", "sampling": eightdna_sampling}, [],
                f"8dna {data.path.name}: direct lobe at x_o + flow sample u_i (uniform channel), {what}; "
                "continuation: direct lobe with probability P_d, else flow direction from u_i")
    if a.kind == "rna":
        lobes = "forward lobe + specular-cone band" if a.variant == "fiber" else "cosine lobe + mirror lobe"
        what = "the uniform sphere" if rna_continuation == "uniform" else f"uniform sphere + {lobes}"
        fetch = data.near_field_fetch
        near = (f"; light fetched at x + {fetch:g} (c_w - x), branch from x (near-field fetch, kinds/rna.md)"
                if fetch > 0 else "")
        return ({"kind": a.kind}, [], f"rna {a.variant} {data.path.name}: continuation directions from {what} "
                                      f"(MIS with the same density){near}")
    return {"kind": a.kind}, [], ""


def make_plan(scene, *, width, height, spp, max_depth, tile, batch, neupress_sampling: str = "auto", prt: bool = False,
              eightdna_sampling: str = "mis", rna_continuation: str = "lobes") -> RenderPlan:
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
            mt = scene.materials
            mats = [m for m in (inst.material, inst.back_material) if m >= 0]
            glass = mt.transmits and any(mt.transmission[m] > 0 for m in mats)
            sharp = any(min(mt.alpha[m], mt.textures[m].sharpest_alpha if m < len(mt.textures) and mt.textures[m]
                            else np.inf) < SHARP_ALPHA for m in mats)
            indirect[i] = (others or not inst.planar or glass or sharp) and max_depth > 1
            why = "other objects present" if others else ("non-planar, may reflect onto itself" if not inst.planar
                                                            else "transmits: light passes through it" if glass
                                                            else "a sharp lobe light samples rarely meet" if sharp
                                                            else "lone planar mesh: NEE only")
            inst_notes.append(f"mesh {inst.prim} ({inst.n_tri} tris): {'indirect on' if indirect[i] else 'indirect off'}"
                              f" ({why})")
    if neupress_sampling not in NEUPRESS_SAMPLING:
        raise UsageError(f"neupress sampling must be one of {NEUPRESS_SAMPLING}, got {neupress_sampling!r}")
    if eightdna_sampling not in EIGHTDNA_SAMPLING:
        raise UsageError(f"8dna sampling must be one of {EIGHTDNA_SAMPLING}, got {eightdna_sampling!r}")
    if rna_continuation not in RNA_CONTINUATION:
        raise UsageError(f"rna continuation must be one of {RNA_CONTINUATION}, got {rna_continuation!r}")
    has_dome = any(isinstance(light, DomeLight) for light in scene.lights)
    comps, modes, kind_notes = {}, [], []
    for data in scene.assets:
        a = data.asset
        mode, extra, note = asset_mode(data, neupress_sampling, prt, eightdna_sampling, has_dome, rna_continuation)
        required = list(a.contract.required_components(a.variant)) + extra
        skipped = [n for n in a.components() if n not in required]
        comps[str(data.path)] = (required, skipped)
        modes.append(mode)
        if note:
            kind_notes.append(note)
    spp_pass = max(1, min(spp, batch // max(1, tile * tile)))
    notes = []
    if any(m["kind"] == "rna" for m in modes):
        notes.append("rna: one decoder evaluation yields both branches; shadow-ray visibility picks one; "
                     "light samples blocked by other objects are not evaluated")
    notes += kind_notes
    return RenderPlan(width, height, spp, max_depth, tile, batch, spp_pass, light_nee, light_notes, indirect, inst_notes,
                      comps, notes, modes)
