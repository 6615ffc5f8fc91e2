"""Hostile inputs for rendering (issue classes 7-9): ``python -m tests.corpus.gen_render OUT_DIR``.

* ``r7_*`` non-finite output from finite input: valid-looking assets whose networks or tensors push
  radiance toward float32 max (constant outputs at and above the probe bound, outputs that are zero
  on zero inputs but huge on real triplane features or directions, 8dna flows with huge spline
  parameters). Expected code None: whatever validates must render finite images.
* ``r8_*`` typed errors: corrupt, truncated, non-EXR and huge-header dome textures, extreme light
  exposure / intensity / non-finite light inputs, bad 8dna spline data.
* ``r9_*`` silent scene mistakes: invalid camera values, NaN/Inf transforms, assets scaled or moved
  beyond float32 ray casting (asset geometry: GEOMETRY_SCALE; scene transforms: SCENE_INVALID), and
  valid extremes just inside the bounds (code None).

Asset cases are validated; scene cases (``scene=True``) are rendered and must raise ``code``.
"""

from __future__ import annotations

import struct
import sys
from pathlib import Path

import numpy as np

from tests.corpus.make_corpus import Case

F32_MAX = float(np.finfo(np.float32).max)


def _io_of(model_bytes: bytes):
    """(input name, input width, output name, output width) of a one-input one-output model."""
    import onnx

    m = onnx.ModelProto()
    m.ParseFromString(model_bytes)
    i, o = m.graph.input[0], m.graph.output[0]
    return (i.name, int(i.type.tensor_type.shape.dim[1].dim_value), o.name, int(o.type.tensor_type.shape.dim[1].dim_value))


def _mlp_like(old: bytes, w1: np.ndarray, b1: np.ndarray, w2: np.ndarray, b2: np.ndarray) -> bytes:
    """A 2-layer ReLU MLP with the old model's input/output names: y = relu(x W1 + b1) W2 + b2."""
    from nasset_sdk.networks import mlp_onnx

    in_name, _, out_name, _ = _io_of(old)
    return mlp_onnx([w1.astype(np.float32), w2.astype(np.float32)], [b1.astype(np.float32), b2.astype(np.float32)],
                    input_name=in_name, output_name=out_name)


def _constant_net(old: bytes, value: float, hidden: int = 8) -> bytes:
    """Same I/O as ``old``; every output equals ``value`` for every input."""
    _, win, _, wout = _io_of(old)
    return _mlp_like(old, np.zeros((win, hidden)), np.zeros(hidden), np.zeros((hidden, wout)), np.full(wout, value))


def _amplifier(old: bytes, cols, gain1: float, gain2: float, hidden: int = 4) -> bytes:
    """Zero on zero inputs; relu(sum of input columns ``cols`` x gain1) x gain2 on every output otherwise."""
    _, win, _, wout = _io_of(old)
    w1 = np.zeros((win, hidden))
    w1[list(cols), 0] = gain1
    w1[list(cols), 1] = -gain1
    w2 = np.zeros((hidden, wout))
    w2[:2, :] = gain2
    return _mlp_like(old, w1, np.zeros(hidden), w2, np.zeros(wout))


def _builder(kind: str, seed: int = 0):
    from nasset_sdk.examples import example_builder

    return example_builder(kind, variant="surface", size="tiny", seed=seed)


def _core(b):
    return b.components["core"][""]


def _set_values(path: Path, prim: str, values) -> None:
    """Overwrite a float tensor's values in a written asset (same count, so the shape stays right)."""
    from pxr import Sdf, Vt

    layer = Sdf.Layer.FindOrOpen(str(path))
    layer.GetAttributeAtPath(prim + ".values").default = Vt.FloatArray([float(v) for v in values])
    layer.Save()


def _write_exr_bytes(path: Path, w: int, h: int, *, value: float = 0.5) -> bytes:
    from nasset_reference_renderer.film import write_exr

    write_exr(path, np.full((h, w, 3), value, np.float32))
    return path.read_bytes()


def _exr_header_only(width: int, height: int) -> bytes:
    """A syntactically valid scanline EXR header declaring ``width`` x ``height`` RGB float pixels, no pixel data."""
    def attr(name: bytes, typ: bytes, value: bytes) -> bytes:
        return name + b"\0" + typ + b"\0" + struct.pack("<i", len(value)) + value

    ch = b"".join(c + b"\0" + struct.pack("<iBBBBii", 2, 0, 0, 0, 0, 1, 1) for c in (b"B", b"G", b"R")) + b"\0"
    box = struct.pack("<4i", 0, 0, width - 1, height - 1)
    head = b"\x76\x2f\x31\x01" + struct.pack("<I", 2)
    head += attr(b"channels", b"chlist", ch) + attr(b"compression", b"compression", b"\0")
    head += attr(b"dataWindow", b"box2i", box) + attr(b"displayWindow", b"box2i", box)
    head += attr(b"lineOrder", b"lineOrder", b"\0") + attr(b"pixelAspectRatio", b"float", struct.pack("<f", 1.0))
    head += attr(b"screenWindowCenter", b"v2f", struct.pack("<2f", 0, 0)) + attr(b"screenWindowWidth", b"float", struct.pack("<f", 1.0))
    return head + b"\0" + bytes(64)


def write_scene(path: Path, asset: str, *, focal=None, haperture=None, vaperture=None, camera_matrix=None,
                asset_matrix=None, ground_matrix=None, key_matrix=None, light_inputs=None, dome_texture=None,
                dome_intensity=None) -> Path:
    """A small scene around ``asset`` (relative path): camera, distant key light, dome, ground, one NeuralAsset.

    Every keyword overrides one authored value (None: a sensible default)."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    cam = UsdGeom.Camera.Define(stage, "/World/Camera")
    cam.CreateFocalLengthAttr(35.0 if focal is None else focal)
    cam.CreateHorizontalApertureAttr(20.955 if haperture is None else haperture)
    cam.CreateVerticalApertureAttr(20.955 if vaperture is None else vaperture)
    look = Gf.Matrix4d().SetLookAt(Gf.Vec3d(0, 0.6, 2.2), Gf.Vec3d(0, 0, 0), Gf.Vec3d(0, 1, 0)).GetInverse()
    cam.AddTransformOp().Set(look if camera_matrix is None else Gf.Matrix4d(*camera_matrix))
    obj = stage.DefinePrim("/World/Asset", "NeuralAsset")
    obj.GetReferences().AddReference(asset)
    if asset_matrix is not None:
        UsdGeom.Xformable(obj).AddTransformOp().Set(Gf.Matrix4d(*asset_matrix))
    key = UsdLux.DistantLight.Define(stage, "/World/Key")
    key.CreateIntensityAttr(3.0)
    key.CreateAngleAttr(1.0)
    if key_matrix is not None:
        key.AddTransformOp().Set(Gf.Matrix4d(*key_matrix))
    else:
        key.AddRotateXYZOp().Set(Gf.Vec3f(-50.0, 30.0, 0.0))
    for name, value in (light_inputs or {}).items():
        key.GetPrim().CreateAttribute(name, Sdf.ValueTypeNames.Float).Set(value)
    dome = UsdLux.DomeLight.Define(stage, "/World/Dome")
    dome.CreateIntensityAttr(0.2 if dome_intensity is None else dome_intensity)
    if dome_texture is not None:
        dome.CreateTextureFileAttr(Sdf.AssetPath(dome_texture))
    g = UsdGeom.Mesh.Define(stage, "/World/Ground")
    g.CreatePointsAttr([(-5, -0.6, -5), (5, -0.6, -5), (5, -0.6, 5), (-5, -0.6, 5)])
    g.CreateFaceVertexCountsAttr([4])
    g.CreateFaceVertexIndicesAttr([0, 3, 2, 1])
    g.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if ground_matrix is not None:
        g.AddTransformOp().Set(Gf.Matrix4d(*ground_matrix))
    stage.GetRootLayer().Save()
    return path


def _scale_matrix(s, t=(0.0, 0.0, 0.0)):
    return (s, 0, 0, 0, 0, s, 0, 0, 0, 0, s, 0, t[0], t[1], t[2], 1)


NAN, INF = float("nan"), float("inf")


def make_cases(out_dir) -> list[Case]:
    """Write every case into ``out_dir``; return them (code None: valid, must render finite)."""
    from nasset_sdk.geometry import MeshGeometry

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    cases: list[Case] = []

    def asset(name, code, builder, severity="error"):
        path = builder.write(out / f"{name}.usdc")
        cases.append(Case(name, path, code, severity))

    # -- class 7: finite inputs, huge radiance --------------------------------------------------------
    nets = {"rna": "decoder", "neupress": "appearance", "8dna": "albedo"}
    for kind, net in nets.items():
        for label, value in (("1e8", 1e8), ("1e20", 1e20), ("f32max", F32_MAX / 2)):
            b = _builder(kind)
            core = _core(b)
            core.networks[net] = _constant_net(core.networks[net], value)
            asset(f"r7_{kind}_{net}_constant_{label}", None, b)
    # rna decoder input: [triplane C, xn 3, n 3, wo 3, wi 3]; zero on zero inputs, huge on real ones
    b = _builder("rna")
    core = _core(b)
    tri, dt, lay = core.tensors["triplane"]
    c = tri.shape[-1]
    core.tensors["triplane"] = (np.full(tri.shape, 65504.0, np.float16), dt, lay)  # fp16 max, finite
    core.networks["decoder"] = _amplifier(core.networks["decoder"], range(c), 1e18 / (65504.0 * c), 1e37 / 1e18)
    asset("r7_rna_triplane_fp16max_amplified", None, b)
    for label, cols in (("wi", range(c + 9, c + 12)), ("wo", range(c + 6, c + 9)), ("xn", range(c, c + 3))):
        b = _builder("rna")
        core = _core(b)
        core.networks["decoder"] = _amplifier(core.networks["decoder"], cols, 1e19, 1e19)
        asset(f"r7_rna_decoder_amplifies_{label}", None, b)
    for flow, value in (("flow1", 1e30), ("flow4", -1e30)):
        b = _builder("8dna")
        core = _core(b)
        core.networks[flow] = _constant_net(core.networks[flow], value)
        asset(f"r7_8dna_{flow}_constant_{value:+.0e}", None, b)
    b = _builder("8dna")  # every raw output within the probe bound 1e8, yet albedo x flow density is ~1e38
    core = _core(b)
    core.networks["albedo"] = _constant_net(core.networks["albedo"], 0.99e8)
    for flow in ("flow1", "flow2", "flow3", "flow4"):
        core.networks[flow] = _constant_net(core.networks[flow], 0.99e8)
    asset("r7_8dna_albedo_and_flows_at_probe_bound", None, b)
    b = _builder("neupress")
    core = _core(b)
    _, win, _, _ = _io_of(core.networks["appearance"])
    core.networks["appearance"] = _amplifier(core.networks["appearance"], range(win), 1e18, 1e18)
    asset("r7_neupress_appearance_amplified", None, b)

    # -- class 8: bad 8dna data is a typed format error ------------------------------------------------
    for label, mins in (("width_sum", (0.9, 0.01, 1e-3)), ("zero_derivative", (1e-3, 1e-3, 0.0)),
                        ("negative", (-0.1, 1e-3, 1e-3))):
        path = _builder("8dna").write(out / f"r8_8dna_spline_minimums_{label}.usdc")  # the builder refuses bad data
        _set_values(path, "/_NassetPayloads/core/splineMinimums", mins)
        cases.append(Case(path.stem, path, "KIND_CONTRACT"))

    # -- class 9: asset geometry beyond / within float32 rendering ------------------------------------
    base = _builder("rna")
    geo = base.geometry
    for label, s, t, code in (("tiny_1e-30", 1e-30, 0.0, "GEOMETRY_SCALE"), ("huge_1e37", 1e37, 0.0, "GEOMETRY_SCALE"),
                              ("huge_1e12", 1e12, 0.0, "GEOMETRY_SCALE"), ("far_1e6", 1.0, 1e6, "GEOMETRY_SCALE"),
                              ("small_2e-8", 2e-8, 0.0, None), ("large_5e9", 5e9, 0.0, None), ("offset_300", 1.0, 300.0, None)):
        b = _builder("rna")
        pts = np.asarray(geo.points, np.float64) * s + t
        b.set_geometry(MeshGeometry(pts.astype(np.float32), geo.faces, geo.normals))
        asset(f"r9_geometry_{label}", code, b)

    # -- scenes (rendered; ``code`` is the typed error the render must raise) --------------------------
    good = _builder("rna").write(out / "_scene_asset.usdc")
    rel = "./" + good.name

    def scene(name, code, **kw):
        path = write_scene(out / f"{name}.usda", rel, **kw)
        cases.append(Case(name, path, code, scene=True))

    scene("r9_scene_control", None)
    # class 7 in a scene: a validated asset at the network output bound under lights at the light bound
    hot = "./r7_rna_decoder_constant_1e8.usdc"
    for label, kw in (("key", {"light_inputs": {"inputs:intensity": 5e29}}), ("dome", {"dome_intensity": 5e29}),
                      ("key_exposure", {"light_inputs": {"inputs:intensity": 1e21, "inputs:exposure": 29.0}})):
        path = write_scene(out / f"r7_scene_{label}_1e30_asset_1e8.usda", hot, **kw)
        cases.append(Case(path.stem, path, None, scene=True))
    for label, kw in (("focal_zero", {"focal": 0.0}), ("focal_negative", {"focal": -35.0}), ("focal_nan", {"focal": NAN}),
                      ("focal_inf", {"focal": INF}), ("focal_tiny", {"focal": 1e-30}), ("aperture_zero", {"haperture": 0.0}),
                      ("aperture_huge", {"haperture": 1e30}), ("vaperture_nan", {"vaperture": NAN})):
        scene(f"r9_camera_{label}", "SCENE_INVALID", **kw)
    nan_m = (NAN,) * 16
    inf_m = _scale_matrix(INF)
    for label, kw in (("asset_nan", {"asset_matrix": nan_m}), ("asset_inf", {"asset_matrix": inf_m}),
                      ("asset_scale_1e-30", {"asset_matrix": _scale_matrix(1e-30)}),
                      ("asset_scale_1e37", {"asset_matrix": _scale_matrix(1e37)}),
                      ("asset_scale_1e13", {"asset_matrix": _scale_matrix(1e13)}),
                      ("asset_translate_1e13", {"asset_matrix": _scale_matrix(1.0, (1e13, 0, 0))}),
                      ("asset_scale_2e-4_vs_ground", {"asset_matrix": _scale_matrix(2e-4)}),
                      ("camera_nan", {"camera_matrix": nan_m}), ("ground_nan", {"ground_matrix": nan_m}),
                      ("light_nan", {"key_matrix": nan_m}), ("camera_far", {"camera_matrix": _scale_matrix(1.0, (0, 0, 1e13))})):
        scene(f"r9_transform_{label}", "SCENE_INVALID", **kw)
    scene("r9_transform_asset_scale_0.05", None, asset_matrix=_scale_matrix(0.05))
    for label, inputs in (("exposure_1e6", {"inputs:exposure": 1e6}), ("exposure_nan", {"inputs:exposure": NAN}),
                          ("exposure_127_intensity_1e30", {"inputs:exposure": 127.0, "inputs:intensity": 1e30}),
                          ("intensity_inf", {"inputs:intensity": INF}), ("intensity_negative", {"inputs:intensity": -1.0}),
                          ("angle_nan", {"inputs:angle": NAN})):
        scene(f"r8_light_{label}", "SCENE_INVALID", light_inputs=inputs)
    scene("r8_light_exposure_90", None, light_inputs={"inputs:exposure": 90.0})  # 3e27: finite, huge, must render finite
    exr = _write_exr_bytes(out / "_dome_ok.exr", 16, 8)
    textures = {
        "ok": exr,
        "garbage": b"\x76\x2f\x31\x01" + np.random.default_rng(7).integers(0, 256, 2048, np.uint8).tobytes(),
        "truncated": exr[: len(exr) // 2],
        "header_truncated": exr[:40],
        "not_exr": b"\x89PNG\r\n\x1a\n" + bytes(100),
        "empty": b"",
        "huge_header": _exr_header_only(1_000_000, 1_000_000),
        "huge_width": _exr_header_only(2_000_000_000, 1),
        "negative_window": _exr_header_only(-5, 10),
        "pixels_missing": _exr_header_only(64, 32),
    }
    for label, data in textures.items():
        tex = out / f"_dome_{label}.exr"
        tex.write_bytes(data)
        scene(f"r8_dome_{label}", None if label == "ok" else "IMAGE_INVALID", dome_texture="./" + tex.name)
    return cases


if __name__ == "__main__":
    target = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent / "generated_render")
    for case in make_cases(target):
        print(f"{case.code or '-':<24} {'scene' if case.scene else 'asset':<6} {case.path.name}")
