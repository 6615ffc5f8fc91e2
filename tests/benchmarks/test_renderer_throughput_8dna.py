"""The 8dna near-field throughput scene around a given asset (``--asset``): camera and lamp framed on the asset's box."""

import numpy as np
import pytest
import trimesh

from nasset_benchmarks.renderer_throughput import _eightdna_scene, main
from nasset_sdk.geometry import MeshGeometry
from nasset_sdk.kinds import get_kind


def _write(tmp_path, name, scale, offset):
    mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.5 * scale)
    mesh.apply_translation(offset)
    b = get_kind("8dna").build_random(np.random.default_rng(0), size="tiny", geometry=MeshGeometry.from_trimesh(mesh))
    return b.write(tmp_path / name)


def _layout(scene):
    (light,) = scene.lights
    return scene.camera.to_world[3, :3], light.c, light.r


def test_the_example_given_as_a_file_keeps_the_example_layout(tmp_path):
    own = _layout(_eightdna_scene("tiny"))
    given = _layout(_eightdna_scene("tiny", _write(tmp_path, "e.usdc", 1.0, (0, 0, 0))))
    for a, b in zip(own, given, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6, atol=1e-6)


def test_a_smaller_offset_asset_is_framed_on_its_box(tmp_path):
    """A box 0.4x the example's, moved: camera and lamp keep their place relative to it, scaled."""
    cam0, light0, r0 = _layout(_eightdna_scene("tiny"))
    offset = np.array([2.0, -1.0, 0.5])
    cam, light, r = _layout(_eightdna_scene("tiny", _write(tmp_path, "s.usdc", 0.4, offset)))
    np.testing.assert_allclose(cam - offset, 0.4 * cam0, rtol=2e-3)
    np.testing.assert_allclose(light - offset, 0.4 * light0, rtol=2e-3)
    assert r == pytest.approx(0.4 * r0, rel=2e-3)


@pytest.mark.parametrize("argv", [["--scene", "8dna-near", "--asset", "missing.usdc"], ["--asset", "x.usdc"]])
def test_asset_option_usage_errors(argv, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2 and "--asset" in capsys.readouterr().err
