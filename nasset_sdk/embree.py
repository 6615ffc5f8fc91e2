"""Triangles into an embreex scene without embreex's copy: Embree reads the numpy arrays in place.

embreex's ``TriangleMesh`` copies a mesh into Embree one element at a time through Python indexing: 5.7 s
of CPU for the 8.4 M triangles of a 20 000-strand groom (docs/benchmarks.md#hair-setup), about 0.7 us per
triangle of any large mesh. Its ray queries, though, are the fastest the reference renderer and the viewer
(``nasset view``) have: one C loop over the rays with the interpreter lock released. (Tracing from Python
through ctypes, sixteen rays to a call, was measured at 0.78x of embreex's ray rate with two render threads,
from the lock taken back after every call.) So an ``EmbreeScene`` is made as usual, and the geometry is
attached to its Embree scene with ``rtcSetSharedGeometryBuffer`` through ctypes, on the same library the
embreex extension has loaded.

The embreex scene keeps its ``RTCScene`` in a C field. Its position is checked at run time before it is
read: the type's size, and the field beside it (``is_committed``, public) written from Python and read
back at its offset. Where any check fails (another embreex build or platform) :func:`attach_triangles`
returns False and the caller copies through embreex; both give the same hits bit for bit
(``tests/renderer/test_embree.py``).

Triangles that come in pairs sharing an edge (the sides and caps of fibre prisms) may be handed over as quads
(:func:`quads_of_pairs`, :func:`attach_quads`): Embree's quad is exactly two triangles, half the primitives for its
BVH (docs/benchmarks.md#hair-quads); :func:`quad_hits_as_triangles` reports a quad hit as the triangle hit.
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

from nasset_sdk.errors import error

_RTC_GEOMETRY_TYPE_TRIANGLE, _RTC_GEOMETRY_TYPE_QUAD = 0, 1
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_UINT4, _RTC_FORMAT_FLOAT3 = 0x5003, 0x5004, 0x9003
_ERRORS = {1: "unknown error", 2: "invalid argument", 3: "invalid operation", 4: "out of memory", 5: "unsupported CPU"}
#: a value written to ``EmbreeScene.is_committed`` and read back at its expected offset
_PROBE = 0x2A5A5A5A

_lock = threading.Lock()
_library: list = []  # [ctypes.CDLL or None], resolved once


def loaded_embree_path() -> str | None:
    """Path of the Embree 4 library the embreex extension links, among those mapped into this process (/proc/self/maps):
    the one in embreex's own wheel folders (``embreex.libs``, or the package folder), else the only one mapped. None
    where that is not known: not Linux, none mapped, or several and none of embreex's own (Blender's ``bpy`` maps its
    own Embree; a scene of one library must not be handed to the other)."""
    import importlib.util
    import os

    try:
        with open("/proc/self/maps") as maps:
            mapped = list(dict.fromkeys(line.split(None, 5)[-1].strip() for line in maps if "/libembree4" in line))
    except OSError:
        return None
    spec = importlib.util.find_spec("embreex")
    if spec is not None and spec.origin:
        package = os.path.dirname(os.path.realpath(spec.origin))
        own = [p for p in mapped if os.path.dirname(os.path.realpath(p)) in (package, package + ".libs")]
        if own:
            return own[0]
    return mapped[0] if len(mapped) == 1 else None


def _embree():
    """The loaded Embree library through ctypes with the functions used here declared, or None."""
    with _lock:
        if not _library:
            path = loaded_embree_path()
            lib = None
            if path is not None:
                try:
                    lib = ctypes.CDLL(path)  # already mapped: the same instance the extension uses
                    p, u, i, z = ctypes.c_void_p, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t
                    for name, res, args in (
                            ("rtcGetSceneDevice", p, [p]), ("rtcReleaseDevice", None, [p]), ("rtcGetDeviceError", i, [p]),
                            ("rtcNewGeometry", p, [p, i]), ("rtcSetSharedGeometryBuffer", None, [p, i, u, i, p, z, z, z]),
                            ("rtcCommitGeometry", None, [p]), ("rtcAttachGeometry", u, [p, p]),
                            ("rtcReleaseGeometry", None, [p])):
                        fn = getattr(lib, name)
                        fn.restype, fn.argtypes = res, args
                except (OSError, AttributeError):
                    lib = None
            _library.append(lib)
        return _library[0]


def scene_handle(scene) -> int | None:
    """The ``RTCScene`` of an embreex ``EmbreeScene``, or None where its layout is not the one checked for:
    PyObject header, then the RTCScene pointer, then the ``is_committed`` int (then the device object)."""
    header = object.__basicsize__
    pointer = ctypes.sizeof(ctypes.c_void_p)
    if type(scene).__basicsize__ != header + 3 * pointer or scene.is_committed != 0:
        return None
    scene.is_committed = _PROBE
    seen = ctypes.c_int.from_address(id(scene) + header + pointer).value
    scene.is_committed = 0
    if seen != _PROBE:
        return None
    return ctypes.c_void_p.from_address(id(scene) + header).value or None


def attach_triangles(scene, points: np.ndarray, faces: np.ndarray) -> bool:
    """Attach triangles ``faces`` [F,3] (uint32 indices) of ``points`` [V+1,3] (float32, C order, one spare
    row: Embree reads the last vertex with a 16-byte load) to the uncommitted embreex ``scene``, Embree
    reading both arrays in place: the caller keeps them alive as long as the scene. False (nothing attached)
    where the library or the scene's layout cannot be confirmed."""
    return _attach(scene, points, faces, 3)


def attach_quads(scene, points: np.ndarray, quads: np.ndarray) -> bool:
    """As :func:`attach_triangles`, for quads [Q,4] (uint32 indices; see :func:`quads_of_pairs`). Embree intersects
    quad (v0, v1, v2, v3) as the triangles (v0, v1, v3) and (v2, v3, v1) and reports a hit's (u, v) so that the first
    has barycentrics (u, v) on (v1, v3) and the second (1 - u, 1 - v) on (v3, v1)."""
    return _attach(scene, points, quads, 4)


def _attach(scene, points, index, width) -> bool:
    if not (points.dtype == np.float32 and points.flags.c_contiguous and points.ndim == 2 and points.shape[1] == 3
            and index.dtype == np.uint32 and index.flags.c_contiguous and index.ndim == 2 and index.shape[1] == width):
        raise error("USAGE", f"Embree's shared buffers take points [V+1,3] float32 and indices [F,{width}] uint32, "
                    "both C order")
    lib = _embree()
    handle = scene_handle(scene) if lib is not None else None
    if handle is None:
        return False
    device = lib.rtcGetSceneDevice(handle)  # counted: released below
    if not device:
        return False
    kind, fmt = (_RTC_GEOMETRY_TYPE_TRIANGLE, _RTC_FORMAT_UINT3) if width == 3 else (_RTC_GEOMETRY_TYPE_QUAD,
                                                                                      _RTC_FORMAT_UINT4)
    try:
        geom = lib.rtcNewGeometry(device, kind)
        lib.rtcSetSharedGeometryBuffer(geom, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3, points.ctypes.data, 0,
                                       12, len(points) - 1)
        lib.rtcSetSharedGeometryBuffer(geom, _RTC_BUFFER_TYPE_INDEX, 0, fmt, index.ctypes.data, 0, 4 * width,
                                       len(index))
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(handle, geom)
        lib.rtcReleaseGeometry(geom)
        code = lib.rtcGetDeviceError(device)
    finally:
        lib.rtcReleaseDevice(device)
    if code:
        what = "triangles" if width == 3 else "quads"
        raise error("SCENE_INVALID", f"Embree could not take an acceleration structure's {len(index)} {what}: "
                    f"{_ERRORS.get(code, f'error {code}')}")
    return True


def quads_of_pairs(faces: np.ndarray, pairs: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(quads [Q,4] uint32, tri [Q,2] int64, corners [Q,2,2] uint8): every triangle of ``faces`` [F,3] in one quad
    whose two Embree triangles (:func:`attach_quads`) are exactly it and, where ``pairs`` [P,2] (triangle indices)
    joins it to a triangle sharing one edge with it, that partner: quad (a, s0, b, s1) of triangles (a, s0, s1) and
    (b, s1, s0) with the shared edge (s0, s1). ``tri[q, h]`` is the index in ``faces`` of Embree's triangle h of quad
    q, ``corners[q, h]`` the quad corners (0-3) that are that triangle's corners 1 and 2. A triangle paired with one
    that does not share exactly one edge with it, or not at all, is a quad (c0, c1, c2, c2) alone (its second triangle
    degenerate), ``tri[q]`` then (f, f). A triangle in more than one pair is a USAGE error."""
    faces = np.asarray(faces, np.int64).reshape(-1, 3)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(pairs) and (pairs.min() < 0 or pairs.max() >= len(faces)):
        raise error("USAGE", "quads_of_pairs: a pair names a triangle that is not in faces")
    twice = np.bincount(pairs[pairs[:, 0] != pairs[:, 1]].ravel(), minlength=len(faces)) > 1
    if twice.any():
        raise error("USAGE", f"quads_of_pairs: triangle {int(np.argmax(twice))} is in more than one pair")
    a, b = faces[pairs[:, 0]], faces[pairs[:, 1]]
    same = a[:, :, None] == b[:, None, :]  # [P,3,3]
    in_b, in_a = same.any(2), same.any(1)
    distinct = lambda f: (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])  # noqa: E731
    ok = (in_b.sum(1) == 2) & (in_a.sum(1) == 2) & distinct(a) & distinct(b) & (pairs[:, 0] != pairs[:, 1])
    a, b, in_b, in_a, good = a[ok], b[ok], in_b[ok], in_a[ok], pairs[ok]
    used = np.bincount(good.ravel(), minlength=len(faces))
    rows = np.arange(len(a))
    shared = a[in_b].reshape(-1, 2)
    joined = np.stack([a[rows, np.argmin(in_b, 1)], shared[:, 0], b[rows, np.argmin(in_a, 1)], shared[:, 1]], 1)
    alone = np.nonzero(used == 0)[0]
    quads = np.concatenate([joined, faces[alone][:, [0, 1, 2, 2]]])
    tri = np.concatenate([good, np.stack([alone, alone], 1)])
    if quads.size and quads.max() >= 2**32 - 1:
        raise error("SCENE_INVALID", f"{int(quads.max()) + 1} points in one acceleration structure: Embree indexes at "
                    "most 2^32 - 2")
    # Embree's triangle h of a quad takes its corners at (0, 1, 3) or (2, 3, 1); (0, 1, 3) alone where they repeat
    corners = np.zeros((len(quads), 2, 2), np.uint8)
    single = np.arange(len(quads)) >= len(joined)
    for h, at in ((0, (0, 1, 3)), (1, (2, 3, 1))):
        own = faces[tri[:, h]]
        for k in (1, 2):
            for j in at[::-1]:  # the first of (0, 1, 3) wins a repeated corner
                hit = quads[:, j] == own[:, k]
                if h == 1:
                    hit &= ~single
                corners[hit, h, k - 1] = j
    corners[single, 1] = corners[single, 0]
    return np.ascontiguousarray(quads, np.uint32), tri, corners


def quad_hits_as_triangles(tri, corners, q, u, v) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(triangle [n] int64, u [n], v [n] float64): hits reported on quads ``q`` [n] (:func:`quads_of_pairs`'s ``tri``
    and ``corners``) with Embree's quad coordinates (u, v) [n] as the triangle that was hit and its barycentrics (the
    weights of its corners 1 and 2). A point on the shared edge (u + v = 1) is on the first triangle."""
    u = np.asarray(u, np.float64)
    v = np.asarray(v, np.float64)
    second = u + v > 1.0
    h = q.astype(np.int64) * 2 + second
    t = tri.reshape(-1)[h].astype(np.int64)
    at = corners.reshape(-1, 2)[h]
    w = (np.where(second, 0.0, 1.0 - u - v), np.where(second, 1.0 - v, u), np.where(second, u + v - 1.0, 0.0),
         np.where(second, 1.0 - u, v))  # the weight of each quad corner
    return t, np.choose(at[:, 0], w), np.choose(at[:, 1], w)


def shared_points(points: np.ndarray) -> np.ndarray:
    """``points`` [V,3] as Embree reads them in place: [V+1,3] float32, C order, a spare zero row."""
    if len(points) >= 2**32 - 1:
        raise error("SCENE_INVALID", f"{len(points)} points in one acceleration structure: Embree indexes at most "
                    "2^32 - 2")
    out = np.zeros((len(points) + 1, 3), np.float32)
    out[:-1] = points
    return out


def shared_buffers(triangles: np.ndarray, mesh: tuple | None) -> tuple[np.ndarray, np.ndarray]:
    """(points [V+1,3] float32 with a spare zero row, faces [F,3] uint32) of ``mesh`` (points [V,3], faces [F,3], ...)
    or, with mesh None, of the triangle soup ``triangles`` [F,3,3] (corner k of triangle f is point 3f + k)."""
    src = np.asarray(triangles).reshape(-1, 3) if mesh is None else np.asarray(mesh[0])
    points = shared_points(src)
    faces = (np.arange(len(src), dtype=np.uint32).reshape(-1, 3) if mesh is None
             else np.ascontiguousarray(mesh[1], np.uint32))
    return points, faces


__all__ = ["attach_quads", "attach_triangles", "loaded_embree_path", "quad_hits_as_triangles", "quads_of_pairs",
           "scene_handle", "shared_buffers",
           "shared_points"]
