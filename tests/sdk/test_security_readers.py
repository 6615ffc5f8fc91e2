"""Every reader probes an untrusted layer before opening it, and the probe counts strings (spec/security.md#bounds).

Two classes of hostile file that used to pass: a crate stores each distinct string once and refers to
it by index, so a string array of N elements naming one long string decodes to N copies (an 18 KB file
to 400 MB, a 26 KB one to 2.6 GB) that the decoded-size bound did not count; and ``inspect``, ``view``,
``render`` and the scene loader opened asset and scene layers in-process without the guarded probe
only ``validate`` ran, so a file that crashes usd-core's parser (deeply nested dictionaries) killed
them with SIGSEGV and an amplified file took their memory. Readers that may crash run in a child.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from nasset_sdk.asset import Asset
from nasset_sdk.errors import NassetError
from nasset_sdk.examples import example_builder
from nasset_sdk.validate import validate_file

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Path:
    return example_builder("rna", variant="surface", size="tiny", seed=0).write(tmp_path_factory.mktemp("readers") / "base.usdc")


def _with_custom_data(base: Path, out: Path, value) -> Path:
    from pxr import Sdf

    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    layer.GetPrimAtPath("/Asset").SetInfo("customData", value)
    assert layer.Export(str(out))
    return out


def _string_array_file(base: Path, out: Path) -> Path:
    """96 elements naming one 1 MiB string: a few KB on disk, 96 MiB decoded (bound: 64 MiB + 16 x the file)."""
    from pxr import Vt

    return _with_custom_data(base, out, {"blob": Vt.StringArray(96, "a" * (1 << 20))})


def _nested_text_file(base: Path, out: Path, depth: int = 100_000) -> Path:
    """The asset as text with a customData dictionary nested ``depth`` levels deep (usd-core's parser overflows its stack)."""
    from pxr import Sdf

    text = Sdf.Layer.OpenAsAnonymous(str(base)).ExportToString()
    head = 'def NeuralAsset "Asset" (\n'
    assert head in text
    nested = "    customData = {\n" + "dictionary k = {\n" * depth + "int leaf = 1\n" + "}\n" * depth + "    }\n"
    out.write_text(text.replace(head, head + nested, 1))
    return out


def _scene(folder: Path, asset_name: str) -> Path:
    scene = folder / f"scene_{Path(asset_name).stem}.usda"
    scene.write_text(f"""#usda 1.0
(
    defaultPrim = "World"
    upAxis = "Y"
)
def Xform "World"
{{
    def Camera "Cam"
    {{
        double3 xformOp:translate = (0, 0, 5)
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
    def DistantLight "Sun"
    {{
        float inputs:intensity = 1
    }}
    def Xform "A" (
        prepend references = @./{asset_name}@
    )
    {{
    }}
}}
""")
    return scene


def test_string_array_amplification_is_array_too_large(base, tmp_path):
    path = _string_array_file(base, tmp_path / "strings.usdc")
    assert path.stat().st_size < 64 << 10
    report = validate_file(path)
    found = [f for f in report.errors if f.code == "ARRAY_TOO_LARGE"]
    assert found, [str(f) for f in report.findings]
    assert "/Asset customData" in found[0].message
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "ARRAY_TOO_LARGE"


def test_dictionaries_nested_past_the_bound_are_refused_by_every_reader(base, tmp_path):
    value = {"leaf": 1}
    for _ in range(40):  # past limits.MAX_VALUE_DEPTH (32); Python walkers fail near 1000, usd-core's parser far deeper
        value = {"k": value}
    path = _with_custom_data(base, tmp_path / "nested.usdc", value)
    report = validate_file(path)
    assert [f.code for f in report.errors] == ["FILE_UNREADABLE"]
    assert "nested more than" in report.errors[0].message
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "FILE_UNREADABLE"


def _child(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_readers_probe_a_layer_that_crashes_usd_before_opening_it(base, tmp_path):
    """inspect, view and render (an asset alone, referenced from a scene, found on a search path) raise FILE_UNREADABLE;
    before: SIGSEGV."""
    asset = _nested_text_file(base, tmp_path / "deep.usda")
    scene = _scene(tmp_path, asset.name)
    lib = tmp_path / "lib"
    lib.mkdir()
    _nested_text_file(base, lib / "deep_lib.usda")
    bare = tmp_path / "bare.usda"  # a bare reference the resolver finds on the render's search path
    bare.write_text(_scene(tmp_path, "deep_lib.usda").read_text().replace("@./deep_lib.usda@", "@deep_lib.usda@"))
    code = f"""
import sys
from nasset_sdk.errors import NassetError
from nasset_sdk.inspect import inspect_asset
from nasset_reference_renderer.scene import load_scene
for what, fn in (("inspect", lambda: inspect_asset({str(asset)!r})), ("asset", lambda: load_scene({str(asset)!r})),
                 ("scene", lambda: load_scene({str(scene)!r})),
                 ("search_path", lambda: load_scene({str(bare)!r}, search_paths=[{str(lib)!r}]))):
    try:
        fn()
        print(what, "opened")
    except NassetError as exc:
        print(what, exc.code)
    sys.stdout.flush()
"""
    run = _child(code)
    assert run.returncode == 0, (run.returncode, run.stdout, run.stderr[-2000:])
    assert run.stdout.split() == ["inspect", "FILE_UNREADABLE", "asset", "FILE_UNREADABLE", "scene", "FILE_UNREADABLE",
                                  "search_path", "FILE_UNREADABLE"]


def test_scene_referencing_an_amplified_asset_is_refused(base, tmp_path):
    from nasset_reference_renderer.scene import load_scene

    _string_array_file(base, tmp_path / "a.usdc")
    with pytest.raises(NassetError) as exc:
        load_scene(_scene(tmp_path, "a.usdc"))
    assert exc.value.code == "ARRAY_TOO_LARGE"
    assert exc.value.file.endswith("a.usdc")


def test_a_written_file_is_trusted_only_while_unchanged(base, tmp_path):
    """AssetBuilder.write records the file; replacing its bytes afterwards makes the next open probe it again."""
    from pxr import Sdf, Vt

    path = example_builder("rna", variant="surface", size="tiny", seed=0).write(tmp_path / "mine.usdc")
    Asset.open(path)  # written here: opened without a probe
    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    layer.GetPrimAtPath("/Asset").SetInfo("customData", {"blob": Vt.StringArray(96, "a" * (1 << 20))})
    assert layer.Export(str(path))  # same name, other bytes
    with pytest.raises(NassetError) as exc:
        Asset.open(path)
    assert exc.value.code == "ARRAY_TOO_LARGE"


def _asset_with_decoder(base: Path, out: Path, model) -> Path:
    from pxr import Sdf, Usd

    from tests.corpus.gen_networks import DEC
    from tests.corpus.make_corpus import _set_model

    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
    with Usd.EditContext(stage, layer):
        _set_model(stage, DEC, model.SerializeToString())
        stage.GetPrimAtPath(DEC).GetAttribute("onnx:opset").Set(17)
    assert layer.Export(str(out))
    return out


def test_readers_run_the_network_runtime_probe_before_evaluating(base, tmp_path):
    """A decoder whose outputs are NaN on probe inputs is refused by the reader as by the validator (before: evaluated)."""
    from tests.corpus.gen_networks import _output_family

    path = _asset_with_decoder(base, tmp_path / "nan.usdc", _output_family()["out_log_negative_nan"])
    asset = Asset.open(path)
    with pytest.raises(NassetError) as exc:
        asset.session("core", "decoder")
    assert exc.value.code == "NETWORK_OUTPUT" and exc.value.attribute == "onnx:model"
    assert exc.value.prim.endswith("/core/decoder")


def test_a_network_too_slow_for_the_probe_is_refused_not_run(base, tmp_path, monkeypatch):
    """4000 Gemm layers of width 2048 (~9 TFLOP per 256 rows): before, rendering 8 x 8 pixels ran for minutes."""
    from nasset_sdk import netprobe
    from tests.corpus.gen_networks import TIME_CASE_TIMEOUT_S, _time_family

    monkeypatch.setattr(netprobe, "PROBE_TIMEOUT_S", TIME_CASE_TIMEOUT_S)  # the bound the corpus uses for this family
    path = _asset_with_decoder(base, tmp_path / "slow.usdc", _time_family()["time_deep_shared_weights"])
    asset = Asset.open(path)
    with pytest.raises(NassetError) as exc:
        asset.evaluator()
    assert exc.value.code == "NETWORK_RUNTIME" and "did not finish" in exc.value.message


def test_decoded_bytes_counts_every_array_type_at_its_width():
    from pxr import Gf, Vt

    from nasset_sdk.safeopen import decoded_bytes

    assert decoded_bytes(Vt.QuatdArray(10)) == 10 * 32
    assert decoded_bytes(Vt.QuatfArray(10)) == 10 * 16
    assert decoded_bytes(Vt.Matrix3dArray(10)) == 10 * 72
    assert decoded_bytes(Vt.Matrix4dArray([Gf.Matrix4d(1)] * 3)) == 3 * 128
    assert decoded_bytes(Vt.Vec3fArray(10)) == 10 * 12
    assert decoded_bytes(Vt.HalfArray(10)) == 10 * 2
    assert decoded_bytes(Vt.StringArray(4, "x" * 100)) == 4 * (32 + 100)  # one stored string, four decoded copies
