"""How a scene refers to an asset (spec/format.md#referencing-an-asset): found through composition, read through Ar.

A scene prim is an *asset instance* when the asset's root reaches it through composition: a spec
in its prim stack is an asset file's default prim typed ``NeuralAsset``, or authors
``nasset:specVersion`` (every asset root does; a flattened scene keeps it). The referencing
prim's own type does not matter; ``def Xform`` is the recommended pattern because USD tools
without the nasset schema keep its transform.

The asset's layer is the one composition opened through USD's asset resolver (Ar), so usdz
packages, search paths, resolver contexts and custom resolvers all work; a flattened scene holds
the asset's specs inline, and the asset is read from a copy of them.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from .errors import error

#: the attribute every asset root authors (spec/format.md#root-prim); it survives flattening
HEADER_ATTRIBUTE = "nasset:specVersion"
ASSET_TYPE = "NeuralAsset"


@dataclass(frozen=True)
class AssetSource:
    """Where one asset instance's specs live.

    ``layer``: the layer's resolved path as Ar gave it (a file, or ``package.usdz[inner.usdc]``);
    ``prim``: the asset's root prim in that layer; ``embedded``: the specs sit inside a scene layer
    (a flattened scene), not at the default prim of an asset file.
    """

    layer: str
    prim: str
    embedded: bool

    @property
    def display(self) -> str:
        """``file`` for an asset file, ``file<prim>`` for an asset embedded in a scene layer."""
        return f"{self.layer}<{self.prim}>" if self.embedded else self.layer


def _layer_path(layer) -> str:
    return layer.realPath or layer.identifier


def _is_file_root(spec) -> bool:
    layer = spec.layer
    return bool(layer.defaultPrim) and str(spec.path) == "/" + layer.defaultPrim and spec.typeName == ASSET_TYPE


def asset_source(prim) -> AssetSource | None:
    """The asset that composition brings to the composed ``prim`` (a ``Usd.Prim``), or None.

    An asset file's typed default prim wins (the usual reference, also inside a usdz package or
    found on a search path); otherwise the strongest spec that authors the header attribute
    (an asset embedded in a flattened scene).
    """
    header = None
    for spec in prim.GetPrimStack():
        if _is_file_root(spec):
            return AssetSource(_layer_path(spec.layer), str(spec.path), False)
        if header is None and HEADER_ATTRIBUTE in spec.attributes:
            header = spec
    if header is None:
        return None
    return AssetSource(_layer_path(header.layer), str(header.path), True)


#: properties of an embedded root that place the instance in its scene, not the asset: dropped from the copy (object space
#: ignores the root's transform, spec/format.md#coordinates), so that every instance of one asset copies to the same specs
_PLACEMENT = ("xformOpOrder", "visibility", "purpose", "proxyPrim")


def embedded_layer(source: AssetSource):
    """An anonymous layer holding the embedded asset's specs copied to ``/Asset`` (its default prim, typed
    ``NeuralAsset``) with the scene layer's ``upAxis`` and ``metersPerUnit``, without the root's placement in the scene
    (its ``xformOp``s, visibility and purpose); ``SCENE_INVALID`` if it cannot be read."""
    from pxr import Sdf

    from .asset import ROOT

    scene = Sdf.Layer.Find(source.layer) or Sdf.Layer.FindOrOpen(source.layer)
    if scene is None or not scene.GetPrimAtPath(source.prim):
        raise error("SCENE_INVALID", "the embedded asset's layer is not open", file=source.layer, prim=source.prim)
    copy = Sdf.Layer.CreateAnonymous(".usdc")
    if not Sdf.CopySpec(scene, source.prim, copy, ROOT):
        raise error("SCENE_INVALID", "cannot copy the embedded asset's specs", file=source.layer, prim=source.prim)
    copy.defaultPrim = ROOT.lstrip("/")
    root = copy.GetPrimAtPath(ROOT)
    root.typeName = ASSET_TYPE
    for prop in list(root.properties):
        if prop.name in _PLACEMENT or prop.name.startswith("xformOp:"):
            root.RemoveProperty(prop)
    for key in ("upAxis", "metersPerUnit"):
        if scene.pseudoRoot.HasInfo(key):
            copy.pseudoRoot.SetInfo(key, scene.pseudoRoot.GetInfo(key))
    return copy


_embedded_files: dict = {}  # (scene layer, prim, the layer file's identity) -> the written copy
_embedded_digests: dict = {}  # sha-256 of a written copy's bytes -> that copy
_embedded_folder: list = []  # the process's folder of copies, made on first use


def embedded_asset_file(source: AssetSource) -> str:
    """A ``.usdc`` file holding :func:`embedded_layer` of ``source`` (an asset embedded in a flattened scene), for readers
    that open assets by path (the Mitsuba implementations): written atomically once per scene file, prim and file
    version into a private temporary folder of this process, removed at exit. Instances whose copies are the same bytes
    (one asset placed several times: flattening repeats its specs under each instance) get the same file, so a
    reader that caches assets by path reads it once."""
    import atexit
    import hashlib
    import shutil
    import tempfile

    from .safeopen import file_identity

    key = (source.layer, source.prim, file_identity(source.layer))
    if key not in _embedded_files:
        if not _embedded_folder:
            folder = tempfile.mkdtemp(prefix="nasset-embedded-")
            atexit.register(shutil.rmtree, folder, True)
            _embedded_folder.append(folder)
        out = os.path.join(_embedded_folder[0], f"asset_{len(_embedded_files)}.usdc")
        tmp = out + ".tmp.usdc"
        if not embedded_layer(source).Export(tmp):
            raise error("WRITE_FAILED", "cannot write the embedded asset's copy", file=out, prim=source.prim)
        with open(tmp, "rb") as f:
            digest = hashlib.file_digest(f, "sha256").hexdigest()
        if digest in _embedded_digests:
            os.remove(tmp)
            out = _embedded_digests[digest]
        else:
            os.replace(tmp, out)
            _embedded_digests[digest] = out
        _embedded_files[key] = out
    return _embedded_files[key]


def open_source(source: AssetSource, *, load: str = "none"):
    """Open the asset of ``source`` as an :class:`~nasset_sdk.asset.Asset` (components loaded per ``load``).

    An asset file is opened through :meth:`Asset.open` with every path check; an embedded asset is
    read from :func:`embedded_layer` (the scene layer it sits in was checked as a scene)."""
    from pxr import Usd

    from .asset import Asset

    if not source.embedded:
        return Asset.open(source.layer, load=load)
    stage = Usd.Stage.Open(embedded_layer(source), Usd.Stage.LoadNone)
    return Asset.from_stage(Path(source.display), stage, load=load)


def fallback_owner(prim) -> str | None:
    """The asset file whose geometry the composed ``prim`` shows without its asset root (e.g. a reference to
    ``</Asset/Geometry>``), or None: such a prim renders as the asset's grey fallback mesh."""
    for spec in prim.GetPrimStack():
        layer = spec.layer
        root = layer.GetPrimAtPath("/" + layer.defaultPrim) if layer.defaultPrim else None
        if root is not None and root.typeName == ASSET_TYPE and str(spec.path).startswith(str(root.path) + "/"):
            return _layer_path(layer)
    return None


def resolver_context(search_paths) -> object | None:
    """An Ar context that searches ``search_paths`` (folders, in order) for bare asset paths, or None when empty."""
    from pxr import Ar

    folders = [os.path.abspath(os.fspath(p)) for p in (search_paths or [])]
    return Ar.DefaultResolverContext(folders) if folders else None


__all__ = ["AssetSource", "asset_source", "embedded_asset_file", "embedded_layer", "fallback_owner", "open_source",
           "resolver_context"]
