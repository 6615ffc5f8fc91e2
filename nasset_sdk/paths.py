"""One asset-path check for the validator and every reader (spec/security.md#paths).

A path is checked twice: by its text (:func:`path_problem`: absolute, URL, ``~``, variable
expression, ``..``, bare search path, malformed or escaping package-relative ``a.usdz[b]`` forms,
outer and inner parts) and by where it resolves (:func:`resolve_problem`: anchored at its layer
through Ar, then ``os.path.realpath``, so a symlink leaving the package is refused; anything that
exists but is not a regular file -- named pipe, device, socket, folder -- is refused with
``os.stat``, never opened).

:func:`check_layer_tree` opens a root layer alone (``Sdf.Layer.FindOrOpen``, no composition), walks
every spec of it (variants included) for sublayers, references, payloads, value clips and every
asset-valued field or time sample, and recurses only into layers whose paths passed.
:func:`open_checked_stage` composes only after that, which is what readers MUST do.
"""

from __future__ import annotations

import os
import re
import stat
from dataclasses import dataclass
from pathlib import PurePosixPath

from .errors import error

#: Layers a reader follows from one root before giving up (cycles are cut by realpath).
MAX_LAYERS = 64
ARC_KINDS = ("sublayer", "reference", "payload", "clip", "clip template")
#: clip-set keys (and legacy clip metadata) whose value is a template string, not an asset path: ``./c.#.usd``
TEMPLATE_KEYS = ("templateAssetPath", "clipTemplateAssetPath")
USD_LAYER_SUFFIXES = (".usd", ".usda", ".usdc", ".usdz")
_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


def _package_split(s: str) -> tuple[str, str] | None:
    """(outer, inner) of a well-formed package-relative path ``outer[inner]``; None if not one."""
    from pxr import Ar

    if not s.endswith("]") or "[" not in s:
        return None
    outer, inner = Ar.SplitPackageRelativePathOuter(s)
    if not outer or not inner or f"{outer}[{inner}]" != s:
        return None
    return outer, inner


def _text_problem(s: str, *, inner: bool) -> str | None:
    if s.startswith("`"):
        return "is a variable expression"
    if _CONTROL.search(s):
        return "contains control characters"
    s = s.replace("\\", "/")
    if s.startswith("/"):
        return "is absolute" if not inner else "has an absolute path inside its package"
    if _SCHEME.match(s):
        return "is a URL or drive path"
    if s.startswith("~"):
        return "is relative to a home folder"
    if "[" in s or "]" in s:
        split = _package_split(s)
        if split is None:
            return "is a malformed package-relative path (unbalanced '[' ']')"
        outer, inner_path = split
        return _text_problem(outer, inner=inner) or _text_problem(inner_path, inner=True)
    depth = 0
    for part in PurePosixPath(s).parts:
        if part == "..":
            depth -= 1
            if depth < 0:
                return "leaves the asset's folder with '..'" if not inner else "leaves its package with '..'"
        elif part not in (".", ""):
            depth += 1
    return None


def path_escapes(asset_path: str) -> str | None:
    """Why the text of ``asset_path`` leaves the package, or None (outer and inner package parts checked)."""
    s = str(asset_path)
    return _text_problem(s, inner=False) if s else None


def path_problem(asset_path: str) -> str | None:
    """:func:`path_escapes`, plus: a bare search-path form (``tex/a.png``, not ``./tex/a.png``) and any ``..``."""
    s = str(asset_path)
    if not s:
        return None
    why = path_escapes(s)
    if why:
        return why
    outer = s.replace("\\", "/")
    split = _package_split(outer) if "[" in outer else None
    while split is not None:  # nested packages: the outermost file path is what the resolver searches
        outer = split[0]
        split = _package_split(outer) if "[" in outer else None
    if ".." in PurePosixPath(outer).parts:
        return "contains a '..' segment"
    if not outer.startswith("./"):
        return "is a bare search-path form; anchor it with './'"
    return None


def _inside(path: str, package: str) -> bool:
    return path == package or path.startswith(package.rstrip(os.sep) + os.sep)


def _not_regular(path: str) -> str | None:
    """Why ``path`` (which exists) is not a regular file, from ``os.stat`` only (never opened)."""
    try:
        st = os.stat(path)
    except OSError:
        return None  # missing: nothing to open
    mode = st.st_mode
    if stat.S_ISREG(mode):
        return None
    what = ("a named pipe" if stat.S_ISFIFO(mode) else "a device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode)
            else "a socket" if stat.S_ISSOCK(mode) else "a folder" if stat.S_ISDIR(mode) else "not a regular file")
    return f"resolves to {what}, not a regular file"


def outer_file(identifier: str) -> str:
    """The file part of a (possibly nested) package-relative identifier."""
    s = identifier
    while s.endswith("]") and "[" in s:
        split = _package_split(s)
        if split is None:
            break
        s = split[0]
    return s


def resolve(asset_path: str, anchor: str | os.PathLike, identifier: str | None = None) -> str:
    """Where ``asset_path`` authored in the layer file ``anchor`` resolves: Ar identifier (``identifier`` when the
    caller computed it from the layer, :func:`arc_identifier`), then realpath of its file part."""
    from pxr import Ar

    resolver = Ar.GetResolver()
    identifier = identifier or resolver.CreateIdentifier(str(asset_path), Ar.ResolvedPath(os.fspath(anchor)))
    resolved = str(resolver.Resolve(identifier)) if identifier else ""
    file = outer_file(resolved or identifier or str(asset_path))
    if not os.path.isabs(file):
        file = os.path.join(os.path.dirname(os.fspath(anchor)), file)
    return os.path.realpath(file)


def arc_identifier(layer, asset_path: str, anchor: str) -> str:
    """The identifier composition opens for ``asset_path`` authored in ``layer``: anchored as Sdf anchors it
    (``Sdf.ComputeAssetPathRelativeToLayer``: inside a usdz package, relative to the package's root layer, so
    ``./b.usda`` in ``a.usdz`` is ``a.usdz[b.usda]``, not a file beside the package); for an anonymous copy of a
    layer, relative to its file ``anchor`` through Ar."""
    from pxr import Ar, Sdf

    if not layer.anonymous:
        return Sdf.ComputeAssetPathRelativeToLayer(layer, str(asset_path))
    return Ar.GetResolver().CreateIdentifier(str(asset_path), Ar.ResolvedPath(os.fspath(anchor)))


def resolve_problem(asset_path: str, anchor: str | os.PathLike, package: str | os.PathLike,
                    identifier: str | None = None) -> str | None:
    """Why ``asset_path`` (authored in layer file ``anchor``) resolves outside ``package`` or to a non-file."""
    if not str(asset_path):
        return None
    target = resolve(asset_path, anchor, identifier)
    pkg = os.path.realpath(os.fspath(package))
    if not _inside(target, pkg):
        return f"resolves to {target}, outside the asset's folder {pkg}"
    return _not_regular(target)


@dataclass(frozen=True)
class PathProblem:
    """One asset path that a reader must not follow."""

    kind: str  # sublayer | reference | payload | clip | asset
    path: str
    why: str
    layer: str
    prim: str | None = None
    field: str | None = None

    def message(self) -> str:
        what = {"sublayer": "sublayer", "reference": "reference", "payload": "payload", "clip": "value clip",
                "clip template": "value clip template"}.get(self.kind, "asset path")
        where = f" ({self.field})" if self.field and self.kind == "asset" and self.field != "default" else ""
        return f"{what}{where} {self.path!r} {self.why}"


def _asset_strings(value):
    """(kind, path) for every asset path inside a metadata / attribute value, recursively."""
    from pxr import Sdf

    if value is None:
        return
    if isinstance(value, Sdf.AssetPath):
        yield "asset", value.path
    elif isinstance(value, Sdf.Reference):
        yield "reference", value.assetPath
    elif isinstance(value, Sdf.Payload):
        yield "payload", value.assetPath
    elif isinstance(value, (Sdf.ReferenceListOp, Sdf.PayloadListOp)):
        kind = "reference" if isinstance(value, Sdf.ReferenceListOp) else "payload"
        for items in (value.explicitItems, value.addedItems, value.prependedItems, value.appendedItems,
                      value.deletedItems, value.orderedItems):
            for item in items:
                yield kind, item.assetPath
    elif isinstance(value, dict):
        for v in value.values():
            yield from _asset_strings(v)
    elif isinstance(value, (str, bytes, int, float, bool)):
        return
    elif type(value).__name__ == "AssetPathArray" or isinstance(value, (list, tuple)):
        for v in value:
            yield from _asset_strings(v)


def _clip_templates(key: str, value) -> list[str]:
    """Template strings of value clips (``clips`` sets' ``templateAssetPath``, legacy ``clipTemplateAssetPath``):
    plain strings from which USD generates the clip layers' paths when it reads a value."""
    if key == "clipTemplateAssetPath" and isinstance(value, str):
        return [value]
    if key != "clips" or not isinstance(value, dict):
        return []
    return [str(v[t]) for v in value.values() if isinstance(v, dict) for t in TEMPLATE_KEYS if v.get(t)]


_SKIP_KEYS = frozenset({"subLayers", "timeSamples", "typeName", "specifier", "variability", "custom", "documentation",
                        "connectionPaths", "targetPaths", "primOrder", "propertyOrder", "variantSetNames"})
_VALUE_KEYS = frozenset({"default", "spline"})


def _prim_spec(spec):
    """The prim spec behind a variant spec (what a variant authors lives on it); other specs unchanged."""
    return spec.primSpec if spec is not None and type(spec).__name__ == "VariantSpec" else spec


def _is_asset_type(spec) -> bool:
    type_name = getattr(spec, "typeName", None)
    return type_name is not None and str(type_name).startswith("asset")


def layer_asset_paths(layer):
    """(kind, path, prim, field) for every asset path of ``layer``: sublayers, arcs, clips, values, metadata, time samples."""
    from pxr import Sdf

    found: list = [("sublayer", s, "/", "subLayers") for s in layer.subLayerPaths]

    def visit(spec_path):
        spec = _prim_spec(layer.GetObjectAtPath(spec_path))
        if spec is None:
            return
        field = spec_path.name if spec_path.IsPropertyPath() else None
        here: list = []  # (kind, path, field) of this spec
        # values are read only where an asset path can live: array data (tensors, geometry) is never materialised
        asset_typed = spec_path.IsPropertyPath() and _is_asset_type(spec)
        for key in spec.ListInfoKeys():
            if key in _SKIP_KEYS or (key in _VALUE_KEYS and not asset_typed):
                continue
            try:
                value = spec.GetInfo(key)
            except Exception:  # noqa: BLE001 - a value type without a Python converter holds no asset path
                continue
            for kind, s in _asset_strings(value):
                if key in ("clips", "clipAssetPaths", "clipManifestAssetPath"):
                    kind = "clip"
                here.append((kind, s, field or key))
            for template in _clip_templates(key, value):
                here.append(("clip template", template, field or key))
        if asset_typed:
            for t in layer.ListTimeSamplesForPath(spec_path):
                for kind, s in _asset_strings(layer.QueryTimeSample(spec_path, t)):
                    here.append((kind, s, f"{field} @ time {t}"))
        if here:  # the prim spelled only where it is named: a path is as long as its depth
            prim = "/" if spec_path.IsAbsoluteRootPath() else str(spec_path.GetPrimPath().StripAllVariantSelections())
            found.extend((kind, s, prim, where) for kind, s, where in here)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    listed = {s for _, s, _, _ in found}
    for s in layer.GetCompositionAssetDependencies():  # cross-check: anything composition would open
        if s not in listed:
            found.append(("reference", s, "/", "composition"))
    return found


def _anchor(layer) -> str:
    return layer.realPath or layer.identifier


def scan_layer(layer, package: str | os.PathLike, *, scene: bool = False,
               anchor: str | None = None) -> tuple[list[PathProblem], list[str]]:
    """Check every asset path of one layer; return (problems, identifiers of arcs that passed).

    ``anchor`` is the layer's file when the layer was opened anonymously from it.
    """
    anchor = anchor or _anchor(layer)
    problems: list[PathProblem] = []
    follow: list[str] = []
    for kind, s, prim, field in layer_asset_paths(layer):
        if not s:
            continue
        if kind == "clip template":  # USD expands it to layers only when a value is read: none of them checked here
            problems.append(PathProblem(kind, s, "generates the paths of its layers when values are read, so they cannot "
                                        "be checked before composing; list the clip layers in assetPaths", anchor, prim, field))
            continue
        why = scene_path_problem(s, kind, anchor) if scene else path_problem(s)
        identifier = arc_identifier(layer, s, anchor) if why is None else None
        if why is None:
            why = _not_regular(resolve(s, anchor, identifier)) if scene else resolve_problem(s, anchor, package, identifier)
        if why:
            problems.append(PathProblem(kind, s, why, anchor, prim, field))
        elif kind in ARC_KINDS:
            follow.append(identifier)
    return problems, follow


def scene_path_problem(asset_path: str, kind: str, anchor: str | os.PathLike | None = None) -> str | None:
    """Text check for a scene layer: local files anywhere, but no URL, expression, home, search path or non-USD layer.

    A bare relative path (``textures/a.exr``, as DCC tools write) of an arc is accepted when that file exists
    next to the scene layer ``anchor``: USD's resolver then finds it there and never consults its
    search paths. A bare path in a value (a texture, a shader's ``info:mdl:sourceAsset = @OmniPBR.mdl@``) is
    not an arc: composition never opens it, and a reader opens only what Ar resolves, the same file a
    search path would give an anchored arc (spec/security.md#paths)."""
    s = str(asset_path)
    if s.startswith("`"):
        return "is a variable expression"
    if _CONTROL.search(s):
        return "contains control characters"
    t = s.replace("\\", "/")
    if _SCHEME.match(t):
        return "is a URL or drive path"
    if t.startswith("~"):
        return "is relative to a home folder"
    if kind in ARC_KINDS and not (t.startswith("/") or t.startswith("./") or t.startswith("../")):
        beside = os.path.join(os.path.dirname(os.fspath(anchor)), outer_file(t)) if anchor else ""
        if not (beside and os.path.isfile(beside)) and not (anchor and _resolves_to_file(s, anchor)):
            return "is a bare search-path form that the resolver (search paths, context) does not find; anchor it with './'"
    if kind in ARC_KINDS and not outer_file(t).lower().endswith(USD_LAYER_SUFFIXES):
        return f"is not a USD layer ({', '.join(USD_LAYER_SUFFIXES)})"
    return None


def _resolves_to_file(asset_path: str, anchor) -> bool:
    """True when Ar (with the bound resolver context: search paths, a studio resolver) resolves ``asset_path``
    authored in the layer ``anchor`` to an existing local file."""
    from pxr import Ar

    resolver = Ar.GetResolver()
    resolved = str(resolver.Resolve(resolver.CreateIdentifier(asset_path, Ar.ResolvedPath(os.fspath(anchor)))))
    return bool(resolved) and os.path.isfile(outer_file(resolved))


def _is_asset_layer(layer) -> bool:
    name = layer.defaultPrim
    spec = layer.GetPrimAtPath("/" + name) if name else None
    return spec is not None and spec.typeName == "NeuralAsset"


def check_layer_tree(path: str | os.PathLike, *, scene: bool = False, max_layers: int = MAX_LAYERS,
                     probe: bool = True) -> list[PathProblem]:
    """Every path problem reachable from the layer file ``path``, found without composing anything.

    Asset layers (defaultPrim a NeuralAsset) keep every path inside their own folder; a scene
    (``scene=True``) may reference local USD files anywhere, and each asset it reaches is checked
    as an asset. Only layers whose own path passed are opened, each alone, and each only after its
    guarded probe passed (``probe``; :func:`nasset_sdk.safeopen.ensure_safe`, which raises
    ``FILE_UNREADABLE`` / ``ARRAY_TOO_LARGE`` naming the layer): a layer that would crash usd-core,
    or decode far beyond its size, is never opened in this process.
    """
    from pxr import Ar, Sdf

    from .safeopen import ensure_safe

    root = os.path.realpath(os.fspath(path))
    problems: list[PathProblem] = []
    seen: set[str] = set()
    files: list[str] = []  # the files of the layers probed
    queue: list[tuple[str, str | None]] = [(root, None)]
    while queue:
        identifier, package = queue.pop(0)
        key = identifier if "[" in identifier else os.path.realpath(identifier)
        if key in seen:
            continue
        seen.add(key)
        if len(seen) > max_layers:
            problems.append(PathProblem("sublayer", identifier, f"is past the limit of {max_layers} layers", root))
            break
        why = _not_regular(outer_file(identifier))
        if why:
            problems.append(PathProblem("sublayer", identifier, why, root))
            continue
        if probe:  # the file the resolver finds (a search path, a resolver context): the probe child has neither
            found = str(Ar.GetResolver().Resolve(identifier)) or identifier
            if os.path.isfile(outer_file(found)):  # held to the asset bounds unless it is a scene's own layer
                ensure_safe(found, asset=not scene or package is not None)
                files.append(found)
        try:
            layer = Sdf.Layer.FindOrOpen(identifier)
        except Exception:  # noqa: BLE001 - composition reports a layer that does not open
            layer = None
        if layer is None:
            continue
        asset_layer = _is_asset_layer(layer)
        if package is None and (asset_layer or not scene):  # where Ar found it (a search path too)
            package = os.path.dirname(os.path.realpath(outer_file(layer.realPath or identifier)))
        found, follow = scan_layer(layer, package or "/", scene=scene and package is None)
        problems.extend(found)
        queue.extend((f, package) for f in follow)
    if probe and not problems and len(files) > 1:
        # each layer passed its probe alone; arcs between layers can still repeat subtrees without bound
        # (ten prims each referencing a file of ten that reference the next file, six files: 10^6 prims)
        from .safeopen import ensure_composes

        ensure_composes(root, files, asset=not scene, search_paths=_context_search_paths())
    return problems


def _context_search_paths() -> list[str]:
    """The search paths of the bound resolver context (a default resolver's), for a probe child to compose with."""
    from pxr import Ar

    return [folder for ctx in Ar.GetResolver().GetCurrentContext().Get() if hasattr(ctx, "GetSearchPath")
            for folder in ctx.GetSearchPath()]


def problems_error(problems: list[PathProblem], file: str | os.PathLike, *, code: str = "ASSET_PATH_ESCAPES"):
    """The typed error for the first problem (with a count of the others)."""
    first = problems[0]
    more = f" (and {len(problems) - 1} more)" if len(problems) > 1 else ""
    where = "" if os.path.realpath(first.layer) == os.path.realpath(os.fspath(file)) else f" in layer {first.layer}"
    return error(code, f"{first.message()}{where}{more}; nothing was composed", file=str(file), prim=first.prim,
                 attribute=first.field if first.kind == "asset" else None)


def ensure_regular_file(path: str | os.PathLike, *, code: str = "FILE_NOT_FOUND"):
    """Raise unless ``path`` is an existing regular file (checked with stat, never opened)."""
    p = outer_file(os.fspath(path))  # a layer inside a package is checked by its package file
    if not os.path.exists(p):
        raise error(code, "no such file", file=p)
    why = _not_regular(p)
    if why:
        raise error("FILE_UNREADABLE" if code == "FILE_NOT_FOUND" else code, f"the path {why[len('resolves to '):]}", file=p)


def open_checked_stage(path: str | os.PathLike, load=None, *, scene: bool = False, probe: bool = True):
    """Compose ``path`` only after :func:`check_layer_tree` found nothing (every layer probed first unless ``probe``
    is False); raises ASSET_PATH_ESCAPES (SCENE_INVALID for scenes)."""
    from pxr import Sdf, Usd

    ensure_regular_file(path, code="SCENE_INVALID" if scene else "FILE_NOT_FOUND")
    problems = check_layer_tree(path, scene=scene, probe=probe)
    if problems:
        raise problems_error(problems, path, code="SCENE_INVALID" if scene else "ASSET_PATH_ESCAPES")
    layer = Sdf.Layer.FindOrOpen(os.fspath(path))
    if layer is None:
        return None
    _reload_if_changed(layer)
    stage = Usd.Stage.Open(layer, Usd.Stage.LoadNone if load is None else load)
    for used in stage.GetUsedLayers():
        if used is not layer:
            _reload_if_changed(used)
    return stage


def _reload_if_changed(layer) -> None:
    """USD keeps a layer that something in the process still holds (another stage, a cached asset) as it was read: a
    file rewritten since (a bake to the same path) composed its old content, unchecked against the new one. Reload
    it when its file changed (Sdf compares the file's timestamp: a no-op otherwise), unless it has unsaved edits."""
    if not layer.anonymous and not layer.dirty:
        layer.Reload()


def strip_external(layer):
    """Anonymous copy of ``layer`` without sublayers, external references / payloads or value clips (composes nothing outside)."""
    from pxr import Sdf

    copy = Sdf.Layer.CreateAnonymous(".usda")
    copy.TransferContent(layer)
    copy.subLayerPaths.clear()
    edits: list = []

    def visit(spec_path):
        if spec_path.IsPrimPath() or spec_path.IsPrimVariantSelectionPath():
            edits.append(spec_path)

    copy.Traverse(Sdf.Path.absoluteRootPath, visit)
    for spec_path in edits:
        spec = _prim_spec(copy.GetObjectAtPath(spec_path))
        if spec is None or not hasattr(spec, "referenceList"):  # e.g. a variant set spec '/A{v=}'
            continue
        for listop, make in ((spec.referenceList, Sdf.Reference), (spec.payloadList, Sdf.Payload)):
            items = [i for i in (*listop.explicitItems, *listop.prependedItems, *listop.appendedItems, *listop.addedItems)]
            if any(i.assetPath for i in items):
                internal = [make("", i.primPath, i.layerOffset) for i in items if not i.assetPath]
                listop.ClearEdits()
                for i in internal:
                    listop.prependedItems.append(i)
        for key in ("clips", "clipSets"):
            if spec.HasInfo(key):
                spec.ClearInfo(key)
    return copy


def has_external(layer) -> bool:
    """True when composing ``layer`` would open another file (sublayer, external arc or clip)."""
    return any(kind in ARC_KINDS and s for kind, s, _, _ in layer_asset_paths(layer))


def is_under(path: str | os.PathLike, folder: str | os.PathLike) -> bool:
    """True when the realpath of ``path`` lies inside the realpath of ``folder``."""
    return _inside(os.path.realpath(os.fspath(path)), os.path.realpath(os.fspath(folder)))


__all__ = ["PathProblem", "check_layer_tree", "ensure_regular_file", "has_external", "layer_asset_paths", "open_checked_stage",
           "path_escapes", "path_problem", "problems_error", "resolve", "resolve_problem", "scan_layer", "strip_external"]
