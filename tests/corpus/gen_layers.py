"""Hidden layer content, memory amplification and tensor shapes: ``python -m tests.corpus.gen_layers OUT_DIR``.

Families (each case names the code it must yield):

- ``vset_*``: variant sets the validator did not look at (on the payload class prims, the root,
  the geometry, nested in a quality variant, ...), whose other variant swaps in NaN tensors, a
  different network or NaN points -> VARIANT_SET_UNEXPECTED; quality variants that author more than
  their payload -> QUALITY_VARIANT.
- ``time_*``: time samples on tensors, networks, geometry and header attributes -> TIME_SAMPLES.
- ``layer_*``: sublayers, in-package references and value clips -> LAYER_EXTERNAL.
- ``version_*`` / ``lookalike_*``: non-ASCII digits and unicode lookalikes -> SPEC_VERSION / KIND_UNKNOWN / ...
- ``amp_*``: crate-compressed arrays that decode to far more than the file size -> ARRAY_TOO_LARGE
  (validate with the probe: it is what bounds them).
- ``shape_*``: shapes whose product wraps int64 or is zero -> TENSOR_TOO_LARGE / TENSOR_SHAPE.
- ``amp_string_*``: one long string repeated by a string array (crate stores it once) -> ARRAY_TOO_LARGE;
  ``nest_*``: values nested past limits.MAX_VALUE_DEPTH -> FILE_UNREADABLE.
- ``struct_*``: more specs than limits.MAX_ASSET_SPECS (empty prims, properties, time samples), prims nested
  past limits.MAX_ASSET_DEPTH, internal arcs that repeat a subtree past the composed-prim bound -> ARRAY_TOO_LARGE.
"""

from __future__ import annotations

import hashlib
import sys
from pathlib import Path

import numpy as np

from tests.corpus.make_corpus import Case

PAY = "/_NassetPayloads"
TRI = PAY + "/core/triplane"
DEC = PAY + "/core/decoder"
GEO = "/Asset/Geometry"
#: faceVertexIndices lengths of the amplification family (all zeros: every index is in range)
AMP_SIZES = (3 << 23, 3 << 24, 3 << 25)


def _nan_half(n: int):
    from pxr import Vt

    arr = np.zeros(n, np.float16)
    arr[::7] = np.nan
    return Vt.HalfArray.FromNumpy(arr)


def _other_network(layer):
    """Model bytes of a different (valid) network of the same interface, and its digest."""
    from pxr import Vt

    from nasset_sdk.examples import example_builder

    other = example_builder("rna", variant="surface", size="tiny", seed=7)
    blob = other.components["core"][""].networks["decoder"]
    del layer
    return Vt.UCharArray.FromNumpy(np.frombuffer(blob, np.uint8)), hashlib.sha256(blob).hexdigest()


def _variant_set(spec, name, *, selected="clean", evil="evil"):
    """Add variant set ``name`` with an empty ``selected`` variant and an ``evil`` one; return the evil prim spec."""
    from pxr import Sdf

    vset = Sdf.VariantSetSpec(spec, name)
    Sdf.VariantSpec(vset, selected)
    bad = Sdf.VariantSpec(vset, evil)
    spec.variantSetNameList.prependedItems.append(name)
    spec.variantSelections[name] = selected
    return bad.primSpec


def _over(parent, name):
    from pxr import Sdf

    return Sdf.PrimSpec(parent, name, Sdf.SpecifierOver)


def _attr(spec, name, type_name, value):
    from pxr import Sdf

    a = Sdf.AttributeSpec(spec, name, type_name, Sdf.VariabilityUniform)
    a.default = value
    return a


def make_cases(out_dir: str | Path, *, amplification: bool = True) -> list[Case]:
    """Write every case into ``out_dir``; return them with their expected codes."""
    from pxr import Sdf, Vt

    from nasset_sdk.examples import example_builder
    from nasset_sdk.limits import MAX_ASSET_DEPTH, MAX_ASSET_SPECS

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    bases = {
        "surface": example_builder("rna", variant="surface", size="tiny", seed=0).write(out / "_lbase_surface.usdc"),
        "quality": example_builder("rna", variant="surface", size="tiny", seed=0, quality_variants=True).write(out / "_lbase_quality.usdc"),
    }
    probe = Sdf.Layer.OpenAsAnonymous(str(bases["surface"]))
    n_tri = len(probe.GetAttributeAtPath(TRI + ".values").default)
    n_pts = len(probe.GetAttributeAtPath(GEO + ".points").default)
    model, digest = _other_network(probe)
    cases: list[Case] = []

    def case(name, code, fn, *, base="surface", probe=False):
        layer = Sdf.Layer.OpenAsAnonymous(str(bases[base]))
        fn(layer)
        path = out / f"{name}.usdc"
        if not layer.Export(str(path)):
            raise RuntimeError(f"case {name} did not export")
        cases.append(Case(name, path, code, probe=probe or code == "ARRAY_TOO_LARGE"))

    # -- hidden variant sets ------------------------------------------------------------------
    def vset_tensor_nan(layer):
        evil = _variant_set(layer.GetPrimAtPath(PAY + "/core"), "look")
        _attr(_over(evil, "triplane"), "values", Sdf.ValueTypeNames.HalfArray, _nan_half(n_tri))

    def vset_network_swap(layer):
        evil = _variant_set(layer.GetPrimAtPath(DEC), "runtime")
        _attr(evil, "onnx:model", Sdf.ValueTypeNames.UCharArray, model)
        _attr(evil, "onnx:sha256", Sdf.ValueTypeNames.String, digest)

    def vset_root_points(layer):
        evil = _variant_set(layer.GetPrimAtPath("/Asset"), "shot")
        pts = np.full((n_pts, 3), np.nan, np.float32)
        _attr(_over(evil, "Geometry"), "points", Sdf.ValueTypeNames.Point3fArray, Vt.Vec3fArray.FromNumpy(pts))

    def vset_geometry(layer):
        evil = _variant_set(layer.GetPrimAtPath(GEO), "lod")
        _attr(evil, "faceVertexIndices", Sdf.ValueTypeNames.IntArray, Vt.IntArray([0, 1, 99999]))

    def vset_components_scope(layer):
        evil = _variant_set(layer.GetPrimAtPath("/Asset/Components"), "mode")
        comp = _over(evil, "core")
        comp.payloadList.ClearEdits()
        comp.payloadList.prependedItems.append(Sdf.Payload("", GEO))

    def vset_payload_root(layer):
        evil = _variant_set(layer.GetPrimAtPath(PAY), "swap")
        _attr(_over(_over(evil, "core"), "triplane"), "values", Sdf.ValueTypeNames.HalfArray, _nan_half(n_tri))

    def vset_nested_in_quality(layer):
        comp = layer.GetPrimAtPath("/Asset/Components/core")
        hq = comp.variantSets["quality"].variants["hq"].primSpec
        _variant_set(hq, "inner")

    def vset_on_hq_tensor(layer):
        spec = layer.GetPrimAtPath(PAY + "/core__hq/triplane")
        n = len(spec.attributes["values"].default)
        evil = _variant_set(spec, "alt")
        _attr(evil, "values", Sdf.ValueTypeNames.HalfArray, _nan_half(n))

    def vset_selected_evil(layer):  # the selection is the evil one: content differs from what a quality switch gives
        evil = _variant_set(layer.GetPrimAtPath(PAY + "/core"), "look", selected="clean")
        _attr(_over(evil, "triplane"), "layout", Sdf.ValueTypeNames.String, "x")
        layer.GetPrimAtPath(PAY + "/core").variantSelections["look"] = "evil"

    def quality_extra_content(layer):
        comp = layer.GetPrimAtPath("/Asset/Components/core")
        hq = comp.variantSets["quality"].variants["hq"].primSpec
        _attr(_over(hq, "triplane"), "values", Sdf.ValueTypeNames.HalfArray, _nan_half(7))

    def quality_extra_attribute(layer):
        comp = layer.GetPrimAtPath("/Asset/Components/core")
        small = comp.variantSets["quality"].variants["small"].primSpec
        _attr(small, "nasset:required", Sdf.ValueTypeNames.Bool, False)

    case("vset_tensor_nan", "VARIANT_SET_UNEXPECTED", vset_tensor_nan)
    case("vset_network_swap", "VARIANT_SET_UNEXPECTED", vset_network_swap)
    case("vset_root_points_nan", "VARIANT_SET_UNEXPECTED", vset_root_points)
    case("vset_geometry_indices", "VARIANT_SET_UNEXPECTED", vset_geometry)
    case("vset_components_scope", "VARIANT_SET_UNEXPECTED", vset_components_scope)
    case("vset_payload_root", "VARIANT_SET_UNEXPECTED", vset_payload_root)
    case("vset_selected_evil", "VARIANT_SET_UNEXPECTED", vset_selected_evil)
    case("vset_nested_in_quality", "VARIANT_SET_UNEXPECTED", vset_nested_in_quality, base="quality")
    case("vset_on_hq_tensor", "VARIANT_SET_UNEXPECTED", vset_on_hq_tensor, base="quality")
    case("vset_quality_extra_content", "QUALITY_VARIANT", quality_extra_content, base="quality")
    case("vset_quality_extra_attribute", "QUALITY_VARIANT", quality_extra_attribute, base="quality")

    # -- time samples ---------------------------------------------------------------------------
    def timed(attr_path, value_fn):
        def fn(layer):
            spec = layer.GetAttributeAtPath(attr_path)
            layer.SetTimeSample(spec.path, 1.0, value_fn(spec.default))
        return fn

    case("time_tensor_values_nan", "TIME_SAMPLES", timed(TRI + ".values", lambda v: _nan_half(len(v))))
    case("time_network_model", "TIME_SAMPLES", timed(DEC + ".onnx:model", lambda v: model))
    case("time_geometry_points", "TIME_SAMPLES",
         timed(GEO + ".points", lambda v: Vt.Vec3fArray.FromNumpy(np.full((len(v), 3), np.nan, np.float32))))
    case("time_extent", "TIME_SAMPLES", timed(GEO + ".extent", lambda v: v))
    case("time_kind", "TIME_SAMPLES", timed("/Asset.nasset:kind", lambda v: "8dna"))
    case("time_spec_version", "TIME_SAMPLES", timed("/Asset.nasset:specVersion", lambda v: "9.9"))
    case("time_tensor_shape", "TIME_SAMPLES", timed(TRI + ".shape", lambda v: Vt.IntArray([1])))

    # -- sublayers and other files inside the package -----------------------------------------------
    side = out / "_layer_side.usda"
    side.write_text('#usda 1.0\nover "_NassetPayloads" { over "core" { over "triplane" { uniform half[] values = [nan, nan] } } }\n')

    case("layer_sublayer_in_package", "LAYER_EXTERNAL", lambda l: l.subLayerPaths.append(f"./{side.name}"))

    def in_package_reference(layer):
        spec = Sdf.CreatePrimInLayer(layer, "/Asset/Extra")
        spec.specifier = Sdf.SpecifierDef
        spec.referenceList.prependedItems.append(Sdf.Reference(f"./{side.name}", "/_NassetPayloads"))

    def in_package_clips(layer):
        layer.GetPrimAtPath(PAY + "/core/triplane").SetInfo(
            "clips", {"default": {"assetPaths": Sdf.AssetPathArray([Sdf.AssetPath(f"./{side.name}")]),
                                  "primPath": "/_NassetPayloads/core/triplane", "active": Vt.Vec2dArray([(0.0, 0.0)])}})

    case("layer_reference_in_package", "LAYER_EXTERNAL", in_package_reference)
    case("layer_clips_in_package", "LAYER_EXTERNAL", in_package_clips)
    case("layer_payload_in_package", "LAYER_EXTERNAL", lambda l: Sdf.CreatePrimInLayer(l, "/Asset/Extra").payloadList.prependedItems.append(
        Sdf.Payload(f"./{side.name}", "/_NassetPayloads")))

    # -- versions and lookalikes ------------------------------------------------------------------------
    def header(name, value):
        return lambda l: setattr(l.GetAttributeAtPath(f"/Asset.{name}"), "default", value)

    for label, value in (("arabic_indic", "\u0660.\u0661"), ("fullwidth", "\uff10.\uff11"), ("devanagari_minor", "0.\u0967"),
                         ("math_bold", "\U0001d7ce.\U0001d7cf"), ("fullwidth_stop", "0\uff0e1"), ("zero_width", "0.1\u200b"),
                         ("leading_space", " 0.1"), ("trailing_newline", "0.1\n"), ("superscript", "0.\u00b9")):
        case(f"version_{label}", "SPEC_VERSION", header("nasset:specVersion", value))
    case("lookalike_kind_cyrillic", "KIND_UNKNOWN", header("nasset:kind", "rn\u0430"))
    case("lookalike_variant_cyrillic", "VARIANT_UNKNOWN", header("nasset:variant", "surf\u0430ce"))

    def lookalike_quality(layer):
        comp = layer.GetPrimAtPath("/Asset/Components/core")
        comp.payloadList.ClearEdits()
        evil = _variant_set(comp, "qu\u0430lity", selected="lq", evil="hq")
        evil.payloadList.prependedItems.append(Sdf.Payload("", PAY + "/core"))

    case("lookalike_quality_set", "QUALITY_VARIANT", lookalike_quality)

    # -- tensor shapes ------------------------------------------------------------------------------------
    def shape(dims, values=None):
        def fn(layer):
            layer.GetAttributeAtPath(TRI + ".shape").default = Vt.IntArray(list(dims))
            if values is not None:
                layer.GetAttributeAtPath(TRI + ".values").default = Vt.HalfArray.FromNumpy(np.zeros(values, np.float16))
        return fn

    # products that wrap int64 to 0 or to a small count: the size bound must still fire
    case("shape_wraps_to_zero", "TENSOR_TOO_LARGE", shape([65536, 65536, 65536, 65536]))
    case("shape_wraps_to_values", "TENSOR_TOO_LARGE", shape([n_tri, 65536, 65536, 65536, 65536]))
    case("shape_wraps_negative", "TENSOR_TOO_LARGE", shape([2147483647, 2147483647, 2147483647, 4]))
    case("shape_rank8_huge", "TENSOR_TOO_LARGE", shape([2147483647] * 8))
    case("shape_zero_dim", "TENSOR_SHAPE", shape([3, 0, 8, 4], values=0))
    case("shape_all_zero", "TENSOR_SHAPE", shape([0, 0, 0, 0], values=0))
    case("shape_zero_rank1", "TENSOR_SHAPE", shape([0], values=0))

    # -- memory amplification: compressed integer arrays -------------------------------------------------
    if amplification:
        for n in AMP_SIZES:
            def amp(layer, n=n):
                layer.GetAttributeAtPath(GEO + ".faceVertexIndices").default = Vt.IntArray(n)  # zeros: in range
                layer.GetAttributeAtPath(GEO + ".faceVertexCounts").default = Vt.IntArray.FromNumpy(np.full(n // 3, 3, np.int32))
            case(f"amp_face_indices_{n // 3 >> 20}M_faces", "ARRAY_TOO_LARGE", amp)

        def amp_metadata(layer):  # decoded in metadata, not in any attribute a reader looks at
            layer.GetPrimAtPath("/Asset").SetInfo("customData", {"blob": Vt.IntArray(3 << 24)})

        case("amp_custom_data", "ARRAY_TOO_LARGE", amp_metadata)

        def amp_widths(layer):
            layer.GetAttributeAtPath(GEO + ".faceVertexCounts").default = Vt.IntArray.FromNumpy(np.full((1 << 25) + 3, 3, np.int32))

        case("amp_face_counts_over_bound", "ARRAY_TOO_LARGE", amp_widths)

        # crate stores a string once and a string array as indices into its table: each element decodes to a copy
        def amp_string_array(layer):
            layer.GetPrimAtPath("/Asset").SetInfo("customData", {"blob": Vt.StringArray(96, "a" * (1 << 20))})

        case("amp_string_array_repeats_one_string", "ARRAY_TOO_LARGE", amp_string_array)

    def nested_custom_data(layer):  # walkers of nested values recurse; usd-core's text parser overflows far deeper
        value = {"leaf": 1}
        for _ in range(40):
            value = {"k": value}
        layer.GetPrimAtPath("/Asset").SetInfo("customData", value)

    case("nest_custom_data_40_deep", "FILE_UNREADABLE", nested_custom_data, probe=True)

    # -- structural amplification: specs a crate stores in a few bytes each, arcs that repeat subtrees ---------------
    def struct(fill):
        def make(layer):
            junk = Sdf.PrimSpec(layer.GetPrimAtPath("/Asset"), "Junk", Sdf.SpecifierDef, "Scope")
            with Sdf.ChangeBlock():
                fill(layer, junk)
        return make

    over = MAX_ASSET_SPECS + 1
    case("struct_empty_prims", "ARRAY_TOO_LARGE", struct(lambda layer, junk: [Sdf.PrimSpec(junk, f"p{i}", Sdf.SpecifierDef)
                                                                              for i in range(over)]))
    case("struct_properties", "ARRAY_TOO_LARGE", struct(lambda layer, junk: [
        Sdf.AttributeSpec(junk, f"a{i}", Sdf.ValueTypeNames.Float) for i in range(over)]))

    def samples(layer, junk):
        attr = Sdf.AttributeSpec(junk, "a", Sdf.ValueTypeNames.Float)
        for i in range(over):
            layer.SetTimeSample(attr.path, float(i), 1.0)

    case("struct_time_samples", "ARRAY_TOO_LARGE", struct(samples))

    def nested(layer, junk):
        for _ in range(MAX_ASSET_DEPTH):
            junk = Sdf.PrimSpec(junk, "d", Sdf.SpecifierDef)

    case("struct_prims_nested_deep", "ARRAY_TOO_LARGE", struct(nested))

    def arcs(layer, junk):  # ten prims per class, each referencing the next class: 10^5 composed prims from ~60 specs
        for k in range(5):
            cls = Sdf.PrimSpec(layer, f"L{k}", Sdf.SpecifierClass)
            for i in range(10):
                child = Sdf.PrimSpec(cls, f"c{i}", Sdf.SpecifierDef)
                if k < 4:
                    child.referenceList.prependedItems.append(Sdf.Reference("", f"/L{k + 1}"))
        junk.referenceList.prependedItems.append(Sdf.Reference("", "/L0"))

    case("struct_arcs_repeat_a_class", "ARRAY_TOO_LARGE", struct(arcs))
    return cases


if __name__ == "__main__":
    for c in make_cases(Path(sys.argv[1] if len(sys.argv) > 1 else "gen_layers_out")):
        print(f"{c.code:<24} {c.path.name} {c.path.stat().st_size}")
