"""A shape's participating medium that the scene's own integrator does not render (Mitsuba's ``path`` ignores media):
bakes render the medium, so the bakes and the in-scene benches warn that the scene shows something else.
Found on an unseen scene: a milky blob behind a smooth boundary, ``<integrator type="path">``, which Mitsuba rendered
as clear glass; the bench read 166 / 137 / 73 % of the energy without saying why."""

import numpy as np
import pytest

pytest.importorskip("mitsuba")

BLOB = """<shape type="cube" id="blob">
  <bsdf type="dielectric"/>
  <medium type="homogeneous" name="interior"><rgb name="albedo" value="0.0, 0.0, 0.0"/><float name="sigma_t" value="50"/></medium>
</shape>"""
PLAIN = '<shape type="sphere" id="plain"><transform name="to_world"><translate x="3"/></transform></shape>'


@pytest.fixture(scope="module")
def mi():
    from nasset_converters.mitsuba import load_mitsuba

    return load_mitsuba()


def _scene(mi, integrator: str, shapes: str = BLOB + PLAIN):
    return mi.load_string(f'<scene version="3.0.0">{integrator}{shapes}</scene>')


@pytest.mark.parametrize("integrator, warns", [
    ('<integrator type="path"/>', True),
    ('<integrator type="direct"/>', True),
    ('<integrator type="prb"/>', True),
    ('<integrator type="volpath"/>', False),
    ('<integrator type="volpathmis"/>', False),
    ('<integrator type="prbvolpath"/>', False),
    ("", False),  # no integrator: a bake renders with its own, and the benches refuse the scene
    # wrappers: the nested integrator makes the image (an aov scene's volpath used to be read as "no media")
    ('<integrator type="aov"><string name="aovs" value="d:depth"/><integrator type="volpath"/></integrator>', False),
    ('<integrator type="aov"><string name="aovs" value="d:depth"/><integrator type="path"/></integrator>', True),
    ('<integrator type="moment"><integrator type="volpath"/></integrator>', False),
    ('<integrator type="moment"><integrator type="path"/></integrator>', True),
])
def test_ignored_media_by_integrator(mi, integrator, warns):
    from nasset_converters.mitsuba.scene import ignored_media

    msg = ignored_media(_scene(mi, integrator), ["blob", "plain"])
    assert (msg is not None) == warns, msg
    if warns:
        assert "['blob']" in msg and "volpath" in msg and "plain" not in msg


def test_no_warning_for_shapes_without_a_medium(mi):
    from nasset_converters.mitsuba.scene import ignored_media

    assert ignored_media(_scene(mi, '<integrator type="path"/>'), ["plain"]) is None


def test_premise_path_renders_the_medium_as_empty(mi):
    """The premise, measured: a black, dense medium behind a smooth boundary, in front of a bright emitter. ``volpath``
    shows it dark; ``path`` lets the light through as if the cube were clear glass."""
    scene_xml = ('<sensor type="orthographic"><transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/>'
                 '<scale x="0.5" y="0.5"/></transform><film type="hdrfilm"><integer name="width" value="8"/>'
                 '<integer name="height" value="8"/></film></sensor>'
                 '<shape type="rectangle"><transform name="to_world"><translate z="-3"/><scale value="4"/></transform>'
                 '<emitter type="area"><rgb name="radiance" value="1"/></emitter></shape>')
    means = {}
    for name in ("path", "volpath"):
        scene = _scene(mi, f'<integrator type="{name}"><integer name="max_depth" value="8"/></integrator>', BLOB + scene_xml)
        means[name] = float(np.mean(np.asarray(mi.render(scene, spp=16))))
    assert means["path"] > 0.5 and means["volpath"] < 0.05, means


def test_8dna_bake_says_it(mi, tmp_path):
    from nasset_bakers.mitsuba.eightdna import scene_shapes

    (tmp_path / "s.xml").write_text(f'<scene version="3.0.0"><integrator type="path"/>{BLOB}</scene>')
    said = []
    scene_shapes(mi, tmp_path / "s.xml", ["blob"], None, tmp_path, said.append)
    assert any(s.startswith("warning:") and "renders no participating media" in s for s in said), said


@pytest.mark.parametrize("integrator, warns", [
    ('<integrator type="volpath"><integer name="max_depth" value="16"/></integrator>', True),
    ('<integrator type="volpath"/>', False),  # Mitsuba's default -1: unbounded
    ('<integrator type="volpath"><integer name="max_depth" value="-1"/></integrator>', False),
    ('<integrator type="direct"/>', False),  # no depth setting
    ('<integrator type="path"><integer name="max_depth" value="16"/></integrator>', False),  # no media at all: ignored_media
    ('<integrator type="aov"><string name="aovs" value="d:depth"/><integrator type="volpath"><integer name="max_depth" '
     'value="16"/></integrator></integrator>', True),
])
def test_truncated_media_by_depth(mi, integrator, warns):
    """A bounded scene depth cuts the many bounces inside a high-albedo medium; bakes trace deeper. Found on the same
    blob: at the scene's max_depth 16 an 8dna bake read 133-150 % in red; with max_depth -1, 94-99 %."""
    from nasset_converters.mitsuba.scene import truncated_media

    msg = truncated_media(_scene(mi, integrator), ["blob", "plain"])
    assert (msg is not None) == warns, msg
    if warns:
        assert "max_depth 16" in msg and "['blob']" in msg and "plain" not in msg
    assert truncated_media(_scene(mi, integrator), ["plain"]) is None


@pytest.mark.parametrize("baked_depth, warns", [(1024, True), (-1, True), (17, True), (16, False), (8, False)])
def test_truncated_media_only_where_the_bake_is_deeper(mi, tmp_path, baked_depth, warns):
    """A bake warns only when its own depth is deeper than the scene's (an rna or neupress bake of a scene deeper than
    its preset trains at the scene's depth, and then holds no more than the scene shows); the 8dna bake passes its
    sampler's depth."""
    from nasset_bakers.mitsuba.eightdna import scene_shapes
    from nasset_converters.mitsuba.scene import truncated_media

    integrator = '<integrator type="volpath"><integer name="max_depth" value="16"/></integrator>'
    assert (truncated_media(_scene(mi, integrator), ["blob"], baked_depth=baked_depth) is not None) == warns
    (tmp_path / "s.xml").write_text(f'<scene version="3.0.0">{integrator}{BLOB}</scene>')
    said = []
    scene_shapes(mi, tmp_path / "s.xml", ["blob"], None, tmp_path, said.append, baked_depth=baked_depth)
    assert any(s.startswith("warning:") and "max_depth 16" in s for s in said) == warns, said


@pytest.mark.parametrize("provenance, warns", [
    ({"data": {"max_depth": 1024}}, True),  # rna / neupress baked deeper than the scene
    ({"sampler": {"max_depth": 1024}}, True),  # 8dna
    ({"data": {"max_depth": 16}}, False),  # baked at the scene's own depth: the asset holds what the scene shows
    ({}, True),  # the provenance does not say: warn
])
def test_bench_depth_caveat_reads_the_assets_baked_depth(mi, tmp_path, provenance, warns):
    from nasset_converters.mitsuba.scene import baked_depth, media_caveats
    from nasset_sdk.examples import example_builder

    builder = example_builder("rna", size="tiny")
    builder.provenance = provenance
    asset = builder.write(tmp_path / "a.usdc")
    scene = _scene(mi, '<integrator type="volpath"><integer name="max_depth" value="16"/></integrator>')
    assert baked_depth(provenance) == (provenance.get("data") or provenance.get("sampler") or {}).get("max_depth")
    caveats = media_caveats(mi, scene, {"blob": asset, "plain": asset})
    assert any("max_depth 16" in c for c in caveats) == warns, caveats


@pytest.mark.parametrize("provenance, depth", [
    ({"data": {"max_depth": 24}}, 24), ({"sampler": {"max_depth": -1}}, -1), ({"data": [24]}, None),
    ({"data": {"max_depth": "24"}}, None), ({"data": {"max_depth": True}}, None), ([], None), ({}, None),
])
def test_baked_depth_reads_untrusted_provenance(provenance, depth):
    from nasset_converters.mitsuba.scene import baked_depth

    assert baked_depth(provenance) == depth


def test_fog_around_the_camera_is_named(mi, tmp_path):
    """A medium on the sensor (fog the camera sits in): USD has no participating media and the benches render from a
    sensor of their own, so neither side shows it. Found on an unseen scene: the bench's figures were those of the
    scene without its fog, without a word."""
    from nasset_converters.mitsuba.scene import camera_medium, media_caveats
    from nasset_converters.mitsuba.usd_export import convert_scene

    camera = ('<sensor type="perspective">{}<transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/>'
              '</transform><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>'
              '</sensor>')
    fog = '<medium type="homogeneous" name="medium"><float name="sigma_t" value="0.05"/></medium>'
    foggy = _scene(mi, '<integrator type="volpath"/>', BLOB + camera.format(fog))
    clear = _scene(mi, '<integrator type="volpath"/>', BLOB + camera.format(""))
    assert "camera sits in a medium (HomogeneousMedium)" in camera_medium(foggy)
    assert camera_medium(clear) is None
    assert any("camera sits in a medium" in c for c in media_caveats(mi, foggy, {"blob": "missing.usdc"}))
    assert not any("camera sits" in c for c in media_caveats(mi, clear, {"blob": "missing.usdc"}))
    (tmp_path / "fog.xml").write_text(f'<scene version="3.0.0">{BLOB}{camera.format(fog)}</scene>')
    res = convert_scene(tmp_path / "fog.xml", tmp_path / "fog.usda", check_usd=False)
    assert any("camera sits in a medium" in w for w in res.warnings), res.warnings
