"""Kind ``rna`` (surface variant) evaluated in Dr.Jit (spec/kinds/rna.md, spec/kinds/encodings.md).

The triplane is three ``Texture2f`` (bilinear, clamp to edge, texel centres at (i + 1/2) / R: the
spec's ``grid_sample_2d``), the decoder a :class:`~.network.DrJitNetwork` traced from its ONNX graph.
Inputs and outputs are Dr.Jit arrays of the active Mitsuba variant, in the asset's object space.
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.asset import Asset
from nasset_sdk.errors import error

from .network import DrJitNetwork

#: TRIPLANE_AXES of spec/kinds/encodings.md#triplane: plane k reads (u, v) = (xn[a], xn[b])
TRIPLANE_AXES = ((0, 1), (1, 2), (2, 0))


def open_asset(path: str, kinds=("rna",)) -> Asset:
    """Open ``path`` with its required components, checking that the plugin renders its kind and variant
    (FILE_NOT_FOUND / FILE_UNREADABLE / format codes from the SDK; SCENE_UNSUPPORTED otherwise)."""
    asset = Asset.open(path)
    if asset.kind not in kinds:
        raise error("SCENE_UNSUPPORTED", f"the Mitsuba plugin renders kinds {', '.join(kinds)}, not {asset.kind!r}", file=str(path))
    if asset.variant != "surface":
        raise error("SCENE_UNSUPPORTED", f"the Mitsuba plugin renders the surface variant, not {asset.variant!r}", file=str(path))
    return asset


def safe_normalize(mi, v):
    """Unit vector of v [Vector3f]; zero, tiny or non-finite v -> (0, 0, 1) (encodings.md#normalize)."""
    import drjit as dr

    n = dr.norm(v)
    ok = (n > 1e-20) & dr.isfinite(n)
    return dr.select(ok, v / dr.select(ok, n, 1.0), mi.Vector3f(0, 0, 1))


class RnaJit:
    """An rna surface asset ready for Dr.Jit: ``transport(x, n, wo, wi) -> (unshadowed, shadowed)`` Color3f (1/sr)."""

    def __init__(self, mi, path: str) -> None:
        import drjit as dr

        self.mi = mi
        self.path = str(path)
        asset = open_asset(path)
        planes = np.asarray(asset.tensor("core", "triplane"), np.float32)
        if planes.ndim != 4 or planes.shape[0] != 3 or planes.shape[1] != planes.shape[2]:
            raise error("TENSOR_CONTRACT", f"triplane shape {planes.shape} is not [3, R, R, C]", file=self.path)
        self.channels = int(planes.shape[-1])
        self.planes = [mi.Texture2f(mi.TensorXf(np.ascontiguousarray(planes[k])), use_accel=False,
                                    filter_mode=dr.FilterMode.Linear, wrap_mode=dr.WrapMode.Clamp) for k in range(3)]
        self.decoder = DrJitNetwork(mi, asset.network_bytes("core", "decoder"), file=self.path, prim="/Asset/core/decoder")
        lo, hi = (np.asarray(a, np.float64) for a in asset.domain)
        self.lo = lo
        self.span = np.maximum(hi - lo, 1e-30)
        self.geometry = asset.geometry()

    def to_unit_box(self, x):
        """xn = 2 (x - lo) / (hi - lo) - 1 [Point3f] (encodings.md#triplane)."""
        mi = self.mi
        return mi.Vector3f(2.0 * (x - mi.ScalarPoint3f(self.lo)) / mi.ScalarVector3f(self.span) - 1.0)

    def triplane(self, xn) -> list:
        """Sum of the three bilinear plane lookups at unit-box points xn: C Floats, plane order 0 + 1 + 2."""
        import drjit as dr

        mi = self.mi
        # the edge clamp makes every |coordinate| >= 1 + 1/R read the edge texel: clamping to [-2, 2]
        # keeps the texture's integer conversion defined; NaN reads texel 0 (-1 is texel 0's edge)
        c = [dr.clip(dr.select(dr.isnan(xn[k]), -1.0, xn[k]), -2.0, 2.0) for k in range(3)]
        out = None
        for k, (a, b) in enumerate(TRIPLANE_AXES):
            f = self.planes[k].eval(mi.Point2f((c[a] + 1.0) * 0.5, (c[b] + 1.0) * 0.5))
            out = list(f) if out is None else [o + v for o, v in zip(out, f, strict=True)]
        return out

    def network_input(self, x, n, wo, wi) -> list:
        """Decoder input row [zeta (C), xn, n, wo, wi] as C + 12 Floats (spec/kinds/rna.md)."""
        mi = self.mi
        xn = self.to_unit_box(x)
        row = self.triplane(xn) + [xn.x, xn.y, xn.z]
        for v in (n, wo, wi):
            u = safe_normalize(mi, mi.Vector3f(v))
            row += [u.x, u.y, u.z]
        return row

    def transport(self, x, n, wo, wi):
        """(unshadowed, shadowed) transports [Color3f, 1/sr]: NaN/Inf -> 0, then max(0, y)."""
        import drjit as dr

        y = self.decoder(self.network_input(x, n, wo, wi))
        y = [dr.select(dr.isfinite(v), dr.maximum(v, 0.0), 0.0) for v in y]
        return self.mi.Color3f(y[0], y[1], y[2]), self.mi.Color3f(y[3], y[4], y[5])

    def technique(self, x, n, wo):
        """None: continuations leave an rna asset uniformly on the world sphere (spec/renderer.md#neural-assets item 4)."""
        return None
