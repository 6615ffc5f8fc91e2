"""The scene integrator's depth as every consumer reads it: Mitsuba stores max_depth unsigned, so its default -1
(unbounded) comes back as 2^32 - 1 and must be read as -1, not passed on as a depth of four billion."""

import pytest

pytest.importorskip("mitsuba")


@pytest.fixture(scope="module")
def mi():
    from nasset_converters.mitsuba import load_mitsuba

    return load_mitsuba()


def _integrator(mi, xml: str):
    return mi.load_string(f'<scene version="3.0.0">{xml}<shape type="sphere"/></scene>').integrator()


@pytest.mark.parametrize("xml, want", [
    ('<integrator type="volpath"/>', {"max_depth": -1, "rr_depth": 5}),  # Mitsuba's defaults: unbounded
    ('<integrator type="path"><integer name="max_depth" value="-1"/></integrator>', {"max_depth": -1, "rr_depth": 5}),
    ('<integrator type="path"><integer name="max_depth" value="7"/><integer name="rr_depth" value="3"/></integrator>',
     {"max_depth": 7, "rr_depth": 3}),
    ('<integrator type="direct"/>', {"max_depth": 2}),  # no depth setting: emitters in view + direct light, 2 segments
    ("", {}),  # no integrator
])
def test_integrator_depths(mi, xml, want):
    from nasset_converters.mitsuba.scene import integrator_depths

    assert str(_integrator(mi, '<integrator type="volpath"/>')).count("4294967295") == 1  # the premise: -1 prints unsigned
    assert integrator_depths(_integrator(mi, xml)) == want


@pytest.mark.parametrize("xml, preset, want", [
    ('<integrator type="volpath"/>', 64, 1024),  # unbounded: the bake's unbounded depth, not 2^32 - 1
    ('<integrator type="volpath"><integer name="max_depth" value="128"/></integrator>', 64, 128),  # deeper than the preset
    ('<integrator type="volpath"><integer name="max_depth" value="8"/></integrator>', 64, 64),  # never shallower
    ('<integrator type="direct"/>', 64, 64),
    ("", 24, 24),
])
def test_training_depth(mi, xml, preset, want):
    from nasset_converters.mitsuba.scene import UNBOUNDED_DEPTH, training_depth

    assert UNBOUNDED_DEPTH == 1024
    assert training_depth(_integrator(mi, xml), preset) == want


def test_unbounded_scene_renders_training_views(mi):
    """The isolated-asset integrator built at that depth loads (it used to fail in Mitsuba's parser on 2^32 - 1)."""
    import numpy as np

    from nasset_converters.mitsuba import scene as msc

    scene = mi.load_string('<scene version="3.0.0"><integrator type="volpath"/>'
                           '<shape type="sphere" id="ball"><bsdf type="diffuse"/></shape></scene>')
    shapes = msc.pick_shapes(scene, ["ball"])
    depth = msc.training_depth(scene.integrator(), 64)
    iso = msc.IsolatedAsset(mi, shapes, np.zeros(3), 1.0, max_depth=depth)
    assert iso.integrator is not None
