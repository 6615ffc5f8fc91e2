"""The codeless USD schema registers: in process, from a built wheel, and through PXR_PLUGINPATH_NAME."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest

import nasset_sdk  # noqa: F401  (registers the schema)
from nasset_sdk.plugin import schema_dir

REPO = Path(__file__).resolve().parents[2]
SCHEMAS = REPO / "schemas"
TYPES = {"NeuralAsset": "NassetNeuralAsset", "NeuralComponent": "NassetNeuralComponent",
         "NeuralTensor": "NassetNeuralTensor", "NeuralNetwork": "NassetNeuralNetwork"}


def _declared_properties() -> dict[str, dict[str, tuple[str, str, object]]]:
    """Read generatedSchema.usda with Sdf (independently of the registry): prim -> attribute -> (type, variability, default)."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(str(SCHEMAS / "generatedSchema.usda"))
    out = {}
    for prim in layer.rootPrims:
        attrs = {}
        for a in prim.attributes:
            default = a.default if a.HasDefaultValue() else None
            attrs[a.name] = (str(a.typeName), str(a.variability), default)
        out[prim.name] = attrs
    return out


def test_schema_dir_is_the_checkout_or_package():
    assert (schema_dir() / "plugInfo.json").is_file() and (schema_dir() / "generatedSchema.usda").is_file()


@pytest.mark.parametrize("usd_name,tf_name", sorted(TYPES.items()))
def test_types_known_to_tf_and_usd(usd_name, tf_name):
    from pxr import Tf, Usd

    tf_type = Tf.Type.FindByName(tf_name)
    assert not tf_type.isUnknown
    assert Usd.SchemaRegistry.GetTypeFromName(usd_name) == tf_type
    assert Usd.SchemaRegistry.GetSchemaTypeName(tf_type) == usd_name
    assert Usd.SchemaRegistry.IsConcrete(tf_type)
    assert tf_type.IsA(Tf.Type.FindByName("UsdTyped"))


def test_neural_asset_is_xformable():
    from pxr import Sdf, Usd, UsdGeom

    stage = Usd.Stage.Open(Sdf.Layer.CreateAnonymous(".usda"))
    prim = stage.DefinePrim("/Asset", "NeuralAsset")
    assert prim.IsA(UsdGeom.Xformable) and not prim.IsA(UsdGeom.Gprim)
    assert UsdGeom.Xformable(prim).AddTranslateOp()  # a scene can place it
    assert not stage.DefinePrim("/T", "NeuralTensor").IsA(UsdGeom.Xformable)


def test_prim_definitions_match_generated_schema():
    from pxr import Usd

    declared = _declared_properties()
    assert set(declared) == set(TYPES)
    reg = Usd.SchemaRegistry()
    for usd_name, attrs in declared.items():
        definition = reg.FindConcretePrimDefinition(usd_name)
        assert definition is not None, usd_name
        assert set(attrs) <= set(definition.GetPropertyNames()), usd_name
        for name, (type_name, variability, default) in attrs.items():
            spec = definition.GetSchemaAttributeSpec(name)
            assert str(spec.typeName) == type_name, (usd_name, name)
            assert str(spec.variability) == variability, (usd_name, name)
            if default is not None:
                assert definition.GetAttributeFallbackValue(name) == default, (usd_name, name)


def test_fallbacks_and_tokens_the_spec_states():
    """The fallbacks spec/format.md documents (a reader must not rely on them for required attributes)."""
    from pxr import Sdf, Usd

    reg = Usd.SchemaRegistry()
    asset = reg.FindConcretePrimDefinition("NeuralAsset")
    assert asset.GetAttributeFallbackValue("nasset:specVersion") == "0.1"
    assert asset.GetAttributeFallbackValue("nasset:variant") == "surface"
    assert asset.GetAttributeFallbackValue("nasset:provenance") == "{}"
    assert list(asset.GetSchemaAttributeSpec("nasset:kind").allowedTokens) == ["rna", "neupress", "8dna"]
    comp = reg.FindConcretePrimDefinition("NeuralComponent")
    assert comp.GetAttributeFallbackValue("nasset:required") is True
    assert comp.GetSchemaAttributeSpec("nasset:required").variability == Sdf.VariabilityUniform
    tensor = reg.FindConcretePrimDefinition("NeuralTensor")
    assert tensor.GetAttributeFallbackValue("dtype") == "float32"
    assert list(tensor.GetSchemaAttributeSpec("dtype").allowedTokens) == ["float16", "float32"]
    assert "values" not in tensor.GetPropertyNames()  # typed per dtype, so authored as a custom attribute
    net = reg.FindConcretePrimDefinition("NeuralNetwork")
    assert str(net.GetSchemaAttributeSpec("onnx:model").typeName) == "uchar[]"


def test_provenance_json_schema_is_packaged_data():
    schema = json.loads((SCHEMAS / "provenance.schema.json").read_text())
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    from nasset_sdk.validate.rules import PROVENANCE_REQUIRED

    assert schema["type"] == "object" and set(schema["required"]) == set(PROVENANCE_REQUIRED)


# -- wheel ------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """Build the wheel from a clean copy of the sources (no stale build/ folder can help it)."""
    src = tmp_path_factory.mktemp("src")
    package_dirs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"].values()
    for item in ("pyproject.toml", "README.md", "nasset_sdk", *package_dirs):
        if (REPO / item).is_dir():
            shutil.copytree(REPO / item, src / item, ignore=shutil.ignore_patterns("__pycache__"))
        elif (REPO / item).is_file():
            shutil.copy2(REPO / item, src / item)
    out = tmp_path_factory.mktemp("wheel")
    cmd = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(out), str(src)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    (whl,) = out.glob("nasset_sdk-*.whl")
    return whl


def test_wheel_contains_the_schema(wheel, tmp_path):
    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        for f in ("plugInfo.json", "generatedSchema.usda", "provenance.schema.json"):
            assert f"nasset_sdk/usdschema/{f}" in names
            assert zf.read(f"nasset_sdk/usdschema/{f}") == (SCHEMAS / f).read_bytes()
        assert "nasset_sdk/plugin.py" in names and "nasset_sdk/inspect.py" in names
        zf.extractall(tmp_path, [n for n in names if n.startswith("nasset_sdk/usdschema/")])
    info = json.loads((tmp_path / "nasset_sdk/usdschema/plugInfo.json").read_text())
    plugin = info["Plugins"][0]
    assert plugin["Root"] == "." and plugin["ResourcePath"] == "." and plugin["LibraryPath"] == ""
    # the packaged folder registers on its own (what an installed wheel does)
    _assert_registers_from(tmp_path / "nasset_sdk/usdschema")



def test_wheel_contains_the_web_viewer(wheel):
    """``nasset web`` needs no Node.js: the built page ships in the wheel, and the verb is an entry point."""
    from nasset_sdk import web

    with zipfile.ZipFile(wheel) as zf:
        names = set(zf.namelist())
        for f in web.PAGE_FILES:
            assert zf.read(f"nasset_sdk/web_viewer/{f}") == (REPO / "nasset_sdk" / "web_viewer" / f).read_bytes()
        (ep,) = [n for n in names if n.endswith(".dist-info/entry_points.txt")]
        assert "web = nasset_sdk.web:VERB" in zf.read(ep).decode()

# -- PXR_PLUGINPATH_NAME ------------------------------------------------------------------------

_PROBE = """
import json, sys
from pxr import Plug, Tf, Usd
Plug.Registry()  # plugins on PXR_PLUGINPATH_NAME are declared when the registry starts
reg = Usd.SchemaRegistry()
d = reg.FindConcretePrimDefinition("NeuralTensor")
print(json.dumps({
    "known": [not Tf.Type.FindByName(n).isUnknown for n in %r],
    "tensorProps": sorted(d.GetPropertyNames()) if d else None,
    "nasset_imported": any(m.split(".")[0] == "nasset_sdk" for m in sys.modules),
}))
""" % (sorted(TYPES.values()),)


def _probe(plugin_path: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PXR_PLUGINPATH_NAME"}
    if plugin_path is not None:
        env["PXR_PLUGINPATH_NAME"] = plugin_path
    proc = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True, env=env, cwd="/", timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def _assert_registers_from(folder: Path) -> None:
    got = _probe(str(folder))
    assert got["known"] == [True] * len(TYPES)
    assert got["tensorProps"] == ["dtype", "layout", "shape"]
    assert got["nasset_imported"] is False


def test_pxr_pluginpath_registers_without_importing_nasset():
    _assert_registers_from(schema_dir())


def test_without_pluginpath_types_are_unknown():
    """Control for the test above: a bare USD does not know the types."""
    got = _probe(None)
    assert got["known"] == [False] * len(TYPES) and got["tensorProps"] is None


def test_cli_schema_path_prints_the_folder(capsys):
    from nasset_sdk.cli import main

    assert main(["schema-path"]) == 0
    assert Path(capsys.readouterr().out.strip()) == schema_dir()


# -- the reader does not let schema fallbacks stand in for required authored values ---------------

def test_unauthored_spec_version_is_rejected_despite_fallback(tmp_path):
    import nasset_sdk as ns
    from nasset_sdk.examples import example_builder

    path = tmp_path / "a.usda"
    example_builder("rna", size="tiny").write(path)
    text = path.read_text()
    authored = f'string nasset:specVersion = "{ns.limits.BASE_SPEC_VERSION}"\n'
    assert authored in text
    path.write_text(text.replace(authored, ""))
    with pytest.raises(ns.AssetFormatError) as info:
        ns.Asset.open(path)
    assert info.value.code == "SPEC_VERSION"


def test_provenance_required_keys_cannot_be_overridden(tmp_path):
    import nasset_sdk as ns
    from nasset_sdk.examples import example_builder

    b = example_builder("rna", size="tiny")
    b.provenance = {"specVersion": "9.9", "kind": "other", "generator": "x"}
    b.write(tmp_path / "a.usdc")
    prov = ns.Asset.open(tmp_path / "a.usdc", load="none").provenance
    assert (prov["specVersion"], prov["kind"], prov["generator"]) == (ns.limits.BASE_SPEC_VERSION, "rna", "x")


def test_network_width_bound():
    import numpy as np

    from nasset_sdk import limits
    from nasset_sdk.errors import NassetError
    from nasset_sdk.networks import mlp_onnx

    too_wide = limits.MAX_NETWORK_WIDTH + 1
    blob = mlp_onnx([np.zeros((too_wide, 1), np.float32)], [np.zeros(1, np.float32)])
    from nasset_sdk.networks import check_model_bytes

    with pytest.raises(NassetError) as info:
        check_model_bytes(blob)
    assert info.value.code == "NETWORK_IO"


def test_written_version_is_the_lowest_that_describes_the_file(tmp_path):
    """A file without 0.2 content declares 0.1 (old readers keep reading it); a portable component makes it 0.2."""
    import nasset_sdk as ns
    from nasset_sdk.examples import example_builder
    from nasset_sdk.portable import add_portable

    plain = example_builder("rna", size="tiny").write(tmp_path / "a.usdc")
    assert ns.Asset.open(plain, load="none").spec_version == "0.1"
    add_portable(plain, tmp_path / "b.usdc")
    b = ns.Asset.open(tmp_path / "b.usdc", load="none")
    assert b.spec_version == "0.2" and b.provenance["specVersion"] == "0.2"


def test_near_field_fetch_is_written_read_and_declares_0_3(tmp_path):
    """nasset:nearFieldFetch (spec/kinds/rna.md#near-field-fetch): authored only when non-zero, read back exactly,
    kept by from_asset, and the file declares 0.3 (the lowest version that describes it)."""
    import nasset_sdk as ns
    from nasset_sdk.examples import example_builder

    b = example_builder("rna", size="tiny")
    assert ns.Asset.open(b.write(tmp_path / "zero.usdc"), load="none").near_field_fetch == 0.0
    b.near_field_fetch = 0.375
    a = ns.Asset.open(b.write(tmp_path / "f.usdc"), load="none")
    assert a.near_field_fetch == 0.375 and a.spec_version == "0.3" and a.provenance["specVersion"] == "0.3"
    copy = ns.AssetBuilder.from_asset(a)
    assert ns.Asset.open(copy.write(tmp_path / "copy.usdc"), load="none").near_field_fetch == 0.375
    assert ns.Asset.open(tmp_path / "zero.usdc", load="none").spec_version == "0.1"
    n = example_builder("neupress", size="tiny")
    n.near_field_fetch = 0.25
    assert ns.Asset.open(n.write(tmp_path / "n.usdc"), load="none").near_field_fetch == 0.25  # neupress has it too


@pytest.mark.parametrize("value, kind", [(float("nan"), "rna"), (1.5, "rna"), (-0.25, "rna"), (float("inf"), "rna"),
                                          (1.5, "neupress"), (0.5, "8dna")])
def test_near_field_fetch_out_of_range_or_on_another_kind_is_refused(tmp_path, value, kind):
    """The writer refuses the value, and a file carrying it fails Asset.open and the validator with NEAR_FIELD_INVALID
    naming the attribute."""
    from pxr import Sdf, Usd

    import nasset_sdk as ns
    from nasset_sdk.errors import NassetError
    from nasset_sdk.examples import example_builder
    from nasset_sdk.validate import validate_file

    b = example_builder(kind, size="tiny")
    b.near_field_fetch = value
    with pytest.raises(NassetError) as info:
        b.write(tmp_path / "refused.usdc")
    assert info.value.code == "NEAR_FIELD_INVALID"
    b.near_field_fetch = 0.0
    path = b.write(tmp_path / "a.usdc")
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath("/Asset").CreateAttribute("nasset:nearFieldFetch", Sdf.ValueTypeNames.Float).Set(value)
    stage.GetRootLayer().Save()
    with pytest.raises(NassetError) as info:
        ns.Asset.open(path, load="none").near_field_fetch  # noqa: B018
    assert info.value.code == "NEAR_FIELD_INVALID" and info.value.attribute == "nasset:nearFieldFetch"
    report = validate_file(path)
    found = [f for f in report.findings if f.code == "NEAR_FIELD_INVALID"]
    assert found and found[0].attribute == "nasset:nearFieldFetch" and not report.ok
