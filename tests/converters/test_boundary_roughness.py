"""The boundary the neupress and 8dna formats store is one GGX lobe with one isotropic constant alpha. Both bakes read
it through ``scene.ggx_dielectric``: an anisotropic roughness used to be baked by 8dna as its first alpha, silently, and
a textured one stopped the 8dna bake with a TypeError. Both are now CONVERT_SHAPE_UNSUPPORTED with a message that
names the shape and the roughness it has."""

import pytest

pytest.importorskip("mitsuba")

MEDIUM = '<medium type="homogeneous" name="interior"><rgb name="albedo" value="0.9"/><float name="sigma_t" value="5"/></medium>'
GGX = '<string name="distribution" value="ggx"/>'


@pytest.fixture(scope="module")
def mi():
    from nasset_converters.mitsuba import load_mitsuba

    m = load_mitsuba()
    m.set_log_level(m.LogLevel.Error)
    return m


def _readers():
    from nasset_bakers.mitsuba.eightdna import boundary_of as eightdna_boundary
    from nasset_converters.mitsuba.neupress_dataset import boundary_of as neupress_boundary

    return {"8dna": lambda mi, shapes: eightdna_boundary(mi, shapes),
            "neupress": lambda mi, shapes: neupress_boundary(mi, shapes)[1:]}


def _shapes(mi, bsdf: str):
    from nasset_converters.mitsuba.scene import pick_shapes

    scene = mi.load_string(f'<scene version="3.0.0"><shape type="sphere" id="ball">{bsdf}{MEDIUM}</shape></scene>')
    return pick_shapes(scene, ["ball"])


@pytest.mark.parametrize("kind", ["8dna", "neupress"])
@pytest.mark.parametrize("roughness, names", [
    ('<float name="alpha_u" value="0.1"/><float name="alpha_v" value="0.3"/>', "alpha_u"),
    ('<texture type="checkerboard" name="alpha"/>', "alpha"),
])
def test_anisotropic_or_textured_roughness_is_refused(mi, kind, roughness, names):
    from nasset_sdk.errors import NassetError

    shapes = _shapes(mi, f'<bsdf type="roughdielectric">{GGX}{roughness}</bsdf>')
    with pytest.raises(NassetError) as ei:
        _readers()[kind](mi, shapes)
    assert ei.value.code == "CONVERT_SHAPE_UNSUPPORTED"
    assert "'ball'" in str(ei.value) and "isotropic constant alpha" in str(ei.value) and names in str(ei.value)


@pytest.mark.parametrize("kind", ["8dna", "neupress"])
def test_constant_ggx_roughness_is_read(mi, kind):
    shapes = _shapes(mi, f'<bsdf type="roughdielectric">{GGX}<float name="alpha" value="0.27"/>'
                         '<float name="int_ior" value="1.45"/></bsdf>')
    eta, alpha = _readers()[kind](mi, shapes)
    assert abs(alpha - 0.27) < 1e-6 and abs(eta - 1.45 / 1.000277) < 1e-4
