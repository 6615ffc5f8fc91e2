"""Kind ``rna``: Relightable Neural Assets (papers/rna-relightable-neural-assets.txt, spec/kinds/rna.md).

Triplane features zeta(x) [C] summed from three planes, concatenated with the property vector and
decoded by an MLP into two RGB transports: y[:, 0:3] when the light is NOT occluded by the asset
itself (unshadowed), y[:, 3:6] when it is (shadowed). Transport T is outgoing radiance per unit
irradiance of a distant light along wi (units 1/sr), negative outputs clamp to 0.

Network input, in this order (object-space unit vectors, wo and wi pointing away from the point):
    surface: [zeta (C), xn (3), n (3), wo (3), wi (3)]            width C + 12
    fiber:   [zeta (C), xn (3), t (3), h (1), wo (3), wi (3)]     width C + 13
"""

from __future__ import annotations

import numpy as np

from ..errors import UsageError
from . import ComponentSpec, KindContract, NetworkSpec, TensorSpec, new_evaluator, register_kind
from .encodings import safe_normalize, to_unit_box, triplane
from .query import Evaluator, Query, check_shapes

SIZES = {  # preset -> (triplane resolution, channels, hidden layers, hidden width)
    "tiny": (8, 4, 2, 16),
    "small": (64, 8, 4, 64),
    "hq": (128, 8, 4, 128),
}


class RnaKind(KindContract):
    id = "rna"
    variants = ("surface", "fiber")
    paper = "rna-relightable-neural-assets.txt"

    def components(self, variant: str) -> dict[str, ComponentSpec]:
        width = "C+12" if variant == "surface" else "C+13"
        return {
            "core": ComponentSpec(
                required=True,
                purpose="evaluation",
                tensors={"triplane": TensorSpec(("3", "R", "R", "C"), "plane,v,u,channel", "feature planes XY, YZ, ZX")},
                networks={"decoder": NetworkSpec((("x", width),), (("y", "6"),), "transport MLP, unshadowed RGB then shadowed RGB")},
            ),
            "portable": ComponentSpec(
                required=False,
                purpose="portable-evaluation",
                networks={"decoder": NetworkSpec(
                    (("x", "3"), ("frame", "3"), ("wo", "3"), ("wi", "3")) + ((("h", "1"),) if variant == "fiber" else ()),
                    (("unshadowed", "3"), ("shadowed", "3")),
                    "the decoder with its encodings: raw queries to clamped transports (nasset_sdk.portable)")},
            ),
        }

    def build_random(self, rng, *, variant="surface", size="small", geometry=None):
        from ..asset import AssetBuilder
        from ..errors import UsageError
        from ..geometry import CurvesGeometry, MeshGeometry
        from ..networks import random_mlp

        if size not in SIZES:
            raise UsageError(f"size must be one of {sorted(SIZES)}")
        res, ch, layers, hidden = SIZES[size]
        b = AssetBuilder("rna", variant=variant)
        if geometry is None:
            geometry = _example_curves(rng) if variant == "fiber" else example_mesh()
        if not isinstance(geometry, (MeshGeometry, CurvesGeometry)):
            geometry = MeshGeometry.from_trimesh(geometry)
        b.set_geometry(geometry)
        core = b.component("core", required=True, purpose="evaluation", quality=None)
        core.add_tensor("triplane", rng.normal(0, 0.5, (3, res, res, ch)), dtype="float16", layout="plane,v,u,channel")
        width = ch + (12 if variant == "surface" else 13)
        core.add_network("decoder", random_mlp(rng, [width] + [hidden] * layers + [6]))
        b.provenance = {"generator": "random", "size": size}
        return b

    def probe_unit_columns(self, variant, component, network, input_name, width):
        """n (or t), wo, wi of the decoder input (module docstring); the portable graph's direction inputs."""
        if component == "portable":
            return (0,) if input_name in ("frame", "wo", "wi") else ()
        f = 0 if variant == "surface" else 1
        c = width - 12 - f
        return (c + 3, c + 6 + f, c + 9 + f) if component == "core" and c >= 0 else ()

    def evaluator(self, asset, **options):
        return new_evaluator(RnaEvaluator, asset, options)


#: rows per onnxruntime call and per input-assembly pass: small enough that the [rows, C + 12] input,
#: the triplane temporaries and the MLP activations stay in a core's L2 cache (a 65536-row batch runs
#: the decoder about 2x slower per row on a 2-core machine). Results do not depend on it.
CHUNK = 8192


def _unit_into(out: np.ndarray, v: np.ndarray) -> None:
    """out[:] = safe_normalize(v), bit for bit, without its copies when v is finite and nonzero."""
    v = np.asarray(v, np.float64)
    if v.ndim == 2 and v.shape[1] == 3 and np.isfinite(v).all():
        n = v[:, 0] * v[:, 0]  # the same sum, in the same order, as np.linalg.norm over the last axis
        n += v[:, 1] * v[:, 1]
        n += v[:, 2] * v[:, 2]
        np.sqrt(n, out=n)
        if n.min(initial=np.inf) > 1e-20 and n.max(initial=0.0) < np.inf:  # (an overflowing norm: safe_normalize rescales)
            np.divide(v, n[:, None], out=out, casting="unsafe")  # float64 quotient rounded to float32
            return
    out[:] = safe_normalize(v)


class RnaEvaluator(Evaluator):
    """Evaluates an rna asset's transport; all directions and points in object space.

    :meth:`radiance` (the interface every kind shares) picks the branch by ``Query.shadowed``;
    :meth:`evaluate` returns both branches."""

    def __init__(self, asset, *, intra_threads: int = 0, batch: int = 65536) -> None:
        self.asset = asset
        self.fiber = asset.variant == "fiber"
        self.planes = np.ascontiguousarray(asset.tensor("core", "triplane"), np.float32)
        self.lo, self.hi = asset.domain
        self.session = asset.session("core", "decoder", intra_threads=intra_threads)
        self.batch = int(batch)

    def network_input(self, x, frame, wo, wi, h=None) -> np.ndarray:
        """[N, C+12] (surface; frame = normal) or [N, C+13] (fiber; frame = tangent, h in [-1, 1])."""
        xn = to_unit_box(x, self.lo, self.hi)
        c = self.planes.shape[-1]
        f = 1 if self.fiber else 0
        inp = np.empty((len(xn), c + 12 + f), np.float32)
        inp[:, :c] = triplane(self.planes, xn)
        inp[:, c:c + 3] = xn
        _unit_into(inp[:, c + 3:c + 6], frame)
        if self.fiber:
            inp[:, c + 6] = 0.0 if h is None else np.clip(np.nan_to_num(np.asarray(h, np.float32)), -1, 1)
        _unit_into(inp[:, c + 6 + f:c + 9 + f], wo)
        _unit_into(inp[:, c + 9 + f:c + 12 + f], wi)
        return inp

    def evaluate(self, x, frame, wo, wi, h=None) -> tuple[np.ndarray, np.ndarray]:
        """Transport (unshadowed [N,3], shadowed [N,3]) in 1/sr, clamped to finite values >= 0.

        x, frame (normal, or fiber tangent), wo, wi: [N, 3] object space; h [N] (fiber, default 0)."""
        file = str(getattr(self.asset, "path", "")) or None
        n = check_shapes(file, x=x, frame=frame, wo=wo, wi=wi)
        if h is not None and np.shape(h) != (n,):
            raise UsageError(f"argument 'h': expected shape [N] with N = {n}, got {tuple(np.shape(h))}", file=file)
        out = np.empty((n, 6), np.float32)
        step = max(1, min(self.batch, CHUNK))
        for s in range(0, n, step):
            e = min(n, s + step)
            inp = self.network_input(x[s:e], frame[s:e], wo[s:e], wi[s:e], None if h is None else h[s:e])
            out[s:e] = self.session.run(None, {"x": inp})[0]
        # non-finite -> 0 and negative -> 0 in place (nan_to_num + maximum, without their copies)
        out[~np.isfinite(out)] = 0.0
        np.maximum(out, 0.0, out=out)
        return out[:, :3], out[:, 3:]

    def _radiance(self, q: Query) -> np.ndarray:
        if q.h is not None and not self.fiber:
            self._no_h(q)
        unshadowed, shadowed = self.evaluate(q.x, q.n, q.wo, q.wi, q.h)
        return np.where(q.shadowed[:, None], shadowed, unshadowed)


def example_mesh():
    import trimesh

    from ..geometry import MeshGeometry

    return MeshGeometry.from_trimesh(trimesh.creation.icosphere(subdivisions=2, radius=0.5))


def _example_curves(rng):
    from ..geometry import CurvesGeometry

    n_curves, seg = 24, 6
    roots = rng.uniform(-0.3, 0.3, (n_curves, 3)) * [1, 0, 1]
    t = np.linspace(0, 1, seg + 1)[None, :, None]
    pts = roots[:, None, :] + t * np.array([0.0, 1.0, 0.0]) + 0.05 * np.sin(6 * t) * np.array([1.0, 0, 0])
    pts = pts.reshape(-1, 3).astype(np.float32)
    return CurvesGeometry(pts, np.full(n_curves, seg + 1, np.int32), np.full(len(pts), 0.01, np.float32))


register_kind(RnaKind())
