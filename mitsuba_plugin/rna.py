"""Kind ``rna`` (surface and fiber variants) evaluated in Dr.Jit (spec/kinds/rna.md, spec/kinds/encodings.md).

The triplane is three ``Texture2f`` (bilinear, clamp to edge, texel centres at (i + 1/2) / R: the
spec's ``grid_sample_2d``), the decoder a :class:`~.network.DrJitNetwork` traced from its ONNX graph.
Inputs and outputs are Dr.Jit arrays of the active Mitsuba variant, in the asset's object space.

Fiber assets are rendered as the prisms of spec/renderer.md#fibers (the second implementation's
``fiber_tubes``, the same triangles in the same order as the reference renderer's), so every hit
knows its segment exactly: the tangent and h come from the segment's axis (:meth:`RnaJit.fiber_frame`),
not from the tessellation, and the triangle range of the segment and its neighbours (exempt from the
branch test) is a table lookup. Mitsuba's curve shapes (``linearcurve``/``bsplinecurve``) are round
tubes: their silhouettes and the shadows they cast differ from the prisms by up to 7.6 %, which the
spec lets a renderer do but the conformance references do not absorb.
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.asset import Asset
from nasset_sdk.errors import error
from nasset_sdk.geometry import MeshGeometry

from .network import DrJitNetwork

#: TRIPLANE_AXES of spec/kinds/encodings.md#triplane: plane k reads (u, v) = (xn[a], xn[b])
TRIPLANE_AXES = ((0, 1), (1, 2), (2, 0))
#: |t x wo| at or below which h = 0: the spec's 1e-9 (float64) is below float32's resolution of a unit
#: cross product (~1e-7 for parallel float32 vectors)
AXIS_EPS = 1e-6


def open_asset(path: str, kinds=("rna",), variants=("surface", "fiber")) -> Asset:
    """Open ``path`` with its required components, checking that the plugin renders its kind and variant
    (FILE_NOT_FOUND / FILE_UNREADABLE / format codes from the SDK; SCENE_UNSUPPORTED otherwise)."""
    asset = Asset.open(path)
    if asset.kind not in kinds:
        raise error("SCENE_UNSUPPORTED", f"the Mitsuba plugin renders kinds {', '.join(kinds)}, not {asset.kind!r}", file=str(path))
    if asset.variant not in variants:
        raise error("SCENE_UNSUPPORTED", f"the Mitsuba plugin renders the variants {', '.join(variants)}, not {asset.variant!r}",
                    file=str(path))
    return asset


def plane_textures(mi, planes: np.ndarray) -> list:
    """Three bilinear, edge-clamped ``Texture2f`` of triplane planes [3, R, R, C] (texel centres at (i + 1/2) / R)."""
    import drjit as dr

    return [mi.Texture2f(mi.TensorXf(np.ascontiguousarray(planes[k], np.float32)), use_accel=False,
                         filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp) for k in range(3)]


def triplane_lookup(mi, textures: list, xn) -> list:
    """Sum of the three bilinear plane lookups at unit-box points xn [Vector3f]: C Floats, plane order 0 + 1 + 2."""
    import drjit as dr

    # the edge clamp makes every |coordinate| >= 1 + 1/R read the edge texel: clamping to [-2, 2]
    # keeps the texture's integer conversion defined; NaN reads texel 0 (-1 is texel 0's edge)
    c = [dr.clip(dr.select(dr.isnan(xn[k]), -1.0, xn[k]), -2.0, 2.0) for k in range(3)]
    out = None
    for k, (a, b) in enumerate(TRIPLANE_AXES):
        f = textures[k].eval(mi.Point2f((c[a] + 1.0) * 0.5, (c[b] + 1.0) * 0.5))
        out = list(f) if out is None else [o + v for o, v in zip(out, f, strict=True)]
    return out


def safe_normalize(mi, v):
    """Unit vector of v [Vector3f]; zero, tiny or non-finite v -> (0, 0, 1) (encodings.md#normalize)."""
    import drjit as dr

    n = dr.norm(v)
    ok = (n > 1e-20) & dr.isfinite(n)
    return dr.select(ok, v / dr.select(ok, n, 1.0), mi.Vector3f(0, 0, 1))


class RnaJit:
    """An rna asset ready for Dr.Jit: ``transport(x, frame, wo, wi, h) -> (unshadowed, shadowed)`` Color3f (1/sr).

    ``geometry``: the triangles Mitsuba traces (the mesh, or the fiber prisms) as a MeshGeometry;
    ``fiber``: whether frame is the curve tangent and h an input."""

    kind = "rna"

    def __init__(self, mi, path: str) -> None:
        self.mi = mi
        self.path = str(path)
        asset = open_asset(path)
        planes = np.asarray(asset.tensor("core", "triplane"), np.float32)
        if planes.ndim != 4 or planes.shape[0] != 3 or planes.shape[1] != planes.shape[2]:
            raise error("TENSOR_CONTRACT", f"triplane shape {planes.shape} is not [3, R, R, C]", file=self.path)
        self.channels = int(planes.shape[-1])
        self.planes = plane_textures(mi, planes)
        self.decoder = DrJitNetwork(mi, asset.evaluable_bytes("core", "decoder"), file=self.path, prim="/Asset/core/decoder")
        lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
        self.lo = lo
        # spec/kinds/rna.md#near-field-fetch: f (0 when not authored) and the encoding box's centre (object space)
        self.fetch = asset.near_field_fetch
        self.centre = 0.5 * (lo + hi)
        self.span = np.maximum(hi - lo, 1e-30)
        self.fiber = asset.variant == "fiber"
        g = asset.geometry()
        self.geometry = self._tubes(g) if self.fiber else g

    def _tubes(self, curves) -> MeshGeometry:
        """The prisms of the curves (spec/renderer.md#fibers) and, as Dr.Jit arrays, the segment of each
        triangle and each segment's axis, radii and exempt triangle range [lo, hi)."""
        from nasset_mitsuba_renderer.rna import fiber_tubes

        mi = self.mi
        pts, faces, tri_seg, p0, p1, r0, r1, exempt = fiber_tubes(curves.points, curves.counts, curves.widths)
        if len(faces) == 0:
            raise error("GEOMETRY_INVALID", "fiber curves have no segment longer than 1e-9 (1 + max |point|)", file=self.path,
                        prim="/Asset/Geometry")
        self.tri_seg = mi.UInt32(tri_seg.astype(np.uint32))
        self.seg_p0 = mi.Float(np.ascontiguousarray(p0, np.float32).ravel())
        self.seg_p1 = mi.Float(np.ascontiguousarray(p1, np.float32).ravel())
        self.seg_r0 = mi.Float(np.asarray(r0, np.float32))
        self.seg_r1 = mi.Float(np.asarray(r1, np.float32))
        self.seg_lo = mi.UInt32(exempt[:, 0].astype(np.uint32))
        self.seg_hi = mi.UInt32(exempt[:, 1].astype(np.uint32))
        return MeshGeometry(pts.astype(np.float32), faces.astype(np.int32), None)

    def fiber_frame(self, prim, x, wo, active=True):
        """(t Vector3f, h Float, exempt lo UInt32, hi UInt32) at object-space hits x on prism triangles ``prim``
        seen along wo (spec/renderer.md#fibers): t = normalize(p1 - p0), s = clamp((x - p0).t / |p1 - p0|, 0, 1),
        r = r0 + s (r1 - r0), h = clamp((x - p0).(t x wo) / (|t x wo| r), -1, 1), 0 where |t x wo| <= 1e-9, which
        in float32 is |t x wo| <= :data:`AXIS_EPS` (a ray within 1e-6 rad of the axis: h ill-conditioned either way)."""
        import drjit as dr

        mi = self.mi
        seg = dr.gather(mi.UInt32, self.tri_seg, prim, active)
        p0 = dr.gather(mi.Point3f, self.seg_p0, seg, active)
        p1 = dr.gather(mi.Point3f, self.seg_p1, seg, active)
        axis = p1 - p0
        ln = dr.norm(axis)
        safe_ln = dr.select(ln > 0, ln, 1.0)
        t = axis / safe_ln
        rel = x - p0
        s = dr.clip(dr.dot(rel, t) / safe_ln, 0.0, 1.0)
        r0 = dr.gather(mi.Float, self.seg_r0, seg, active)
        r = r0 + s * (dr.gather(mi.Float, self.seg_r1, seg, active) - r0)
        c = dr.cross(t, wo)
        cl = dr.norm(c)
        ok = (cl > AXIS_EPS) & (r > 0)
        h = dr.select(ok, dr.dot(rel, c) / dr.select(ok, cl * r, 1.0), 0.0)
        lo = dr.gather(mi.UInt32, self.seg_lo, seg, active)
        hi = dr.gather(mi.UInt32, self.seg_hi, seg, active)
        return t, dr.clip(h, -1.0, 1.0), lo, hi

    def to_unit_box(self, x):
        """xn = 2 (x - lo) / (hi - lo) - 1 [Point3f] (encodings.md#triplane)."""
        mi = self.mi
        return mi.Vector3f(2.0 * (x - mi.ScalarPoint3f(self.lo)) / mi.ScalarVector3f(self.span) - 1.0)

    def triplane(self, xn) -> list:
        """Sum of the three bilinear plane lookups at unit-box points xn: C Floats, plane order 0 + 1 + 2."""
        return triplane_lookup(self.mi, self.planes, xn)

    def network_input(self, x, frame, wo, wi, h=None) -> list:
        """Decoder input row (spec/kinds/rna.md): surface [zeta (C), xn, n, wo, wi] (C + 12 Floats), fiber
        [zeta, xn, t, h, wo, wi] (C + 13; h NaN -> 0, clamped to [-1, 1], absent -> 0)."""
        import drjit as dr

        mi = self.mi
        xn = self.to_unit_box(x)
        row = self.triplane(xn) + [xn.x, xn.y, xn.z]
        for k, v in enumerate((frame, wo, wi)):
            u = safe_normalize(mi, mi.Vector3f(v))
            row += [u.x, u.y, u.z]
            if k == 0 and self.fiber:
                hh = mi.Float(0.0) if h is None else mi.Float(h)
                row.append(dr.clip(dr.select(dr.isnan(hh), 0.0, hh), -1.0, 1.0))
        return row

    def transport(self, x, frame, wo, wi, h=None):
        """(unshadowed, shadowed) transports [Color3f, 1/sr]: NaN/Inf -> 0, then max(0, y). frame: the
        normal (surface) or curve tangent (fiber); h [Float]: the fiber offset (ignored for surfaces)."""
        import drjit as dr

        y = self.decoder(self.network_input(x, frame, wo, wi, h))
        y = [dr.select(dr.isfinite(v), dr.maximum(v, 0.0), 0.0) for v in y]
        return self.mi.Color3f(y[0], y[1], y[2]), self.mi.Color3f(y[3], y[4], y[5])

    def technique(self, x, n, wo):
        """The continuation mixture of spec/renderer.md#neural-assets item 4 at these hits (:class:`.lobes.RnaLobes`;
        frame n: the normal, or the tangent of a fiber); ``nasset_path`` with ``lobe`` false samples the uniform
        world sphere instead."""
        from .lobes import RnaLobes

        return RnaLobes(self.mi, self.fiber, n, wo)
