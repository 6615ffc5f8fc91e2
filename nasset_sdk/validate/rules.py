"""The validator's rules (spec/validation.md) and the checks that apply them.

Each :class:`Rule` has a stable code from :data:`nasset_sdk.errors.CODES`, a severity, a
one-line description and the spec paragraph it enforces (``CODES[code].spec``). Checks run in
phases over one file; every phase is guarded, so a malformed file yields findings, never an
exception. Corrupted crate files can crash usd-core itself, so the file is first opened in a
child process (:mod:`nasset_sdk.safeopen`) and only opened here when that probe passed.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .. import limits
from ..errors import CODES, NassetError
from ..paths import path_escapes  # noqa: F401 - re-exported: nasset_sdk.validate.path_escapes
from .report import Finding, Report


@dataclass(frozen=True)
class Rule:
    code: str
    severity: str  # error | warning | info
    description: str

    @property
    def spec(self) -> str:
        return CODES[self.code].spec

    def to_dict(self) -> dict:
        return {"code": self.code, "severity": self.severity, "description": self.description, "spec": self.spec}


RULES: tuple[Rule, ...] = (
    Rule("FILE_NOT_FOUND", "error", "the file exists"),
    Rule("FILE_UNREADABLE", "error",
         "the file opens as a USD layer in a guarded child process, then in-process, and the stage composes"),
    Rule("ROOT_MISSING", "error", "defaultPrim is /Asset and its type is NeuralAsset"),
    Rule("SPEC_VERSION", "error", "nasset:specVersion is authored, MAJOR.MINOR, with a MAJOR this SDK reads"),
    Rule("SPEC_VERSION_NEWER", "warning",
         "nasset:specVersion's MINOR is at most the one this SDK implements (content of a newer minor is not validated)"),
    Rule("KIND_UNKNOWN", "error", "nasset:kind is authored and names a registered kind"),
    Rule("VARIANT_UNKNOWN", "error", "nasset:variant is authored and one the kind allows"),
    Rule("SCHEMA_TYPE", "error",
         "components are NeuralComponent, their children NeuralTensor or NeuralNetwork; schema attributes have the schema's value types"),
    Rule("PAYLOAD_INVALID", "error",
         "each component carries exactly one internal payload (per quality variant) to a child of the /_NassetPayloads class prim"),
    Rule("QUALITY_VARIANT", "error", "the only variant set on a component is 'quality', with variants and a valid selection"),
    Rule("COMPONENT_MISSING", "error", "every component the kind requires for the variant is present"),
    Rule("COMPONENT_UNKNOWN", "warning", "every component is declared by the kind"),
    Rule("TENSOR_MISSING", "error", "every tensor the kind requires is present"),
    Rule("TENSOR_DTYPE", "error", "dtype is float16/float32 and values is half[]/float[] to match"),
    Rule("TENSOR_SHAPE", "error", "shape is authored, rank 1..8, non-negative, and its product equals len(values)"),
    Rule("TENSOR_TOO_LARGE", "error", "a tensor declares at most MAX_TENSOR_ELEMENTS elements"),
    Rule("TENSOR_NONFINITE", "error", "no tensor value is NaN or Inf (fp16 overflow included)"),
    Rule("TENSOR_CONTRACT", "error", "tensor ranks and dimensions match the kind contract; an undeclared tensor is a warning"),
    Rule("NETWORK_MISSING", "error", "every network the kind requires is present with model bytes"),
    Rule("NETWORK_TOO_LARGE", "error", "model bytes are within MAX_NETWORK_BYTES"),
    Rule("NETWORK_DIGEST", "error", "onnx:sha256 equals the sha256 of onnx:model"),
    Rule("NETWORK_PARSE", "error", "onnx:model parses as an ONNX ModelProto and passes onnx.checker"),
    Rule("NETWORK_EXTERNAL_DATA", "error", "no model tensor references external data"),
    Rule("NETWORK_CUSTOM_DOMAIN", "error", "the model uses only the default operator domain and no local functions"),
    Rule("NETWORK_OPSET", "error", "the default-domain opset is within [OPSET_MIN, OPSET_MAX] and equals onnx:opset"),
    Rule("NETWORK_IO", "error", "input/output names and widths equal the declaration and the kind contract"),
    Rule("NETWORK_RUNTIME", "error",
         "onnxruntime loads and runs the model at batch sizes 1, 7 and 256 within the probe's time and memory bound, "
         "with outputs [n, declared width]"),
    Rule("NETWORK_OP_FORBIDDEN", "error",
         "only allow-listed operators, with row-preserving attributes and constant parameters; no sparse tensors"),
    Rule("NETWORK_SHAPE", "error", "shape inference proves every value computed from the inputs to be [N, fixed width]"),
    Rule("NETWORK_OUTPUT", "error",
         "on probe inputs every output is finite, within MAX_NETWORK_OUTPUT in magnitude, and each row depends on its own input row only"),
    Rule("KIND_CONTRACT", "error", "kind-specific constraints hold (values, nasset:required flags)"),
    Rule("GEOMETRY_MISSING", "error", "/Asset/Geometry exists with the type the variant needs (Mesh or BasisCurves)"),
    Rule("GEOMETRY_INVALID", "error", "points finite; triangle counts; indices in range; curve counts and widths valid"),
    Rule("GEOMETRY_DEGENERATE", "error", "at least one face has non-zero area / one curve non-zero length"),
    Rule("GEOMETRY_NORMALS", "error", "normals, when authored, are per vertex and unit length (|n| within 1e-3 of 1)"),
    Rule("GEOMETRY_SCALE", "error", "|coordinates| <= MAX_GEOMETRY_COORDINATE; bounding-box diagonal >= MIN_GEOMETRY_SIZE and "
         ">= MIN_GEOMETRY_SIZE_RATIO x the largest |coordinate|"),
    Rule("EXTENT_MISMATCH", "error", "the geometry's extent is authored and equals its bounds (widths included for curves)"),
    Rule("DOMAIN_INVALID", "error", "the encoding box is authored, finite, non-empty and contains the geometry"),
    Rule("NEAR_FIELD_INVALID", "error", "nasset:nearFieldFetch, when authored, is a float in [0, 1], and non-zero only on kinds rna and neupress"),
    Rule("ASSET_PATH_ESCAPES", "error",
         "no asset path (sublayer, reference, payload, clip, attribute value, metadata, time sample; every variant) is absolute, "
         "a URL, an expression, a bare search path, malformed, or resolves (Ar, then realpath) outside the package or to a "
         "non-regular file"),
    Rule("LAYER_EXTERNAL", "error", "the asset is one layer: no sublayers, no references or payloads to other files, no value clips"),
    Rule("VARIANT_SET_UNEXPECTED", "error", "no variant set other than a component's 'quality' set (none on other prims, none nested)"),
    Rule("TIME_SAMPLES", "error", "no attribute carries time samples"),
    Rule("ARRAY_TOO_LARGE", "error",
         "geometry and other arrays are within the format bounds, the layer's specs, nesting and the prims it composes to "
         "within the asset bounds, and reading the file stays within its memory bound"),
    Rule("METADATA_MISSING", "error", "nasset:provenance is authored and has the required keys specVersion, kind and generator"),
    Rule("METADATA_INVALID", "error", "nasset:provenance is a JSON object whose specVersion and kind equal the root's"),
    Rule("FALLBACK_MISSING", "warning", "the geometry is bound to a material whose surface is a UsdPreviewSurface"),
    Rule("USD_CHECK", "warning", "OpenUSD's validators (--usd-checks) report nothing; their error/warning/info severity is kept"),
    Rule("CHECK_FAILED", "error", "every check completed on this input (otherwise the asset is treated as invalid)"),
)
RULE_BY_CODE: dict[str, Rule] = {r.code: r for r in RULES}
PROVENANCE_REQUIRED = ("specVersion", "kind", "generator")
NORMAL_TOLERANCE = 1e-3
PROBE_TIMEOUT_S = 120.0
NETWORK_PROBE_TIMEOUT_S = 30.0

_NASSET_TYPES = ("NeuralAsset", "NeuralComponent", "NeuralTensor", "NeuralNetwork")
class _Abort(Exception):
    """Stop the run: later checks need what failed."""


class Validation:
    """One validation run over one file; :func:`validate_file` is the entry point."""

    def __init__(self, path: str, *, usd_checks: bool = False, probe: bool = True,
                 probe_timeout: float = PROBE_TIMEOUT_S, network_probe_timeout: float = NETWORK_PROBE_TIMEOUT_S) -> None:
        self.path = Path(path)
        self.report = Report(str(path))
        self.usd_checks = usd_checks
        self.probe = probe
        self.probe_timeout = probe_timeout
        self.layer = None
        self.stage = None
        self.asset = None
        self.kind = None
        self.variant = None
        self.domain = None
        self.components: dict = {}
        self.checked = {"components": [], "tensors": 0, "networks": 0}
        self._net_jobs: dict = {}  # probe key -> (ProbeJob, [(prim path, message suffix)])
        self.network_probe_timeout = network_probe_timeout

    # -- reporting -------------------------------------------------------------------------
    def emit(self, code: str, message: str, prim=None, attribute=None, severity: str | None = None) -> None:
        rule = RULE_BY_CODE.get(code)
        sev = severity or (rule.severity if rule else "error")
        self.report.add(Finding(code, sev, message, None if prim is None else str(prim), attribute))

    def _guard(self, phase, *args) -> bool:
        """Run a phase; map typed errors to findings and anything else to CHECK_FAILED."""
        try:
            phase(*args)
            return True
        except _Abort:
            raise
        except NassetError as exc:
            self.emit(exc.code, exc.message, exc.prim, exc.attribute)
        except Exception as exc:  # a check tripped on malformed input: report it, never crash
            self.emit("CHECK_FAILED", f"{phase.__name__}: {type(exc).__name__}: {str(exc).strip()[:200]}")
        return False

    def run(self) -> Report:
        try:
            self._guard(self._open)
            if self.layer is not None:
                self._guard(self._asset_paths)
                self._guard(self._layer_content)
                self._guard(self._compose)
            if self.stage is not None:
                if self._guard(self._header) and self.kind is not None:
                    self._guard(self._schema_types)
                    self._guard(self._payload_layout)
                    self._guard(self._components)
                    self._guard(self._network_probe)
                    self._guard(self._geometry)
                    self._guard(self._metadata)
                    self._guard(self._fallback)
                if self.usd_checks:
                    self._guard(self._usd_checks)
        except _Abort:
            pass
        self.report.kind, self.report.variant = self.kind, self.variant
        self.report.checked = self.checked
        return self.report

    # -- phases ----------------------------------------------------------------------------
    def _open(self) -> None:
        from pxr import Sdf

        from ..plugin import register_schema
        from ..safeopen import probe

        register_schema()
        if not self.path.exists():
            self.emit("FILE_NOT_FOUND", "no such file")
            raise _Abort
        if not self.path.is_file() or self.path.is_fifo():
            self.emit("FILE_UNREADABLE", "not a regular file (named pipe, device, socket or folder)")
            raise _Abort
        if self.path.stat().st_size == 0:
            self.emit("FILE_UNREADABLE", "the file is empty")
            raise _Abort
        if self.probe:
            result = probe(self.path, level="full", timeout=self.probe_timeout, asset=True)
            self.checked["probe_s"] = round(result.seconds, 3)
            if not result.ok:
                self.emit(result.code, result.message(), "/" if result.code != "FILE_UNREADABLE" else None)
                raise _Abort
        try:
            # a layer already open in this process may hold edits: read the file as it is on disk
            if Sdf.Layer.Find(str(self.path)):
                layer = Sdf.Layer.OpenAsAnonymous(str(self.path))
            else:
                layer = Sdf.Layer.FindOrOpen(str(self.path))
        except Exception as exc:
            self.emit("FILE_UNREADABLE", f"USD cannot open it: {(str(exc).strip().splitlines() or ['?'])[-1][:200]}")
            raise _Abort from None
        if layer is None:
            self.emit("FILE_UNREADABLE", "USD cannot open it")
            raise _Abort
        self.layer = layer

    def _asset_paths(self) -> None:
        """Check every asset path of the root layer before composing it (spec/security.md#paths).

        Escaping paths are ASSET_PATH_ESCAPES; any sublayer, external reference / payload or value
        clip is LAYER_EXTERNAL (an asset is one self-contained layer). The stage is then composed
        from a copy without them, so the validator never opens another file.
        """
        from ..paths import ARC_KINDS, layer_asset_paths, scan_layer, strip_external

        layer = self.layer
        problems, _ = scan_layer(layer, self.path.resolve().parent, anchor=str(self.path.resolve()))
        for p in problems:
            self.emit("ASSET_PATH_ESCAPES", p.message(), p.prim, p.field if p.kind == "asset" else None)
        external = [(kind, s, prim) for kind, s, prim, _ in layer_asset_paths(layer) if kind in ARC_KINDS and s]
        for kind, s, prim in external:
            self.emit("LAYER_EXTERNAL", f"{kind} {s!r}: an asset is one self-contained layer (no sublayers, external "
                      "references, payloads or value clips)", prim, "subLayers" if kind == "sublayer" else None)
        if external:
            self.layer = strip_external(layer)

    def _layer_content(self) -> None:
        """Variant sets, quality variant contents and time samples, read from the layer's specs (spec/security.md#layer-content)."""
        from pxr import Sdf

        from ..asset import COMPONENTS, QUALITY_SET

        layer = self.layer
        timed: list = []
        vsets: list = []
        extra: list = []

        def visit(spec_path):
            if spec_path.IsPropertyPath():
                if layer.GetNumTimeSamplesForPath(spec_path):
                    timed.append(spec_path)
                return
            spec = layer.GetObjectAtPath(spec_path)
            if spec is not None and type(spec).__name__ == "VariantSpec":
                spec = spec.primSpec  # sets nested inside a variant
            if spec is None or not hasattr(spec, "variantSets"):
                return
            is_component = (not spec_path.ContainsPrimVariantSelection()
                            and str(spec_path.GetParentPath()) == COMPONENTS)
            for name in spec.variantSets.keys():
                if not (is_component and name == QUALITY_SET):
                    if not is_component:
                        vsets.append((spec_path, name))
                    continue
                for vname, variant in spec.variantSets[name].variants.items():
                    inner = variant.primSpec
                    if inner.nameChildren or inner.properties:
                        extra.append((spec_path, vname, [c.name for c in inner.nameChildren] + [p.name for p in inner.properties]))

        layer.Traverse(Sdf.Path.absoluteRootPath, visit)
        for spec_path in timed:
            prim = spec_path.GetPrimPath().StripAllVariantSelections()
            n = layer.GetNumTimeSamplesForPath(spec_path)
            self.emit("TIME_SAMPLES", f"{n} time samples; every attribute of an asset is a default value", prim, spec_path.name)
        for spec_path, name in vsets:
            where = " inside a variant" if spec_path.ContainsPrimVariantSelection() else ""
            self.emit("VARIANT_SET_UNEXPECTED", f"variant set {name!r}{where}: only a component's {QUALITY_SET!r} variant set is allowed",
                      spec_path.GetPrimPath().StripAllVariantSelections())
        for spec_path, vname, names in extra:
            self.emit("QUALITY_VARIANT", f"quality variant {vname!r} authors {names} besides its payload", spec_path)

    def _compose(self) -> None:
        from pxr import Usd

        try:
            stage = Usd.Stage.Open(self.layer, Usd.Stage.LoadNone)
        except Exception as exc:
            self.emit("FILE_UNREADABLE", f"the stage does not compose: {(str(exc).strip().splitlines() or ['?'])[-1][:200]}")
            return
        if stage is None:
            self.emit("FILE_UNREADABLE", "the stage does not compose")
            return
        self.stage = stage

    def _authored(self, prim, name):
        attr = prim.GetAttribute(name)
        return attr.Get() if attr and attr.HasAuthoredValue() else None

    def _header(self) -> None:
        from ..asset import NEAR_FIELD_FETCH, ROOT, Asset
        from ..kinds import KINDS

        stage = self.stage
        default = stage.GetDefaultPrim()
        if not default or str(default.GetPath()) != ROOT or default.GetTypeName() != "NeuralAsset":
            got = f"{default.GetPath()} ({default.GetTypeName() or 'untyped'})" if default else "none"
            self.emit("ROOT_MISSING", f"defaultPrim must be a NeuralAsset at {ROOT}; found {got}", str(default.GetPath()) if default else "/")
            return
        root = default
        version = self._authored(root, "nasset:specVersion")
        m = re.fullmatch(r"([0-9]+)\.([0-9]+)", version, re.ASCII) if isinstance(version, str) else None
        if version is None:
            self.emit("SPEC_VERSION", "nasset:specVersion is not authored", ROOT, "nasset:specVersion")
        elif not m or int(m.group(1)) != limits.SUPPORTED_MAJOR:
            self.emit("SPEC_VERSION", f"specVersion {version!r} is not MAJOR.MINOR with MAJOR {limits.SUPPORTED_MAJOR}",
                      ROOT, "nasset:specVersion")
        else:
            self.report.spec_version = version
            known = int(limits.SPEC_VERSION.split(".")[1])
            if int(m.group(2)) > known:  # readable (format.md#versioning), but this validator knows nothing newer
                self.emit("SPEC_VERSION_NEWER", f"specVersion {version!r} is newer than {limits.SPEC_VERSION}, the version this "
                          "SDK implements: what that minor adds is not checked", ROOT, "nasset:specVersion")
        kind = self._authored(root, "nasset:kind")
        if kind is None or str(kind) not in KINDS:
            self.emit("KIND_UNKNOWN", f"kind {kind!r} is not one of {sorted(KINDS)}", ROOT, "nasset:kind")
            return
        variant = self._authored(root, "nasset:variant")
        if variant is None or str(variant) not in KINDS[str(kind)].variants:
            self.emit("VARIANT_UNKNOWN", f"variant {variant!r} not in {KINDS[str(kind)].variants}", ROOT, "nasset:variant")
            return
        self.kind, self.variant = str(kind), str(variant)
        lo, hi = self._authored(root, "nasset:domainMin"), self._authored(root, "nasset:domainMax")
        domain_ok = False
        if lo is None or hi is None:
            self.emit("DOMAIN_INVALID", "nasset:domainMin / nasset:domainMax not authored", ROOT,
                      "nasset:domainMin" if lo is None else "nasset:domainMax")
        else:
            try:
                lo_a, hi_a = np.array(lo, np.float64).reshape(-1), np.array(hi, np.float64).reshape(-1)
            except (TypeError, ValueError):
                lo_a = hi_a = np.zeros(0)
            if lo_a.shape != (3,) or hi_a.shape != (3,) or not (np.isfinite(lo_a).all() and np.isfinite(hi_a).all()) \
                    or not (hi_a > lo_a).all():
                self.emit("DOMAIN_INVALID", f"domain {lo} .. {hi} must be finite 3-vectors with max > min", ROOT, "nasset:domainMin")
            else:
                self.domain = (lo_a, hi_a)
                domain_ok = True
        self.asset = Asset(self.path, stage)
        self.asset.kind, self.asset.variant, self.asset.spec_version = self.kind, self.variant, self.report.spec_version
        try:
            self.asset.near_field_fetch  # noqa: B018 (read for its check)
        except NassetError as exc:
            self.emit(exc.code, exc.message, ROOT, NEAR_FIELD_FETCH)
        self.asset.domain = self.domain if domain_ok else (np.full(3, -1.0), np.full(3, 1.0))

    def _schema_types(self) -> None:
        from pxr import Usd

        from ..asset import COMPONENTS, ROOT

        comps = self.stage.GetPrimAtPath(COMPONENTS)
        if comps:
            for child in comps.GetAllChildren():
                if child.GetTypeName() != "NeuralComponent":
                    self.emit("SCHEMA_TYPE", f"component prim has type {child.GetTypeName() or 'none'!r}, not NeuralComponent",
                              child.GetPath())
        # payload targets, composed from the layer's class prim
        for prim in self.stage.TraverseAll():
            path = str(prim.GetPath())
            if not path.startswith(ROOT + "/"):
                continue
            tname = prim.GetTypeName()
            if tname == "NeuralAsset":
                self.emit("SCHEMA_TYPE", "NeuralAsset is only allowed at the root", path)
            self._attribute_types(prim)
        for spec_prim in self.stage.GetPseudoRoot().GetAllChildren():
            if spec_prim.IsAbstract():
                for target in spec_prim.GetAllChildren():
                    for child in target.GetAllChildren():
                        if child.GetTypeName() not in ("NeuralTensor", "NeuralNetwork"):
                            self.emit("SCHEMA_TYPE", f"payload content has type {child.GetTypeName() or 'none'!r}, "
                                      "not NeuralTensor or NeuralNetwork", child.GetPath())
                        self._attribute_types(child)
        self._attribute_types(self.stage.GetPrimAtPath(ROOT))
        del Usd

    def _attribute_types(self, prim) -> None:
        if prim.GetTypeName() not in _NASSET_TYPES:
            return
        definition = prim.GetPrimDefinition()
        for name in definition.GetPropertyNames():
            attr_def = definition.GetAttributeDefinition(name)
            attr = prim.GetAttribute(name)
            if not attr_def or not attr:
                continue
            want = attr_def.GetTypeName()
            for spec in attr.GetPropertyStack():  # authored specs: the composed type is the schema's
                got = getattr(spec, "typeName", None)
                if got is not None and got != want:
                    self.emit("SCHEMA_TYPE", f"{name} is authored as {got}, the schema says {want}", prim.GetPath(), name)
                    break

    def _payload_layout(self) -> None:
        from pxr import Sdf

        from ..asset import COMPONENTS, PAYLOAD_ROOT, QUALITY_SET

        layer = self.stage.GetRootLayer()
        root_spec = layer.GetPrimAtPath(PAYLOAD_ROOT)
        comps = self.stage.GetPrimAtPath(COMPONENTS)
        if comps and comps.GetAllChildren() and (root_spec is None or root_spec.specifier != Sdf.SpecifierClass):
            self.emit("PAYLOAD_INVALID", f"{PAYLOAD_ROOT} must be a class prim holding the component payloads", PAYLOAD_ROOT)
        if not comps:
            return
        for comp in comps.GetAllChildren():
            path = comp.GetPath()
            spec = layer.GetPrimAtPath(path)
            if spec is None:
                self.emit("PAYLOAD_INVALID", "component is not authored in the asset's own layer", path)
                continue

            def payloads_of(prim_spec):
                op = prim_spec.payloadList
                return [p for items in (op.explicitItems, op.addedItems, op.prependedItems, op.appendedItems) for p in items]

            def check(payload_list, where, path=path):
                if len(payload_list) != 1:
                    self.emit("PAYLOAD_INVALID", f"{where}needs exactly one payload, has {len(payload_list)}", path, "payload")
                for p in payload_list:
                    target = str(p.primPath)
                    if p.assetPath:
                        self.emit("PAYLOAD_INVALID", f"{where}payload to another file {p.assetPath!r}; must be internal", path, "payload")
                    elif not target.startswith(PAYLOAD_ROOT + "/") or Sdf.Path(target).GetParentPath() != Sdf.Path(PAYLOAD_ROOT):
                        self.emit("PAYLOAD_INVALID", f"{where}payload target {target or '(default prim)'} is not a child of {PAYLOAD_ROOT}",
                                  path, "payload")
                    elif layer.GetPrimAtPath(target) is None:
                        self.emit("PAYLOAD_INVALID", f"{where}payload target {target} does not exist", path, "payload")

            if spec.nameChildren:
                self.emit("PAYLOAD_INVALID", "component holds prims inline; contents belong behind its payload", path)
            vsets = list(spec.variantSets.keys())
            base = payloads_of(spec)
            extra = [v for v in vsets if v != QUALITY_SET]
            if extra:
                self.emit("QUALITY_VARIANT", f"variant sets {extra} not allowed; only {QUALITY_SET!r}", path)
            if QUALITY_SET in vsets:
                vset = spec.variantSets[QUALITY_SET]
                names = list(vset.variants.keys())
                selection = spec.variantSelections.get(QUALITY_SET)
                if not names:
                    self.emit("QUALITY_VARIANT", "quality variant set has no variants", path)
                if selection not in names:
                    self.emit("QUALITY_VARIANT", f"quality selection {selection!r} is not one of {names}", path)
                if base:
                    self.emit("PAYLOAD_INVALID", "payload authored both on the component and inside quality variants", path, "payload")
                for name in names:
                    check(payloads_of(vset.variants[name].primSpec), f"quality {name!r}: ")
            else:
                check(base, "")

    # -- components ------------------------------------------------------------------------
    def _components(self) -> None:
        from pxr import Usd

        from ..asset import COMPONENTS, QUALITY_SET

        contract = self.asset.contract
        specs = contract.components(self.variant)
        comps = self.stage.GetPrimAtPath(COMPONENTS)
        prims = [c for c in (comps.GetAllChildren() if comps else []) if c.GetTypeName() == "NeuralComponent"]
        if not comps:
            self.emit("COMPONENT_MISSING", f"{COMPONENTS} is absent", COMPONENTS)
        # configurations: each component at each of its qualities; the default selection first
        default_present: dict = {}
        default_tensors: dict = {}
        default_ok = True
        alternatives: list = []
        for prim in prims:
            name = prim.GetName()
            req = self._authored(prim, "nasset:required")
            if name in specs and req is not None and bool(req) != specs[name].required:
                self.emit("KIND_CONTRACT", f"nasset:required is {bool(req)}, the {self.kind} contract says {specs[name].required}",
                          prim.GetPath(), "nasset:required")
            vsets = prim.GetVariantSets()
            qualities = list(vsets.GetVariantSet(QUALITY_SET).GetVariantNames()) if vsets.HasVariantSet(QUALITY_SET) else []
            selection = vsets.GetVariantSet(QUALITY_SET).GetVariantSelection() if qualities else None
            order = [selection] + [q for q in qualities if q != selection] if qualities else [None]
            for q in order:
                if q is not None:
                    with Usd.EditContext(self.stage, self.stage.GetSessionLayer()):
                        vsets.GetVariantSet(QUALITY_SET).SetVariantSelection(q)
                self.stage.Load(prim.GetPath())
                entry, tensors, ok = self._read_component(prim, q)
                self.checked["components"].append(name + (f"[{q}]" if q else ""))
                if q == order[0]:
                    default_present[name] = entry
                    default_tensors.update({(name, t): v for t, v in tensors.items()})
                    default_ok &= ok
                else:
                    alternatives.append((name, q, entry, tensors, ok))
            if qualities and selection in qualities:
                with Usd.EditContext(self.stage, self.stage.GetSessionLayer()):
                    vsets.GetVariantSet(QUALITY_SET).SetVariantSelection(selection)

        def prim_of(c, n=None):
            return f"{COMPONENTS}/{c}" + (f"/{n}" if n else "")

        def add(findings, suffix=""):
            for f in findings:
                self.emit(f.code, f.message + suffix, f.prim, f.attribute, severity=f.severity)

        getter = (lambda c, n: default_tensors[(c, n)]) if default_ok else None
        add(contract.findings(self.variant, default_present, getter, prim_of))
        for name, q, entry, tensors, ok in alternatives:
            present = {**default_present, name: entry}
            getter = (lambda c, n, t=tensors, d=default_tensors, nm=name: t[n] if c == nm else d[(c, n)]) if ok and default_ok else None
            found = [f for f in contract.findings(self.variant, present, getter, prim_of)
                     if (f.prim or "").startswith(prim_of(name)) and f.code not in ("COMPONENT_MISSING", "COMPONENT_UNKNOWN")]
            add(found, f" (quality {q!r})")

    def _read_component(self, prim, quality):
        """Read and check every tensor and network of a loaded component; return contract inputs."""
        suffix = f" (quality {quality!r})" if quality else ""
        name = prim.GetName()
        tensors: dict = {}
        values: dict = {}
        networks: dict = {}
        ok = True
        if not prim.IsLoaded():
            self.emit("PAYLOAD_INVALID", "component payload could not be loaded" + suffix, prim.GetPath())
            return (tensors, networks), values, False
        for child in prim.GetAllChildren():
            path = child.GetPath()
            tname = child.GetTypeName()
            self._attribute_types(child)
            if tname == "NeuralTensor":
                self.checked["tensors"] += 1
                shape = self._authored(child, "shape")
                if shape is None:
                    self.emit("TENSOR_SHAPE", "shape is not authored" + suffix, path, "shape")
                    ok = False
                    continue
                if self._authored(child, "dtype") is None:
                    self.emit("TENSOR_DTYPE", "dtype is not authored" + suffix, path, "dtype")
                    ok = False
                    continue
                try:
                    shape_t = tuple(int(s) for s in shape)
                except (TypeError, ValueError):
                    self.emit("TENSOR_SHAPE", "shape is not a list of integers" + suffix, path, "shape")
                    ok = False
                    continue
                tensors[child.GetName()] = shape_t
                try:
                    arr = self.asset.tensor(name, child.GetName())
                except NassetError as exc:
                    self.emit(exc.code, exc.message + suffix, exc.prim, exc.attribute)
                    ok = False
                    continue
                with np.errstate(invalid="ignore", over="ignore"):
                    finite = np.isfinite(arr)
                if not finite.all():
                    bad = int(arr.size - np.count_nonzero(finite))
                    first = tuple(int(i) for i in np.argwhere(~finite)[0])
                    self.emit("TENSOR_NONFINITE", f"{bad} NaN/Inf values ({arr.dtype}), first at index {first}" + suffix,
                              path, "values")
                    ok = False
                values[child.GetName()] = arr
            elif tname == "NeuralNetwork":
                self.checked["networks"] += 1
                try:
                    ref = self.asset.network_refs(name)[child.GetName()]
                except (TypeError, ValueError):
                    self.emit("NETWORK_IO", "declared onnx:* attributes are not of the schema's types" + suffix, path)
                    ok = False
                    continue
                info = ref.info
                networks[child.GetName()] = (info.input_names, info.input_widths, info.output_names, info.output_widths)
                try:
                    data = self.asset.network_bytes(name, child.GetName())
                except NassetError as exc:
                    self.emit(exc.code, exc.message + suffix, exc.prim, exc.attribute)
                    continue
                self._queue_network_probe(name, child.GetName(), data, info, path, suffix)
        return (tensors, networks), values, ok

    def _queue_network_probe(self, component, network, data, info, path, suffix) -> None:
        """Remember a network that passed the static checks for the runtime probe (one child per file)."""
        from ..netprobe import ProbeJob
        from ..networks import sha256_hex

        key = f"{sha256_hex(data)}:{info.input_names}:{info.input_widths}:{info.output_names}:{info.output_widths}"
        if key not in self._net_jobs:
            units = tuple(self.asset.contract.probe_unit_columns(self.variant, component, network, n, int(w))
                          for n, w in zip(info.input_names, info.input_widths, strict=True))
            self._net_jobs[key] = (ProbeJob(key, data, tuple(info.input_names), tuple(int(w) for w in info.input_widths),
                                            tuple(info.output_names), tuple(int(w) for w in info.output_widths), units), [])
        self._net_jobs[key][1].append((path, suffix))

    def _network_probe(self) -> None:
        """Run every queued network under the runtime probe's time and memory bound (spec/security.md#networks)."""
        import time

        from ..netprobe import probe_networks

        if not self._net_jobs:
            return
        t0 = time.perf_counter()
        found = probe_networks([job for job, _ in self._net_jobs.values()], timeout=self.network_probe_timeout)
        self.checked["network_probe_s"] = round(time.perf_counter() - t0, 3)
        for key, (_, sites) in self._net_jobs.items():
            for code, message in found.get(key, []):
                for path, suffix in sites:
                    self.emit(code, message + suffix, path, "onnx:model")

    # -- geometry --------------------------------------------------------------------------
    def _geometry(self) -> None:
        from ..asset import GEOMETRY, ROOT
        from ..geometry import MeshGeometry, scale_problem

        geo = self.asset.geometry()  # typed errors for missing / malformed arrays
        prim = self.stage.GetPrimAtPath(GEOMETRY)
        if isinstance(geo, MeshGeometry):
            p = geo.points.astype(np.float64)
            tri = p[geo.faces]
            area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
            scale = float(np.max(p.max(0) - p.min(0))) or 1.0
            if not (area > 1e-12 * scale * scale).any():
                self.emit("GEOMETRY_DEGENERATE", f"all {len(area)} faces have zero area", GEOMETRY, "faceVertexIndices")
            if geo.normals is not None:
                length = np.linalg.norm(geo.normals.astype(np.float64), axis=1)
                off = np.abs(length - 1.0) > NORMAL_TOLERANCE
                if not np.isfinite(length).all() or off.any():
                    self.emit("GEOMETRY_NORMALS", f"{int(off.sum()) if np.isfinite(length).all() else 'some'} normals are not unit "
                              f"length (|n| within {NORMAL_TOLERANCE} of 1)", GEOMETRY, "normals")
            lo, hi = p.min(0), p.max(0)
        else:
            p = geo.points.astype(np.float64)
            starts = np.concatenate([[0], np.cumsum(geo.counts)[:-1]])
            seg = np.linalg.norm(np.diff(p, axis=0), axis=1)
            seg_mask = np.ones(len(seg), bool)
            seg_mask[(starts[1:] - 1)] = False  # segments between consecutive curves do not exist
            scale = float(np.max(p.max(0) - p.min(0))) or 1.0
            if not (seg[seg_mask] > 1e-12 * scale).any():
                self.emit("GEOMETRY_DEGENERATE", "every curve has zero length", GEOMETRY, "points")
            lo, hi = (np.asarray(b, np.float64) for b in geo.bounds())
        if why := scale_problem(lo, hi):
            self.emit("GEOMETRY_SCALE", why, GEOMETRY, "points")
        scale = max(float(np.max(hi - lo)), 1e-12)
        tol = 1e-5 * scale + 1e-7
        extent = prim.GetAttribute("extent").Get() if prim.GetAttribute("extent").HasAuthoredValue() else None
        if extent is None or len(extent) != 2:
            self.emit("EXTENT_MISMATCH", "extent is not authored as two corners", GEOMETRY, "extent")
        else:
            e = np.array(extent, np.float64)
            if not np.isfinite(e).all() or np.abs(e[0] - lo).max() > tol or np.abs(e[1] - hi).max() > tol:
                self.emit("EXTENT_MISMATCH", f"extent {e.tolist()} differs from the geometry bounds "
                          f"{[lo.tolist(), hi.tolist()]}", GEOMETRY, "extent")
        if self.domain is not None:
            dlo, dhi = self.domain
            if (dlo > lo + tol).any() or (dhi < hi - tol).any():
                self.emit("DOMAIN_INVALID", f"encoding box {dlo.tolist()} .. {dhi.tolist()} does not contain the geometry bounds "
                          f"{lo.tolist()} .. {hi.tolist()}", ROOT, "nasset:domainMin")

    def _metadata(self) -> None:
        from ..asset import ROOT

        raw = self._authored(self.stage.GetPrimAtPath(ROOT), "nasset:provenance")
        if raw is None:
            self.emit("METADATA_MISSING", "nasset:provenance is not authored", ROOT, "nasset:provenance")
            return
        try:
            value = json.loads(raw, parse_constant=lambda c: math.nan)
        except (TypeError, ValueError):
            self.emit("METADATA_INVALID", "nasset:provenance is not JSON", ROOT, "nasset:provenance")
            return
        if not isinstance(value, dict):
            self.emit("METADATA_INVALID", f"nasset:provenance must be a JSON object, not {type(value).__name__}", ROOT, "nasset:provenance")
            return
        missing = [k for k in PROVENANCE_REQUIRED if k not in value]
        if missing:
            self.emit("METADATA_MISSING", f"provenance lacks {missing}", ROOT, "nasset:provenance")
        if "specVersion" in value and self.report.spec_version and value["specVersion"] != self.report.spec_version:
            self.emit("METADATA_INVALID", f"provenance specVersion {value['specVersion']!r} differs from nasset:specVersion "
                      f"{self.report.spec_version!r}", ROOT, "nasset:provenance")
        if "kind" in value and value["kind"] != self.kind:
            self.emit("METADATA_INVALID", f"provenance kind {value['kind']!r} differs from nasset:kind {self.kind!r}",
                      ROOT, "nasset:provenance")
        if "generator" in value and not (isinstance(value["generator"], str) and value["generator"]):
            self.emit("METADATA_INVALID", "provenance 'generator' must be a non-empty string", ROOT, "nasset:provenance")

    def _fallback(self) -> None:
        from pxr import UsdShade

        from ..asset import GEOMETRY

        prim = self.stage.GetPrimAtPath(GEOMETRY)
        if not prim:
            return
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if not material:
            self.emit("FALLBACK_MISSING", "geometry has no bound material", GEOMETRY, "material:binding")
            return
        source = material.ComputeSurfaceSource()
        shader = source[0] if source else None
        shader_id = shader.GetIdAttr().Get() if shader else None
        if shader_id != "UsdPreviewSurface":
            self.emit("FALLBACK_MISSING", f"bound material {material.GetPath()} has no UsdPreviewSurface surface "
                      f"(found {shader_id!r})", material.GetPath(), "outputs:surface")

    def _usd_checks(self) -> None:
        from pxr import UsdValidation

        self.stage.Load()
        registry = UsdValidation.ValidationRegistry()
        context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
        severity = {UsdValidation.ValidationErrorType.Error: "error", UsdValidation.ValidationErrorType.Warn: "warning"}
        for err in context.Validate(self.stage):
            prim = attribute = None
            for site in err.GetSites():
                if site.IsProperty():
                    prop = site.GetProperty()
                    prim, attribute = str(prop.GetPrimPath()), prop.GetName()
                elif site.IsPrim():
                    prim = str(site.GetPrim().GetPath())
                if prim:
                    break
            self.emit("USD_CHECK", f"{err.GetName()}: {err.GetMessage().strip()[:300]}", prim, attribute,
                      severity=severity.get(err.GetType(), "info"))
        self.checked["usd_checks"] = True
