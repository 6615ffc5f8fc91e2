"""nasset SDK: read, write, validate and evaluate relightable neural 3D assets (spec/)."""

from .plugin import register_schema

register_schema()

from .asset import Asset, AssetBuilder  # noqa: E402
from .errors import (  # noqa: E402
    CODES,
    AssetFormatError,
    AssetReadError,
    AssetSecurityError,
    AssetWriteError,
    NassetError,
    SceneError,
    UsageError,
)
from .geometry import CurvesGeometry, MeshGeometry  # noqa: E402
from .kinds import KINDS, get_kind  # noqa: E402
from .kinds.query import Evaluator, Query  # noqa: E402
from .limits import SPEC_VERSION  # noqa: E402

__version__ = "0.1.0"

__all__ = [
    "Asset", "AssetBuilder", "CODES", "KINDS", "SPEC_VERSION", "AssetFormatError", "AssetReadError",
    "AssetSecurityError", "AssetWriteError", "CurvesGeometry", "Evaluator", "MeshGeometry", "NassetError",
    "Query", "SceneError", "UsageError", "get_kind", "register_schema",
]
