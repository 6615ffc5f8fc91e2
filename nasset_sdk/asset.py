"""Write and read neural assets (spec/format.md).

Layer layout written by :class:`AssetBuilder` (one ``.usdc`` crate file)::

    /Asset                      NeuralAsset   (defaultPrim; kind, specVersion, variant, domain, provenance)
    /Asset/Geometry             Mesh | BasisCurves, bound to /Asset/Looks/Fallback
    /Asset/Looks/Fallback       Material with a UsdPreviewSurface
    /Asset/Components/<name>    NeuralComponent, internal payload -> /_NassetPayloads/<name>[__<quality>]
    /_NassetPayloads            class prim holding every component's NeuralTensor / NeuralNetwork prims

Only components asked for are loaded (:meth:`Asset.open`), so optional ones cost nothing.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable

import numpy as np

from . import limits
from .arrays import real_array
from .errors import NassetError, UsageError, error, path_arg, usd_reason
from .geometry import CurvesGeometry, MeshGeometry
from .networks import CheckedSession, NetworkInfo, check_model_bytes, info_from_model, make_session, sha256_hex
from .plugin import register_schema

ROOT = "/Asset"
PAYLOAD_ROOT = "/_NassetPayloads"
COMPONENTS = ROOT + "/Components"
GEOMETRY = ROOT + "/Geometry"
FALLBACK = ROOT + "/Looks/Fallback"
QUALITY_SET = "quality"
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


#: root attribute of rna and neupress assets, format 0.3 (spec/kinds/rna.md#near-field-fetch)
NEAR_FIELD_FETCH = "nasset:nearFieldFetch"
#: the kinds whose transport is a response to distant light, which the fetch point applies to
NEAR_FIELD_KINDS = ("rna", "neupress")


def check_near_field_fetch(value, kind: str, where: dict) -> float:
    """The near-field fetch fraction as a float: ``value`` None (not authored) is 0; else it must be a finite real in
    [0, 1], non-zero only on NEAR_FIELD_KINDS, or NEAR_FIELD_INVALID is raised with the location ``where`` (file, prim, attribute)."""
    if value is None:
        return 0.0
    try:
        f = float(value)
    except (TypeError, ValueError):
        f = float("nan")
    if isinstance(value, (bool, str)) or not 0.0 <= f <= 1.0:  # NaN fails both comparisons
        raise error("NEAR_FIELD_INVALID", f"{NEAR_FIELD_FETCH} = {value!r} must be a number in [0, 1]", **where)
    if f > 0 and kind not in NEAR_FIELD_KINDS:
        raise error("NEAR_FIELD_INVALID", f"{NEAR_FIELD_FETCH} is defined for kinds {' and '.join(NEAR_FIELD_KINDS)} only, "
                    f"not {kind!r}", **where)
    return f


def _check_name(what: str, name: str) -> None:
    if not isinstance(name, str) or not _NAME.match(name) or "__" in name:
        raise UsageError(f"{what} name {name!r} must match [A-Za-z_][A-Za-z0-9_]* without '__'")


@dataclass
class ComponentData:
    """Tensors and networks of one component (one quality level of it)."""

    required: bool
    purpose: str = ""
    tensors: dict[str, tuple[np.ndarray, str, str]] = field(default_factory=dict)  # name -> (array, dtype, layout)
    networks: dict[str, bytes] = field(default_factory=dict)

    def add_tensor(self, name: str, array, *, dtype: str = "float32", layout: str = "") -> None:
        """Add a dense tensor; ``dtype`` 'float16' or 'float32' is the stored type."""
        _check_name("tensor", name)
        if dtype not in limits.TENSOR_DTYPES:
            raise UsageError(f"tensor {name!r}: dtype must be one of {limits.TENSOR_DTYPES}")
        arr = real_array(array, f"tensor {name!r}: expected a real number array")
        if arr.size > limits.MAX_TENSOR_ELEMENTS or arr.ndim > limits.MAX_TENSOR_RANK or arr.ndim == 0:
            raise UsageError(f"tensor {name!r}: shape {arr.shape} outside the format bounds")
        with np.errstate(over="ignore", invalid="ignore"):
            stored = arr.astype(np.dtype(dtype))
        if not np.isfinite(stored).all():
            raise UsageError(f"tensor {name!r} holds NaN/Inf after conversion to {dtype}")
        self.tensors[name] = (stored, dtype, layout)

    def add_network(self, name: str, onnx_bytes: bytes) -> None:
        """Add an ONNX model (checked with the same rules the reader applies)."""
        _check_name("network", name)
        check_model_bytes(onnx_bytes)
        self.networks[name] = bytes(onnx_bytes)


class AssetBuilder:
    """Collects an asset in memory and writes it atomically with :meth:`write`."""

    def __init__(self, kind: str, *, variant: str = "surface") -> None:
        from .kinds import get_kind

        contract = get_kind(kind)
        if variant not in contract.variants:
            raise UsageError(f"kind {kind!r} has no variant {variant!r}; one of {contract.variants}")
        self.kind = kind
        self.variant = variant
        self.geometry: MeshGeometry | CurvesGeometry | None = None
        self.domain: tuple[np.ndarray, np.ndarray] | None = None
        self.provenance: dict = {}
        self.fallback_color = (0.5, 0.5, 0.5)
        self.fallback_roughness = 0.5
        self.meters_per_unit = 1.0
        #: rna and neupress: the fraction f of the way from a hit to the encoding box's centre at which light is fetched
        #: (spec/kinds/rna.md#near-field-fetch); 0 (the distant-light rule) is not written
        self.near_field_fetch = 0.0
        # name -> {quality or "": ComponentData}
        self.components: dict[str, dict[str, ComponentData]] = {}
        self.default_quality: dict[str, str] = {}

    def set_geometry(self, geometry: MeshGeometry | CurvesGeometry, *, padding: float = 0.01) -> None:
        """Set geometry; the encoding domain defaults to its bounds padded by ``padding`` (relative)."""
        geometry.validate()
        self.geometry = geometry
        lo, hi = geometry.bounds()
        pad = float(padding) * max(float(np.max(hi - lo)), 1e-12)
        self.domain = (lo - pad, hi + pad)

    def component(self, name: str, *, required: bool | None = None, purpose: str = "", quality: str | None = None) -> ComponentData:
        """Get or create a component (one quality variant of it when ``quality`` is given).

        ``required`` may be left out to get a level that exists (e.g. to edit one from :meth:`from_asset`)."""
        _check_name("component", name)
        if quality is not None:
            _check_name("quality", quality)
        key = quality or ""
        if required is None:
            if key not in self.components.get(name, {}):
                have = {n: sorted(levels) for n, levels in self.components.items()}
                raise UsageError(f"component {name!r}{' quality ' + repr(quality) if quality else ''} does not exist "
                                 f"(have {have}); pass required= to create it")
            return self.components[name][key]
        levels = self.components.setdefault(name, {})
        if levels and (("" in levels) != (key == "")):
            raise UsageError(f"component {name!r} mixes quality variants with a plain version")
        if key not in levels:
            levels[key] = ComponentData(required=required, purpose=purpose)
            self.default_quality.setdefault(name, key)
        return levels[key]

    @classmethod
    def from_asset(cls, asset: "Asset") -> "AssetBuilder":
        """A builder holding all of ``asset``, to edit and :meth:`write` again (spec/format.md#editing).

        Copies kind, variant, geometry, encoding domain, metersPerUnit, fallback material, provenance and
        every component at every quality level (tensors in their stored dtype and layout, network bytes),
        with the file's default quality selections. Loads all components of ``asset``; its session-layer
        quality selections are left as they were."""
        if not isinstance(asset, Asset):
            raise UsageError(f"from_asset takes an opened nasset_sdk.Asset, got {type(asset).__name__}")
        b = cls(asset.kind, variant=asset.variant)
        geo = asset.geometry()
        geo.validate()
        b.geometry = geo
        b.domain = (np.array(asset.domain[0], np.float64), np.array(asset.domain[1], np.float64))
        b.meters_per_unit = float(asset.stage.GetMetadata("metersPerUnit") or 1.0)
        b.near_field_fetch = asset.near_field_fetch
        shader = asset.stage.GetPrimAtPath(FALLBACK + "/PreviewSurface")
        color = shader.GetAttribute("inputs:diffuseColor").Get() if shader else None
        roughness = shader.GetAttribute("inputs:roughness").Get() if shader else None
        if color is not None:
            b.fallback_color = tuple(float(c) for c in color)
        if roughness is not None:
            b.fallback_roughness = float(roughness)
        b.provenance = {k: v for k, v in asset.provenance.items() if k not in ("specVersion", "kind")}
        asset.load("all")
        root_layer = asset.stage.GetRootLayer()
        for cname, info in asset.components().items():
            if not info.qualities:
                b.components[cname] = {"": read_component(asset, cname)}
                b.default_quality[cname] = ""
                continue
            spec = root_layer.GetPrimAtPath(info.prim_path)
            default = (spec.variantSelections.get(QUALITY_SET) if spec else None) or info.quality
            levels = {}
            try:
                for q in info.qualities:
                    asset.select_quality({cname: q})
                    levels[q] = read_component(asset, cname)
            finally:
                asset.select_quality({cname: info.quality})
            b.components[cname] = levels
            b.default_quality[cname] = default
        return b

    # -- writing ---------------------------------------------------------------------------
    def build_layer(self):
        """Return an anonymous Sdf layer holding the asset."""
        register_schema()
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

        if self.geometry is None or self.domain is None:
            raise UsageError("asset has no geometry; call set_geometry first")
        from .kinds import get_kind

        get_kind(self.kind).check_builder(self)
        fetch = check_near_field_fetch(self.near_field_fetch, self.kind, {"attribute": NEAR_FIELD_FETCH})
        layer = Sdf.Layer.CreateAnonymous(".usdc")
        stage = Usd.Stage.Open(layer)
        stage.SetMetadata("upAxis", "Y")
        stage.SetMetadata("metersPerUnit", float(self.meters_per_unit))
        root = stage.DefinePrim(ROOT, "NeuralAsset")
        stage.SetDefaultPrim(root)
        Usd.ModelAPI(root).SetKind("component")
        root.CreateAttribute("nasset:kind", Sdf.ValueTypeNames.Token).Set(self.kind)
        version = limits.written_version(self.components, [NEAR_FIELD_FETCH] if fetch > 0 else [])
        root.CreateAttribute("nasset:specVersion", Sdf.ValueTypeNames.String).Set(version)
        root.CreateAttribute("nasset:variant", Sdf.ValueTypeNames.Token).Set(self.variant)
        lo, hi = self.domain
        root.CreateAttribute("nasset:domainMin", Sdf.ValueTypeNames.Float3).Set(Gf.Vec3f(*map(float, lo)))
        root.CreateAttribute("nasset:domainMax", Sdf.ValueTypeNames.Float3).Set(Gf.Vec3f(*map(float, hi)))
        if fetch > 0:
            root.CreateAttribute(NEAR_FIELD_FETCH, Sdf.ValueTypeNames.Float).Set(fetch)
        prov = {**self.provenance, "specVersion": version, "kind": self.kind}  # required keys win
        root.CreateAttribute("nasset:provenance", Sdf.ValueTypeNames.String).Set(json.dumps(prov, sort_keys=True))

        geo = self.geometry
        lo_g, hi_g = geo.bounds()
        if isinstance(geo, MeshGeometry):
            mesh = UsdGeom.Mesh.Define(stage, GEOMETRY)
            mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(geo.points, np.float32)))
            mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(geo.faces), 3, np.int32)))
            mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(geo.faces.reshape(-1), np.int32)))
            mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
            mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
            if geo.normals is not None:
                mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(geo.normals, np.float32)))
                mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
            gprim = mesh
        else:
            curves = UsdGeom.BasisCurves.Define(stage, GEOMETRY)
            curves.CreateTypeAttr(UsdGeom.Tokens.linear)
            curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(geo.points, np.float32)))
            curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(geo.counts, np.int32)))
            curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(np.ascontiguousarray(geo.widths, np.float32)))
            curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
            gprim = curves
        gprim.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*map(float, lo_g)), Gf.Vec3f(*map(float, hi_g))]))

        UsdGeom.Scope.Define(stage, ROOT + "/Looks")
        material = UsdShade.Material.Define(stage, FALLBACK)
        shader = UsdShade.Shader.Define(stage, FALLBACK + "/PreviewSurface")
        shader.CreateIdAttr("UsdPreviewSurface")
        shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*map(float, self.fallback_color)))
        shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(self.fallback_roughness))
        material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        UsdShade.MaterialBindingAPI.Apply(gprim.GetPrim()).Bind(material)

        UsdGeom.Scope.Define(stage, COMPONENTS)
        stage.CreateClassPrim(PAYLOAD_ROOT)
        for name, levels in self.components.items():
            comp_prim = stage.DefinePrim(f"{COMPONENTS}/{name}", "NeuralComponent")
            first = next(iter(levels.values()))
            comp_prim.CreateAttribute("nasset:required", Sdf.ValueTypeNames.Bool, custom=False).Set(bool(first.required))
            comp_prim.CreateAttribute("nasset:purpose", Sdf.ValueTypeNames.String, custom=False).Set(first.purpose)
            for quality, data in levels.items():
                target = f"{PAYLOAD_ROOT}/{name}" + (f"__{quality}" if quality else "")
                self._write_component(stage, target, data)
            if "" in levels:
                comp_prim.GetPayloads().AddInternalPayload(f"{PAYLOAD_ROOT}/{name}")
            else:
                vset = comp_prim.GetVariantSets().AddVariantSet(QUALITY_SET)
                for quality in levels:
                    vset.AddVariant(quality)
                    vset.SetVariantSelection(quality)
                    with vset.GetVariantEditContext():
                        comp_prim.GetPayloads().AddInternalPayload(f"{PAYLOAD_ROOT}/{name}__{quality}")
                vset.SetVariantSelection(self.default_quality[name])
        return layer

    @staticmethod
    def _write_component(stage, path: str, data: ComponentData) -> None:
        from pxr import Sdf, UsdGeom, Vt

        UsdGeom.Scope.Define(stage, path)
        for tname, (arr, dtype, layout) in data.tensors.items():
            prim = stage.DefinePrim(f"{path}/{tname}", "NeuralTensor")
            prim.CreateAttribute("shape", Sdf.ValueTypeNames.IntArray, custom=False).Set(Vt.IntArray(list(arr.shape)))
            prim.CreateAttribute("dtype", Sdf.ValueTypeNames.Token, custom=False).Set(dtype)
            prim.CreateAttribute("layout", Sdf.ValueTypeNames.String, custom=False).Set(layout)
            flat = np.ascontiguousarray(arr.reshape(-1))
            if dtype == "float16":
                value = Vt.HalfArray.FromNumpy(flat)
                vtype = Sdf.ValueTypeNames.HalfArray
            else:
                value = Vt.FloatArray.FromNumpy(flat)
                vtype = Sdf.ValueTypeNames.FloatArray
            prim.CreateAttribute("values", vtype, custom=True, variability=Sdf.VariabilityUniform).Set(value)
        for nname, blob in data.networks.items():
            info = info_from_model(blob)
            prim = stage.DefinePrim(f"{path}/{nname}", "NeuralNetwork")
            a = lambda n, t, prim=prim: prim.CreateAttribute(n, t, custom=False)  # noqa: E731
            a("onnx:model", Sdf.ValueTypeNames.UCharArray).Set(Vt.UCharArray.FromNumpy(np.frombuffer(blob, np.uint8)))
            a("onnx:sha256", Sdf.ValueTypeNames.String).Set(sha256_hex(blob))
            a("onnx:opset", Sdf.ValueTypeNames.Int).Set(info.opset)
            a("onnx:inputNames", Sdf.ValueTypeNames.StringArray).Set(list(info.input_names))
            a("onnx:outputNames", Sdf.ValueTypeNames.StringArray).Set(list(info.output_names))
            a("onnx:inputWidths", Sdf.ValueTypeNames.IntArray).Set(list(info.input_widths))
            a("onnx:outputWidths", Sdf.ValueTypeNames.IntArray).Set(list(info.output_widths))

    def write(self, path: str | os.PathLike) -> Path:
        """Write the asset to ``path`` (.usdc, or .usda for small fixtures) atomically.

        The layer is exported to a temporary file in the target folder, flushed to disk and
        renamed over the target, so an interrupted write never leaves a partial file there.
        """
        target = Path(path)
        if target.suffix not in (".usdc", ".usda", ".usd"):
            raise UsageError(f"asset path must end in .usdc, .usda or .usd: {target}", file=str(target))
        layer = self.build_layer()
        atomic_export(layer, target)
        return target


def atomic_export(layer, target: Path) -> None:
    """Export an Sdf layer to ``target`` via temp file + fsync + rename (:func:`~nasset_sdk.images.atomic_output`:
    the file gets the permissions the process umask gives, as with a plain ``open``)."""
    from .images import atomic_output

    target = Path(target)
    if not target.parent.is_dir():
        raise error("WRITE_FAILED", "target folder does not exist", file=str(target))
    fmt_args = {"format": "usdc"} if target.suffix == ".usd" else {}
    with atomic_output(target, "USD layer") as tmp:
        if not layer.Export(tmp, args=fmt_args):
            raise OSError("USD could not export the layer")
        with open(tmp, "rb") as fh:
            os.fsync(fh.fileno())
    try:
        dir_fd = os.open(target.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)
    except OSError as exc:
        raise error("WRITE_FAILED", f"{exc.strerror or exc}", file=str(target)) from None
    from .safeopen import trust

    trust(target)  # written from checked data by this process: reopened without a probe while unchanged


# ----------------------------------------------------------------------------------------
# reading


def read_component(asset: "Asset", name: str) -> ComponentData:
    """The loaded component ``name`` of ``asset`` (its selected quality level) as ComponentData:
    tensors in their stored dtype and layout, network bytes after the digest and security checks."""
    info = asset.components()[name]
    data = ComponentData(required=info.required, purpose=info.purpose)
    for tname, ref in asset.tensor_refs(name).items():
        data.add_tensor(tname, asset.tensor(name, tname), dtype=ref.dtype, layout=ref.layout)
    for nname in asset.network_refs(name):
        data.add_network(nname, asset.network_bytes(name, nname))
    return data


@dataclass(frozen=True)
class TensorRef:
    component: str
    name: str
    prim_path: str
    shape: tuple[int, ...]
    dtype: str
    layout: str

    @property
    def nbytes(self) -> int:
        return shape_count(self.shape) * (2 if self.dtype == "float16" else 4)


def shape_count(shape) -> int:
    """Number of elements of ``shape`` as an exact Python int (``np.prod`` wraps int64 on overflow)."""
    count = 1
    for d in shape:
        count *= int(d)
    return count


@dataclass(frozen=True)
class NetworkRef:
    component: str
    name: str
    prim_path: str
    info: NetworkInfo


@dataclass
class ComponentInfo:
    name: str
    prim_path: str
    required: bool
    purpose: str
    loaded: bool
    qualities: tuple[str, ...]
    quality: str | None


class Asset:
    """A neural asset opened for reading. Use :meth:`open`.

    Components are loaded on demand (:meth:`load`); tensors come back as read-only numpy
    arrays, networks as verified bytes or onnxruntime sessions.
    """

    def __init__(self, path: Path, stage) -> None:
        from .safeopen import written_here

        self.path = path
        self.stage = stage
        self.root = stage.GetPrimAtPath(ROOT) if stage.GetDefaultPrim() else stage.GetDefaultPrim()
        self._sessions: dict = {}
        self._runs: set[tuple[str, str]] = set()  # networks that passed the runtime probe
        self._written_here = written_here(path)  # networks this process wrote are not probed again

    # -- opening ---------------------------------------------------------------------------
    @classmethod
    def open(
        cls,
        path: str | os.PathLike,
        *,
        load: str | Iterable[str] = "required",
        quality: dict[str, str] | str | None = None,
        probe: bool | None = None,
    ) -> "Asset":
        """Open lazily (``Usd.Stage.LoadNone``) and load ``load``: 'required', 'all', 'none' or names.

        ``quality`` picks a quality variant ('hq', or {component: variant}) without editing the file.
        The file is untrusted: it is first read whole in a child process (nasset_sdk.safeopen, ~0.4 s +
        one read), so a corrupted crate that would crash usd-core raises FILE_UNREADABLE and one that
        decodes beyond its bounds, or holds more specs than an asset may, ARRAY_TOO_LARGE, instead of taking this process down. ``probe=None``
        skips that for a file this process wrote or already probed, unchanged since; ``True`` always
        probes; ``False`` never does (the caller trusts the file with this process's memory).
        """
        register_schema()
        from pxr import Tf, Usd

        from .paths import open_checked_stage, outer_file

        p = path_arg(path, "Asset.open: the asset")
        if not os.path.isfile(outer_file(str(p))):  # a file, or a layer inside a package: 'scene.usdz[a.usdc]'
            raise error("FILE_NOT_FOUND", "no such file", file=str(p))
        from .safeopen import ensure_readable, ensure_safe

        if probe:
            ensure_readable(p, asset=True)
        elif probe is None:
            ensure_safe(p, asset=True)
        try:
            # every sublayer / reference / payload / clip / asset path is checked before anything composes
            stage = open_checked_stage(p, Usd.Stage.LoadNone, probe=probe is not False)
        except Tf.ErrorException as exc:
            raise error("FILE_UNREADABLE", f"USD cannot open it: {usd_reason(exc)}", file=str(p)) from None
        if stage is None:
            raise error("FILE_UNREADABLE", "USD cannot open it", file=str(p))
        return cls.from_stage(p, stage, load=load, quality=quality)

    @classmethod
    def from_stage(cls, path: Path, stage, *, load: str | Iterable[str] = "required",
                   quality: dict[str, str] | str | None = None) -> "Asset":
        """An asset read from an opened ``stage`` whose default prim is its root (``path`` names it in messages);
        the header is checked as in :meth:`open`, whose file and path checks the caller is responsible for."""
        default = stage.GetDefaultPrim()
        if not default or default.GetTypeName() != "NeuralAsset" or str(default.GetPath()) != ROOT:
            raise error("ROOT_MISSING", f"defaultPrim must be a NeuralAsset at {ROOT}", file=str(path),
                        prim=str(default.GetPath()) if default else None)
        asset = cls(Path(path), stage)
        asset._check_header()
        if quality is not None:
            asset.select_quality(quality)
        if load != "none":
            asset.load(load)
        return asset

    def _loc(self, prim=None, attribute=None) -> dict:
        return {"file": str(self.path), "prim": str(prim) if prim is not None else ROOT, "attribute": attribute}

    def _attr(self, prim, name: str, *, required: bool = True, code: str = "SCHEMA_TYPE"):
        attr = prim.GetAttribute(name)
        # authored opinions only: schema fallbacks (e.g. specVersion "0.1") must not stand in for them
        value = attr.Get() if attr and attr.HasAuthoredValue() else None
        if value is None and required:
            raise error(code, f"missing attribute {name}", **self._loc(prim.GetPath(), name))
        return value

    def _check_header(self) -> None:
        from .kinds import KINDS

        version = self._attr(self.root, "nasset:specVersion", code="SPEC_VERSION")
        m = re.fullmatch(r"([0-9]+)\.([0-9]+)", str(version), re.ASCII)
        if not m or int(m.group(1)) != limits.SUPPORTED_MAJOR:
            raise error("SPEC_VERSION", f"specVersion {version!r} not readable by this SDK (major {limits.SUPPORTED_MAJOR})",
                        **self._loc(ROOT, "nasset:specVersion"))
        self.spec_version = str(version)
        self.kind = str(self._attr(self.root, "nasset:kind", code="KIND_UNKNOWN"))
        if self.kind not in KINDS:
            raise error("KIND_UNKNOWN", f"kind {self.kind!r} is not one of {sorted(KINDS)}", **self._loc(ROOT, "nasset:kind"))
        self.variant = str(self._attr(self.root, "nasset:variant", code="VARIANT_UNKNOWN"))
        if self.variant not in KINDS[self.kind].variants:
            raise error("VARIANT_UNKNOWN", f"variant {self.variant!r} not in {KINDS[self.kind].variants}",
                        **self._loc(ROOT, "nasset:variant"))
        lo = self._attr(self.root, "nasset:domainMin", code="DOMAIN_INVALID")
        hi = self._attr(self.root, "nasset:domainMax", code="DOMAIN_INVALID")
        lo, hi = np.array(lo, np.float64), np.array(hi, np.float64)
        if lo.shape != (3,) or hi.shape != (3,) or not (np.isfinite(lo).all() and np.isfinite(hi).all()) or not (hi > lo).all():
            raise error("DOMAIN_INVALID", f"domain {lo} .. {hi} must be finite with max > min", **self._loc(ROOT, "nasset:domainMin"))
        self.domain = (lo, hi)

    @property
    def near_field_fetch(self) -> float:
        """f in [0, 1]: a renderer fetches the light of an rna or neupress hit x at x + f (c - x), c the encoding box's centre
        (spec/kinds/rna.md#near-field-fetch); 0 where the attribute is not authored (the distant-light rule)."""
        return check_near_field_fetch(self._attr(self.root, NEAR_FIELD_FETCH, required=False), self.kind,
                                      self._loc(ROOT, NEAR_FIELD_FETCH))

    @property
    def provenance(self) -> dict:
        raw = self._attr(self.root, "nasset:provenance", required=False) or "{}"
        try:
            value = json.loads(raw)
        except (TypeError, ValueError):
            raise error("METADATA_INVALID", "provenance is not JSON", **self._loc(ROOT, "nasset:provenance")) from None
        if not isinstance(value, dict):
            raise error("METADATA_INVALID", "provenance must be a JSON object", **self._loc(ROOT, "nasset:provenance"))
        return value

    @property
    def contract(self):
        from .kinds import get_kind

        return get_kind(self.kind)

    # -- components ------------------------------------------------------------------------
    def components(self) -> dict[str, ComponentInfo]:
        out = {}
        comps = self.stage.GetPrimAtPath(COMPONENTS)
        if not comps:
            return out
        for child in comps.GetAllChildren():
            if child.GetTypeName() != "NeuralComponent":
                continue
            vs = child.GetVariantSets()
            qualities = tuple(vs.GetVariantSet(QUALITY_SET).GetVariantNames()) if vs.HasVariantSet(QUALITY_SET) else ()
            quality = vs.GetVariantSet(QUALITY_SET).GetVariantSelection() if qualities else None
            req = child.GetAttribute("nasset:required").Get()
            out[child.GetName()] = ComponentInfo(
                child.GetName(), str(child.GetPath()), bool(req) if req is not None else True,
                str(child.GetAttribute("nasset:purpose").Get() or ""), child.IsLoaded(), qualities, quality or None,
            )
        return out

    def select_quality(self, quality: dict[str, str] | str) -> None:
        """Pick quality variants in the session layer (the file is not edited)."""
        from pxr import Usd

        comps = self.components()
        wanted = quality if isinstance(quality, dict) else {n: quality for n, c in comps.items() if c.qualities}
        if not wanted:
            raise UsageError(f"asset has no quality variants; asked for {quality!r}", file=str(self.path))
        with Usd.EditContext(self.stage, self.stage.GetSessionLayer()):
            for name, q in wanted.items():
                if name not in comps or q not in comps[name].qualities:
                    raise UsageError(f"component {name!r} has no quality {q!r}", file=str(self.path))
                prim = self.stage.GetPrimAtPath(comps[name].prim_path)
                prim.GetVariantSets().GetVariantSet(QUALITY_SET).SetVariantSelection(q)

    def load(self, which: str | Iterable[str] = "required") -> None:
        """Load components: 'required', 'all' or an iterable of names."""
        comps = self.components()
        if which == "all":
            names = list(comps)
        elif which == "required":
            names = [n for n, c in comps.items() if c.required]
            missing = [n for n in self.contract.required_components(self.variant) if n not in comps]
            if missing:
                raise error("COMPONENT_MISSING", f"required components {missing} absent", **self._loc(COMPONENTS))
        elif isinstance(which, str):
            names = [which]
        else:
            try:
                names = list(which)
            except TypeError:
                raise UsageError(f"load: 'required', 'all', 'none' or component names, got {which!r}") from None
        for n in names:
            if n not in comps:
                raise error("COMPONENT_MISSING", f"no component {n!r}", **self._loc(f"{COMPONENTS}/{n}"))
            self.stage.Load(comps[n].prim_path)

    def _component_prim(self, component: str):
        prim = self.stage.GetPrimAtPath(f"{COMPONENTS}/{component}")
        if not prim or prim.GetTypeName() != "NeuralComponent":
            raise error("COMPONENT_MISSING", f"no component {component!r}", **self._loc(f"{COMPONENTS}/{component}"))
        if not prim.IsLoaded():
            raise UsageError(f"component {component!r} is not loaded; call load({component!r})", file=str(self.path),
                             prim=str(prim.GetPath()))
        return prim

    def tensor_refs(self, component: str) -> dict[str, TensorRef]:
        prim = self._component_prim(component)
        out = {}
        for child in prim.GetChildren():
            if child.GetTypeName() != "NeuralTensor":
                continue
            shape = child.GetAttribute("shape").Get()
            dtype = child.GetAttribute("dtype").Get()
            out[child.GetName()] = TensorRef(component, child.GetName(), str(child.GetPath()),
                                             tuple(int(s) for s in (shape or ())), str(dtype), str(child.GetAttribute("layout").Get() or ""))
        return out

    def network_refs(self, component: str) -> dict[str, NetworkRef]:
        prim = self._component_prim(component)
        out = {}
        for child in prim.GetChildren():
            if child.GetTypeName() != "NeuralNetwork":
                continue
            g = lambda n, child=child: child.GetAttribute(n).Get()  # noqa: E731
            info = NetworkInfo(tuple(g("onnx:inputNames") or ()), tuple(g("onnx:outputNames") or ()),
                               tuple(g("onnx:inputWidths") or ()), tuple(g("onnx:outputWidths") or ()), int(g("onnx:opset") or -1))
            out[child.GetName()] = NetworkRef(component, child.GetName(), str(child.GetPath()), info)
        return out

    def tensor(self, component: str, name: str) -> np.ndarray:
        """Tensor as a read-only numpy array of its stored dtype and shape (no copy where crate maps it)."""
        prim = self._component_prim(component).GetChild(name)
        path = f"{COMPONENTS}/{component}/{name}"
        if not prim or prim.GetTypeName() != "NeuralTensor":
            raise error("TENSOR_MISSING", f"no tensor {name!r} in component {component!r}", **self._loc(path))
        shape = prim.GetAttribute("shape").Get()
        dtype = prim.GetAttribute("dtype").Get()
        values_attr = prim.GetAttribute("values")
        if dtype not in limits.TENSOR_DTYPES:
            raise error("TENSOR_DTYPE", f"dtype {dtype!r} not one of {limits.TENSOR_DTYPES}", **self._loc(path, "dtype"))
        want_type = "half[]" if dtype == "float16" else "float[]"
        if not values_attr or str(values_attr.GetTypeName()) != want_type:
            raise error("TENSOR_DTYPE", f"values must be {want_type} for dtype {dtype}", **self._loc(path, "values"))
        if shape is None or len(shape) == 0 or len(shape) > limits.MAX_TENSOR_RANK or any(int(s) < 0 for s in shape):
            raise error("TENSOR_SHAPE", f"shape {list(shape) if shape is not None else None} malformed", **self._loc(path, "shape"))
        shape = tuple(int(s) for s in shape)
        count = shape_count(shape)  # Python ints: np.prod wraps at 2**63
        if count == 0:
            raise error("TENSOR_SHAPE", f"shape {shape} has a zero dimension; a tensor holds data", **self._loc(path, "shape"))
        if count > limits.MAX_TENSOR_ELEMENTS:
            raise error("TENSOR_TOO_LARGE", f"shape {shape} has {count} elements > {limits.MAX_TENSOR_ELEMENTS}", **self._loc(path, "shape"))
        raw = values_attr.Get()
        arr = np.asarray(raw) if raw is not None else np.zeros(0, np.dtype(dtype))
        if arr.size != count:
            raise error("TENSOR_SHAPE", f"shape {shape} needs {count} values, found {arr.size}", **self._loc(path, "values"))
        arr = arr.reshape(shape)
        arr.flags.writeable = False
        return arr

    def network_bytes(self, component: str, name: str) -> bytes:
        """Model bytes after the digest and the security checks (spec/security.md#networks)."""
        prim = self._component_prim(component).GetChild(name)
        path = f"{COMPONENTS}/{component}/{name}"
        if not prim or prim.GetTypeName() != "NeuralNetwork":
            raise error("NETWORK_MISSING", f"no network {name!r} in component {component!r}", **self._loc(path))
        raw = prim.GetAttribute("onnx:model").Get()
        if raw is None:
            raise error("NETWORK_MISSING", "onnx:model is empty", **self._loc(path, "onnx:model"))
        data = np.asarray(raw, dtype=np.uint8).tobytes()
        digest = prim.GetAttribute("onnx:sha256").Get()
        if not digest or sha256_hex(data) != str(digest).lower():
            raise error("NETWORK_DIGEST", "sha256 of onnx:model differs from onnx:sha256", **self._loc(path, "onnx:sha256"))
        ref = self.network_refs(component)[name]
        check_model_bytes(data, ref.info, **self._loc(path, "onnx:model"))
        return data

    def check_runtime(self, component: str, name: str) -> None:
        """Raise the runtime probe's finding for network ``name`` (spec/security.md#networks), as the validator does:
        NETWORK_RUNTIME for a network that does not run within the probe's time and memory bound (a reader would
        hang or run out of memory in it), NETWORK_OUTPUT for non-finite, huge or row-mixing outputs. The networks of
        ``component`` are probed together in one bounded child, once per process (``netprobe.probe_once``); an
        asset file this process wrote is trusted."""
        from .netprobe import make_job, probe_once

        if self._written_here or (component, name) in self._runs:
            return
        jobs = {}
        for nname, ref in self.network_refs(component).items():
            try:
                data = self.network_bytes(component, nname)
            except NassetError:
                if nname == name:
                    raise
                continue  # raised when that network is asked for
            units = tuple(self.contract.probe_unit_columns(self.variant, component, nname, n, int(w))
                          for n, w in zip(ref.info.input_names, ref.info.input_widths, strict=True))
            jobs[nname] = make_job(data, ref.info, units)
        found = probe_once(list(jobs.values()))
        for nname, job in jobs.items():
            if not found[job.key]:
                self._runs.add((component, nname))
        if found[jobs[name].key]:
            code, message = found[jobs[name].key][0]
            raise error(code, f"runtime probe: {message}", **self._loc(f"{COMPONENTS}/{component}/{name}", "onnx:model"))

    def evaluable_bytes(self, component: str, name: str) -> bytes:
        """Model bytes for an evaluator that runs them itself (not through :meth:`session`): :meth:`network_bytes`
        after :meth:`check_runtime`."""
        data = self.network_bytes(component, name)
        self.check_runtime(component, name)
        return data

    def session(self, component: str, name: str, *, intra_threads: int = 0, inter_threads: int = 1):
        """onnxruntime session for a network (cached per thread setting), after :meth:`check_runtime`."""
        key = (component, name, intra_threads, inter_threads)
        if key not in self._sessions:
            data = self.network_bytes(component, name)
            self.check_runtime(component, name)
            loc = self._loc(f"{COMPONENTS}/{component}/{name}", "onnx:model")
            try:
                session = make_session(data, intra_threads=intra_threads, inter_threads=inter_threads)
            except Exception as exc:
                raise error("NETWORK_RUNTIME", f"onnxruntime cannot load it: {str(exc)[:200]}", **loc) from None
            # evaluation failures become typed NETWORK_RUNTIME errors naming this network
            self._sessions[key] = CheckedSession(session, self.network_refs(component)[name].info, **loc)
        return self._sessions[key]

    # -- geometry --------------------------------------------------------------------------
    def geometry(self) -> MeshGeometry | CurvesGeometry:
        """Geometry arrays in object space (checked: counts, index range, finiteness)."""
        from pxr import UsdGeom

        prim = self.stage.GetPrimAtPath(GEOMETRY)
        if not prim:
            raise error("GEOMETRY_MISSING", "no Geometry prim", **self._loc(GEOMETRY))
        loc = lambda a=None: self._loc(GEOMETRY, a)  # noqa: E731
        want = "Mesh" if self.variant == "surface" else "BasisCurves"
        if prim.GetTypeName() != want:
            raise error("GEOMETRY_MISSING", f"Geometry must be a {want} for variant {self.variant}", **loc())
        pts_raw = prim.GetAttribute("points").Get()
        pts = np.asarray(pts_raw, np.float32).reshape(-1, 3) if pts_raw is not None else np.zeros((0, 3), np.float32)
        if len(pts) == 0 or not np.isfinite(pts).all():
            raise error("GEOMETRY_INVALID", "points empty or non-finite", **loc("points"))
        if want == "Mesh":
            mesh = UsdGeom.Mesh(prim)
            counts = np.asarray(mesh.GetFaceVertexCountsAttr().Get() or [], np.int64)
            idx = np.asarray(mesh.GetFaceVertexIndicesAttr().Get() or [], np.int64)
            if len(counts) == 0 or (counts != 3).any() or counts.sum() != len(idx):
                raise error("GEOMETRY_INVALID", "faceVertexCounts must be all 3 and sum to len(faceVertexIndices)", **loc("faceVertexCounts"))
            if idx.min() < 0 or idx.max() >= len(pts):
                raise error("GEOMETRY_INVALID", "faceVertexIndices out of range", **loc("faceVertexIndices"))
            normals = mesh.GetNormalsAttr().Get()
            n = np.asarray(normals, np.float32).reshape(-1, 3) if normals is not None and len(normals) else None
            if n is not None and n.shape != pts.shape:
                raise error("GEOMETRY_NORMALS", "normals must be per vertex", **loc("normals"))
            return MeshGeometry(pts, idx.reshape(-1, 3).astype(np.int32), n)
        curves = UsdGeom.BasisCurves(prim)
        counts = np.asarray(curves.GetCurveVertexCountsAttr().Get() or [], np.int64)
        widths = np.asarray(curves.GetWidthsAttr().Get() or [], np.float32)
        if len(counts) == 0 or (counts < 2).any() or counts.sum() != len(pts):
            raise error("GEOMETRY_INVALID", "curveVertexCounts must be >= 2 and sum to len(points)", **loc("curveVertexCounts"))
        if widths.shape != (len(pts),) or not np.isfinite(widths).all() or (widths <= 0).any():
            raise error("GEOMETRY_INVALID", "widths must be one positive value per point", **loc("widths"))
        return CurvesGeometry(pts, counts.astype(np.int32), widths)

    def evaluator(self, **options):
        """The kind's numpy + onnxruntime evaluator over the loaded components; ``options`` are its keyword arguments
        (USAGE for one it does not take, :func:`nasset_sdk.kinds.new_evaluator`)."""
        return self.contract.evaluator(self, **options)
