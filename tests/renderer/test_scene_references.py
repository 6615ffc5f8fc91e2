"""How a scene refers to an asset: any referencing prim type, usdz packages, flattened scenes, relative and anchored
paths, search paths (spec/format.md#referencing-an-asset)."""

import os
import subprocess
import sys

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.scene import SceneWarning
from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_asset
from nasset_sdk.errors import SceneError

SHIFT = (0.3, 0.0, 0.0)
SETTINGS = dict(width=16, height=16, spp=1, max_depth=1)  # direct light only: deterministic given the seed


def _scene(folder, asset_ref, typed="Xform", name="scene.usda"):
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0), focal=60)
    b.distant("Sun", (0.3, 1.0, 0.5), 2.0)
    m = np.eye(4)
    m[3, :3] = SHIFT
    b.asset("Chair", asset_ref, m, typed=typed)
    return b.write(folder / name)


def _image(scene, **kw):
    s = load_scene(scene, **kw)
    assert [i.kind for i in s.instances] == ["neural"], "the asset must render as a neural instance"
    return render(s, RenderSettings(**SETTINGS)).image


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The image of the asset referenced by an untyped ``def`` (the pattern that rendered neural before) and its folder."""
    folder = tmp_path_factory.mktemp("ref")
    constant_rna_asset(folder / "a.usdc")
    img = _image(_scene(folder, "./a.usdc", typed=False))
    # independent check: the asset shifted right by SHIFT shows up right of the image centre
    cols = np.nonzero(img.sum(axis=(0, 2)) > 0)[0]
    assert len(cols) and cols.mean() > img.shape[1] / 2
    return folder, img


@pytest.mark.parametrize("typed", ["Xform", True])
def test_any_referencing_prim_type_renders_neural(reference, tmp_path, typed):
    folder, ref = reference
    img = _image(_scene(folder, "./a.usdc", typed=typed, name=f"s_{typed}.usda"))
    np.testing.assert_allclose(img, ref, atol=1e-6)


def test_usdz_package(reference, tmp_path):
    from pxr import UsdUtils

    folder, ref = reference
    scene = _scene(folder, "./a.usdc", name="zip.usda")
    assert UsdUtils.CreateNewUsdzPackage(scene, str(tmp_path / "scene.usdz"))
    np.testing.assert_allclose(_image(tmp_path / "scene.usdz"), ref, atol=1e-6)


def test_flattened_scene(reference, tmp_path):
    from pxr import Usd

    folder, ref = reference
    Usd.Stage.Open(_scene(folder, "./a.usdc", name="toflat.usda")).Flatten().Export(str(tmp_path / "flat.usda"))
    s = load_scene(tmp_path / "flat.usda")
    assert str(s.assets[0].path).endswith("flat.usda</World/Chair>")
    np.testing.assert_allclose(render(s, RenderSettings(**SETTINGS)).image, ref, atol=1e-6)


def test_relative_and_absolute_paths(reference, tmp_path):
    folder, ref = reference
    sub = tmp_path / "shots"
    sub.mkdir()
    rel = os.path.relpath(folder / "a.usdc", sub)  # '../../refN/a.usdc'
    np.testing.assert_allclose(_image(_scene(sub, rel, name="rel.usda")), ref, atol=1e-6)
    np.testing.assert_allclose(_image(_scene(sub, str(folder / "a.usdc"), name="abs.usda")), ref, atol=1e-6)


def test_search_path_resolver_context(reference, tmp_path):
    """A bare path found only through a search path: refused without it, rendered with it."""
    folder, ref = reference
    shots = tmp_path / "shots"
    shots.mkdir()
    scene = _scene(shots, "a.usdc", name="bare.usda")
    with pytest.raises(SceneError) as exc:
        load_scene(scene)
    assert exc.value.code == "SCENE_INVALID" and "search-path" in str(exc.value)
    np.testing.assert_allclose(_image(scene, search_paths=[folder]), ref, atol=1e-6)


def test_opened_stage_keeps_its_resolver_context(reference, tmp_path):
    from pxr import Ar, Usd

    folder, ref = reference
    shots = tmp_path / "shots2"
    shots.mkdir()
    scene = _scene(shots, "a.usdc", name="bare.usda")
    stage = Usd.Stage.Open(str(scene), Ar.DefaultResolverContext([str(folder)]))
    np.testing.assert_allclose(_image(stage), ref, atol=1e-6)


def test_fallback_mesh_warns_naming_the_prim(reference, tmp_path):
    """Referencing only the asset's geometry renders its fallback mesh: a warning names the prim and the asset."""
    from pxr import Sdf

    folder, _ = reference
    b = SceneBuilder()
    b.camera((0, 0, 3), (0, 0, 0), focal=60)
    b.distant("Sun", (0.3, 1.0, 0.5), 2.0)
    prim = b.stage.DefinePrim("/World/Chair", "Mesh")
    prim.GetReferences().AddReference(Sdf.Reference("./a.usdc", "/Asset/Geometry"))
    with pytest.warns(SceneWarning, match=r"/World/Chair.*fallback mesh of the neural asset .*a\.usdc"):
        s = load_scene(b.write(folder / "fallback.usda"))
    assert [i.kind for i in s.instances] == ["mesh"]


PLAIN_USD_BBOX = """
import sys
from pxr import Usd, UsdGeom
stage = Usd.Stage.Open(sys.argv[1])
box = UsdGeom.BBoxCache(Usd.TimeCode.Default(), ["default"]).ComputeWorldBound(stage.GetPrimAtPath("/World/Chair"))
print(*box.ComputeAlignedRange().GetMidpoint())
"""


def _plain_usd_center(scene) -> np.ndarray:
    """World bounding-box centre of /World/Chair computed by a USD process that never registered the nasset schema."""
    env = {k: v for k, v in os.environ.items() if k != "PXR_PLUGINPATH_NAME"}
    out = subprocess.run([sys.executable, "-c", PLAIN_USD_BBOX, str(scene)], capture_output=True, text=True, env=env,
                         timeout=120, check=True).stdout
    return np.array([float(v) for v in out.split()])


def test_plain_usd_keeps_the_transform_of_the_recommended_pattern(reference):
    folder, _ = reference
    centre = _plain_usd_center(_scene(folder, "./a.usdc", typed="Xform", name="plain_xform.usda"))
    np.testing.assert_allclose(centre, SHIFT, atol=1e-6)  # the constant asset is a sphere centred at its origin
    # the trap the recommended pattern avoids: an untyped prim is not Xformable for USD without the schema
    untyped = _plain_usd_center(_scene(folder, "./a.usdc", typed=False, name="plain_untyped.usda"))
    assert np.allclose(untyped, 0.0, atol=1e-6)


def test_cli_search_path_flag(reference, tmp_path, capsys):
    from nasset_sdk.cli import main

    folder, _ = reference
    scene = _scene(tmp_path, "a.usdc", name="bare_cli.usda")
    out = tmp_path / "o.exr"
    argv = ["render", str(scene), "-o", str(out), "--spp", "1", "--width", "8", "--height", "8", "--quiet"]
    assert main(argv) == 1 and "[SCENE_INVALID]" in capsys.readouterr().err and not out.exists()
    assert main(argv + ["--search-path", str(folder)]) == 0 and out.is_file()


def test_search_path_asset_keeps_its_own_package(tmp_path, monkeypatch):
    """An asset found through a search path is checked in the folder the resolver found it in (its package), not the
    working folder: its in-package path renders, a path leaving that folder is refused."""
    from pxr import Sdf

    lib, shots = tmp_path / "lib", tmp_path / "shots"
    lib.mkdir()
    shots.mkdir()
    (lib / "notes.txt").write_text("in the package")
    (tmp_path / "outside.txt").write_text("outside")
    for name, value in (("ok.usdc", "./notes.txt"), ("bad.usdc", str(tmp_path / "outside.txt"))):
        constant_rna_asset(lib / name)
        layer = Sdf.Layer.FindOrOpen(str(lib / name))
        attr = Sdf.AttributeSpec(layer.GetPrimAtPath("/Asset"), "notes", Sdf.ValueTypeNames.Asset)
        attr.default = Sdf.AssetPath(value)
        layer.Save()
    monkeypatch.chdir(shots)
    assert _image(_scene(shots, "ok.usdc", name="ok.usda"), search_paths=[lib]).max() > 0
    with pytest.raises(SceneError) as exc:
        load_scene(_scene(shots, "bad.usdc", name="bad.usda"), search_paths=[lib])
    assert exc.value.code == "SCENE_INVALID" and "outside.txt" in str(exc.value)


def test_flattened_instances_of_one_asset_share_it(tmp_path):
    """Flattening repeats an asset's specs under each instance, with the instance's xformOps on the copy's root. Each
    instance was read as its own asset (N instances: the asset's networks, tensors and structures N times); now copies
    equal but for their placement are one asset, a different asset stays its own, and the image is the unflattened
    scene's."""
    from pxr import Usd

    constant_rna_asset(tmp_path / "a.usdc")
    constant_rna_asset(tmp_path / "b.usdc", unshadowed=(0.2, 0.9, 0.4))
    b = SceneBuilder()
    b.camera((0, 0, 4), (0, 0, 0), focal=40)
    b.distant("Sun", (0.3, 1.0, 0.5), 2.0)
    for name, file, x in (("Left", "./a.usdc", -1.1), ("Middle", "./b.usdc", 0.0), ("Right", "./a.usdc", 1.1)):
        m = np.eye(4)
        m[3, :3] = (x, 0.0, 0.0)
        b.asset(name, file, m, typed="Xform")
    scene = b.write(tmp_path / "three.usda")
    want = render(load_scene(scene), RenderSettings(**SETTINGS)).image
    Usd.Stage.Open(scene).Flatten().Export(str(tmp_path / "flat.usda"))
    s = load_scene(tmp_path / "flat.usda")
    assert len(s.assets) == 2 and len([i for i in s.instances if i.kind == "neural"]) == 3
    assert len(np.unique(want[..., 1] > 0.0)) == 2  # something rendered
    np.testing.assert_allclose(render(s, RenderSettings(**SETTINGS)).image, want, atol=1e-6)


def test_an_asset_rewritten_in_place_is_read_again(tmp_path):
    """tests/stage_scenes.py::check_rewritten_asset_is_read_again: USD kept the layer another stage held, as first read
    (nasset_sdk.paths.open_checked_stage now reloads a layer whose file changed, unless it has unsaved edits)."""
    from tests.stage_scenes import check_rewritten_asset_is_read_again

    def reference(scene, spp, w, h):
        return render(load_scene(scene), RenderSettings(width=w, height=h, spp=spp, max_depth=1)).image

    check_rewritten_asset_is_read_again(reference, tmp_path)


def test_unsaved_edits_of_an_open_layer_are_kept(tmp_path):
    """The reload is skipped for a layer with unsaved edits: what this process changed in memory is what it renders."""
    from pxr import Gf, Sdf

    constant_rna_asset(tmp_path / "a.usdc")
    scene = _scene(tmp_path, "./a.usdc")
    layer = Sdf.Layer.FindOrOpen(scene)
    m = np.eye(4)
    m[3, :3] = (-SHIFT[0], 0.0, 0.0)
    layer.GetAttributeAtPath("/World/Chair.xformOp:transform").default = Gf.Matrix4d(m.tolist())
    assert layer.dirty
    img = _image(scene)
    cols = np.nonzero(img.sum(axis=(0, 2)) > 0)[0]
    assert cols.mean() < img.shape[1] / 2  # moved left by the unsaved edit (it is authored right of the centre)
