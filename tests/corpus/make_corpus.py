"""Deterministic bad-input corpus for the validator: ``python -m tests.corpus.make_corpus OUT_DIR``.

Each case starts from a valid example asset (nasset_sdk.examples.example_builder), is mutated
with the Sdf/Usd API (ONNX models with onnx.helper) and written to OUT_DIR; :func:`make_corpus`
returns the cases with the code the validator must report. Nothing binary is kept in the repo.
"""

from __future__ import annotations

import hashlib
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np


@dataclass(frozen=True)
class Case:
    """One hostile input. ``code``: what the validator must report (with ``severity``); None for a valid
    input that must open, evaluate and render with finite output. ``scene``: ``path`` is a scene to
    render (not an asset) and ``code`` the typed error the render must raise (tests/test_hostile_corpus.py).
    ``probe``: the check the case targets runs in the validator's crash probe child (decoded array sizes),
    so fast in-process validation (``probe=False``) cannot see it; validate it as ``nasset validate`` does."""

    name: str
    path: Path
    code: str | None
    severity: str = "error"
    scene: bool = False
    probe: bool = False


PAY = "/_NassetPayloads"
CORE = PAY + "/core"
TRI = CORE + "/triplane"
DEC = CORE + "/decoder"
GEO = "/Asset/Geometry"


def _model(nodes, inputs, outputs, inits=(), opset=17, domain_opsets=()):
    import onnx
    from onnx import helper

    graph = helper.make_graph(nodes, "g", inputs, outputs, list(inits))
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", opset), *domain_opsets])
    model.ir_version = 8
    del onnx
    return model.SerializeToString()


def _io(name, width):
    from onnx import TensorProto, helper

    return helper.make_tensor_value_info(name, TensorProto.FLOAT, ["N", width])


def _gemm_model(in_w, out_w, *, in_name="x", out_name="y", opset=17, w_rows=None):
    from onnx import helper, numpy_helper

    w = numpy_helper.from_array(np.zeros((w_rows or in_w, out_w), np.float32), "W")
    b = numpy_helper.from_array(np.zeros(out_w, np.float32), "B")
    return _model([helper.make_node("Gemm", [in_name, "W", "B"], [out_name])], [_io(in_name, in_w)], [_io(out_name, out_w)],
                  [w, b], opset=opset)


def _set_model(stage, path, blob, *, digest=True):
    from pxr import Vt

    prim = stage.GetPrimAtPath(path)
    prim.GetAttribute("onnx:model").Set(Vt.UCharArray.FromNumpy(np.frombuffer(blob, np.uint8)))
    if digest:
        prim.GetAttribute("onnx:sha256").Set(hashlib.sha256(blob).hexdigest())


def _retype(layer, prim_path, name, type_name, value):
    from pxr import Sdf

    spec = layer.GetPrimAtPath(prim_path)
    spec.RemoveProperty(spec.properties[name])
    attr = Sdf.AttributeSpec(spec, name, type_name, Sdf.VariabilityUniform)
    attr.default = value


def make_corpus(out_dir: str | Path) -> list[Case]:
    """Write every case into ``out_dir``; return them with their expected codes."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade, Vt

    from nasset_sdk.examples import example_builder

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bases = {
        "surface": example_builder("rna", variant="surface", size="tiny", seed=0).write(out / "_base_surface.usdc"),
        "fiber": example_builder("rna", variant="fiber", size="tiny", seed=0).write(out / "_base_fiber.usdc"),
        "quality": example_builder("rna", variant="surface", size="tiny", seed=0, quality_variants=True).write(out / "_base_quality.usdc"),
    }
    cases: list[Case] = []
    base_stage = Usd.Stage.Open(str(bases["surface"]))
    base_tri = np.asarray(base_stage.GetPrimAtPath(TRI).GetAttribute("shape").Get())
    dec_in = int(base_stage.GetPrimAtPath(DEC).GetAttribute("onnx:inputWidths").Get()[0])
    del base_stage

    def edit(name, code, fn, *, base="surface", severity="error", suffix=".usdc"):
        layer = Sdf.Layer.OpenAsAnonymous(str(bases[base]))
        stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
        with Usd.EditContext(stage, layer):
            fn(stage, layer)
        path = out / f"{name}{suffix}"
        if not layer.Export(str(path)):
            raise RuntimeError(f"corpus case {name} did not export")
        cases.append(Case(name, path, code, severity))

    def raw(name, code, data: bytes, suffix=".usdc"):
        path = out / f"{name}{suffix}"
        path.write_bytes(data)
        cases.append(Case(name, path, code))

    good = bases["surface"].read_bytes()
    # -- unreadable files ------------------------------------------------------------------
    raw("garbage_bytes", "FILE_UNREADABLE", np.random.default_rng(1).integers(0, 256, 4096, np.uint8).tobytes())
    raw("empty_file", "FILE_UNREADABLE", b"")
    raw("truncated_half", "FILE_UNREADABLE", good[: len(good) // 2])
    raw("truncated_header", "FILE_UNREADABLE", good[:64])
    raw("crate_magic_only", "FILE_UNREADABLE", b"PXR-USDC" + bytes(80))
    toc = bytearray(good)
    toc[89] ^= 0x28  # first structural section of the crate: crashed usd-core 26.11 (SIGSEGV) when read
    raw("crate_section_flip", "FILE_UNREADABLE", bytes(toc))
    raw("usda_syntax_error", "FILE_UNREADABLE", b'#usda 1.0\n(\n defaultPrim = "Asset"\n)\ndef NeuralAsset "Asset" {\n  float x = \n', ".usda")
    raw("usda_as_usdc_bytes", "FILE_UNREADABLE", b"#usda 1.0\n", ".usdc")
    cases.append(Case("missing_file", out / "does_not_exist.usdc", "FILE_NOT_FOUND"))

    # -- root, version, kind -----------------------------------------------------------------
    edit("no_default_prim", "ROOT_MISSING", lambda s, l: l.ClearDefaultPrim())
    edit("root_wrong_type", "ROOT_MISSING", lambda s, l: s.GetPrimAtPath("/Asset").SetTypeName("Xform"))
    edit("spec_version_major", "SPEC_VERSION", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:specVersion").Set("1.0"))
    edit("spec_version_garbage", "SPEC_VERSION", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:specVersion").Set("v0"))
    edit("spec_version_newer_minor", "SPEC_VERSION_NEWER",
         lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:specVersion").Set("0.7"), severity="warning")
    edit("spec_version_missing", "SPEC_VERSION", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:specVersion").Clear())
    edit("near_field_fetch_above_one", "NEAR_FIELD_INVALID", lambda s, l: s.GetPrimAtPath("/Asset").CreateAttribute(
        "nasset:nearFieldFetch", Sdf.ValueTypeNames.Float).Set(3.0))
    edit("kind_unknown", "KIND_UNKNOWN", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:kind").Set("gaussians"))
    edit("variant_unknown", "VARIANT_UNKNOWN", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:variant").Set("volume"))
    edit("domain_nan", "DOMAIN_INVALID",
         lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:domainMin").Set(Gf.Vec3f(float("nan"), 0, 0)))
    edit("domain_not_covering", "DOMAIN_INVALID",
         lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:domainMax").Set(Gf.Vec3f(0.1, 0.1, 0.1)))
    edit("domain_empty", "DOMAIN_INVALID", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:domainMax").Set(
        s.GetPrimAtPath("/Asset").GetAttribute("nasset:domainMin").Get()))

    # -- schema types and layout -------------------------------------------------------------
    edit("component_wrong_type", "SCHEMA_TYPE", lambda s, l: s.GetPrimAtPath("/Asset/Components/core").SetTypeName("Scope"))
    edit("tensor_wrong_type", "SCHEMA_TYPE", lambda s, l: s.GetPrimAtPath(TRI).SetTypeName("Scope"))
    edit("network_unknown_type", "SCHEMA_TYPE", lambda s, l: s.GetPrimAtPath(DEC).SetTypeName("NeuralNetwrk"))
    edit("shape_wrong_value_type", "SCHEMA_TYPE",
         lambda s, l: _retype(l, TRI, "shape", Sdf.ValueTypeNames.FloatArray, Vt.FloatArray([float(v) for v in base_tri])))

    def payload_to(asset_path, prim_path):
        def fn(s, l):
            comp = l.GetPrimAtPath("/Asset/Components/core")
            comp.payloadList.ClearEdits()
            comp.payloadList.prependedItems.append(Sdf.Payload(asset_path, prim_path))
        return fn

    edit("payload_external_file", "PAYLOAD_INVALID", payload_to("./core.usdc", "/core"))
    edit("payload_wrong_target", "PAYLOAD_INVALID", payload_to("", GEO))
    edit("payload_missing_target", "PAYLOAD_INVALID", payload_to("", PAY + "/nothing"))
    edit("payload_none", "PAYLOAD_INVALID", lambda s, l: l.GetPrimAtPath("/Asset/Components/core").payloadList.ClearEdits())
    edit("payload_root_not_class", "PAYLOAD_INVALID", lambda s, l: setattr(l.GetPrimAtPath(PAY), "specifier", Sdf.SpecifierDef))

    def inline(s, l):
        Sdf.CopySpec(l, TRI, l, "/Asset/Components/core/triplane")

    edit("component_inline_prims", "PAYLOAD_INVALID", inline)

    def quality_sel(value):
        return lambda s, l: l.GetPrimAtPath("/Asset/Components/core").variantSelections.__setitem__("quality", value)

    edit("quality_bad_selection", "QUALITY_VARIANT", quality_sel("ultra"), base="quality")

    def extra_vset(s, l):
        vs = s.GetPrimAtPath("/Asset/Components/core").GetVariantSets().AddVariantSet("lod")
        vs.AddVariant("a")
        vs.SetVariantSelection("a")

    edit("quality_extra_variant_set", "QUALITY_VARIANT", extra_vset, base="quality")

    def hq_nan(s, l):
        attr = s.GetPrimAtPath(PAY + "/core__hq/triplane").GetAttribute("values")
        arr = np.array(attr.Get(), np.float16)
        arr[5] = np.nan
        attr.Set(Vt.HalfArray.FromNumpy(arr))

    edit("quality_hq_nan", "TENSOR_NONFINITE", hq_nan, base="quality")

    # -- components and tensors ----------------------------------------------------------------
    edit("component_missing", "COMPONENT_MISSING", lambda s, l: s.RemovePrim("/Asset/Components/core"))

    def extra_component(s, l):
        p = s.DefinePrim("/Asset/Components/extra", "NeuralComponent")
        s.DefinePrim(PAY + "/extra", "Scope")
        p.GetPayloads().AddInternalPayload(PAY + "/extra")

    edit("component_unknown", "COMPONENT_UNKNOWN", extra_component, severity="warning")
    edit("component_required_flag", "KIND_CONTRACT",
         lambda s, l: s.GetPrimAtPath("/Asset/Components/core").GetAttribute("nasset:required").Set(False))
    edit("tensor_missing", "TENSOR_MISSING", lambda s, l: s.RemovePrim(TRI))
    edit("network_missing", "NETWORK_MISSING", lambda s, l: s.RemovePrim(DEC))
    edit("tensor_dtype_token", "TENSOR_DTYPE", lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("dtype").Set("int8"))
    edit("tensor_dtype_values_mismatch", "TENSOR_DTYPE", lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("dtype").Set("float32"))
    edit("tensor_shape_product", "TENSOR_SHAPE",
         lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("shape").Set(Vt.IntArray([3, 8, 8, 5])))
    edit("tensor_shape_negative", "TENSOR_SHAPE",
         lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("shape").Set(Vt.IntArray([3, -8, -8, 4])))
    r, c = int(base_tri[1]), int(base_tri[3])
    edit("tensor_contract_shape", "TENSOR_CONTRACT",
         lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("shape").Set(Vt.IntArray([3, r * 2, r // 2, c])))
    edit("tensor_contract_rank", "TENSOR_CONTRACT",
         lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("shape").Set(Vt.IntArray([3 * r, r, c])))
    edit("tensor_oversized_declared", "TENSOR_TOO_LARGE",
         lambda s, l: s.GetPrimAtPath(TRI).GetAttribute("shape").Set(Vt.IntArray([3, 100000, 100000, c])))

    def poke(value, dtype=np.float16):
        def fn(s, l):
            attr = s.GetPrimAtPath(TRI).GetAttribute("values")
            arr = np.array(attr.Get(), np.float32)
            arr[3] = value
            with np.errstate(over="ignore"):
                attr.Set(Vt.HalfArray.FromNumpy(arr.astype(np.float16)))
        return fn

    edit("tensor_nan", "TENSOR_NONFINITE", poke(np.nan))
    edit("tensor_inf", "TENSOR_NONFINITE", poke(-np.inf))
    edit("tensor_fp16_overflow", "TENSOR_NONFINITE", poke(70000.0))  # finite in fp32, +inf once stored as half

    # -- networks ----------------------------------------------------------------------------
    edit("network_digest_wrong", "NETWORK_DIGEST", lambda s, l: s.GetPrimAtPath(DEC).GetAttribute("onnx:sha256").Set("0" * 64))
    edit("network_garbage_bytes", "NETWORK_PARSE", lambda s, l: _set_model(s, DEC, b"\x08\x07garbage-not-onnx" * 8))
    bad_graph = _model([helper.make_node("Gemm", ["x", "W_undefined", "B_undefined"], ["y"])], [_io("x", dec_in)], [_io("y", 6)])
    edit("network_checker_fails", "NETWORK_PARSE", lambda s, l: _set_model(s, DEC, bad_graph))
    custom = _model([helper.make_node("Fancy", ["x"], ["y"], domain="com.evil")], [_io("x", dec_in)], [_io("y", 6)],
                    domain_opsets=[helper.make_opsetid("com.evil", 1)])
    edit("network_custom_domain", "NETWORK_CUSTOM_DOMAIN", lambda s, l: _set_model(s, DEC, custom))
    ext = onnx.ModelProto()
    ext.ParseFromString(_gemm_model(dec_in, 6))
    w = ext.graph.initializer[0]
    w.ClearField("raw_data")
    w.data_location = TensorProto.EXTERNAL
    w.external_data.add(key="location", value="../../weights.bin")
    edit("network_external_data", "NETWORK_EXTERNAL_DATA", lambda s, l: _set_model(s, DEC, ext.SerializeToString()))
    edit("network_opset_too_high", "NETWORK_OPSET", lambda s, l: _set_model(s, DEC, _gemm_model(dec_in, 6, opset=40)))
    edit("network_opset_declared", "NETWORK_OPSET", lambda s, l: s.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(13))
    edit("network_io_name_declared", "NETWORK_IO",
         lambda s, l: s.GetPrimAtPath(DEC).GetAttribute("onnx:inputNames").Set(Vt.StringArray(["inp"])))
    edit("network_io_width_declared", "NETWORK_IO",
         lambda s, l: s.GetPrimAtPath(DEC).GetAttribute("onnx:outputWidths").Set(Vt.IntArray([7])))

    def contract_width(s, l):
        _set_model(s, DEC, _gemm_model(dec_in + 1, 6))
        s.GetPrimAtPath(DEC).GetAttribute("onnx:inputWidths").Set(Vt.IntArray([dec_in + 1]))
        s.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(17)

    edit("network_io_width_contract", "NETWORK_IO", contract_width)

    def with_model(blob, opset=17):
        def fn(s, l):
            _set_model(s, DEC, blob)
            s.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(opset)
        return fn

    # Gemm weights that do not fit the input: strict shape inference refuses it before any runtime
    edit("network_shape_weights_misfit", "NETWORK_SHAPE", with_model(_gemm_model(dec_in, 6, w_rows=dec_in + 5)))
    # statically fine, but onnxruntime refuses the attribute value when it runs the node
    gelu = onnx.ModelProto()
    gelu.ParseFromString(_gemm_model(dec_in, 6, out_name="h", opset=20))
    gelu.graph.node.append(helper.make_node("Gelu", ["h"], ["y"], approximate="cubic"))
    gelu.graph.output[0].name = "y"
    edit("network_runtime_fails", "NETWORK_RUNTIME", with_model(gelu.SerializeToString(), 20))
    # the sparse-initializer hole of issue 13 class 1 (inline here; external data in gen_networks.py)
    sparse = onnx.ModelProto()
    sparse.ParseFromString(_gemm_model(dec_in, 6))
    w_dense = sparse.graph.initializer[0]
    sparse.graph.sparse_initializer.append(helper.make_sparse_tensor(
        numpy_helper.from_array(np.ones(1, np.float32), "W"), numpy_helper.from_array(np.zeros(1, np.int64), "W_i"), list(w_dense.dims)))
    del sparse.graph.initializer[0]
    edit("network_sparse_initializer", "NETWORK_OP_FORBIDDEN", with_model(sparse.SerializeToString()))
    reshape = _model([helper.make_node("Gemm", ["x", "W", "B"], ["h"]), helper.make_node("Reshape", ["h", "s"], ["y"])],
                     [_io("x", dec_in)], [_io("y", 6)],
                     [numpy_helper.from_array(np.zeros((dec_in, 6), np.float32), "W"), numpy_helper.from_array(np.zeros(6, np.float32), "B"),
                      numpy_helper.from_array(np.array([-1, 6], np.int64), "s")])
    edit("network_op_forbidden", "NETWORK_OP_FORBIDDEN", with_model(reshape))
    huge = onnx.ModelProto()
    huge.ParseFromString(_gemm_model(dec_in, 6))
    huge.graph.initializer[1].CopyFrom(numpy_helper.from_array(np.full(6, 3e38, np.float32), "B"))  # outputs near float max
    edit("network_output_huge", "NETWORK_OUTPUT", with_model(huge.SerializeToString()))
    del numpy_helper

    # -- asset paths ------------------------------------------------------------------------
    edit("path_absolute_reference", "ASSET_PATH_ESCAPES",
         lambda s, l: s.DefinePrim("/Asset/Extra").GetReferences().AddReference("/etc/secret.usda"))
    edit("path_dotdot_payload", "ASSET_PATH_ESCAPES", payload_to("../../outside.usdc", "/core"))
    edit("path_url_sublayer", "ASSET_PATH_ESCAPES", lambda s, l: l.subLayerPaths.append("https://example.com/evil.usda"))

    def shader_file(value):
        def fn(s, l):
            shader = UsdShade.Shader(s.GetPrimAtPath("/Asset/Looks/Fallback/PreviewSurface"))
            shader.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath(value))
        return fn

    edit("path_asset_attribute_absolute", "ASSET_PATH_ESCAPES", shader_file("/etc/passwd"))
    edit("path_asset_attribute_dotdot", "ASSET_PATH_ESCAPES", shader_file("textures/../../../secret.png"))
    edit("path_asset_metadata", "ASSET_PATH_ESCAPES",
         lambda s, l: s.GetPrimAtPath("/Asset").SetCustomDataByKey("thumb", Sdf.AssetPath("file:///tmp/x.png")))

    # -- geometry ---------------------------------------------------------------------------
    edit("geometry_missing", "GEOMETRY_MISSING", lambda s, l: s.RemovePrim(GEO))
    edit("geometry_type_for_variant", "GEOMETRY_MISSING", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:variant").Set("fiber"))

    def mesh_attr(name, fn_value):
        def fn(s, l):
            attr = s.GetPrimAtPath(GEO).GetAttribute(name)
            attr.Set(fn_value(np.array(attr.Get())))
        return fn

    def bump_index(a):
        a = a.copy()
        a[7] = 10_000
        return Vt.IntArray.FromNumpy(a.astype(np.int32))

    def nan_point(a):
        a = a.astype(np.float32).copy()
        a[2, 1] = np.nan
        return Vt.Vec3fArray.FromNumpy(a)

    edit("indices_out_of_range", "GEOMETRY_INVALID", mesh_attr("faceVertexIndices", bump_index))
    edit("indices_negative", "GEOMETRY_INVALID", mesh_attr("faceVertexIndices", lambda a: Vt.IntArray.FromNumpy((a * 0 - 1).astype(np.int32))))
    edit("points_nan", "GEOMETRY_INVALID", mesh_attr("points", nan_point))
    edit("face_counts_quads", "GEOMETRY_INVALID", mesh_attr("faceVertexCounts", lambda a: Vt.IntArray.FromNumpy(np.full(len(a), 4, np.int32))))
    edit("degenerate_mesh", "GEOMETRY_DEGENERATE",
         mesh_attr("faceVertexIndices", lambda a: Vt.IntArray.FromNumpy(np.repeat(a.reshape(-1, 3)[:, :1], 3, axis=1).reshape(-1).astype(np.int32))))
    edit("geometry_scale_tiny", "GEOMETRY_SCALE", mesh_attr("points", lambda a: Vt.Vec3fArray.FromNumpy((a * 1e-30).astype(np.float32))))
    edit("geometry_scale_far", "GEOMETRY_SCALE", mesh_attr("points", lambda a: Vt.Vec3fArray.FromNumpy((a + 1e7).astype(np.float32))))
    edit("normals_not_unit", "GEOMETRY_NORMALS", mesh_attr("normals", lambda a: Vt.Vec3fArray.FromNumpy((a * 2.0).astype(np.float32))))
    edit("normals_wrong_count", "GEOMETRY_NORMALS", mesh_attr("normals", lambda a: Vt.Vec3fArray.FromNumpy(a[:-3].astype(np.float32))))
    edit("extent_wrong", "EXTENT_MISMATCH",
         lambda s, l: UsdGeom.Boundable(s.GetPrimAtPath(GEO)).GetExtentAttr().Set(Vt.Vec3fArray([Gf.Vec3f(-1), Gf.Vec3f(1)])))
    edit("extent_missing", "EXTENT_MISMATCH", lambda s, l: UsdGeom.Boundable(s.GetPrimAtPath(GEO)).GetExtentAttr().Clear())
    edit("curves_bad_counts", "GEOMETRY_INVALID", mesh_attr("curveVertexCounts", lambda a: Vt.IntArray.FromNumpy((a * 0 + 1).astype(np.int32))),
         base="fiber")
    edit("curves_zero_width", "GEOMETRY_INVALID", mesh_attr("widths", lambda a: Vt.FloatArray.FromNumpy((a * 0).astype(np.float32))),
         base="fiber")

    def collapse_curves(s, l):
        attr = s.GetPrimAtPath(GEO).GetAttribute("points")
        pts = np.zeros((len(attr.Get()), 3), np.float32)
        attr.Set(Vt.Vec3fArray.FromNumpy(pts))

    edit("curves_zero_length", "GEOMETRY_DEGENERATE", collapse_curves, base="fiber")

    # -- metadata and fallback ------------------------------------------------------------------
    prov = lambda v: lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:provenance").Set(v)  # noqa: E731
    edit("provenance_missing", "METADATA_MISSING", lambda s, l: s.GetPrimAtPath("/Asset").GetAttribute("nasset:provenance").Clear())
    edit("provenance_not_json", "METADATA_INVALID", prov("{generator: random"))
    edit("provenance_array", "METADATA_INVALID", prov('["specVersion", "kind"]'))
    edit("provenance_no_generator", "METADATA_MISSING", prov('{"kind": "rna", "specVersion": "0.1"}'))
    edit("provenance_kind_differs", "METADATA_INVALID", prov('{"kind": "8dna", "specVersion": "0.1", "generator": "x"}'))
    edit("fallback_unbound", "FALLBACK_MISSING", lambda s, l: UsdShade.MaterialBindingAPI(s.GetPrimAtPath(GEO)).UnbindAllBindings(),
         severity="warning")
    return cases


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "generated")
    for case in make_corpus(target):
        print(f"{case.code:<24} {case.severity:<8} {case.path.name}")
