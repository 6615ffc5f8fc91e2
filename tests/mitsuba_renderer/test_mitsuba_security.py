"""The Mitsuba implementation reads assets and scenes as untrusted input, like the SDK (spec/security.md).

It used to open asset and scene files with ``Usd.Stage.Open`` and hand network bytes to onnxruntime after
the digest check alone: a decoder whose initializer names external data was loaded, and onnxruntime read
that file relative to the working folder into the weights (the bytes of ``secret.bin`` in the render);
an asset's sublayer outside its folder was composed. Both are refused now, with the SDK's codes.
"""

from __future__ import annotations

import hashlib

import numpy as np
import pytest

pytest.importorskip("onnxruntime")

from nasset_sdk.errors import NassetError  # noqa: E402
from nasset_sdk.examples import example_builder  # noqa: E402

DEC = "/_NassetPayloads/core/decoder"


def _asset_with_decoder(path, blob: bytes):
    from pxr import Sdf, Usd, Vt

    base = example_builder("rna", variant="surface", size="tiny", seed=0).write(path.parent / "_base.usdc")
    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    stage = Usd.Stage.Open(layer, Usd.Stage.LoadAll)
    with Usd.EditContext(stage, layer):
        prim = stage.GetPrimAtPath(DEC)
        prim.GetAttribute("onnx:model").Set(Vt.UCharArray.FromNumpy(np.frombuffer(blob, np.uint8)))
        prim.GetAttribute("onnx:sha256").Set(hashlib.sha256(blob).hexdigest())
        prim.GetAttribute("onnx:opset").Set(17)
    assert layer.Export(str(path))
    return path


def test_decoder_with_external_data_never_reaches_onnxruntime(tmp_path, monkeypatch):
    from nasset_mitsuba_renderer.rna import RnaAsset
    from tests.corpus.gen_networks import IN_W, OUT_W, _ext_family

    model = _ext_family()["ext_initializer"]  # W [16, 6] read from 'secret.bin', relative to the working folder
    path = _asset_with_decoder(tmp_path / "asset.usdc", model.SerializeToString())
    (tmp_path / "secret.bin").write_bytes(b"SECRET!!" * (IN_W * OUT_W * 4 // 8))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(NassetError) as exc:
        RnaAsset(str(path))
    assert exc.value.code == "NETWORK_EXTERNAL_DATA"
    assert exc.value.prim.endswith("decoder") and exc.value.attribute == "onnx:model"


def test_scene_whose_asset_sublayers_a_file_outside_its_folder_is_refused(tmp_path):
    from pxr import Sdf

    from nasset_mitsuba_renderer.usdscene import read_scene

    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "evil.usda").write_text('#usda 1.0\nover "Asset"\n{\n    custom string secret = "outside"\n}\n')
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    base = example_builder("rna", variant="surface", size="tiny", seed=0).write(tmp_path / "base.usdc")
    layer = Sdf.Layer.OpenAsAnonymous(str(base))
    layer.subLayerPaths.append(str(outside / "evil.usda"))
    assert layer.Export(str(pkg / "asset.usdc"))
    scene = tmp_path / "scene.usda"  # as text: a SceneBuilder stage would compose the reference while building it
    scene.write_text('#usda 1.0\n(\n    defaultPrim = "World"\n)\ndef Xform "World"\n{\n    def Camera "Cam"\n    {\n    }\n'
                     '    def Xform "A" (\n        prepend references = @./pkg/asset.usdc@\n    )\n    {\n    }\n}\n')
    with pytest.raises(NassetError) as exc:
        read_scene(scene)
    assert exc.value.code == "SCENE_INVALID"
    assert "is absolute in layer" in exc.value.message and "nothing was composed" in exc.value.message
    assert Sdf.Layer.Find(str(outside / "evil.usda")) is None  # never opened


def test_decoder_failing_the_runtime_probe_is_not_run(tmp_path):
    from nasset_mitsuba_renderer.rna import RnaAsset
    from tests.corpus.gen_networks import _output_family

    path = _asset_with_decoder(tmp_path / "nan.usdc", _output_family()["out_log_negative_nan"].SerializeToString())
    with pytest.raises(NassetError) as exc:
        RnaAsset(str(path))
    assert exc.value.code == "NETWORK_OUTPUT" and exc.value.prim.endswith("decoder")


def test_sessions_run_at_most_the_rows_the_probe_ran(tmp_path):
    """The implementation's 65 536-row chunks reach onnxruntime as runs of at most limits.MAX_NETWORK_ROWS rows."""
    from nasset_mitsuba_renderer.rna import RnaAsset
    from nasset_sdk import limits
    from nasset_sdk.networks import CheckedSession

    path = example_builder("rna", variant="surface", size="tiny", seed=0).write(tmp_path / "a.usdc")
    asset = RnaAsset(str(path))
    assert isinstance(asset.session, CheckedSession)
    n = 2 * limits.MAX_NETWORK_ROWS + 3
    x = np.random.default_rng(0).uniform(-1, 1, (n, asset.session.get_inputs()[0].shape[-1])).astype(np.float32)
    whole = asset.session.session.run([asset.output_name], {asset.input_name: x})[0]
    assert np.allclose(asset.session.run([asset.output_name], {asset.input_name: x})[0], whole, rtol=1e-6, atol=1e-7)


def test_dome_textures_go_through_the_sdks_bounded_reader(tmp_path):
    """The Mitsuba implementation read dome textures with OpenEXR directly: a header declaring 10^12 pixels went to
    the decoder unchecked, and NaN pixels reached the light. Now its reader is the SDK's (header bounds, chunk table,
    IMAGE_INVALID naming the prim), and pixels must be finite and >= 0 (SCENE_INVALID), as the reference renderer."""
    from nasset_mitsuba_renderer.usdscene import read_scene
    from tests.corpus.gen_render import make_cases

    cases = {c.path.stem: c for c in make_cases(tmp_path) if c.path.stem.startswith("r8_dome_")}
    ok = read_scene(str(cases.pop("r8_dome_ok").path))
    assert [lt.texture.shape for lt in ok.lights if getattr(lt, "texture", None) is not None] == [(8, 16, 3)]
    assert {"r8_dome_huge_header", "r8_dome_pixels_missing", "r8_dome_truncated"} <= set(cases)
    for name, case in cases.items():
        with pytest.raises(NassetError) as exc:
            read_scene(str(case.path))
        assert exc.value.code == "IMAGE_INVALID" and exc.value.prim == "/World/Dome", (name, exc.value)
    nan = np.full((8, 16, 3), 0.5, np.float32)
    nan[2, 3] = np.nan
    texture = tmp_path / "_dome_ok.exr"  # the ok scene's texture, now with a NaN pixel written as-is
    import OpenEXR

    OpenEXR.File({"type": OpenEXR.scanlineimage, "compression": OpenEXR.ZIP_COMPRESSION}, {"RGB": nan}).write(str(texture))
    with pytest.raises(NassetError) as exc:
        read_scene(str(tmp_path / "r8_dome_ok.usda"))
    assert exc.value.code == "SCENE_INVALID" and "NaN" in exc.value.message
