"""Primary hits and light visibility on an asset's own exported geometry (Embree).

The bakers whose source renderer does not hand back the geometric inputs of a hit (Cycles), or whose
geometry differs from what the reference renderer traces (Mitsuba's round curves against the fiber
prisms of spec/renderer.md#fibers), cast the pixel-centre rays themselves through the reference
renderer's :class:`nasset_reference_renderer.accel.Accel`, with fibers tessellated exactly as the renderer
tessellates them: hit point x, shading normal n (surfaces; interpolated vertex normals) or tangent t
and offset h (fibers; :func:`nasset_reference_renderer.shaders.rna_fiber.fiber_frame`), and the light
visibility V from the hit against the asset alone, cast the way the renderer casts it.
"""

from __future__ import annotations

import numpy as np


class Caster:
    """Primary hits and light visibility on the exported asset geometry (Embree)."""

    def __init__(self, variant: str, geo) -> None:
        from nasset_reference_renderer.accel import Accel

        self.variant = variant
        if variant == "fiber":
            from nasset_reference_renderer.shaders.rna_fiber import tessellate

            self.tubes = tessellate(geo.points, geo.counts, geo.widths)
            tris = self.tubes.points[self.tubes.faces]
        else:
            self.faces = np.asarray(geo.faces, np.int64)
            pts = np.asarray(geo.points, np.float64)
            tris = pts[self.faces]
            e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
            ng = np.cross(e1, e2)
            self.ng = ng / np.maximum(np.linalg.norm(ng, axis=1, keepdims=True), 1e-300)
            self.corner_n = (np.asarray(geo.normals, np.float64)[self.faces] if geo.normals is not None
                             else np.repeat(self.ng[:, None], 3, axis=1))  # flat: the face normal at every corner
        self.accel = Accel(tris, np.zeros(len(tris), np.int64))

    def hits(self, o, d) -> dict:
        """Rows that hit: {'pix', 'x', 'frame' (n or t), 'h' (fibers), 'prim'}."""
        from nasset_reference_renderer.shaders.rna_fiber import fiber_frame

        h = self.accel.trace(o, d)
        hit = np.nonzero(h.prim >= 0)[0]
        x = o[hit] + d[hit] * h.t[hit][:, None]
        prim = h.prim[hit]
        out = {"pix": hit, "x": x, "prim": prim}
        if self.variant == "fiber":
            seg = self.tubes.tri_seg[prim]
            t, hh = fiber_frame(self.tubes, seg, x, -d[hit])
            out.update(frame=t, h=hh, seg=seg)
        else:
            bu, bv = h.u[hit], h.v[hit]
            cn = self.corner_n[prim]
            n = cn[:, 0] * (1 - bu - bv)[:, None] + cn[:, 1] * bu[:, None] + cn[:, 2] * bv[:, None]
            out["frame"] = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
        return out

    def visibility(self, hit: dict, wi) -> np.ndarray:
        """1 where wi is not blocked by the asset, cast as the reference renderer casts it
        (spec/renderer.md#neural-vertex, #fibers)."""
        x = hit["x"]
        n = len(x)
        if n == 0:
            return np.zeros(0, bool)
        wi = np.broadcast_to(np.asarray(wi, np.float64), (n, 3))
        ignore = np.zeros(n, np.int64)
        if self.variant == "fiber":
            res = self.accel.trace(x, wi, ignore=ignore, exempt=self.tubes.exempt[hit["seg"]])
        else:
            return self.shadow(x, self.ng[hit["prim"]], wi)
        return ~res.self_hit

    def shadow(self, x, ng, wi) -> np.ndarray:
        """1 where wi is not blocked by the asset from surface points ``x`` [N, 3] of geometric normals ``ng`` [N, 3]
        (either side), the shadow ray offset off the surface as the reference renderer offsets it (a share of the
        scene's scale, spec/renderer.md#neural-vertex): the rule the renderer computes the input V with."""
        x, ng = np.asarray(x, np.float64), np.asarray(ng, np.float64)
        if len(x) == 0:
            return np.zeros(0, bool)
        wi = np.broadcast_to(np.asarray(wi, np.float64), x.shape)
        scale = self.accel.eps * (1.0 + np.max(np.abs(x), axis=1) / self.accel.scale)
        o = x + ng * (np.sign((ng * wi).sum(1)) * scale)[:, None]
        return ~self.accel.trace(o, wi, ignore=np.zeros(len(x), np.int64)).self_hit


def agree(hit: dict, pixels: int, keep: np.ndarray, theirs: np.ndarray) -> tuple[dict, int, int]:
    """The rows of ``hit`` (from :meth:`Caster.hits` over ``pixels`` rays) whose pixel the source renderer also
    puts on the asset (``keep`` [pixels] bool), and the mask statistics against its coverage ``theirs``
    [pixels] bool: (kept rows, pixels where the two masks disagree, pixels either covers)."""
    ours = np.zeros(pixels, bool)
    ours[hit["pix"]] = True
    rows = keep[hit["pix"]]
    kept = {k: (v[rows] if isinstance(v, np.ndarray) and len(v) == len(rows) else v) for k, v in hit.items()}
    return kept, int(np.count_nonzero(ours != theirs)), int(np.count_nonzero(ours | theirs))
