"""Mesh lights (spec/renderer.md#mesh-lights): small emissive meshes are light-sampled with MIS."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from nasset_reference_renderer import RenderSettings, load_scene, render
from nasset_reference_renderer.lights import MeshLight
from nasset_reference_renderer.testscenes import SceneBuilder, constant_rna_asset
from nasset_sdk.examples import example_builder
from nasset_sdk.networks import mlp_onnx
from tests.stats import stat_seed

PANEL = np.array([[-0.4, 1.0, -0.4], [0.4, 1.0, -0.4], [0.4, 1.0, 0.4], [-0.4, 1.0, 0.4]])


def test_sample_pdf_matches_pdf_and_integrates_irradiance():
    tri = PANEL[[[0, 1, 2], [0, 2, 3]]]  # normal -Y (down)
    light = MeshLight(tri, [1.0, 1.0, 1.0], back_radiance=[0.0, 0.0, 0.0], instance=0)
    rng = np.random.default_rng(stat_seed(21))
    p = np.tile([0.1, 0.0, 0.2], (200_000, 1))
    wi, _, li, pdf = light.sample(p, rng.random((len(p), 2)))
    np.testing.assert_allclose(light.pdf(p, wi), pdf, rtol=1e-9)
    # irradiance at p by light sampling vs a midpoint quadrature over the square (unit radiance)
    e_mc = np.mean(li[:, 0] * wi[:, 1] / pdf)
    xs = (np.arange(600) + 0.5) / 600 * 0.8 - 0.4
    x, z = np.meshgrid(xs, xs)
    v = np.stack([x - 0.1, np.ones_like(x), z - 0.2], -1).reshape(-1, 3)
    d2 = (v * v).sum(1)
    e_q = np.sum(v[:, 1] ** 2 / d2 ** 2) * (0.8 / 600) ** 2
    assert abs(e_mc / e_q - 1) < 0.01
    # one-sided: nothing toward its back
    _, _, li_b, pdf_b = light.sample(np.tile([0.0, 2.0, 0.0], (100, 1)), rng.random((100, 2)))
    assert not li_b.any() and not pdf_b.any()


def _scene(tmp_path, one_sided, *, left_handed=False, back_emission=None):
    from pxr import UsdGeom

    b = SceneBuilder()
    b.camera((0, 0.5, 0.001), (0, 0, 0), focal=400)  # a small patch of floor under the panel
    b.quad("Floor", (0, 0, 0), 10.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    panel = b.mesh("Panel", PANEL, [[0, 1, 2, 3]], diffuse=(0, 0, 0), emission=(1, 1, 1), specular=(0, 0, 0))
    if one_sided is not None:
        panel.CreateDoubleSidedAttr(not one_sided)
    if left_handed:
        panel.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    if back_emission is not None:
        back = b.material("PanelBack", diffuse=(0, 0, 0), emission=back_emission, specular=(0, 0, 0))
        panel.GetPrim().CreateRelationship("nasset:backMaterial", custom=True).SetTargets([back.GetPath()])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return load_scene(b.write(tmp_path / "s.usda"))


def _floor_under_panel() -> float:
    """kd / pi * E at the origin under the unit-radiance panel (midpoint quadrature)."""
    xs = (np.arange(800) + 0.5) / 800 * 0.8 - 0.4
    x, z = np.meshgrid(xs, xs)
    return 0.5 / np.pi * np.sum(1.0 / (x * x + 1.0 + z * z) ** 2) * (0.8 / 800) ** 2


def test_mesh_light_direct_and_mis_match_the_analytic_irradiance(tmp_path):
    expect = _floor_under_panel()
    scene = _scene(tmp_path, None)
    assert [type(light).__name__ for light in scene.lights] == ["MeshLight"]
    for depth in (1, 2):  # 1: light samples only; 2: light samples and BSDF hits, MIS-weighted
        r = render(scene, RenderSettings(spp=64, width=4, height=4, max_depth=depth, seed=depth))
        se = np.sqrt(r.variance.mean() / 16)
        assert abs(r.image.mean() - expect) < 5 * se + 2e-4, (depth, r.image.mean(), expect, se)


def test_one_sided_mesh_light_emits_from_its_front_only(tmp_path):
    scene = _scene(tmp_path, True)  # the panel faces down: the floor is lit
    assert render(scene, RenderSettings(spp=4, width=4, height=4, max_depth=2)).image.mean() > 0.05
    flipped = _scene(tmp_path, True, left_handed=True)  # its front now faces up, away from the floor
    for depth in (1, 2):  # light samples; light samples and BSDF hits on the panel's back
        assert render(flipped, RenderSettings(spp=4, width=4, height=4, max_depth=depth)).image.mean() == 0.0


@pytest.mark.parametrize("back_emission, lit", [((0, 0, 0), False), ((2, 2, 2), True)])
def test_back_material_decides_what_the_back_of_an_emitter_emits(tmp_path, back_emission, lit):
    """A panel whose front faces up (away from the floor) with a ``nasset:backMaterial``: the floor gets the back
    material's emission, by light samples and by BSDF hits (an area emitter on a twosided Mitsuba BSDF emits from
    its front only: the converter gives it a back material without emission). Before, the back emitted the front
    material's emission whatever the back material said."""
    scene = _scene(tmp_path, None, left_handed=True, back_emission=back_emission)
    for depth in (1, 2):
        r = render(scene, RenderSettings(spp=16, width=4, height=4, max_depth=depth, seed=depth))
        if lit:
            expect, se = 2.0 * _floor_under_panel(), np.sqrt(r.variance.mean() / 16)
            assert abs(r.image.mean() - expect) < 5 * se + 2e-4, (depth, r.image.mean(), expect, se)
        else:
            assert r.image.mean() == 0.0, (depth, r.image.mean())


def test_mesh_light_reaches_a_floor_point_at_a_grazing_angle(tmp_path):
    """Light samples toward the panel from 3 m aside (cos 0.32 at the panel): shadow rays leave the offset origin
    and must not be stopped by the emitting panel itself (spec/renderer.md#ray-offsets). Before they were aimed at
    the light sample, this point was lit by MIS-weighted BSDF hits only (a few per cent of its irradiance)."""
    xs = (np.arange(800) + 0.5) / 800 * 0.8 - 0.4
    x, z = np.meshgrid(xs, xs)
    expect = 0.5 / np.pi * np.sum(1.0 / ((x - 3.0) ** 2 + 1.0 + z * z) ** 2) * (0.8 / 800) ** 2
    b = SceneBuilder()
    b.camera((3.0, 0.5, 0.01), (3.0, 0.0, 0.0), focal=400.0)  # a ~1.3 cm footprint on the floor
    b.quad("Floor", (0, 0, 0), 10.0, diffuse=(0.5, 0.5, 0.5), specular=(0, 0, 0), roughness=1.0)
    b.mesh("Panel", PANEL, [[0, 1, 2, 3]], diffuse=(0, 0, 0), emission=(1, 1, 1), specular=(0, 0, 0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(b.write(tmp_path / "s.usda"))
    r = render(scene, RenderSettings(spp=64, width=4, height=4, max_depth=1, seed=stat_seed(4)))
    se = np.sqrt(r.variance.mean() / 16)
    assert abs(r.image.mean() - expect) < 5 * se + 0.01 * expect, (r.image.mean(), expect, se)



def _neural_asset(kind, tmp_path):
    if kind == "rna":
        return constant_rna_asset(tmp_path / "a.usda", unshadowed=(1.0, 1.0, 1.0), shadowed=(0.0, 0.0, 0.0))
    b = example_builder(kind, size="tiny", seed=3)
    if kind == "8dna":  # only a rough direct lobe (GGX alpha 1; zero albedo), lit by the grazing panel from above
        core = b.components["core"][""]
        c = core.tensors["triplane"][0].shape[-1]
        core.add_network("albedo", mlp_onnx([np.zeros((2 * c + 6, 3), np.float32)], [np.zeros(3, np.float32)]))
        core.add_tensor("direct", np.array([1.5, 1.0]), dtype="float32", layout="parameter")
    return b.write(tmp_path / "a.usdc")


@pytest.mark.parametrize("kind, sampling", [("rna", {}), ("neupress", {"neupress_sampling": "dome"}),
                                            ("8dna", {"eightdna_sampling": "light"})])
def test_neural_asset_lit_by_a_grazing_mesh_light_matches_the_same_rect_light(tmp_path, kind, sampling):
    """The neural shaders' shadow rays toward an emitting mesh are aimed like a mesh vertex's
    (spec/renderer.md#ray-offsets): the top of an asset (y = 0.5) lit by a panel 4 m aside and 0.5 m higher (cos 0.12
    at the panel) gets the same light as from a RectLight of the same size and radiance (light surfaces never
    occlude). Along the sampled direction from the offset origin the panel shadowed itself: the image was black.
    Light sampling only (depth 1; neupress dome mode, 8dna light mode), where each shader traces its shadow rays."""
    asset = _neural_asset(kind, tmp_path)
    means = {}
    for light in ("mesh", "rect"):
        b = SceneBuilder()
        b.camera((0.0, 3.0, 0.01), (0.0, 0.0, 0.0), focal=400.0)  # only the top of the asset
        b.asset("Obj", asset)
        if light == "mesh":
            b.mesh("Panel", PANEL + [4.0, 0.0, 0.0], [[0, 1, 2, 3]], diffuse=(0, 0, 0), emission=(1, 1, 1),
                   specular=(0, 0, 0))
        else:
            b.rect_light("Panel", (4.0, 1.0, 0.0), 0.8, 0.8, (0, -1, 0), 1.0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            scene = load_scene(b.write(tmp_path / f"{light}.usda"))
        r = render(scene, RenderSettings(spp=64, width=4, height=4, max_depth=1, seed=stat_seed(5), **sampling))
        means[light] = (r.image.mean(), np.sqrt(r.variance.mean() / 16))
    (m, se_m), (q, se_q) = means["mesh"], means["rect"]
    assert q > 10 * se_q, means  # lit, measurably
    assert abs(m - q) < 5 * np.hypot(se_m, se_q) + 0.01 * q, means
