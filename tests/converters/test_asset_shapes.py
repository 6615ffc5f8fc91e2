"""Which Mitsuba shapes can become an asset.

A shape that emits light cannot: the format carries light transport (the response to light arriving), not emission.
Baked, its training targets would hold the emission as if it were lit; replaced, its light would leave the scene.
Every Mitsuba entry point that takes shape ids refuses it with CONVERT_SHAPE_UNSUPPORTED. And a shape id given twice
is a usage error."""

import pytest

pytest.importorskip("mitsuba")

SCENE = """<scene version="3.0.0">
  <integrator type="path"/>
  <sensor type="perspective"><transform name="to_world"><lookat origin="0,0,4" target="0,0,0" up="0,1,0"/></transform>
    <film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film></sensor>
  <shape type="sphere" id="bulb"><float name="radius" value="0.3"/>
    <emitter type="area"><rgb name="radiance" value="5"/></emitter></shape>
  <shape type="cube" id="lamp"><transform name="to_world"><scale value="0.2"/><translate x="1"/></transform>
    <bsdf type="dielectric"/>
    <emitter type="area"><rgb name="radiance" value="2"/></emitter></shape>
  <shape type="cube" id="box"><transform name="to_world"><scale value="0.2"/><translate x="-1"/></transform></shape>
</scene>"""


@pytest.fixture
def scene_file(tmp_path):
    path = tmp_path / "lamp.xml"
    path.write_text(SCENE)
    return path


@pytest.mark.parametrize("sid", ["bulb", "lamp"])
def test_bakes_refuse_an_emitter(scene_file, sid):
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import load_scene, pick_shapes
    from nasset_sdk.errors import NassetError

    mi = load_mitsuba()
    scene = load_scene(mi, scene_file)
    assert len(pick_shapes(scene, ["box"])) == 1
    with pytest.raises(NassetError) as ei:
        pick_shapes(scene, ["box", sid], file=str(scene_file))
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED" and repr(sid) in str(ei.value) and "emitter" in str(ei.value)


def test_rna_bake_refuses_an_emitter_before_rendering(scene_file, tmp_path):
    from nasset_bakers.mitsuba.rna import bake
    from nasset_sdk.errors import NassetError

    with pytest.raises(NassetError) as ei:
        bake(scene_file, ["bulb"], tmp_path / "a.usdc", size="tiny", quiet=True)
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED"
    assert not (tmp_path / "a.usdc").exists()


def test_convert_and_bench_refuse_to_replace_an_emitter(scene_file, tmp_path):
    from nasset_benchmarks.accuracy import check_asset_fits
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.usd_export import convert_scene
    from nasset_sdk.errors import NassetError
    from nasset_sdk.examples import example_builder

    asset = example_builder("rna", size="tiny").write(tmp_path / "a.usdc")
    with pytest.raises(NassetError) as ei:
        convert_scene(scene_file, tmp_path / "out.usda", replace={"bulb": asset}, check_usd=False)
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "'bulb'" in str(ei.value)
    mi = load_mitsuba()
    with pytest.raises(NassetError) as ei:
        check_asset_fits(mi, mi.load_file(str(scene_file)), {"lamp": asset}, scene_file=str(scene_file))
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "'lamp'" in str(ei.value)


def test_an_id_given_twice_is_a_usage_error(scene_file):
    """--asset box --asset box used to bake the shape twice over (coincident triangles, every edge shared by four
    faces)."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba.scene import load_scene, pick_shapes
    from nasset_sdk.errors import UsageError

    scene = load_scene(load_mitsuba(), scene_file)
    with pytest.raises(UsageError, match=r"\['box'\] given more than once"):
        pick_shapes(scene, ["box", "box"])


def test_the_plugin_scene_loader_refuses_to_replace_an_emitter(scene_file, tmp_path):
    """The JIT plugin's ``load_file(replace=...)``, which ``bench error-vs-time`` renders the asset scene with."""
    from nasset_mitsuba_plugin.scene import load_file
    from nasset_mitsuba_plugin.variant import jit_mitsuba
    from nasset_sdk.errors import NassetError
    from nasset_sdk.examples import example_builder

    asset = example_builder("rna", size="tiny").write(tmp_path / "a.usdc")
    with pytest.raises(NassetError) as ei:
        load_file(scene_file, mi=jit_mitsuba(), replace={"lamp": asset})
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED" and "'lamp'" in str(ei.value)
