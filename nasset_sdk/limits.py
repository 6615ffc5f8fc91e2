"""Bounds applied to untrusted assets (spec/security.md#bounds) and the version this SDK writes."""

SPEC_VERSION = "0.1"
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
