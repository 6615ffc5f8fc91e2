"""A hand-written stage may give a schema attribute another type (``string inputs:intensity = "x"``): USD reads it,
and the renderer must answer with SCENE_INVALID naming the prim, not a Python traceback (spec/renderer.md#limits)."""

from __future__ import annotations

import warnings

import pytest

from nasset_reference_renderer import load_scene
from nasset_sdk.errors import SceneError

CAMERA = """    def Camera "Camera"
    {{
        {camera}
        matrix4d xformOp:transform = ( (1, 0, 0, 0), (0, 1, 0, 0), (0, 0, 1, 0), (0, 0, 3, 1) )
        uniform token[] xformOpOrder = ["xformOp:transform"]
    }}
"""


@pytest.mark.parametrize("prim, body, camera", [
    ("/World/L", ('SphereLight "L"', ['string inputs:intensity = "x"']), ""),
    ("/World/L", ('DiskLight "L"', ['string inputs:radius = "wide"']), ""),
    ("/World/L", ('DistantLight "L"', ['string inputs:color = "red"']), ""),
    ("/World/Ball", ('Sphere "Ball"', ['string radius = "big"']), ""),
    ("/World/M", ('Mesh "M"', ["int[] faceVertexCounts = [3]", "int[] faceVertexIndices = [0, 1, 2]",
                               "point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]", 'string[] holeIndices = ["a"]']), ""),
    ("/World/Camera", None, 'string focalLength = "x"'),
])
def test_a_value_of_the_wrong_type_is_a_scene_error_naming_its_prim(tmp_path, prim, body, camera):
    extra = "" if body is None else (f"    def {body[0]}\n    {{\n" + "".join(f"        {a}\n" for a in body[1]) + "    }\n")
    text = '#usda 1.0\n(\n    defaultPrim = "World"\n)\n\ndef Xform "World"\n{\n' + CAMERA.format(camera=camera) + extra + "}\n"
    path = tmp_path / "s.usda"
    path.write_text(text)
    with pytest.raises(SceneError) as exc, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        load_scene(str(path))
    assert exc.value.code == "SCENE_INVALID" and exc.value.prim == prim, str(exc.value)
