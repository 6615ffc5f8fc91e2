"""Triangles into an embreex scene without embreex's copy: Embree reads the numpy arrays in place.

embreex's ``TriangleMesh`` copies a mesh into Embree one element at a time through Python indexing: 5.7 s
of CPU for the 8.4 M triangles of a 20 000-strand groom (docs/benchmarks.md#hair-setup), about 0.7 us per
triangle of any large mesh. Its ray queries, though, are the fastest this renderer has: one C loop over
the rays with the interpreter lock released. (Tracing from Python through ctypes, sixteen rays to a
call, was measured at 0.78x of embreex's ray rate with two render threads, from the lock taken back after
every call.) So an ``EmbreeScene`` is made as usual, and the geometry is attached to its Embree scene
with ``rtcSetSharedGeometryBuffer`` through ctypes, on the same library the embreex extension has loaded.

The embreex scene keeps its ``RTCScene`` in a C field. Its position is checked at run time before it is
read: the type's size, and the field beside it (``is_committed``, public) written from Python and read
back at its offset. Where any check fails (another embreex build or platform) :func:`attach_triangles`
returns False and the caller copies through embreex; both give the same hits bit for bit
(``tests/renderer/test_embree.py``).
"""

from __future__ import annotations

import ctypes
import threading

import numpy as np

from nasset_sdk.errors import error

_RTC_GEOMETRY_TYPE_TRIANGLE = 0
_RTC_BUFFER_TYPE_INDEX, _RTC_BUFFER_TYPE_VERTEX = 0, 1
_RTC_FORMAT_UINT3, _RTC_FORMAT_FLOAT3 = 0x5003, 0x9003
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
    if not (points.dtype == np.float32 and points.flags.c_contiguous and points.ndim == 2 and points.shape[1] == 3
            and faces.dtype == np.uint32 and faces.flags.c_contiguous and faces.ndim == 2 and faces.shape[1] == 3):
        raise error("USAGE", "attach_triangles takes points [V+1,3] float32 and faces [F,3] uint32, both C order")
    lib = _embree()
    handle = scene_handle(scene) if lib is not None else None
    if handle is None:
        return False
    device = lib.rtcGetSceneDevice(handle)  # counted: released below
    if not device:
        return False
    try:
        geom = lib.rtcNewGeometry(device, _RTC_GEOMETRY_TYPE_TRIANGLE)
        lib.rtcSetSharedGeometryBuffer(geom, _RTC_BUFFER_TYPE_VERTEX, 0, _RTC_FORMAT_FLOAT3, points.ctypes.data, 0,
                                       12, len(points) - 1)
        lib.rtcSetSharedGeometryBuffer(geom, _RTC_BUFFER_TYPE_INDEX, 0, _RTC_FORMAT_UINT3, faces.ctypes.data, 0, 12,
                                       len(faces))
        lib.rtcCommitGeometry(geom)
        lib.rtcAttachGeometry(handle, geom)
        lib.rtcReleaseGeometry(geom)
        code = lib.rtcGetDeviceError(device)
    finally:
        lib.rtcReleaseDevice(device)
    if code:
        raise error("SCENE_INVALID", f"Embree could not take an acceleration structure's {len(faces)} triangles: "
                    f"{_ERRORS.get(code, f'error {code}')}")
    return True


def shared_buffers(triangles: np.ndarray, mesh: tuple | None) -> tuple[np.ndarray, np.ndarray]:
    """(points [V+1,3] float32 with a spare zero row, faces [F,3] uint32) of ``mesh`` (points [V,3], faces [F,3])
    or, with mesh None, of the triangle soup ``triangles`` [F,3,3] (corner k of triangle f is point 3f + k)."""
    src = np.asarray(triangles).reshape(-1, 3) if mesh is None else np.asarray(mesh[0])
    if len(src) >= 2**32 - 1:
        raise error("SCENE_INVALID", f"{len(src)} triangle corners in one acceleration structure: Embree indexes at "
                    "most 2^32 - 2")
    points = np.zeros((len(src) + 1, 3), np.float32)
    points[:-1] = src
    faces = (np.arange(len(src), dtype=np.uint32).reshape(-1, 3) if mesh is None
             else np.ascontiguousarray(mesh[1], np.uint32))
    return points, faces


__all__ = ["attach_triangles", "loaded_embree_path", "scene_handle", "shared_buffers"]
