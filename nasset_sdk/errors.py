"""One exception hierarchy for the SDK, the validator, the converters and the renderer.

Every error carries a stable ``code`` from :data:`CODES` (shared with the validator's rules)
and names the file, prim and attribute it concerns, so a message alone locates the problem.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Code:
    """A stable error code: its category, one-line meaning and the spec paragraph behind it."""

    code: str
    category: str
    summary: str
    spec: str


def _codes(*rows: tuple[str, str, str, str]) -> dict[str, Code]:
    return {r[0]: Code(*r) for r in rows}


#: code -> Code. Codes are never renamed or reused; new ones are appended.
CODES: dict[str, Code] = _codes(
    # reading and writing
    ("FILE_NOT_FOUND", "read", "the asset file does not exist", "format.md#files"),
    ("FILE_UNREADABLE", "read", "the file is not a USD layer that opens", "format.md#files"),
    ("WRITE_FAILED", "write", "the asset could not be written", "format.md#files"),
    # layout
    ("ROOT_MISSING", "format", "no defaultPrim, or it is not a NeuralAsset", "format.md#root-prim"),
    ("SCHEMA_TYPE", "format", "a prim has the wrong schema type", "format.md#layer-layout"),
    ("SPEC_VERSION", "format", "specVersion missing, malformed or unsupported", "format.md#versioning"),
    ("KIND_UNKNOWN", "format", "nasset:kind is not a registered kind", "format.md#root-prim"),
    ("VARIANT_UNKNOWN", "format", "nasset:variant is not one the kind allows", "format.md#root-prim"),
    ("DOMAIN_INVALID", "format", "encoding box missing, non-finite, empty or not covering the geometry", "format.md#coordinates"),
    ("COMPONENT_MISSING", "format", "a required component is absent", "format.md#components"),
    ("COMPONENT_UNKNOWN", "format", "a component the kind does not declare", "format.md#components"),
    ("PAYLOAD_INVALID", "format", "a component payload is not an internal payload to the payload root", "format.md#lazy-loading"),
    ("QUALITY_VARIANT", "format", "quality variant set malformed or selection missing", "format.md#quality-variants"),
    # tensors
    ("TENSOR_MISSING", "format", "a tensor the kind requires is absent", "format.md#tensors"),
    ("TENSOR_DTYPE", "format", "dtype token unknown or values type does not match it", "format.md#tensors"),
    ("TENSOR_SHAPE", "format", "shape malformed or its product differs from the number of values", "format.md#tensors"),
    ("TENSOR_CONTRACT", "format", "tensor shape does not match the kind contract", "kinds/README.md"),
    ("TENSOR_NONFINITE", "format", "tensor holds NaN or Inf", "format.md#tensors"),
    ("TENSOR_TOO_LARGE", "security", "declared tensor size above the format bound", "security.md#bounds"),
    # networks
    ("NETWORK_MISSING", "format", "a network the kind requires is absent", "format.md#networks"),
    ("NETWORK_DIGEST", "security", "sha256 missing or does not match the model bytes", "format.md#networks"),
    ("NETWORK_PARSE", "format", "the model bytes are not a valid ONNX model", "format.md#networks"),
    ("NETWORK_OPSET", "format", "opset outside the allowed range or differing from onnx:opset", "format.md#networks"),
    ("NETWORK_CUSTOM_DOMAIN", "security", "the model uses an operator domain other than the default", "security.md#networks"),
    ("NETWORK_EXTERNAL_DATA", "security", "the model references external data", "security.md#networks"),
    ("NETWORK_IO", "format", "input/output names or widths differ from the declaration or the kind contract", "format.md#networks"),
    ("NETWORK_TOO_LARGE", "security", "model bytes above the format bound", "security.md#bounds"),
    ("NETWORK_RUNTIME", "format", "onnxruntime could not load or run the model", "format.md#networks"),
    # geometry
    ("GEOMETRY_MISSING", "format", "no Geometry child of the right type", "format.md#geometry"),
    ("GEOMETRY_INVALID", "format", "geometry arrays malformed: counts, indices out of range, non-finite points", "format.md#geometry"),
    ("GEOMETRY_DEGENERATE", "format", "every face has zero area / every curve zero length", "format.md#geometry"),
    ("GEOMETRY_NORMALS", "format", "normals not unit length or wrong count", "format.md#geometry"),
    ("EXTENT_MISMATCH", "format", "authored extent differs from the geometry's bounds", "format.md#geometry"),
    # security
    ("ASSET_PATH_ESCAPES", "security", "an asset path is absolute, a URL or leaves the asset's package", "security.md#paths"),
    # metadata
    ("METADATA_MISSING", "format", "provenance metadata absent or lacking a required key", "format.md#provenance"),
    ("METADATA_INVALID", "format", "provenance is not a JSON object of the documented form", "format.md#provenance"),
    ("FALLBACK_MISSING", "format", "no fallback UsdPreviewSurface bound to the geometry", "format.md#fallback-material"),
    # kind-specific contract checks
    ("KIND_CONTRACT", "format", "a kind-specific constraint is violated (e.g. spline knots)", "kinds/README.md"),
    # callers
    ("USAGE", "usage", "invalid argument to a public function or CLI verb", "format.md#files"),
    ("SCENE_INVALID", "scene", "the scene cannot be rendered as given", "renderer.md"),
    ("SCENE_UNSUPPORTED", "scene", "the scene uses a type the renderer does not support", "renderer.md"),
    # converters (bake)
    ("CONVERT_SCENE_MISSING", "scene", "the source scene file given to a converter does not exist", "bake.md#errors"),
    ("CONVERT_SCENE_LOAD", "scene", "the source renderer cannot load the scene", "bake.md#errors"),
    ("CONVERT_SHAPE_UNKNOWN", "scene", "a requested asset shape id is not in the source scene", "bake.md#errors"),
    ("CONVERT_SHAPE_UNSUPPORTED", "scene", "an asset shape is not a triangle mesh the converter can store", "bake.md#errors"),
    ("CONVERT_BACKEND", "scene", "the source renderer or the training framework is not installed or usable", "bake.md#errors"),
    ("CONVERT_DATASET", "scene", "the dataset directory does not match the bake settings or is corrupt", "bake.md#resume"),
    ("CONVERT_TRAINING", "scene", "training produced non-finite values or no usable samples", "bake.md#training"),
    # validator
    ("USD_CHECK", "format", "an OpenUSD validator (the usdchecker engine) reported a problem", "validation.md#usd-checks"),
    ("CHECK_FAILED", "format", "a validation check could not complete on this input", "validation.md#report"),
    # converters (scene conversion)
    ("CONVERT_ASSET_REFERENCE", "scene", "a --replace asset file is missing or is not a neural asset", "bake.md#scene-conversion"),
    # layer content (spec/security.md)
    ("LAYER_EXTERNAL", "format", "the asset has a sublayer, value clips, or a reference or payload to another file", "format.md#files"),
    ("VARIANT_SET_UNEXPECTED", "security", "a variant set other than a component's quality variant set", "security.md#layer-content"),
    ("TIME_SAMPLES", "format", "an attribute carries time samples", "security.md#layer-content"),
    ("ARRAY_TOO_LARGE", "security", "a geometry or other array is above the format bound, an asset layer holds or composes to more "
     "specs than its bound, or reading it exceeds the memory bound",
     "security.md#bounds"),
    # networks (allow-list and runtime probe)
    ("NETWORK_OP_FORBIDDEN", "security", "the model uses an operator, attribute, input or construct outside the network allow-list",
     "security.md#networks"),
    ("NETWORK_SHAPE", "security", "shape inference cannot prove every value to be [N, fixed width] with N the batch", "security.md#networks"),
    ("NETWORK_OUTPUT", "format", "on probe inputs the outputs are non-finite, above the magnitude bound or depend on other rows",
     "security.md#networks"),
    # rendering limits (spec/renderer.md#limits)
    ("GEOMETRY_SCALE", "format", "geometry coordinates above the bound, or the geometry too small for its position to render in float32",
     "security.md#bounds"),
    ("IMAGE_INVALID", "read", "an image the renderer reads (dome texture) is corrupt, unsupported or above the size bound", "renderer.md#limits"),
    # benchmarks (in-scene accuracy)
    ("BENCH_ASSET_MISMATCH", "scene", "a bench's --replace or --asset asset was not baked from the shapes it replaces", "accuracy.md#errors"),
    ("BENCH_ASSET_KIND", "scene", "a bench's --replace or --asset asset's kind or variant cannot stand in for those shapes", "accuracy.md#errors"),
    # installation and versions
    ("EXTRA_MISSING", "usage", "a verb needs packages of an optional extra that are not installed", "README.md#extras"),
    ("SPEC_VERSION_NEWER", "format", "specVersion has a MINOR newer than this SDK knows: newer content is not validated",
     "format.md#versioning"),
    # near-field light (format 0.3)
    ("NEAR_FIELD_INVALID", "format", "nasset:nearFieldFetch is not a number in [0, 1], or is non-zero on a kind without it (8dna)",
     "kinds/rna.md#near-field-fetch"),
)


class NassetError(Exception):
    """Base class. ``code`` is a key of :data:`CODES`; location fields may be None."""

    def __init__(
        self,
        code: str,
        message: str,
        *,
        file: str | None = None,
        prim: str | None = None,
        attribute: str | None = None,
    ) -> None:
        if code not in CODES:
            raise ValueError(f"unknown nasset error code {code!r}")
        self.code = code
        self.message = message
        self.file = None if file is None else str(file)
        self.prim = None if prim is None else str(prim)
        self.attribute = attribute
        super().__init__(self.__str__())

    def __reduce__(self):
        # pickled (multiprocessing, Ray workers) as its fields: __init__ takes more than the message
        return (_rebuild, (self.code, self.message, self.file, self.prim, self.attribute))

    def location(self) -> str:
        parts = [p for p in (self.file, self.prim) if p]
        loc = ":".join(parts)
        if self.attribute:
            loc += f".{self.attribute}"
        return loc

    def __str__(self) -> str:
        loc = self.location()
        return f"[{self.code}] {loc + ': ' if loc else ''}{self.message}"

    def to_dict(self) -> dict:
        return {
            "code": self.code,
            "message": self.message,
            "file": self.file,
            "prim": self.prim,
            "attribute": self.attribute,
        }


class AssetReadError(NassetError):
    """The file is missing or is not readable as an asset."""


class AssetFormatError(NassetError):
    """The asset opens but breaks a rule of the format or of its kind."""


class AssetSecurityError(AssetFormatError):
    """The asset breaks a security rule (spec/security.md); never evaluated."""


class AssetWriteError(NassetError):
    """Writing failed; the target path is untouched."""


class UsageError(NassetError):
    """A caller passed invalid arguments."""

    def __init__(self, message: str, **loc) -> None:
        super().__init__("USAGE", message, **loc)


class SceneError(NassetError):
    """A scene given to the renderer or a converter cannot be used."""


_CATEGORY_CLASS = {
    "read": AssetReadError,
    "write": AssetWriteError,
    "format": AssetFormatError,
    "security": AssetSecurityError,
    "usage": NassetError,
    "scene": SceneError,
}


def _rebuild(code: str, message: str, file, prim, attribute) -> NassetError:
    return error(code, message, file=file, prim=prim, attribute=attribute)


def error(code: str, message: str, **loc) -> NassetError:
    """Build the exception of the right class for ``code``."""
    cls = _CATEGORY_CLASS[CODES[code].category]
    if cls is NassetError and code == "USAGE":
        return UsageError(message, **loc)
    return cls(code, message, **loc)


def path_arg(value, what: str):
    """``value`` as a ``pathlib.Path`` when it is a str or os.PathLike, else USAGE naming ``what`` (a Python API's
    file argument: None or a number used to fail as a bare TypeError deep inside)."""
    import os
    from pathlib import Path

    if not isinstance(value, (str, os.PathLike)):
        raise UsageError(f"{what} must be a file path, got {type(value).__name__}")
    return Path(value)


def usd_reason(exc) -> str:
    """The messages of a USD ``Tf.ErrorException`` without USD's source locations, for an error's message: the
    parser's (``file:line:column: what``, the prim and attribute) first; USD's generic ``Failed to open layer`` only
    when there is nothing else."""
    texts = []
    for arg in exc.args:
        text = str(arg).strip()
        text = text.split(" : ", 1)[1].strip() if text.startswith("Error in ") and " : " in text else text
        texts.append(text.strip("'").strip())
    specific = [t for t in texts if t and not t.startswith("Failed to open layer")]
    return "; ".join(specific or texts)[:400]
