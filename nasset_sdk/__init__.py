"""nasset SDK: read, write, validate and evaluate relightable neural 3D assets (spec/).

Importing the package registers the schema and loads the error types only; the rest (``Asset``, the kinds, ...)
is imported on first use, so that processes which only check or open a layer (the crash probe's child, the CLI's
usage errors) do not pay for numpy-heavy modules they never touch.
"""

from .errors import (
    CODES,
    AssetFormatError,
    AssetReadError,
    AssetSecurityError,
    AssetWriteError,
    NassetError,
    SceneError,
    UsageError,
)
from .plugin import register_schema

register_schema()

__version__ = "0.1.0"

#: public name -> the module that defines it (imported on first access)
_LAZY = {"Asset": "asset", "AssetBuilder": "asset", "CurvesGeometry": "geometry", "MeshGeometry": "geometry",
         "KINDS": "kinds", "get_kind": "kinds", "Evaluator": "kinds.query", "Query": "kinds.query",
         "SPEC_VERSION": "limits"}

__all__ = [
    "Asset", "AssetBuilder", "CODES", "KINDS", "SPEC_VERSION", "AssetFormatError", "AssetReadError",
    "AssetSecurityError", "AssetWriteError", "CurvesGeometry", "Evaluator", "MeshGeometry", "NassetError",
    "Query", "SceneError", "UsageError", "get_kind", "register_schema",
]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        value = getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
