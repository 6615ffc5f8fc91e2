"""Bounds applied to untrusted assets (spec/security.md#bounds) and the version this SDK writes."""

SPEC_VERSION = "0.3"  # the newest version this SDK writes
#: the version a written file declares: the lowest one that describes it (a 0.1 reader keeps reading
#: every file that uses nothing newer), spec/format.md#versioning
VERSION_OF_COMPONENT = {"portable": "0.2"}
#: root attributes added by a minor version (written only when they say something: spec/format.md#versioning)
VERSION_OF_ATTRIBUTE = {"nasset:nearFieldFetch": "0.3"}
BASE_SPEC_VERSION = "0.1"


def written_version(components, attributes=()) -> str:
    """specVersion for a file with these component names and these optional root attributes authored: the highest
    minor any of them needs."""
    needed = [VERSION_OF_COMPONENT.get(c, BASE_SPEC_VERSION) for c in components]
    needed += [VERSION_OF_ATTRIBUTE.get(a, BASE_SPEC_VERSION) for a in attributes]
    return max(needed, key=lambda v: tuple(int(x) for x in v.split(".")), default=BASE_SPEC_VERSION)
#: MAJOR versions this SDK reads; any MINOR of a known MAJOR is read (spec/format.md#versioning).
SUPPORTED_MAJOR = 0
MAX_TENSOR_ELEMENTS = 1 << 27  # 134 M elements (256 MiB at fp16)
MAX_TENSOR_RANK = 8
MAX_NETWORK_BYTES = 64 << 20
MAX_NETWORK_WIDTH = 4096
OPSET_MIN = 13
OPSET_MAX = 21
ALLOWED_OP_DOMAINS = ("", "ai.onnx")
TENSOR_DTYPES = ("float16", "float32")
#: Geometry arrays (spec/security.md#bounds), checked on declared lengths before values are used.
MAX_GEOMETRY_POINTS = 1 << 24  # 16.8 M points / normals / widths (192 MiB as float3)
MAX_GEOMETRY_FACES = 1 << 25  # 33.5 M triangles: faceVertexCounts; faceVertexIndices <= 3x this
MAX_ARRAY_ELEMENTS = 1 << 24  # any other array-valued field (extent, names, ...)
#: Reading a file may decode at most this many array bytes beyond DECODE_RATIO x its size (crate compresses
#: integer and float arrays: a 34 KB file can otherwise decode to GBs).
DECODE_BASE_BYTES = 64 << 20
#: Dictionaries and lists inside one field nest at most this deep (a reader walks them).
MAX_VALUE_DEPTH = 32
DECODE_RATIO = 16
#: Structure of an *asset* layer (spec/security.md#bounds). Readers walk every spec of a layer in Python and
#: compose it: a crate stores an empty prim in ~9 bytes, so a 1.8 MB file of 200 000 prims validated clean in 18 s
#: at 437 MB, and 10x the prims took minutes and GBs. The largest asset the SDK writes (8dna with portable graphs)
#: has 24 prims and 93 properties; 10 000 specs (prims, variant sets, variants, properties, relationship targets
#: and connections, time samples) is ~80x that and reads in well under a second. Scenes are not bounded by it.
MAX_ASSET_SPECS = 10_000
#: Prims of an asset nest at most this deep (the SDK writes 4: /Asset/Looks/Fallback/PreviewSurface); every
#: reader that spells a spec's path pays its depth, so a 10 000-deep chain costs 10^8 characters per walk.
MAX_ASSET_DEPTH = 64
_ARRAY_BOUNDS = {
    "points": MAX_GEOMETRY_POINTS, "normals": MAX_GEOMETRY_POINTS, "widths": MAX_GEOMETRY_POINTS,
    "curveVertexCounts": MAX_GEOMETRY_POINTS, "faceVertexCounts": MAX_GEOMETRY_FACES, "faceVertexIndices": 3 * MAX_GEOMETRY_FACES,
    "values": MAX_TENSOR_ELEMENTS, "shape": MAX_TENSOR_RANK, "onnx:model": MAX_NETWORK_BYTES,
}


def array_bound(name: str, field: str = "default") -> int:
    """Most elements an array-valued field named ``name`` may hold."""
    if field != "default" and field != "timeSamples":
        return MAX_ARRAY_ELEMENTS
    return _ARRAY_BOUNDS.get(name, MAX_ARRAY_ELEMENTS)


def decoded_bound(file_bytes: int) -> int:
    """Most array bytes a file of ``file_bytes`` may decode to."""
    return DECODE_BASE_BYTES + DECODE_RATIO * int(file_bytes)
MAX_NETWORK_NODES = 4096
#: Most rows one run of a network is given: readers split larger batches (networks.CheckedSession), and the
#: runtime probe runs every network once at this size under its memory bound (memory grows with the rows).
#: 16 384 holds a reference-renderer wavefront (8 192 camera rays) and its light rows for two lights in one run
#: (4 096 split it: the 8dna near-field render 1.036x slower, docs/benchmarks.md#network-rows).
MAX_NETWORK_ROWS = 16384
#: A network output magnitude above this on the validator's probe inputs is rejected (NETWORK_OUTPUT).
MAX_NETWORK_OUTPUT = 1e8
#: Geometry (object space) that float32 ray casting resolves (GEOMETRY_SCALE, spec/security.md#bounds):
#: |coordinate| <= MAX_GEOMETRY_COORDINATE, bounding-box diagonal >= MIN_GEOMETRY_SIZE and
#: >= MIN_GEOMETRY_SIZE_RATIO x the largest |coordinate|.
MAX_GEOMETRY_COORDINATE = 1e10
MIN_GEOMETRY_SIZE = 1e-8
MIN_GEOMETRY_SIZE_RATIO = 1e-3
