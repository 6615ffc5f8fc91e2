"""Registers the codeless USD schema shipped in ``nasset_sdk/usdschema`` (the repo's ``schemas/``).

``import nasset_sdk`` calls :func:`register_schema`; USD accepts plugins registered after it was
initialised. Hosts that start USD outside Python can instead add the folder printed by
``nasset schema-path`` to ``PXR_PLUGINPATH_NAME`` before starting.
"""

from __future__ import annotations

from pathlib import Path

_INSTALLED = Path(__file__).resolve().parent / "usdschema"  # wheel: schemas/ is packaged here
_CHECKOUT = Path(__file__).resolve().parent.parent / "schemas"  # running from a source checkout
SCHEMA_DIR = _INSTALLED if (_INSTALLED / "plugInfo.json").is_file() else _CHECKOUT
_registered = False


def schema_dir() -> Path:
    """Folder holding ``plugInfo.json`` and ``generatedSchema.usda``."""
    return SCHEMA_DIR


def register_schema() -> None:
    """Register the NeuralAsset / NeuralComponent / NeuralTensor / NeuralNetwork types once."""
    global _registered
    if _registered:
        return
    from pxr import Plug, Tf

    if not Tf.Type.FindByName("NassetNeuralAsset").isUnknown:
        _registered = True  # a host registered it through PXR_PLUGINPATH_NAME
        return
    Plug.Registry().RegisterPlugins(str(SCHEMA_DIR))
    if Tf.Type.FindByName("NassetNeuralAsset").isUnknown:
        raise ImportError(f"nasset USD schema did not register from {SCHEMA_DIR}")
    _registered = True


def run_schema_path(args) -> int:
    """CLI: print the schema folder."""
    print(SCHEMA_DIR)
    return 0
