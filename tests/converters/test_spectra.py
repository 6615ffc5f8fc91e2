"""Spectra Mitsuba's RGB variants cannot evaluate (spec/bake.md, Lights): a ``blackbody`` radiance converts to the RGB
a spectral render records. Before, it converted to intensity 0 without a word (and the RGB variant the converter
loads cannot render the scene at all)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from nasset_converters.mitsuba import load_mitsuba  # noqa: E402
from nasset_converters.mitsuba.usd_export import blackbody_rgb, convert_scene, tabulated_rgb  # noqa: E402

SPECTRAL_RENDER = """
import json, sys, numpy as np, mitsuba as mi
mi.set_variant("scalar_spectral")
sc = mi.load_dict({"type": "scene", "integrator": {"type": "path"},
    "sensor": {"type": "perspective", "fov": 5, "to_world": mi.ScalarTransform4f().look_at([0, 0, 3], [0, 0, 0], [0, 1, 0]),
               "film": {"type": "hdrfilm", "width": 2, "height": 2, "rfilter": {"type": "box"}}},
    "lamp": {"type": "rectangle", "emitter": {"type": "area", "radiance": json.loads(sys.argv[1])}}})
print(json.dumps(np.asarray(mi.render(sc, spp=2048)).reshape(-1, 3).mean(0).tolist()))
"""


@pytest.mark.parametrize("kelvin", [2500.0, 6000.0])
def test_blackbody_rgb_is_what_a_spectral_render_records(kelvin):
    """The emitter seen head-on by Mitsuba's scalar_spectral variant (its own spectral sampling and film) against
    Planck's law integrated with Mitsuba's CIE table: within 2 % per channel (the render's colour noise)."""
    spectrum = json.dumps({"type": "blackbody", "temperature": kelvin})
    out = subprocess.run([sys.executable, "-c", SPECTRAL_RENDER, spectrum], capture_output=True, text=True, check=True)
    render = np.array(json.loads(out.stdout.strip().splitlines()[-1]))
    np.testing.assert_allclose(blackbody_rgb(load_mitsuba(), kelvin), render, rtol=0.02)


TABULATED = {"irregular": {"type": "irregular", "wavelengths": "420, 480, 560, 610, 690", "values": "2, 6, 3, 9, 4"},
             "regular": {"type": "regular", "wavelength_min": 450, "wavelength_max": 650, "values": "8, 1, 5"}}


@pytest.mark.parametrize("kind", list(TABULATED))
def test_tabulated_emission_rgb_is_what_a_spectral_render_records(kind):
    """``irregular`` and ``regular`` emission spectra (which Mitsuba's RGB variants cannot render either): linear
    between the nodes, 0 outside them, through the CIE table, within 2 % of a scalar_spectral render."""
    spec = TABULATED[kind]
    out = subprocess.run([sys.executable, "-c", SPECTRAL_RENDER, json.dumps(spec)], capture_output=True, text=True,
                         check=True)
    render = np.array(json.loads(out.stdout.strip().splitlines()[-1]))
    values = np.array([float(v) for v in spec["values"].split(",")])
    nodes = (np.array([float(v) for v in spec["wavelengths"].split(",")]) if kind == "irregular"
             else np.linspace(spec["wavelength_min"], spec["wavelength_max"], len(values)))
    np.testing.assert_allclose(tabulated_rgb(load_mitsuba(), nodes, values), render, rtol=0.02, atol=0.01 * render.max())


def test_tabulated_light_spectra_convert_to_their_rgb(tmp_path):
    """A point light's ``irregular`` intensity and a sun's ``regular`` irradiance were written as 0 (warned): dark."""
    from pxr import Usd, UsdLux

    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><integrator type="path"/><sensor type="perspective"><float name="fov" '
                   'value="40"/><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>'
                   '</film></sensor><emitter type="point" id="bulb"><spectrum type="irregular" name="intensity"><string '
                   'name="wavelengths" value="400, 500, 600, 700"/><string name="values" value="5, 8, 10, 12"/></spectrum>'
                   '</emitter><emitter type="directional" id="sun"><spectrum type="regular" name="irradiance"><float '
                   'name="wavelength_min" value="400"/><float name="wavelength_max" value="700"/><string name="values" '
                   'value="1, 2, 3"/></spectrum></emitter></scene>')
    res = convert_scene(xml, tmp_path / "o.usda", check_usd=False)
    assert not res.warnings
    stage = Usd.Stage.Open(str(res.output))
    mi = load_mitsuba()
    for path, want in (("/World/Lights/bulb", tabulated_rgb(mi, [400, 500, 600, 700], [5, 8, 10, 12])),
                       ("/World/Lights/sun", tabulated_rgb(mi, [400, 550, 700], [1, 2, 3]))):
        light = UsdLux.LightAPI(stage.GetPrimAtPath(path))
        rgb = light.GetIntensityAttr().Get() * np.array(light.GetColorAttr().Get())
        np.testing.assert_allclose(rgb, want, rtol=1e-5)
        assert rgb.min() > 0.5


def test_blackbody_emitter_converts_to_its_rgb(tmp_path):
    from pxr import Usd, UsdLux

    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><integrator type="path"/><sensor type="perspective"><float name="fov" '
                   'value="40"/><transform name="to_world"><lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/>'
                   '</transform><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>'
                   '</film></sensor><shape type="rectangle" id="lamp"><transform name="to_world"><translate y="2"/>'
                   '</transform><emitter type="area"><spectrum type="blackbody" name="radiance"><float '
                   'name="temperature" value="3000"/></spectrum></emitter></shape></scene>')
    res = convert_scene(xml, tmp_path / "o.usda", check_usd=False)
    stage = Usd.Stage.Open(str(res.output))
    light = next(UsdLux.RectLight(p) for p in stage.Traverse() if p.GetTypeName() == "RectLight")
    rgb = light.GetIntensityAttr().Get() * np.array(light.GetColorAttr().Get())
    np.testing.assert_allclose(rgb, blackbody_rgb(load_mitsuba(), 3000.0), rtol=1e-5)
    assert rgb[0] > 700  # W / (m^2 sr nm) integrated: a 3000 K surface is bright


def test_parameters_the_converter_cannot_evaluate_are_warned(tmp_path):
    """A light's radiance (and a BSDF input) of a texture the reader knows nothing of (a ``mesh_attribute`` on an area
    emitter and on a conductor's specular reflectance) used to be written as the default without a word: a dark
    light. Now each is named in a warning."""
    from nasset_converters.mitsuba.examples import write_ply

    write_ply(tmp_path / "m.ply", np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]], np.int64))
    xml = tmp_path / "s.xml"
    xml.write_text('<scene version="3.0.0"><integrator type="path"/><sensor type="perspective"><float name="fov" '
                   'value="40"/><transform name="to_world"><lookat origin="0, 1, 4" target="0, 0, 0" up="0, 1, 0"/>'
                   '</transform><film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/>'
                   '</film></sensor><shape type="ply" id="m"><string name="filename" value="m.ply"/><bsdf '
                   'type="roughconductor"><texture type="mesh_attribute" name="specular_reflectance"><string name="name" '
                   'value="vertex_color"/></texture></bsdf></shape><shape type="rectangle" id="lamp"><emitter type="area">'
                   '<texture type="mesh_attribute" name="radiance"><string name="name" value="vertex_color"/></texture>'
                   '</emitter></shape></scene>')
    text = "\n".join(convert_scene(xml, tmp_path / "o.usda", check_usd=False).warnings)
    assert "shape lamp: radiance is a texture or spectrum the converter cannot evaluate" in text
    assert "RoughConductor.specular_reflectance is a texture the converter cannot evaluate" in text
