"""Generate the renderer conformance cases in nasset_sdk/conformance_cases/ (spec/conformance.md).

    python tests/conformance/make_cases.py                  # (re)generate every case
    python tests/conformance/make_cases.py --cases NAME ..  # only these
    python tests/conformance/make_cases.py --check          # verify the committed files

Each case directory holds ``scene.usda`` (camera, lights, plain meshes, NeuralAsset prims that
reference assets by relative path), the asset files it uses, ``reference.exr`` (the reference
renderer at ``ref_spp``) and ``case.json`` (what to render, the metric, the tolerance and how it
was measured). Everything but the reference image and the measured numbers is a deterministic
function of this script; ``--check`` compares those bytes exactly, and checks the reference image
statistically: a fresh render at the case's spp with an unused seed must be within tolerance.

The tolerance of a case comes from measured Monte Carlo noise: the case is rendered ``NOISE_RUNS``
times at its test spp with seeds 1..NOISE_RUNS, the metric of each image against the reference is
recorded, and ``tolerance = TOL_FACTOR * max(max(e), mean(e) + 3 std(e))``; ``bias_tolerance`` is
derived the same way from the same renders' mean brightness bias (``nasset_sdk.conformance.mean_bias``).

Adding a case is one entry in ``CASES``. Entries with ``pending=True`` use a kind or variant the
reference renderer may not render yet: they are generated only when it accepts the scene.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from nasset_sdk.conformance import CASES_DIR

REF_SEED = 1_000_003  # reference image seed; never used by the noise runs (1..NOISE_RUNS) or tests (0, 9xx)
NOISE_RUNS = 8
TOL_FACTOR = 2.0
CHECK_SEED = 977
STATIC_KEYS = ("description", "spp", "width", "height", "metric", "block", "needs", "kinds", "ref_spp", "max_depth", "files")


# -- matrices (row-vector convention: p_world = p @ M) ---------------------------------------
def translate(x, y, z):
    m = np.eye(4)
    m[3, :3] = (x, y, z)
    return m


def scale(sx, sy, sz):
    return np.diag([float(sx), float(sy), float(sz), 1.0])


def rotate(axis, degrees):
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    t = np.radians(degrees)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    r_col = np.eye(3) + np.sin(t) * k + (1 - np.cos(t)) * (k @ k)  # column-vector rotation
    m = np.eye(4)
    m[:3, :3] = r_col.T
    return m


def chain(*ms):
    """Apply the matrices left to right (the first one is applied to the point first)."""
    out = np.eye(4)
    for m in ms:
        out = out @ m
    return out


# -- assets --------------------------------------------------------------------------------
def _rna_random(seed, *, dtype="float16", variant="surface", curves=None, h_gain=1.0):
    """Builder of a tiny rna asset with random networks (triplane stored as ``dtype``); variant
    ``fiber`` uses ``curves`` (default :func:`_fiber_curves`) as its geometry, and its first layer's
    weights of the cross-fibre offset h are multiplied by ``h_gain``.

    The decoder is a random 2 x 16 ReLU MLP whose last layer is scaled so that transports stay
    in a plausible range (about 0.05 to 0.3 / sr, shadowed darker than unshadowed) while still
    varying with position (triplane), normal and both directions.
    """
    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.kinds.rna import example_mesh
    from nasset_sdk.networks import mlp_onnx

    rng = np.random.default_rng(seed)
    b = AssetBuilder("rna", variant=variant)
    b.set_geometry((curves or _fiber_curves()) if variant == "fiber" else example_mesh())
    core = b.component("core", required=True, purpose="evaluation", quality=None)
    res, ch, hidden = 8, 4, 16
    core.add_tensor("triplane", rng.normal(0, 1.0, (3, res, res, ch)), dtype=dtype, layout="plane,v,u,channel")
    widths = [ch + (13 if variant == "fiber" else 12), hidden, hidden, 6]
    ws = [rng.normal(0.0, np.sqrt(2.0 / a), (a, o)) for a, o in zip(widths[:-1], widths[1:], strict=True)]
    bs = [rng.normal(0.0, 0.05, o) for o in widths[1:]]
    if variant == "fiber":
        ws[0][ch + 6] *= h_gain  # input column of h (nasset_sdk.kinds.rna)
    ws[-1] *= 0.05
    bs[-1] = np.array([0.16, 0.12, 0.08, 0.05, 0.05, 0.07]) + bs[-1] * 0.2
    core.add_network("decoder", mlp_onnx([w.astype(np.float32) for w in ws], [x.astype(np.float32) for x in bs]))
    b.provenance = {"generator": "random", "size": "tiny", "seed": int(seed)}
    return b


def _fiber_curves():
    """A tuft of 14 wavy, tapered linear curves (6 segments each) standing on y = -0.5, 0.5 high."""
    from nasset_sdk.geometry import CurvesGeometry

    rng = np.random.default_rng(7)
    n, seg = 14, 6
    roots = rng.uniform(-0.35, 0.35, (n, 3)) * [1, 0, 1] + [0.0, -0.5, 0.0]
    phase = rng.uniform(0, 2 * np.pi, n)[:, None, None]
    t = np.linspace(0, 1, seg + 1)[None, :, None]
    sway = 0.12 * t * np.concatenate([np.sin(5 * t + phase), 0 * phase + 0 * t, np.cos(4 * t + phase)], 2)
    pts = (roots[:, None, :] + t * np.array([0.0, 1.0, 0.0]) + sway).reshape(-1, 3).astype(np.float32)
    widths = np.tile(np.linspace(0.07, 0.035, seg + 1), n).astype(np.float32)
    return CurvesGeometry(pts, np.full(n, seg + 1, np.int32), widths)


def asset_rand(path):
    return _rna_random(11).write(path)


def asset_rand_fp32(path):
    return _rna_random(11, dtype="float32").write(path)


def asset_rand_near_field(path):
    """The asset of rna_point_light with nasset:nearFieldFetch = 0.5 (format 0.3, spec/kinds/rna.md#near-field-fetch)."""
    b = _rna_random(11)
    b.near_field_fetch = 0.5
    return b.write(path)


def asset_neupress_near_field(path):
    """The asset of the neupress cases with nasset:nearFieldFetch = 0.5 (format 0.3, kinds/neupress.md#near-field-fetch)."""
    from nasset_sdk.examples import example_builder

    b = example_builder("neupress", size="tiny", seed=5)
    b.near_field_fetch = 0.5
    return b.write(path)


def asset_fiber(path):
    return _rna_random(13, variant="fiber").write(path)


def asset_fiber_h(path):
    """The fiber asset of rna_fiber_distant with a decoder that depends strongly on h (gain 8)."""
    return _rna_random(13, variant="fiber", h_gain=8.0).write(path)


def asset_fiber_dense(path):
    """1200 strands of 3 segments packed around a small sphere: rays cross tens of fibres."""
    from nasset_reference_renderer.testscenes import dense_hair_curves

    curves = dense_hair_curves(1200, 3, seed=5, radius=0.12, length=0.35, width=0.012)
    return _rna_random(17, variant="fiber", curves=curves).write(path)


def asset_const(path):
    from nasset_reference_renderer.testscenes import constant_rna_asset

    return constant_rna_asset(path, unshadowed=(0.30, 0.22, 0.12), shadowed=(0.05, 0.08, 0.11), subdivisions=2)


def asset_quality(path):
    """rna asset whose core has quality variants 'small' (default) and 'hq' (different networks)."""
    b = _rna_random(21)
    other = _rna_random(22)
    b.components["core"] = {"small": b.components.pop("core")[""], "hq": other.components["core"][""]}
    b.default_quality["core"] = "small"
    return b.write(path)


def asset_example(kind, variant="surface", seed=5):
    """Factory for the SDK's random example asset of another kind (tiny preset)."""

    def make(path):
        from nasset_sdk.examples import example_builder

        return example_builder(kind, variant=variant, size="tiny", seed=seed).write(path)

    return make


ASSETS: dict[str, Callable] = {
    "rna_rand.usdc": asset_rand,
    "rna_rand_fp32.usdc": asset_rand_fp32,
    "rna_rand_near_field.usdc": asset_rand_near_field,
    "rna_const.usdc": asset_const,
    "rna_fiber.usdc": asset_fiber,
    "rna_fiber_dense.usdc": asset_fiber_dense,
    "rna_fiber_h.usdc": asset_fiber_h,
    "rna_quality.usdc": asset_quality,
    "neupress.usdc": asset_example("neupress"),
    "8dna.usdc": asset_example("8dna"),
    "neupress_near_field.usdc": asset_neupress_near_field,
}


def env_map(path):
    """A small asymmetric lat-long EXR: blue-ish sky gradient, warm ground, one bright 'sun' patch."""
    from nasset_reference_renderer.film import write_exr

    h, w = 16, 32
    v = (np.arange(h) + 0.5) / h
    u = (np.arange(w) + 0.5) / w
    img = np.zeros((h, w, 3))
    sky = v < 0.5
    img[sky] = np.array([0.25, 0.35, 0.6]) * (1.2 - v[sky][:, None, None].mean())
    img[~sky] = [0.20, 0.12, 0.06]
    img += 0.15 * np.sin(2 * np.pi * u)[None, :, None] * np.array([1.0, 0.6, 0.2])  # azimuthal variation
    img = np.maximum(img, 0.0)
    img[3:5, 6:8] = [40.0, 32.0, 20.0]
    write_exr(path, img)


# -- scene building --------------------------------------------------------------------------
class Ctx:
    """What a case's ``build`` function gets: the SceneBuilder and helpers that copy assets in."""

    def __init__(self, folder: Path) -> None:
        from nasset_reference_renderer.testscenes import SceneBuilder

        self.dir = folder
        self.sb = SceneBuilder()
        self.files: list[str] = []

    def world(self, matrix):
        """Transform of /World (everything in the scene inherits it)."""
        self.sb._xform(self.sb.stage.GetPrimAtPath("/World"), matrix)

    def asset_file(self, name):
        if name not in self.files:
            ASSETS[name](self.dir / name)
            self.files.append(name)
        return "./" + name

    def asset(self, prim_name, name, matrix=None, *, typed=True, payload=False):
        rel = self.asset_file(name)
        if not payload:
            return self.sb.asset(prim_name, rel, matrix, typed=typed)
        prim = self.sb.stage.DefinePrim(f"/World/{prim_name}", "NeuralAsset" if typed else "")
        prim.GetPayloads().AddPayload(rel)
        if matrix is not None:
            self.sb._xform(prim, matrix)
        return prim

    def floor(self, y=-0.5, size=6.0, **mat):
        mat.setdefault("diffuse", (0.55, 0.55, 0.55))
        return self.sb.quad("Floor", (0.0, y, 0.0), size, **mat)

    def camera(self, eye=(0.0, 1.0, 3.2), target=(0.0, 0.0, 0.0), focal=35.0):
        return self.sb.camera(eye, target, focal=focal)


@dataclass
class Case:
    name: str
    description: str
    build: Callable[[Ctx], None]
    spp: int = 64
    width: int = 48
    height: int = 48
    block: int = 4
    ref_spp: int = 2048
    max_depth: int = 5
    pending: bool = False  # kind/variant the reference renderer may not support yet
    tags: list = field(default_factory=list)


def _box(ctx, name, lo, hi, **mat):
    """Axis-aligned box mesh (an ordinary occluder)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    return ctx.sb.mesh(name, c, faces, **mat)


def b_distant(asset):
    def build(ctx):
        ctx.camera()
        ctx.floor()
        ctx.sb.distant("Sun", (0.5, 1.0, 0.35), 3.0)
        ctx.asset("Asset", asset)

    return build


def b_distant_angle(ctx):
    ctx.camera(eye=(0.3, 2.2, 3.0), target=(0.4, -0.2, 0.0))
    ctx.floor()
    ctx.sb.distant("Sun", (-0.7, 1.0, 0.25), 3.0, angle=30.0)
    ctx.asset("Asset", "rna_const.usdc", translate(0.0, 0.6, 0.0))


def b_sphere(ctx):
    ctx.camera()
    ctx.floor()
    ctx.sb.sphere_light("Bulb", (1.0, 1.4, 0.9), 0.3, 40.0, color=(1.0, 0.9, 0.8))
    ctx.asset("Asset", "rna_rand.usdc")


def b_point(ctx):
    from pxr import UsdLux

    ctx.camera()
    ctx.floor()
    lt = ctx.sb.sphere_light("Point", (-1.0, 1.3, 1.0), 0.0, 10.0)
    UsdLux.SphereLight(lt.GetPrim()).CreateTreatAsPointAttr(True)
    ctx.asset("Asset", "rna_rand.usdc")


def b_near_field(ctx):
    """A point light low beside the asset, 0.3 above the floor and about 0.4 from the asset's nearest side: its
    distance, direction and visibility differ between a hit and its fetch point; the floor around the asset is lit
    unevenly (its own shadow), so the continuations from p see another bounce than those from x."""
    from pxr import UsdLux

    ctx.camera()
    ctx.floor()
    lt = ctx.sb.sphere_light("Point", (0.9, -0.2, 0.7), 0.0, 3.0)
    UsdLux.SphereLight(lt.GetPrim()).CreateTreatAsPointAttr(True)
    ctx.asset("Asset", "rna_rand_near_field.usdc")


def b_neupress_near_field(ctx):
    """rna_near_field_fetch's light and floor around the neupress asset: the point light's distance, direction and
    visibility differ between a hit and its fetch point; the A samples (Gaussian lobe, MIS) leaving p see another
    bounce of the unevenly lit floor than those from x."""
    from pxr import UsdLux

    ctx.camera(eye=(0.0, 0.6, 2.2))
    ctx.floor()
    lt = ctx.sb.sphere_light("Point", (0.9, -0.2, 0.7), 0.0, 3.0)
    UsdLux.SphereLight(lt.GetPrim()).CreateTreatAsPointAttr(True)
    ctx.asset("Asset", "neupress_near_field.usdc")


def b_rect(ctx):
    ctx.camera()
    ctx.floor()
    ctx.sb.rect_light("Panel", (0.4, 1.8, 0.8), 1.2, 0.8, (-0.2, -1.0, -0.4), 8.0)
    ctx.asset("Asset", "rna_rand.usdc")


def b_dome(ctx):
    env_map(ctx.dir / "env.exr")
    ctx.files.append("env.exr")
    ctx.camera()
    ctx.floor(diffuse=(0.4, 0.4, 0.4))
    dome = ctx.sb.dome("Sky", 1.0, texture="./env.exr")
    ctx.sb._xform(dome.GetPrim(), rotate((0, 1, 0), 25.0))
    ctx.asset("Asset", "rna_rand.usdc")


def b_suns_and_dome(ctx):
    env_map(ctx.dir / "env.exr")
    ctx.files.append("env.exr")
    ctx.camera(eye=(0.3, 2.2, 3.0), target=(0.3, -0.2, 0.0))
    ctx.floor(diffuse=(0.4, 0.4, 0.4))
    ctx.sb.distant("Sun", (-0.7, 1.0, 0.25), 2.0, angle=12.0)
    ctx.sb.distant("LowSun", (0.9, 0.45, -0.3), 1.5, angle=30.0, color=(1.0, 0.8, 0.6))
    dome = ctx.sb.dome("Sky", 0.5, texture="./env.exr")
    ctx.sb._xform(dome.GetPrim(), rotate((0, 1, 0), -40.0))
    ctx.asset("Asset", "rna_rand.usdc", translate(0.0, 0.3, 0.0))


def _hide_from_camera(light):
    from pxr import Sdf

    light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool, custom=True).Set(False)


def b_hidden_lights(ctx):
    env_map(ctx.dir / "env.exr")
    ctx.files.append("env.exr")
    ctx.camera()
    ctx.floor()
    _hide_from_camera(ctx.sb.sphere_light("Bulb", (0.25, 0.15, 1.2), 0.25, 12.0, color=(1.0, 0.9, 0.8)))
    _hide_from_camera(ctx.sb.rect_light("Panel", (-0.9, 0.5, -0.6), 0.8, 0.5, (0.6, -0.2, 1.0), 6.0))
    _hide_from_camera(ctx.sb.dome("Sky", 0.6, texture="./env.exr"))
    ctx.sb.distant("Sun", (-0.5, 1.0, 0.3), 1.5, angle=10.0)
    ctx.asset("Asset", "rna_rand.usdc")


def b_many_lights(ctx):
    """28 small SphereLights hidden from the camera and 12 point lights around the asset (both kinds beyond the
    reference renderer's 8 light draws per vertex, spec/renderer.md#light-selection), powers over 30x, on a floor."""
    rng = np.random.default_rng(40)
    ctx.camera()
    ctx.floor()
    for i in range(28):
        p = (rng.uniform(-1.6, 1.6), rng.uniform(-0.3, 1.4), rng.uniform(-1.6, 1.0))
        _hide_from_camera(ctx.sb.sphere_light(f"Bulb{i}", p, rng.uniform(0.04, 0.1), 10 ** rng.uniform(0.3, 1.8),
                                              color=tuple(rng.uniform(0.4, 1.0, 3))))
    for i in range(12):
        p = (rng.uniform(-1.6, 1.6), rng.uniform(-0.2, 1.4), rng.uniform(-1.6, 1.0))
        ctx.sb.sphere_light(f"Point{i}", p, 0.0, 10 ** rng.uniform(-0.8, 0.6), color=tuple(rng.uniform(0.4, 1.0, 3)))
    ctx.asset("Asset", "rna_rand.usdc")


def _spot(ctx, name, position, aim, intensity, cone, softness, profile, color=(1, 1, 1)):
    """A point light (radius 0) with UsdLux.ShapingAPI aimed along ``aim`` (its local -Z)."""
    from pxr import Gf, Sdf, UsdGeom, UsdLux

    from nasset_reference_renderer.testscenes import _frame_matrix

    lt = ctx.sb.sphere_light(name, position, 0.0, intensity, color=color)
    m = _frame_matrix(-np.asarray(aim, np.float64), position)
    UsdGeom.Xformable(lt.GetPrim()).GetOrderedXformOps()[0].Set(Gf.Matrix4d(*np.asarray(m, np.float64).ravel().tolist()))
    api = UsdLux.ShapingAPI.Apply(lt.GetPrim())
    api.CreateShapingConeAngleAttr(float(cone))
    api.CreateShapingConeSoftnessAttr(float(softness))
    lt.GetPrim().CreateAttribute("nasset:shaping:falloff", Sdf.ValueTypeNames.Token, custom=True).Set(profile)
    return lt


def b_spot_lights(ctx):
    ctx.camera()
    ctx.floor()
    _spot(ctx, "Spot", (0.6, 1.5, 0.6), (-0.45, -1.0, -0.4), 25.0, 30.0, 0.4, "linear", color=(1.0, 0.9, 0.8))
    _spot(ctx, "Blender", (-1.0, 1.2, 0.2), (0.8, -1.0, -0.1), 15.0, 20.0, 0.3, "smoothstep", color=(0.7, 0.8, 1.0))
    ctx.asset("Asset", "rna_rand.usdc")


def _microfacet(ctx, mesh_name, value):
    """Set ``nasset:microfacet`` on the UsdPreviewSurface of the material ``ctx.sb.mesh`` made for ``mesh_name``."""
    from pxr import Sdf

    shader = ctx.sb.stage.GetPrimAtPath(f"/World/Looks/{mesh_name}Mat/PreviewSurface")
    shader.CreateAttribute("nasset:microfacet", Sdf.ValueTypeNames.Token, custom=True).Set(value)


def b_beckmann(ctx):
    """A rough copper floor and a glossy plastic block, both with Beckmann microfacets, a wide panel low behind the asset
    facing the camera: the floor's highlight runs toward the camera, its spread and tail the shape of D."""
    ctx.camera(eye=(0.0, 0.8, 3.2), target=(0.0, -0.35, 0.0))
    ctx.floor(diffuse=(0.95, 0.64, 0.54), metallic=1.0, roughness=0.55)  # alpha 0.30
    _microfacet(ctx, "Floor", "beckmann")
    _box(ctx, "Block", (0.55, -0.5, -0.3), (1.05, -0.05, 0.2), diffuse=(0.02, 0.03, 0.08), specular=(0.5, 0.5, 0.5),
         roughness=0.7)  # alpha 0.49
    _microfacet(ctx, "Block", "beckmann")
    ctx.sb.rect_light("Panel", (0.0, 0.2, -1.8), 2.0, 0.8, (0.0, -0.25, 1.0), 3.0, color=(1.0, 0.9, 0.8))
    ctx.asset("Asset", "rna_rand.usdc")


def b_spot_radius(ctx):
    """A spot with a radius (a SphereLight of radius 0.2 with ShapingAPI, Cycles' spot with Soft Falloff off) aimed at
    the asset from above the camera: a pool of light on the floor and the asset's soft-edged shadow in it."""
    ctx.camera()
    ctx.floor()
    spot = _spot(ctx, "Spot", (-0.5, 1.6, 0.9), (0.45, -1.0, -0.55), 60.0, 32.0, 0.25, "smoothstep", color=(1.0, 0.9, 0.8))
    spot.CreateRadiusAttr(0.2)
    spot.CreateNormalizeAttr(True)  # radiance 60 / (4 pi 0.2^2) from each point of the sphere
    ctx.sb.distant("Fill", (0.3, 1.0, -0.6), 0.3, color=(0.6, 0.7, 1.0))
    ctx.asset("Asset", "rna_rand.usdc")


def b_rect_light_back(ctx):
    ctx.camera()
    ctx.floor()
    ctx.sb.rect_light("Panel", (0.25, 0.35, 1.1), 0.9, 0.6, (0.2, -0.3, -1.0), 8.0, color=(1.0, 0.85, 0.7))
    ctx.sb.distant("Sun", (-0.4, 1.0, 0.6), 1.5)
    ctx.asset("Asset", "rna_rand.usdc")


def b_lights_in_the_way(ctx):
    ctx.camera()
    ctx.floor()
    # a wide, faint panel hidden from the camera over the asset, between it and a bright sky; a small bulb in view in
    # front of the floor (the floor behind it shows through)
    _hide_from_camera(ctx.sb.rect_light("Panel", (0.0, 0.9, 0.0), 2.4, 2.4, (0.0, -1.0, 0.0), 0.15))
    ctx.sb.sphere_light("Bulb", (0.7, -0.25, 1.2), 0.12, 3.0, color=(1.0, 0.8, 0.6))
    ctx.sb.dome("Sky", 1.2, color=(0.6, 0.75, 1.0))
    ctx.asset("Asset", "rna_rand.usdc")


def _glass(ctx, prim, name, *, thin, ior=1.5, roughness=0.0, color=(1.0, 1.0, 1.0)):
    """Bind a MaterialX standard_surface glass (spec/renderer.md#transmission) to ``prim``."""
    from pxr import Gf, Sdf, UsdShade

    mat = UsdShade.Material.Define(ctx.sb.stage, f"/World/Looks/{name}")
    sh = UsdShade.Shader.Define(ctx.sb.stage, f"/World/Looks/{name}/Surface")
    sh.CreateIdAttr("ND_standard_surface_surfaceshader")
    for k, v in (("base", 0.0), ("transmission", 1.0), ("specular_IOR", ior), ("specular_roughness", roughness)):
        sh.CreateInput(k, Sdf.ValueTypeNames.Float).Set(float(v))
    sh.CreateInput("transmission_color", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*color))
    sh.CreateInput("thin_walled", Sdf.ValueTypeNames.Bool).Set(bool(thin))
    mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")
    UsdShade.MaterialBindingAPI.Apply(prim.GetPrim()).Bind(mat)


def b_behind_glass(ctx):
    ctx.camera()
    ctx.floor()
    # a tinted thin pane over the left of the view, a smooth solid ball and a frosted one beside the asset
    _glass(ctx, ctx.sb.quad("Pane", (-0.55, 0.05, 1.2), 1.1, normal=(0.35, 0.0, 1.0)), "Pane", thin=True,
           color=(0.8, 0.95, 1.0))
    _glass(ctx, ctx.sb.sphere_mesh("Ball", (0.75, -0.2, 0.5), 0.3, subdivisions=3), "Ball", thin=False)
    _glass(ctx, ctx.sb.sphere_mesh("Frosted", (-0.8, -0.3, -0.5), 0.2, subdivisions=3), "Frosted", thin=False,
           ior=1.33, roughness=0.35)
    # a dome alone. A light that paths reach through glass (a RectLight, a sun of 4 deg) makes caustics on the floor
    # whose rare bright samples left the 2048-spp reference 0.65 % above other renders of the same renderer (heavier
    # tails than a bias tolerance of a few tenths of a per cent allows); a delta sun makes a glint on the smooth glass
    # (alpha 1e-3) of a far smaller area than a pixel: tolerance 3.9
    ctx.sb.dome("Sky", 1.5, color=(0.6, 0.75, 1.0))
    ctx.asset("Asset", "rna_rand.usdc")


def b_disk_cylinder_lights(ctx):
    from pxr import UsdLux

    from nasset_reference_renderer.testscenes import _frame_matrix

    ctx.camera()
    ctx.floor()
    disk = UsdLux.DiskLight.Define(ctx.sb.stage, "/World/Disk")
    disk.CreateIntensityAttr(4.0)
    disk.CreateRadiusAttr(0.35)
    disk.CreateNormalizeAttr(True)
    ctx.sb._xform(disk.GetPrim(), scale(1.6, 0.7, 1.0) @ _frame_matrix(-np.array([-0.5, -1.0, -0.4]), (0.9, 1.4, 0.7)))
    tube = UsdLux.CylinderLight.Define(ctx.sb.stage, "/World/Tube")
    tube.CreateIntensityAttr(3.0)
    tube.CreateRadiusAttr(0.06)
    tube.CreateLengthAttr(1.4)
    tube.CreateColorAttr((0.7, 0.85, 1.0))
    ctx.sb._xform(tube.GetPrim(), _frame_matrix((0.3, 0.0, 1.0), (-0.2, 0.25, 1.1)))
    ctx.asset("Asset", "rna_rand.usdc")


def b_light_spread(ctx):
    """A RectLight over the floor in front of the asset with nasset:spread 0.9 rad (a soft box: a pool of light with a
    soft edge) and a DiskLight from the side with spread 1.6 rad; the panel's own face is in view. A faint dome lights
    what the boxes do not (a renderer that takes one light sample per vertex must not waste it on a box whose cone
    misses the point: docs/bench-mitsuba-jit.md#cone-lights)."""
    from pxr import Sdf, UsdLux

    from nasset_reference_renderer.testscenes import _frame_matrix

    ctx.camera(eye=(0.0, 1.3, 3.2), target=(0.0, -0.2, 0.0))
    ctx.floor()
    rect = ctx.sb.rect_light("Box", (0.3, 0.9, 0.5), 0.5, 0.35, (-0.25, -1.0, -0.2), 12.0, color=(1.0, 0.9, 0.75))
    rect.GetPrim().CreateAttribute("nasset:spread", Sdf.ValueTypeNames.Float, custom=True).Set(0.9)
    disk = UsdLux.DiskLight.Define(ctx.sb.stage, "/World/Side")
    disk.CreateIntensityAttr(6.0)
    disk.CreateRadiusAttr(0.25)
    disk.CreateColorAttr((0.7, 0.8, 1.0))
    ctx.sb._xform(disk.GetPrim(), _frame_matrix(-np.array([1.0, -0.45, -0.1]), (-1.3, 0.4, 0.2)))
    disk.GetPrim().CreateAttribute("nasset:spread", Sdf.ValueTypeNames.Float, custom=True).Set(1.6)
    ctx.sb.dome("Sky", 0.15, color=(0.6, 0.7, 0.9))
    ctx.asset("Asset", "rna_rand.usdc")


def b_self_shadow(ctx):
    ctx.camera(eye=(0.0, 0.4, 2.2))
    ctx.sb.distant("Sun", (1.0, 0.35, 0.2), 2.0)
    ctx.asset("Asset", "rna_const.usdc")


def b_shadow_on_asset(ctx):
    ctx.camera(eye=(0.0, 1.2, 2.8))
    ctx.floor()
    ctx.sb.distant("Sun", (0.0, 1.0, 0.15), 3.0)
    _box(ctx, "Blocker", (-0.9, 0.9, -0.6), (0.05, 0.95, 0.6), diffuse=(0.3, 0.3, 0.3))
    ctx.asset("Asset", "rna_const.usdc")


def b_asset_shadow(ctx):
    ctx.camera(eye=(0.0, 3.2, 2.0), target=(0.6, -0.5, -0.4))
    ctx.floor(diffuse=(0.7, 0.7, 0.7))
    ctx.sb.distant("Sun", (-0.8, 0.45, 0.6), 3.0)
    ctx.asset("Asset", "rna_rand.usdc")


def b_instances(ctx):
    ctx.camera(eye=(0.0, 1.7, 4.8), target=(0.0, -0.05, 0.0))
    ctx.floor(y=-0.6, size=8.0)
    ctx.sb.distant("Sun", (0.4, 1.0, 0.6), 3.0)
    ctx.asset("Rotated", "rna_rand.usdc", chain(rotate((1, 1, 0), 70.0), translate(-1.15, 0.0, 0.0)))
    ctx.asset("Stretched", "rna_rand.usdc", chain(scale(1.5, 0.55, 0.8), rotate((0, 1, 0), 35.0), translate(0.0, -0.3, 0.2)))
    ctx.asset("Mirrored", "rna_rand.usdc", chain(scale(-1.0, 1.0, 1.0), rotate((0, 0, 1), 40.0), translate(1.15, 0.0, 0.0)))


def b_instances_shadow(ctx):
    ctx.camera(eye=(0.0, 0.8, 3.4))
    ctx.floor()
    ctx.sb.distant("Sun", (1.0, 0.35, 0.0), 3.0)
    ctx.asset("Front", "rna_const.usdc", translate(0.75, 0.0, 0.0))
    ctx.asset("Back", "rna_const.usdc", translate(-0.55, 0.0, 0.0))


def b_grazing(ctx):
    ctx.camera(eye=(0.0, 0.02, 3.5), target=(0.0, -0.05, 0.0), focal=50.0)
    ctx.floor(y=-0.2, size=10.0)
    ctx.sb.distant("Sun", (-1.0, 0.12, -0.3), 4.0)
    ctx.asset("Asset", "rna_rand.usdc", chain(scale(1.6, 0.35, 1.6), rotate((0, 1, 0), 20.0), translate(0.0, -0.02, 0.0)))


def b_far(ctx):
    ctx.world(translate(700.0, 100.0, -700.0))
    ctx.camera()
    ctx.floor()
    ctx.sb.distant("Sun", (0.5, 1.0, 0.35), 3.0)
    ctx.asset("Asset", "rna_rand.usdc", rotate((0, 1, 0), 30.0), typed=False, payload=True)


def b_scaled(s):
    def build(ctx):
        ctx.world(scale(s, s, s))
        ctx.camera()
        ctx.floor()
        ctx.sb.distant("Sun", (0.5, 1.0, 0.35), 2.0, angle=4.0)
        ctx.sb.rect_light("Panel", (-1.0, 1.5, 1.0), 0.8, 0.8, (0.6, -1.0, -0.5), 6.0)
        ctx.asset("Asset", "rna_rand.usdc", rotate((1, 0, 0), 25.0))

    return build


def b_quality(ctx):
    ctx.camera(eye=(0.0, 0.7, 2.0))
    ctx.sb.distant("Sun", (0.4, 1.0, 0.8), 3.0)
    ctx.asset("Asset", "rna_quality.usdc")


def b_indirect(ctx):
    ctx.camera(eye=(0.2, 1.0, 3.3), target=(0.0, 0.1, 0.0))
    ctx.floor(diffuse=(0.5, 0.5, 0.5), metallic=0.0, roughness=0.3)
    # the sun lights the upper part of a red wall; a blocker keeps it off the asset, whose light is
    # the wall, the floor and an emissive quad (reached by continuation rays only)
    ctx.sb.quad("Wall", (-1.1, 0.5, 0.0), 2.2, normal=(1.0, 0.0, 0.0), diffuse=(0.9, 0.15, 0.1))
    ctx.sb.quad("Blocker", (0.9, 0.25, 0.0), 1.5, normal=(1.0, 0.0, 0.0), diffuse=(0.3, 0.3, 0.3))
    ctx.sb.quad("Lamp", (0.3, 0.9, -1.2), 0.8, normal=(0.0, 0.0, 1.0), diffuse=(0.0, 0.0, 0.0), emission=(2.0, 2.0, 2.5))
    ctx.sb.distant("Sun", (1.0, 0.5, 0.0), 4.0)
    ctx.asset("Asset", "rna_rand.usdc")


def b_fiber_closeup(ctx):
    ctx.camera(eye=(0.0, 0.1, 2.0), target=(0.0, 0.05, 0.0), focal=110.0)  # fibres several pixels wide
    ctx.floor()
    ctx.sb.distant("Sun", (0.5, 1.0, 0.35), 3.0)
    ctx.asset("Asset", "rna_fiber_h.usdc")


def b_neupress_direct(ctx):
    ctx.camera(eye=(0.0, 0.6, 2.2))
    ctx.sb.distant("Sun", (0.15, 0.5, -1.0), 3.0)  # behind the asset: grazing GGX highlight on its top
    ctx.asset("Asset", "neupress.usdc")


def b_other_kind(asset):
    def build(ctx):
        ctx.camera()
        ctx.floor()
        ctx.sb.distant("Sun", (0.5, 1.0, 0.35), 3.0)
        ctx.asset("Asset", asset)

    return build


def b_8dna_near(ctx):
    """A small SphereLight (out of view) about one asset radius above it: its distance to u_i spans 3x across the
    box; the instance rotated, scaled and moved, the camera close: the neural term's light samples from u_i in world
    space."""
    ctx.camera(eye=(0.0, 0.3, 2.2), target=(-0.1, -0.05, 0.0))
    ctx.floor()
    ctx.sb.sphere_light("Bulb", (0.25, 0.7, 0.2), 0.12, 20.0, color=(1.0, 0.85, 0.7))
    ctx.asset("Asset", "8dna.usdc", chain(rotate((0, 1, 0), 40.0), scale(0.8, 0.8, 0.8), translate(-0.15, -0.1, 0.0)))


CASES = [
    Case("rna_distant_fp16", "rna surface asset (fp16 triplane, random networks) on a floor under a delta DistantLight: "
         "triplane lookup, decoder input order, both transport branches, shadow on the floor", b_distant("rna_rand.usdc")),
    Case("rna_distant_fp32", "the same scene as rna_distant_fp16 with the triplane stored as float32", b_distant("rna_rand_fp32.usdc")),
    Case("rna_distant_angle", "constant-transport asset floating above a floor under a DistantLight with angle 30 degrees: "
         "sampled cone, soft terminator (per-sample branch choice) and a wide penumbra", b_distant_angle),
    Case("rna_sphere_light", "SphereLight (radius 0.3): area light sampling at the asset, MIS with continuation rays", b_sphere),
    Case("rna_point_light", "SphereLight with treatAsPoint: point light, inverse-square falloff, delta-light weight 1", b_point),
    Case("rna_near_field_fetch", "rna surface asset with nasset:nearFieldFetch = 0.5 (format 0.3) on a floor, a point light "
         "low and close beside it: light samples drawn at the fetch point p = x + f (c_w - x), other objects seen from p, "
         "the branch from x, continuations (the floor's bounce) leaving from p", b_near_field),
    Case("rna_rect_light", "RectLight emitting toward its local -Z, tilted: one-sided emitter, area sampling", b_rect),
    Case("rna_dome_exr", "DomeLight with an asymmetric lat-long OpenEXR texture, rotated 25 degrees about +Y: texture "
         "orientation and importance sampling", b_dome),
    Case("rna_suns_and_dome", "two DistantLights with angles 12 and 30 degrees and a rotated lat-long DomeLight together: "
         "every light seen by escaping rays (several lights at infinity, not one environment) and sampled, asset above a "
         "floor", b_suns_and_dome),
    Case("rna_hidden_lights", "a SphereLight in front of the asset, a RectLight facing the camera and a textured DomeLight, all "
         "with nasset:cameraVisibility = false, and a visible sun with an angle: camera rays pass through the hidden "
         "surfaces and see black where they escape, every other ray reaches them; the sphere lies between the sun and the "
         "floor, which it must not shadow", b_hidden_lights),
    Case("rna_spot_lights", "two point lights with UsdLux.ShapingAPI aimed past the asset at the floor: a linear falloff "
         "(cone 30 degrees, softness 0.4) and nasset:shaping:falloff = smoothstep (cone 20, softness 0.3): the pools "
         "of light, their soft edges and the asset's light samples", b_spot_lights),
    Case("rna_beckmann", "a rough copper floor (alpha 0.30) and a glossy plastic block (alpha 0.49) with nasset:microfacet = "
         "beckmann, a wide RectLight low behind the asset facing the camera: Beckmann's D, its rational Lambda in the "
         "height-correlated G2 and its half-vector sampling, the asset's light reflected by the floor", b_beckmann),
    Case("rna_light_spread", "a RectLight over the floor with nasset:spread = 0.9 rad (a soft box: the pool of light and its "
         "soft edge) and a DiskLight from the side with spread 1.6 rad, a faint dome: the spread's profile on light "
         "samples and on rays that meet the lights, the power it keeps", b_light_spread),
    Case("rna_spot_radius", "a spot with a radius (SphereLight of radius 0.2, ShapingAPI cone 32 degrees, smoothstep "
         "falloff) aimed at the asset, a faint fill sun: the shaping of every point of the sphere, the asset's soft shadow "
         "in the pool of light", b_spot_radius),
    Case("rna_rect_light_back", "a RectLight between the camera and the asset, emitting away from the camera toward the "
         "asset and the floor: camera rays reach its back and pass through it (one-sided light surface), its light on "
         "the asset", b_rect_light_back),
    Case("rna_lights_in_the_way", "light surfaces occlude nothing: a wide faint RectLight hidden from the camera over the "
         "asset and the floor, between them and a bright dome, and a small SphereLight in view in front of the floor; "
         "rays that meet a light surface add its emission and go on (the dome reaches the asset and the floor through "
         "the panel, the floor shows behind the bulb)", b_lights_in_the_way),
    Case("rna_many_lights", "40 lights around the asset on a floor: 28 small SphereLights hidden from the camera and 12 point "
         "lights, powers over 30x: every light's share of the asset's and the floor's light, whether an implementation "
         "samples every light or draws some (spec/renderer.md#light-selection)", b_many_lights),
    Case("rna_behind_glass", "the asset on a floor seen through a tinted thin glass pane, beside a smooth glass ball and a "
         "frosted one (MaterialX transmission, spec/renderer.md#transmission), under a dome: camera and continuation "
         "rays reach the asset through glass, whose shadow rays stop at glass", b_behind_glass, spp=256),
    Case("rna_disk_cylinder_lights", "a tilted DiskLight, normalized, scaled into an ellipse, and a CylinderLight in front of "
         "the asset, its side in view: one-sided disk, the tube emitting outward and hit only from outside", b_disk_cylinder_lights),
    Case("rna_self_shadow", "lone constant-transport asset lit from the side: the shadowed/unshadowed branch is chosen by "
         "self-occlusion only (no other objects: next-event estimation only)", b_self_shadow),
    Case("rna_shadow_on_asset", "a box between the light and the asset: light samples blocked by another object contribute 0 "
         "(not the shadowed branch)", b_shadow_on_asset),
    Case("rna_asset_shadow_on_floor", "low sun, camera looking down at the floor: the asset's triangles occlude shadow rays of "
         "ordinary surfaces", b_asset_shadow),
    Case("rna_instances_transforms", "three instances of one asset: rotated, non-uniformly scaled, mirrored (negative "
         "determinant); points, directions and normals must be mapped to object space", b_instances, width=64),
    Case("rna_instances_shadow", "two instances of the same asset, one shadowing the other: only the instance's own triangles "
         "are ignored by its rays, so the other instance blocks (0), it does not pick the shadowed branch", b_instances_shadow),
    Case("rna_grazing_view", "camera and light at grazing angles over a flattened, rotated instance", b_grazing),
    Case("rna_far_from_origin", "the whole scene translated by (700, 100, -700); the asset is an untyped prim with a payload "
         "arc", b_far),
    Case("rna_scale_tiny", "the whole scene scaled by 1e-3 (DistantLight with angle + RectLight)", b_scaled(1e-3)),
    Case("rna_scale_huge", "the whole scene scaled by 1e3 (DistantLight with angle + RectLight)", b_scaled(1e3)),
    Case("rna_quality_variant", "asset whose required core has quality variants 'small' (default) and 'hq' with different "
         "networks: the plan loads the default variant only", b_quality),
    Case("rna_indirect", "asset lit mostly indirectly (red wall, emissive quad reached by continuation rays only, glossy "
         "floor): continuation rays leaving the asset and their branch weights", b_indirect),
    Case("rna_fiber_distant", "rna fiber asset (tuft of tapered linear curves, random networks) on a floor under a delta "
         "DistantLight: curve tubes, tangent and h inputs, fibers shadowing fibers (shadowed branch), shadows on the floor",
         b_distant("rna_fiber.usdc")),
    Case("rna_fiber_dense", "dense rna fiber asset (1200 drooping strands around a small sphere) on a floor under a delta "
         "DistantLight: shadow and continuation rays cross tens of fibres of their own asset (shadowed branch however "
         "many are crossed; own and neighbouring segments exempt), fibres shadowing the floor", b_distant("rna_fiber_dense.usdc")),
    Case("neupress_distant", "neupress surface asset on a floor under a DistantLight; its optional components (importance "
         "sampling, PRT) are not needed by the plan", b_other_kind("neupress.usdc"), spp=256),
    Case("rna_fiber_closeup", "close-up of a few rna fibres several pixels wide, the decoder strongly dependent on the "
         "cross-fibre offset h: the sign and range of h across the fibre", b_fiber_closeup),
    Case("neupress_direct", "lone neupress surface asset under a delta DistantLight, no other objects (low noise): the "
         "subsurface network's w_i input and the GGX boundary reflection, its lobe width", b_neupress_direct, spp=256, ref_spp=4096),
    Case("neupress_near_field_fetch", "neupress surface asset with nasset:nearFieldFetch = 0.5 (format 0.3) on a floor, a "
         "point light low and close beside it: the light of S^ and of the surface reflection drawn at the fetch point "
         "p = x + f (c_w - x), other objects seen from p, V_self from x, the A samples (the floor's bounce) leaving from p",
         b_neupress_near_field, spp=256, ref_spp=4096),
    Case("8dna_distant", "8dna surface asset on a floor under a DistantLight", b_other_kind("8dna.usdc")),
    Case("8dna_near", "8dna surface asset (rotated, scaled, moved) next to a small SphereLight: the near field, light "
         "samples from the flow's u_i in world space, MIS with the flow's direction", b_8dna_near, spp=256, ref_spp=8192),
]


# -- metric ----------------------------------------------------------------------------------
def metric(image, reference, block):
    """Normalised RMSE of b x b block means (see nasset_sdk.conformance.rmse_normalised)."""
    from nasset_sdk.conformance import rmse_normalised

    return rmse_normalised(image, reference, block)


def mean_bias(image, reference):
    """Relative brightness bias (see nasset_sdk.conformance.mean_bias)."""
    from nasset_sdk.conformance import mean_bias as bias

    return bias(image, reference)


def noise_bound(e) -> float:
    """max(max(e), mean(e) + 3 std(e)) of the noise runs' errors [NOISE_RUNS]."""
    e = np.asarray(e, np.float64)
    return max(float(e.max()), float(e.mean() + 3 * e.std(ddof=1)))


# -- generation --------------------------------------------------------------------------------
def needs_of(folder: Path, files) -> dict:
    from nasset_sdk.asset import Asset

    out = {}
    for f in files:
        if not f.endswith(".usdc"):
            continue
        a = Asset.open(folder / f, load="none")
        comps = []
        for n, c in a.components().items():
            if c.required:
                comps.append(f"{n} (quality '{c.quality}')" if c.qualities else n)
        out[f] = {"kind": a.kind, "variant": a.variant, "components": comps,
                  "not_needed": [n for n, c in a.components().items() if not c.required]}
    return out


def build_case(case: Case, folder: Path) -> dict:
    """Write scene.usda and the assets of ``case`` into ``folder``; return the static part of case.json."""
    folder.mkdir(parents=True, exist_ok=True)
    ctx = Ctx(folder)
    case.build(ctx)
    ctx.sb.write(folder / "scene.usda")
    needs = needs_of(folder, ctx.files)
    kinds = sorted({f"{v['kind']}/{v['variant']}" for v in needs.values()})
    return {
        "description": case.description, "spp": case.spp, "width": case.width, "height": case.height,
        "metric": "rmse_normalised", "block": case.block, "needs": needs, "kinds": kinds,
        "ref_spp": case.ref_spp, "max_depth": case.max_depth, "files": sorted(["scene.usda"] + ctx.files),
    }


def render_ref(folder: Path, case: Case, spp: int, seed: int) -> np.ndarray:
    import warnings

    from nasset_reference_renderer import RenderSettings, load_scene, render

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load_scene(str(folder / "scene.usda"))
    s = RenderSettings(spp=spp, seed=seed, width=case.width, height=case.height, max_depth=case.max_depth)
    return render(scene, s).image


def supported(folder: Path) -> str | None:
    """None when the reference renderer loads the scene, else why not."""
    import warnings

    from nasset_reference_renderer import load_scene
    from nasset_sdk.errors import SceneError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            load_scene(str(folder / "scene.usda"))
    except SceneError as exc:
        return str(exc)
    return None


def generate(case: Case, log=print) -> bool:
    from nasset_reference_renderer.film import write_exr

    folder = CASES_DIR / case.name
    tmp = Path(tempfile.mkdtemp(prefix=f"case-{case.name}-"))
    try:
        info = build_case(case, tmp)
        why = supported(tmp)
        if why is not None:
            if case.pending:
                log(f"{case.name}: pending, the reference renderer does not render it yet ({why.splitlines()[0][:120]})")
                return False
            raise RuntimeError(f"{case.name}: {why}")
        t0 = time.perf_counter()
        ref = render_ref(tmp, case, case.ref_spp, REF_SEED)
        t_ref = time.perf_counter() - t0
        t0 = time.perf_counter()
        images = [render_ref(tmp, case, case.spp, s) for s in range(1, NOISE_RUNS + 1)]
        t_noise = (time.perf_counter() - t0) / NOISE_RUNS
        e = np.array([metric(im, ref, case.block) for im in images])
        q = noise_bound(e)
        tol = TOL_FACTOR * q
        info["tolerance"] = round(tol, 6)
        eb = np.array([mean_bias(im, ref) for im in images])
        qb = noise_bound(eb)
        info["bias_tolerance"] = round(TOL_FACTOR * qb, 6)
        info["bias_tolerance_derivation"] = {
            "text": (f"|mean(image) / mean(reference) - 1| of the same {NOISE_RUNS} noise renders; bias_tolerance = "
                     f"{TOL_FACTOR} x max(max(b), mean(b) + 3 std(b))."),
            "errors": [round(float(x), 6) for x in eb], "mean": round(float(eb.mean()), 6),
            "std": round(float(eb.std(ddof=1)), 6), "max": round(float(eb.max()), 6), "bound": round(qb, 6), "factor": TOL_FACTOR,
        }
        info["tolerance_derivation"] = {
            "text": (f"reference: reference renderer, {case.ref_spp} spp, seed {REF_SEED}. Noise: {NOISE_RUNS} renders at the "
                     f"test spp ({case.spp}) with seeds 1..{NOISE_RUNS}, metric against the reference each. tolerance = "
                     f"{TOL_FACTOR} x max(max(e), mean(e) + 3 std(e)); the factor {TOL_FACTOR} leaves room for a renderer "
                     f"with up to about {TOL_FACTOR ** 2:.0f}x the reference renderer's variance at the same spp."),
            "noise_runs": NOISE_RUNS, "seeds": list(range(1, NOISE_RUNS + 1)), "errors": [round(float(x), 6) for x in e],
            "mean": round(float(e.mean()), 6), "std": round(float(e.std(ddof=1)), 6), "max": round(float(e.max()), 6),
            "bound": round(q, 6), "factor": TOL_FACTOR, "ref_seed": REF_SEED,
            "reference_mean_radiance": round(float(ref.mean()), 6),
            "seconds_per_test_render": round(t_noise, 2), "seconds_reference": round(t_ref, 1),
        }
        write_exr(tmp / "reference.exr", ref)
        with open(tmp / "case.json", "w") as fh:
            json.dump(info, fh, indent=2, sort_keys=True)
            fh.write("\n")
        if folder.exists():
            shutil.rmtree(folder)
        shutil.copytree(tmp, folder)
        log(f"{case.name}: tolerance {tol:.4f} (noise mean {e.mean():.4f}, max {e.max():.4f}); "
            f"reference {t_ref:.1f} s, test render {t_noise:.2f} s")
        return True
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _same_file(a: Path, b: Path) -> bool:
    """Byte-identical, or for USD layers the same prims and attribute values (floats within 1e-6).

    Geometry helpers (e.g. trimesh's summed vertex normals) differ in the last bits between numpy
    builds, which changes the bytes but not the case."""
    if _digest(a) == _digest(b):
        return True
    if a.suffix not in (".usdc", ".usda"):
        return False
    from pxr import Sdf

    la, lb = Sdf.Layer.FindOrOpen(str(a)), Sdf.Layer.FindOrOpen(str(b))
    specs: dict[str, list] = {"a": [], "b": []}
    la.Traverse("/", lambda p: specs["a"].append(p))
    lb.Traverse("/", lambda p: specs["b"].append(p))
    if sorted(map(str, specs["a"])) != sorted(map(str, specs["b"])):
        return False
    for path in specs["a"]:
        sa, sb = la.GetObjectAtPath(path), lb.GetObjectAtPath(path)
        if not isinstance(sa, Sdf.AttributeSpec):
            continue
        va, vb = sa.default, sb.default
        try:
            xa, xb = np.asarray(va), np.asarray(vb)
            numeric = xa.dtype.kind in "fiu" and xb.dtype.kind in "fiu"
        except Exception:  # noqa: BLE001 - non-array values compare exactly below
            numeric = False
        if numeric:
            if xa.shape != xb.shape or not np.allclose(xa, xb, rtol=1e-6, atol=1e-6):
                return False
        elif va != vb:
            return False
    return True


def check(case: Case, log=print, *, render: bool = True) -> list[str]:
    """Problems of the committed case (empty when it is what this script makes); ``render``: also render it afresh
    and compare with its reference image (else the files and the case.json keys only)."""
    from nasset_reference_renderer.film import read_exr

    folder = CASES_DIR / case.name
    tmp = Path(tempfile.mkdtemp(prefix=f"check-{case.name}-"))
    try:
        info = build_case(case, tmp)
        if not folder.is_dir():
            if case.pending and supported(tmp) is not None:
                log(f"{case.name}: pending (not rendered by the reference renderer yet)")
                return []
            return [f"{case.name}: missing (run make_cases.py --cases {case.name})"]
        problems = []
        with open(folder / "case.json") as fh:
            stored = json.load(fh)
        for k in STATIC_KEYS:
            if stored.get(k) != info.get(k):
                problems.append(f"{case.name}: case.json '{k}' differs from what make_cases.py makes")
        for f in info["files"]:
            if not (folder / f).is_file() or not _same_file(folder / f, tmp / f):
                problems.append(f"{case.name}: {f} differs from what make_cases.py makes")
        extra = {p.name for p in folder.iterdir()} - set(info["files"]) - {"case.json", "reference.exr"}
        if extra:
            problems.append(f"{case.name}: unexpected files {sorted(extra)}")
        if not problems and render:
            from nasset_sdk.conformance import compare

            ref = read_exr(folder / "reference.exr")
            cmp = compare(render_ref(folder, case, case.spp, CHECK_SEED), ref, stored)
            e, b = cmp["error"], cmp["bias_error"]
            bias = "" if b is None else f", bias {b:.4f} vs {stored['bias_tolerance']:.4f}"
            log(f"{case.name}: files ok; fresh render (seed {CHECK_SEED}) error {e:.4f} vs tolerance {stored['tolerance']:.4f}"
                f"{bias} {'ok' if cmp['passed'] else 'FAIL'}")
            if not cmp["passed"]:
                problems.append(f"{case.name}: reference image is not what the reference renderer converges to "
                                f"(error {e:.4f} vs {stored['tolerance']:.4f}{bias})")
        return problems
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=None, help="only these cases")
    ap.add_argument("--check", action="store_true", help="verify the committed cases instead of writing them")
    ap.add_argument("--list", action="store_true", help="list the cases and exit")
    args = ap.parse_args(argv)
    names = {c.name for c in CASES}
    if args.cases:
        unknown = set(args.cases) - names
        if unknown:
            ap.error(f"unknown cases: {sorted(unknown)}")
    sel = [c for c in CASES if not args.cases or c.name in args.cases]
    if args.list:
        for c in sel:
            print(f"{c.name}{' (pending)' if c.pending else ''}: {c.description}")
        return 0
    if args.check:
        problems = []
        for c in sel:
            problems += check(c)
        if not args.cases:
            stray = sorted(p.name for p in CASES_DIR.iterdir() if p.is_dir() and p.name not in names) if CASES_DIR.is_dir() else []
            problems += [f"{s}: a case folder make_cases.py does not make" for s in stray]
        for p in problems:
            print("FAIL", p)
        print(f"{len(sel)} cases checked, {len(problems)} problems")
        return 1 if problems else 0
    CASES_DIR.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    for c in sel:
        generate(c)
    print(f"done in {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
