"""Reading and evaluating an ``rna`` asset from the spec text alone.

spec/format.md (root prim, components, tensors, networks), spec/kinds/rna.md (decoder row, both
variants), spec/kinds/encodings.md (to_unit_box, safe_normalize, grid_sample_2d, triplane),
spec/renderer.md#fibers (the prism tessellation of ``fiber`` curves and the h input).

:func:`open_root` and :func:`read_network` are the shared asset-file readers of every kind module.
"""

from __future__ import annotations

import hashlib
import os
import re

import numpy as np

from nasset_sdk.asset import NEAR_FIELD_FETCH, check_near_field_fetch
from nasset_sdk.errors import SceneError

KNOWN_KINDS = ("rna", "neupress", "8dna")
#: sides of the prism around each fiber segment (spec/renderer.md#fibers)
TUBE_SIDES = 8


def safe_normalize(v: np.ndarray) -> np.ndarray:
    """encodings.md#normalize: non-finite -> 0; a length that overflows is recomputed after dividing by
    max |v_k|; |v| <= 1e-20 -> (0, 0, 1)."""
    v = np.where(np.isfinite(v), v, 0.0).astype(np.float64)
    with np.errstate(over="ignore"):
        n = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    big = np.isinf(n[..., 0])
    if big.any():
        v[big] /= np.abs(v[big]).max(-1, keepdims=True)
        n[big] = np.sqrt(np.sum(v[big] * v[big], axis=-1, keepdims=True))
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


def _fail(path, code, msg, prim=None):
    return SceneError(code, msg, file=str(path), prim=prim)


def open_root(path: str):
    """(stage, root prim, attr(name) reader) of an asset file, checking existence, the NeuralAsset
    default prim and the spec major version (spec/format.md)."""
    from pxr import Tf, Usd

    from nasset_sdk.paths import open_checked_stage, outer_file

    if not os.path.exists(outer_file(str(path))):  # a file, or a layer inside a usdz package
        raise _fail(path, "SCENE_INVALID", "referenced asset file does not exist")
    try:
        # untrusted input (spec/security.md): probed in a child, every asset path checked, then composed
        stage = open_checked_stage(str(path), Usd.Stage.LoadNone)
    except Tf.ErrorException as exc:
        raise _fail(path, "SCENE_INVALID", f"asset does not open as a USD layer: {str(exc).splitlines()[0][:200]}") from None
    root = stage.GetDefaultPrim()
    if not root or root.GetTypeName() != "NeuralAsset":
        raise _fail(path, "SCENE_INVALID", "asset has no NeuralAsset default prim")
    rp = str(root.GetPath())

    def attr(name):
        a = root.GetAttribute(name)
        if not a or not a.HasAuthoredValue():
            raise _fail(path, "SCENE_INVALID", f"required attribute {name} is not authored", rp)
        return a.Get()

    version = str(attr("nasset:specVersion"))
    if not re.fullmatch(r"[0-9]+\.[0-9]+", version) or int(version.split(".")[0]) != 0:
        raise _fail(path, "SCENE_UNSUPPORTED", f"nasset:specVersion {version!r}: this renderer reads major 0", rp)
    near_field_fetch(path, root)
    return stage, root, attr


def near_field_fetch(path, root) -> float:
    """``nasset:nearFieldFetch`` of an asset's root prim (spec/kinds/rna.md#near-field-fetch): 0 when not authored;
    NEAR_FIELD_INVALID naming the file and attribute for a value outside [0, 1], of another type, or non-zero on a
    kind other than rna and neupress."""
    a = root.GetAttribute(NEAR_FIELD_FETCH)
    k = root.GetAttribute("nasset:kind")
    return check_near_field_fetch(a.Get() if a and a.HasAuthoredValue() else None, str(k.Get()) if k else "",
                                  {"file": str(path), "prim": str(root.GetPath()), "attribute": NEAR_FIELD_FETCH})


def asset_kind(path: str) -> str:
    """``nasset:kind`` of an asset file (after the checks of :func:`open_root`)."""
    stage, _, attr = open_root(path)  # keep the stage alive while reading
    kind = str(attr("nasset:kind"))
    del stage
    return kind


def read_tensor(path, comp, name, shape_check=None) -> np.ndarray:
    """Tensor ``name`` of a loaded component prim as float64 array of its ``shape``."""
    t = comp.GetChild(name)
    if not t:
        raise _fail(path, "SCENE_INVALID", f"component {comp.GetName()} lacks tensor {name}", str(comp.GetPath()))
    shape = [int(v) for v in (t.GetAttribute("shape").Get() or [])]
    vals = t.GetAttribute("values").Get()
    if vals is None or len(vals) != int(np.prod(shape)) or (shape_check is not None and not shape_check(shape)):
        raise _fail(path, "SCENE_INVALID", f"tensor {name} has shape {shape} / {0 if vals is None else len(vals)} values", str(t.GetPath()))
    return np.asarray(vals, np.float32).reshape(shape).astype(np.float64)


def check_network(path, prim, data: bytes) -> None:
    """The security rules of spec/security.md#networks on untrusted model bytes, before onnxruntime sees them: no
    external data (onnxruntime would read it from files relative to the working folder), allowed operators only,
    shapes [N, fixed width], then the runtime probe (time and memory bound, finite outputs, independent rows, with
    the kind's unit-vector input columns); a typed error naming the network otherwise."""
    from nasset_sdk.errors import error
    from nasset_sdk.kinds import get_kind
    from nasset_sdk.netprobe import make_job, probe_once
    from nasset_sdk.networks import check_model_bytes, info_from_model

    loc = dict(file=str(path), prim=str(prim.GetPath()), attribute="onnx:model")
    check_model_bytes(data, **loc)
    root = prim.GetStage().GetDefaultPrim()
    kind, variant = (str(root.GetAttribute(a).Get()) for a in ("nasset:kind", "nasset:variant"))
    component, network = prim.GetParent().GetName(), prim.GetName()
    info = info_from_model(data)
    units = tuple(get_kind(kind).probe_unit_columns(variant, component, network, n, int(w))
                  for n, w in zip(info.input_names, info.input_widths, strict=True))
    job = make_job(data, info, units)
    found = probe_once([job])[job.key]
    if found:
        raise error(found[0][0], f"runtime probe: {found[0][1]}", **loc)


def read_network(path, comp, name, threads: int, in_width: int, out_width: int):
    """(onnxruntime session, input name, output name) of network ``name``: sha256-checked bytes, io widths."""
    dec = comp.GetChild(name)
    if not dec:
        raise _fail(path, "SCENE_INVALID", f"component {comp.GetName()} lacks network {name}", str(comp.GetPath()))
    model = dec.GetAttribute("onnx:model").Get()
    digest = dec.GetAttribute("onnx:sha256").Get()
    if model is None or len(model) == 0:
        raise _fail(path, "SCENE_INVALID", f"{name} has no onnx:model bytes", str(dec.GetPath()))
    data = bytes(np.asarray(model, np.uint8).tobytes())
    if not digest or hashlib.sha256(data).hexdigest() != str(digest).lower():
        raise _fail(path, "SCENE_INVALID", f"{name} onnx:sha256 does not match the model bytes", str(dec.GetPath()))
    check_network(path, dec, data)
    import onnxruntime as ort

    so = ort.SessionOptions()
    so.intra_op_num_threads = int(threads)
    so.log_severity_level = 3
    try:
        session = ort.InferenceSession(data, sess_options=so, providers=["CPUExecutionProvider"])
    except Exception as exc:
        raise _fail(path, "SCENE_INVALID", f"{name} does not load in onnxruntime: {str(exc)[:200]}", str(dec.GetPath())) from None
    ins, outs = session.get_inputs(), session.get_outputs()
    if len(ins) != 1 or len(outs) != 1 or ins[0].shape[-1] != in_width or outs[0].shape[-1] != out_width:
        raise _fail(path, "SCENE_INVALID", f"{name} io does not match the kind contract (x: {in_width}, y: {out_width})", str(dec.GetPath()))
    return checked(session, path, dec), ins[0].name, outs[0].name


def checked(session, path, prim):
    """``session`` run through the SDK's wrapper: at most the rows the runtime probe ran it at per run (memory grows
    with the rows, spec/security.md#networks), failures typed NETWORK_RUNTIME naming the network."""
    from nasset_sdk.networks import CheckedSession

    return CheckedSession(session, None, file=str(path), prim=str(prim.GetPath()), attribute="onnx:model")


def read_triangles(path, geom, rp):
    """(points, faces, vertex normals or None) of an asset's triangle Mesh ``Geometry``."""
    from pxr import UsdGeom

    if not geom or geom.GetTypeName() != "Mesh":
        raise _fail(path, "SCENE_INVALID", "asset has no Mesh geometry", rp + "/Geometry")
    mesh = UsdGeom.Mesh(geom)
    pts = np.asarray(mesh.GetPointsAttr().Get(), np.float64).reshape(-1, 3)
    counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get(), np.int64)
    idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get(), np.int64)
    if len(pts) == 0 or len(counts) == 0 or np.any(counts != 3) or len(idx) != 3 * len(counts) or idx.min() < 0 or idx.max() >= len(pts):
        raise _fail(path, "SCENE_INVALID", "asset geometry is not a valid triangle mesh", str(geom.GetPath()))
    nrm = mesh.GetNormalsAttr().Get()
    normals = np.asarray(nrm, np.float64).reshape(-1, 3) if nrm is not None and len(nrm) == len(pts) else None
    return pts, idx.reshape(-1, 3), normals


def fiber_tubes(points, counts, widths, sides: int = TUBE_SIDES):
    """spec/renderer.md#fibers: closed ``sides``-gon prisms around every non-degenerate segment.

    -> (vertices [V,3], faces [F,3], tri_seg [F], p0, p1 [S,3], r0, r1 [S], exempt [S,2]); ``exempt``
    is the triangle range [lo, hi) of a segment and its neighbours in the same curve."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    r = 0.5 * np.asarray(widths, np.float64)
    seg_a, seg_first = [], [0]
    start = 0
    for c in counts:
        seg_a.extend(range(start, start + int(c) - 1))
        start += int(c)
        seg_first.append(len(seg_a))
    a = np.asarray(seg_a, np.int64)
    p0, p1, r0, r1 = p[a], p[a + 1], r[a], r[a + 1]
    live = np.linalg.norm(p1 - p0, axis=1) > 1e-9 * (1.0 + float(np.abs(p).max(initial=0.0)))
    t = safe_normalize(p1 - p0)
    helper = np.where(np.abs(t[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    b1 = safe_normalize(np.cross(t, helper))
    b2 = np.cross(t, b1)
    th = 2.0 * np.pi * np.arange(sides) / sides
    ring = np.cos(th)[None, :, None] * b1[:, None] + np.sin(th)[None, :, None] * b2[:, None]
    verts = np.concatenate([p0[:, None] + r0[:, None, None] * ring, p1[:, None] + r1[:, None, None] * ring], 1)
    k = np.arange(sides)
    kn = (k + 1) % sides
    fan = np.arange(1, sides - 1)
    local = np.concatenate([np.stack([k, kn, sides + kn], 1), np.stack([k, sides + kn, sides + k], 1),
                            np.stack([np.zeros_like(fan), fan + 1, fan], 1), np.stack([np.full_like(fan, sides), sides + fan, sides + fan + 1], 1)])
    ids = np.nonzero(live)[0]
    faces = (ids[:, None, None] * 2 * sides + local[None]).reshape(-1, 3)
    tri_seg = np.repeat(ids, len(local))
    first = np.concatenate([[0], np.cumsum(np.where(live, len(local), 0))])
    seg_first = np.asarray(seg_first, np.int64)
    curve = np.repeat(np.arange(len(counts)), np.asarray(counts, np.int64) - 1)
    seg = np.arange(len(a))
    lo = np.maximum(seg - 1, seg_first[curve]) if len(a) else seg
    hi = np.minimum(seg + 1, seg_first[curve + 1] - 1) if len(a) else seg
    exempt = np.stack([first[lo], first[hi + 1]], 1).astype(np.int64) if len(a) else np.zeros((0, 2), np.int64)
    return verts.reshape(-1, 3), faces.astype(np.int64), tri_seg.astype(np.int64), p0, p1, r0, r1, exempt


class RnaAsset:
    """One rna asset file: object-space triangles (the mesh, or the fiber prisms), encoding box, triplane and decoder session."""

    kind = "rna"

    def __init__(self, path: str, *, threads: int = 0) -> None:
        self.path = str(path)
        self._read(threads)

    def _fail(self, code: str, msg: str, prim: str | None = None):
        return SceneError(code, msg, file=self.path, prim=prim)

    def _read(self, threads: int) -> None:

        stage, root, attr = open_root(self.path)
        rp = str(root.GetPath())
        kind = str(attr("nasset:kind"))
        if kind != "rna":
            raise self._fail("SCENE_INVALID", f"nasset:kind {kind!r} is not rna", rp)
        self.variant = str(attr("nasset:variant"))
        if self.variant not in ("surface", "fiber"):
            raise self._fail("SCENE_UNSUPPORTED", f"rna variant {self.variant!r} is not supported by this renderer (surface, fiber)", rp)
        self.fiber = self.variant == "fiber"
        self.lo = np.asarray(attr("nasset:domainMin"), np.float32).astype(np.float64)
        self.hi = np.asarray(attr("nasset:domainMax"), np.float32).astype(np.float64)
        if not (np.all(np.isfinite(self.lo)) and np.all(np.isfinite(self.hi)) and np.all(self.hi > self.lo)):
            raise self._fail("SCENE_INVALID", "invalid encoding box", rp)
        # spec/kinds/rna.md#near-field-fetch: f (0 when not authored) and the encoding box's centre c
        self.fetch = near_field_fetch(self.path, root)
        self.centre = 0.5 * (self.lo + self.hi)

        geom = root.GetChild("Geometry")
        self.normals = None
        if self.fiber:
            self._read_curves(geom, rp)
        else:
            self.points, self.faces, self.normals = read_triangles(self.path, geom, rp)
        p0, p1, p2 = (self.points[self.faces[:, k]] for k in range(3))
        self.face_normals = safe_normalize(np.cross(p1 - p0, p2 - p0))

        core = stage.GetPrimAtPath(rp + "/Components/core")
        if not core:
            raise self._fail("SCENE_INVALID", "required component core is missing", rp + "/Components/core")
        stage.Load(core.GetPath())
        self.planes = read_tensor(self.path, core, "triplane", lambda sh: len(sh) == 4 and sh[0] == 3 and sh[1] == sh[2])
        self.channels = self.planes.shape[3]
        width = self.channels + (13 if self.fiber else 12)
        self.session, self.input_name, self.output_name = read_network(self.path, core, "decoder", threads, width, 6)

    def _read_curves(self, geom, rp) -> None:
        """Linear BasisCurves -> prisms (spec/renderer.md#fibers)."""
        from pxr import UsdGeom

        if not geom or geom.GetTypeName() != "BasisCurves":
            raise self._fail("SCENE_INVALID", "fiber asset has no BasisCurves geometry", rp + "/Geometry")
        cv = UsdGeom.BasisCurves(geom)
        gp = str(geom.GetPath())
        if (cv.GetTypeAttr().Get() or "cubic") != "linear":
            raise self._fail("SCENE_UNSUPPORTED", "fiber curves must be linear BasisCurves", gp)
        pts = np.asarray(cv.GetPointsAttr().Get() or [], np.float64).reshape(-1, 3)
        counts = np.asarray(cv.GetCurveVertexCountsAttr().Get() or [], np.int64)
        widths = cv.GetWidthsAttr().Get()
        if widths is None:
            pv = UsdGeom.PrimvarsAPI(geom).GetPrimvar("widths")
            widths = pv.ComputeFlattened() if pv and pv.HasAuthoredValue() else None
        w = np.asarray(widths if widths is not None else [], np.float64).ravel()  # format.md#geometry: one width > 0 per point
        if (len(pts) == 0 or len(counts) == 0 or np.any(counts < 2) or counts.sum() != len(pts) or len(w) != len(pts)
                or not np.all(np.isfinite(pts)) or not np.all(np.isfinite(w)) or np.any(w <= 0)):
            raise self._fail("SCENE_INVALID", "fiber curves are invalid (counts, points or per-vertex widths)", gp)
        (self.points, self.faces, self.tri_seg, self.seg_p0, self.seg_p1, self.seg_r0, self.seg_r1,
         self.seg_exempt) = fiber_tubes(pts, counts, w)
        if len(self.faces) == 0:
            raise self._fail("SCENE_INVALID", "fiber curves have no non-degenerate segment", gp)

    # --- fibers -------------------------------------------------------------------------------------

    def fiber_frame(self, prim: np.ndarray, x: np.ndarray, wo: np.ndarray):
        """(tangent t [n,3], h [n], exempt triangle ranges [n,2]) at object-space hits on triangles ``prim``."""
        seg = self.tri_seg[prim]
        p0, p1 = self.seg_p0[seg], self.seg_p1[seg]
        axis = p1 - p0
        ln = np.linalg.norm(axis, axis=1)
        t = axis / np.maximum(ln, 1e-300)[:, None]
        rel = x - p0
        s = np.clip(np.einsum("ij,ij->i", rel, t) / np.maximum(ln, 1e-300), 0.0, 1.0)
        r = self.seg_r0[seg] + s * (self.seg_r1[seg] - self.seg_r0[seg])
        c = np.cross(t, wo)
        cl = np.linalg.norm(c, axis=1)
        ok = (cl > 1e-9) & (r > 0)
        h = np.where(ok, np.einsum("ij,ij->i", rel, c) / np.where(ok, cl * r, 1.0), 0.0)
        return t, np.clip(h, -1.0, 1.0), self.seg_exempt[seg]

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

    def transport(self, x: np.ndarray, n: np.ndarray, wo: np.ndarray, wi: np.ndarray, shadowed: np.ndarray, h: np.ndarray | None = None,
                  chunk: int = 65536) -> np.ndarray:
        """RGB transport T (1/sr) for object-space inputs; ``shadowed`` picks y[3:6] over y[0:3].

        Fiber variant: ``n`` is the tangent t and ``h`` the offset input (spec/kinds/rna.md)."""
        m = len(x)
        out = np.zeros((m, 3), np.float64)
        for s in range(0, m, chunk):
            e = min(m, s + chunk)
            xn = self.to_unit_box(x[s:e])
            cols = [triplane(self.planes, xn), xn, safe_normalize(n[s:e])]
            if self.fiber:
                hh = np.zeros(e - s) if h is None else np.asarray(h[s:e], np.float64)
                cols.append(np.clip(np.where(np.isnan(hh), 0.0, hh), -1.0, 1.0)[:, None])
            row = np.concatenate([*cols, safe_normalize(wo[s:e]), safe_normalize(wi[s:e])], 1)
            y = self.session.run([self.output_name], {self.input_name: row.astype(np.float32)})[0].astype(np.float64)
            y = np.maximum(np.where(np.isfinite(y), y, 0.0), 0.0)
            out[s:e] = np.where(shadowed[s:e, None], y[:, 3:6], y[:, 0:3])
        return out
