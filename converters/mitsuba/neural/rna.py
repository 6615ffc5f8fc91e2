"""Reading and evaluating an ``rna`` asset from the spec text alone.

spec/format.md (root prim, components, tensors, networks), spec/kinds/rna.md (decoder row),
spec/kinds/encodings.md (to_unit_box, safe_normalize, grid_sample_2d, triplane).
"""

from __future__ import annotations

import hashlib
import os
import re

import numpy as np

from nasset_sdk.errors import SceneError

SUPPORTED_KINDS = ("rna",)
KNOWN_KINDS = ("rna", "neupress", "8dna")


def safe_normalize(v: np.ndarray) -> np.ndarray:
    """encodings.md#normalize: non-finite -> 0; |v| <= 1e-20 -> (0, 0, 1)."""
    v = np.where(np.isfinite(v), v, 0.0).astype(np.float64)
    n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    out = v / np.maximum(n, 1e-300)
    small = n[..., 0] <= 1e-20
    out[small] = (0.0, 0.0, 1.0)
    return out


def grid_sample_2d(plane: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """encodings.md#grid2d: bilinear, texel centres at (2k+1)/W - 1, edge clamp."""
    h, w = plane.shape[0], plane.shape[1]

    def coord(t, size):
        f = (t.astype(np.float64) + 1.0) * 0.5 * size - 0.5
        f = np.where(np.isnan(f), 0.0, f)
        f = np.clip(f, 0.0, size - 1)
        i0 = np.floor(f).astype(np.int64)
        i1 = np.minimum(i0 + 1, size - 1)
        return i0, i1, (f - i0)[:, None]

    i0, i1, a = coord(u, w)
    j0, j1, b = coord(v, h)
    p = plane
    return (1 - b) * ((1 - a) * p[j0, i0] + a * p[j0, i1]) + b * ((1 - a) * p[j1, i0] + a * p[j1, i1])


def triplane(planes: np.ndarray, xn: np.ndarray) -> np.ndarray:
    """encodings.md#triplane: planes XY (u=x, v=y), YZ (u=y, v=z), ZX (u=z, v=x), summed."""
    x, y, z = xn[:, 0], xn[:, 1], xn[:, 2]
    return grid_sample_2d(planes[0], x, y) + grid_sample_2d(planes[1], y, z) + grid_sample_2d(planes[2], z, x)


class RnaAsset:
    """One rna asset file: object-space triangles, encoding box, triplane and decoder session."""

    def __init__(self, path: str, *, threads: int = 0) -> None:
        self.path = str(path)
        self._read(threads)

    def _fail(self, code: str, msg: str, prim: str | None = None):
        return SceneError(code, msg, file=self.path, prim=prim)

    def _read(self, threads: int) -> None:
        from pxr import Usd, UsdGeom

        if not os.path.exists(self.path):
            raise self._fail("SCENE_INVALID", "referenced asset file does not exist")
        try:
            stage = Usd.Stage.Open(self.path, Usd.Stage.LoadNone)
        except Exception as exc:  # pxr raises Tf errors
            raise self._fail("SCENE_INVALID", f"asset does not open as a USD layer: {str(exc).splitlines()[0][:200]}") from None
        root = stage.GetDefaultPrim()
        if not root or root.GetTypeName() != "NeuralAsset":
            raise self._fail("SCENE_INVALID", "asset has no NeuralAsset default prim")
        rp = str(root.GetPath())

        def attr(name):
            a = root.GetAttribute(name)
            if not a or not a.HasAuthoredValue():
                raise self._fail("SCENE_INVALID", f"required attribute {name} is not authored", rp)
            return a.Get()

        version = str(attr("nasset:specVersion"))
        if not re.fullmatch(r"[0-9]+\.[0-9]+", version) or int(version.split(".")[0]) != 0:
            raise self._fail("SCENE_UNSUPPORTED", f"nasset:specVersion {version!r}: this renderer reads major 0", rp)
        kind = str(attr("nasset:kind"))
        if kind not in SUPPORTED_KINDS:
            what = "a kind this renderer does not implement" if kind in KNOWN_KINDS else "not a registered kind"
            raise self._fail("SCENE_UNSUPPORTED", f"nasset:kind {kind!r} is {what} (supported: {', '.join(SUPPORTED_KINDS)})", rp)
        variant = str(attr("nasset:variant"))
        if variant != "surface":
            raise self._fail("SCENE_UNSUPPORTED", f"rna variant {variant!r} is not supported by this renderer (surface only)", rp)
        self.lo = np.asarray(attr("nasset:domainMin"), np.float32).astype(np.float64)
        self.hi = np.asarray(attr("nasset:domainMax"), np.float32).astype(np.float64)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi)) and np.all(self.hi > self.lo)):
            raise self._fail("SCENE_INVALID", "invalid encoding box", rp)

        geom = root.GetChild("Geometry")
        if not geom or geom.GetTypeName() != "Mesh":
            raise self._fail("SCENE_INVALID", "asset has no Mesh geometry", rp + "/Geometry")
        mesh = UsdGeom.Mesh(geom)
        pts = np.asarray(mesh.GetPointsAttr().Get(), np.float64).reshape(-1, 3)
        counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), np.int64)
        idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), np.int64)
        if len(pts) == 0 or len(counts) == 0 or np.any(counts != 3) or len(idx) != 3 * len(counts) or idx.min() < 0 or idx.max() >= len(pts):
            raise self._fail("SCENE_INVALID", "asset geometry is not a valid triangle mesh", str(geom.GetPath()))
        self.points = pts
        self.faces = idx.reshape(-1, 3)
        nrm = mesh.GetNormalsAttr().Get()
        self.normals = None
        if nrm is not None and len(nrm) == len(pts):
            self.normals = np.asarray(nrm, np.float64).reshape(-1, 3)
        p0, p1, p2 = (pts[self.faces[:, k]] for k in range(3))
        self.face_normals = safe_normalize(np.cross(p1 - p0, p2 - p0))

        core = stage.GetPrimAtPath(rp + "/Components/core")
        if not core:
            raise self._fail("SCENE_INVALID", "required component core is missing", rp + "/Components/core")
        stage.Load(core.GetPath())
        tri = core.GetChild("triplane")
        dec = core.GetChild("decoder")
        if not tri or not dec:
            raise self._fail("SCENE_INVALID", "component core lacks triplane or decoder", str(core.GetPath()))
        shape = [int(s) for s in tri.GetAttribute("shape").Get()]
        vals = tri.GetAttribute("values").Get()
        if len(shape) != 4 or shape[0] != 3 or shape[1] != shape[2] or vals is None or len(vals) != int(np.prod(shape)):
            raise self._fail("SCENE_INVALID", f"triplane shape {shape} does not match [3, R, R, C]", str(tri.GetPath()))
        self.planes = np.asarray(vals, np.float32).reshape(shape).astype(np.float64)
        self.channels = shape[3]

        model = dec.GetAttribute("onnx:model").Get()
        digest = dec.GetAttribute("onnx:sha256").Get()
        if model is None or len(model) == 0:
            raise self._fail("SCENE_INVALID", "decoder has no onnx:model bytes", str(dec.GetPath()))
        data = bytes(np.asarray(model, np.uint8).tobytes())
        if not digest or hashlib.sha256(data).hexdigest() != str(digest).lower():
            raise self._fail("SCENE_INVALID", "decoder onnx:sha256 does not match the model bytes", str(dec.GetPath()))
        import onnxruntime as ort

        so = ort.SessionOptions()
        so.intra_op_num_threads = int(threads)
        so.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise self._fail("SCENE_INVALID", f"decoder does not load in onnxruntime: {str(exc)[:200]}", str(dec.GetPath())) from None
        ins, outs = self.session.get_inputs(), self.session.get_outputs()
        if len(ins) != 1 or len(outs) != 1 or ins[0].shape[-1] != self.channels + 12 or outs[0].shape[-1] != 6:
            msg = f"decoder io does not match the rna contract (x: C+12 = {self.channels + 12}, y: 6)"
            raise self._fail("SCENE_INVALID", msg, str(dec.GetPath()))
        self.input_name, self.output_name = ins[0].name, outs[0].name

    # --- evaluation -------------------------------------------------------------------------------

    def shading_normal(self, prim: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
        """Object-space normal at a hit: vertex normals interpolated with barycentrics, else the face normal."""
        if self.normals is None:
            return self.face_normals[prim]
        f = self.faces[prim]
        b0 = 1.0 - b1 - b2
        n = b0[:, None] * self.normals[f[:, 0]] + b1[:, None] * self.normals[f[:, 1]] + b2[:, None] * self.normals[f[:, 2]]
        return safe_normalize(n)

    def to_unit_box(self, x: np.ndarray) -> np.ndarray:
        return (2.0 * (x - self.lo) / np.maximum(self.hi - self.lo, 1e-30) - 1.0).astype(np.float32).astype(np.float64)

    def transport(self, x: np.ndarray, n: np.ndarray, wo: np.ndarray, wi: np.ndarray, shadowed: np.ndarray, chunk: int = 65536) -> np.ndarray:
        """RGB transport T (1/sr) for object-space inputs; ``shadowed`` picks y[3:6] over y[0:3]."""
        m = len(x)
        out = np.zeros((m, 3), np.float64)
        for s in range(0, m, chunk):
            e = min(m, s + chunk)
            xn = self.to_unit_box(x[s:e])
            row = np.concatenate([triplane(self.planes, xn), xn, safe_normalize(n[s:e]), safe_normalize(wo[s:e]), safe_normalize(wi[s:e])], 1)
            y = self.session.run([self.output_name], {self.input_name: row.astype(np.float32)})[0].astype(np.float64)
            y = np.maximum(np.where(np.isfinite(y), y, 0.0), 0.0)
            out[s:e] = np.where(shadowed[s:e, None], y[:, 3:6], y[:, 0:3])
        return out
