"""Programmatic scene building for tests, benchmarks and examples (writes plain USD)."""

from __future__ import annotations

import numpy as np


def _frame_matrix(z_axis, position=(0.0, 0.0, 0.0)):
    """4x4 (row-vector) whose local +Z maps to ``z_axis``, placed at ``position``."""
    w = np.asarray(z_axis, np.float64)
    w = w / np.linalg.norm(w)
    a = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t = np.cross(a, w)
    t /= np.linalg.norm(t)
    b = np.cross(w, t)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = t, b, w, position
    return m


def look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """Camera-to-world (row-vector) looking from ``eye`` at ``target`` (camera looks down -Z)."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = eye - target
    z /= np.linalg.norm(z)
    x = np.cross(up, z)
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(np.array([0.0, 0.0, 1.0]), z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = x, y, z, eye
    return m


class SceneBuilder:
    def __init__(self) -> None:
        from pxr import Usd, UsdGeom

        from nasset_sdk.plugin import register_schema

        register_schema()
        self.stage = Usd.Stage.CreateInMemory()
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        self.stage.DefinePrim("/World", "Xform")

    def _xform(self, prim, matrix):
        from pxr import Gf, UsdGeom

        UsdGeom.Xformable(prim).AddTransformOp().Set(Gf.Matrix4d(*np.asarray(matrix, np.float64).ravel().tolist()))

    def camera(self, eye, target, *, focal=35.0, aperture=20.955, name="Camera", matrix=None):
        from pxr import UsdGeom

        cam = UsdGeom.Camera.Define(self.stage, f"/World/{name}")
        cam.CreateFocalLengthAttr(float(focal))
        cam.CreateHorizontalApertureAttr(float(aperture))
        cam.CreateVerticalApertureAttr(float(aperture))
        self._xform(cam.GetPrim(), look_at(eye, target) if matrix is None else matrix)
        return cam

    def material(self, name, *, diffuse=(0.5, 0.5, 0.5), emission=None, specular=None, roughness=0.5, metallic=None):
        from pxr import Gf, Sdf, UsdShade

        mat = UsdShade.Material.Define(self.stage, f"/World/Looks/{name}")
        sh = UsdShade.Shader.Define(self.stage, f"/World/Looks/{name}/PreviewSurface")
        sh.CreateIdAttr("UsdPreviewSurface")
        c3 = Sdf.ValueTypeNames.Color3f
        sh.CreateInput("diffuseColor", c3).Set(Gf.Vec3f(*map(float, diffuse)))
        sh.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(float(roughness))
        if emission is not None:
            sh.CreateInput("emissiveColor", c3).Set(Gf.Vec3f(*map(float, emission)))
        if metallic is not None:
            sh.CreateInput("metallic", Sdf.ValueTypeNames.Float).Set(float(metallic))
        else:
            sh.CreateInput("useSpecularWorkflow", Sdf.ValueTypeNames.Int).Set(1)
            spec = (0.0, 0.0, 0.0) if specular is None else specular
            sh.CreateInput("specularColor", c3).Set(Gf.Vec3f(*map(float, spec)))
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        return mat

    def texture(self, material: str, connections: dict, file: str, *, wrap: str = "clamp", space: str | None = None,
                scale=None, bias=None, st=None, mesh=None):
        """A UsdUVTexture reading ``file`` (relative to the scene) at primvar ``st`` of material ``material``'s
        UsdPreviewSurface: ``connections`` {surface input: texture output} (e.g. ``{"roughness": "g"}``); optional
        ``sourceColorSpace``, float4 ``scale`` / ``bias``; ``st`` [V, 2] per vertex written on ``mesh``."""
        from pxr import Gf, Sdf, UsdGeom, UsdShade

        looks = f"/World/Looks/{material}"
        surf = UsdShade.Shader(self.stage.GetPrimAtPath(f"{looks}/PreviewSurface"))
        reader = UsdShade.Shader.Define(self.stage, f"{looks}/st")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        node = UsdShade.Shader.Define(self.stage, f"{looks}/tex_{len(surf.GetInputs())}")
        node.CreateIdAttr("UsdUVTexture")
        node.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(f"./{file}")
        for k in ("wrapS", "wrapT"):
            node.CreateInput(k, Sdf.ValueTypeNames.Token).Set(wrap)
        if space is not None:
            node.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set(space)
        for name, v in (("scale", scale), ("bias", bias)):
            if v is not None:
                node.CreateInput(name, Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*map(float, v)))
        node.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
        kinds = {"rgb": Sdf.ValueTypeNames.Color3f}
        for inp, out in connections.items():
            kind = Sdf.ValueTypeNames.Normal3f if inp == "normal" else kinds.get(out, Sdf.ValueTypeNames.Float)
            (surf.GetInput(inp) or surf.CreateInput(inp, kind)).ConnectToSource(node.ConnectableAPI(), out)
        if st is not None:
            pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.vertex)
            pv.Set(np.asarray(st, np.float32))
        return node

    def mesh(self, name, points, faces, *, matrix=None, **material):
        from pxr import UsdGeom, UsdShade

        faces = [list(map(int, f)) for f in faces]
        m = UsdGeom.Mesh.Define(self.stage, f"/World/{name}")
        m.CreatePointsAttr([tuple(map(float, p)) for p in np.asarray(points)])
        m.CreateFaceVertexCountsAttr([len(f) for f in faces])
        m.CreateFaceVertexIndicesAttr([i for f in faces for i in f])
        m.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        if matrix is not None:
            self._xform(m.GetPrim(), matrix)
        mat = self.material(name + "Mat", **material)
        UsdShade.MaterialBindingAPI.Apply(m.GetPrim()).Bind(mat)
        return m

    def quad(self, name, center, size, normal=(0.0, 1.0, 0.0), **material):
        fm = _frame_matrix(normal, center)
        s = 0.5 * float(size)
        pts = np.array([[-s, -s, 0], [s, -s, 0], [s, s, 0], [-s, s, 0]]) @ fm[:3, :3] + fm[3, :3]
        return self.mesh(name, pts, [[0, 1, 2, 3]], **material)

    def sphere_mesh(self, name, center=(0, 0, 0), radius=1.0, subdivisions=3, **material):
        import trimesh

        tm = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
        return self.mesh(name, np.asarray(tm.vertices) + np.asarray(center), np.asarray(tm.faces), **material)

    def _light_common(self, light, intensity, color):
        from pxr import Gf

        light.CreateIntensityAttr(float(intensity))
        light.CreateColorAttr(Gf.Vec3f(*map(float, color)))

    def distant(self, name, toward_light, intensity=1.0, *, angle=0.0, color=(1, 1, 1)):
        from pxr import UsdLux

        lt = UsdLux.DistantLight.Define(self.stage, f"/World/{name}")
        self._light_common(lt, intensity, color)
        lt.CreateAngleAttr(float(angle))
        self._xform(lt.GetPrim(), _frame_matrix(toward_light))
        return lt

    def sphere_light(self, name, position, radius, intensity=1.0, *, color=(1, 1, 1)):
        from pxr import UsdLux

        lt = UsdLux.SphereLight.Define(self.stage, f"/World/{name}")
        self._light_common(lt, intensity, color)
        lt.CreateRadiusAttr(float(radius))
        self._xform(lt.GetPrim(), _frame_matrix((0, 0, 1), position))
        return lt

    def rect_light(self, name, center, width, height, emit_dir, intensity=1.0, *, color=(1, 1, 1)):
        from pxr import UsdLux

        lt = UsdLux.RectLight.Define(self.stage, f"/World/{name}")
        self._light_common(lt, intensity, color)
        lt.CreateWidthAttr(float(width))
        lt.CreateHeightAttr(float(height))
        self._xform(lt.GetPrim(), _frame_matrix(-np.asarray(emit_dir, np.float64), center))
        return lt

    def dome(self, name, intensity=1.0, *, texture=None, color=(1, 1, 1)):
        from pxr import Sdf, UsdLux

        lt = UsdLux.DomeLight.Define(self.stage, f"/World/{name}")
        self._light_common(lt, intensity, color)
        if texture is not None:
            lt.CreateTextureFileAttr(Sdf.AssetPath(str(texture)))
        return lt

    def asset(self, name, file, matrix=None, *, typed: bool | str = True):
        """A prim referencing the asset ``file``; ``typed``: True (``def NeuralAsset``), False (untyped ``def``) or a
        type name (``"Xform"``: the recommended pattern, spec/format.md#referencing-an-asset)."""
        type_name = typed if isinstance(typed, str) else ("NeuralAsset" if typed else "")
        prim = self.stage.DefinePrim(f"/World/{name}", type_name)
        prim.GetReferences().AddReference(str(file))
        if matrix is not None:
            self._xform(prim, matrix)
        return prim

    def write(self, path) -> str:
        from nasset_sdk.safeopen import trust

        self.stage.GetRootLayer().Export(str(path))
        trust(path)  # this process wrote it: rendered without a probe while unchanged
        return str(path)


def constant_rna_asset(path, *, unshadowed=(1.0, 1.0, 1.0), shadowed=(0.25, 0.25, 0.25), radius=0.5, subdivisions=3,
                       near_field_fetch=0.0):
    """An rna asset (icosphere) whose decoder returns constant transports: handy for exact tests. ``near_field_fetch``:
    its f (spec/kinds/rna.md#near-field-fetch; 0 is not written)."""
    import trimesh

    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.geometry import MeshGeometry
    from nasset_sdk.networks import mlp_onnx

    b = AssetBuilder("rna", variant="surface")
    b.set_geometry(MeshGeometry.from_trimesh(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)))
    core = b.component("core", required=True, purpose="evaluation")
    ch = 4
    core.add_tensor("triplane", np.zeros((3, 8, 8, ch)), dtype="float16", layout="plane,v,u,channel")
    w = np.zeros((ch + 12, 6), np.float32)
    bias = np.array(list(unshadowed) + list(shadowed), np.float32)
    core.add_network("decoder", mlp_onnx([w], [bias]))
    b.provenance = {"generator": "constant"}
    b.near_field_fetch = near_field_fetch
    return b.write(path)


def constant_neupress_asset(path, *, subsurface=(0.2, 0.2, 0.2), boundary=(1.5, 0.2), radius=0.5, subdivisions=3,
                            near_field_fetch=0.0):
    """A neupress asset (icosphere, ``core`` only) whose network returns the constant S ``subsurface`` (1/sr) and whose
    surface reflection is the GGX dielectric of ``boundary`` (eta, alpha): handy for exact tests.
    ``near_field_fetch``: its f (spec/kinds/neupress.md#near-field-fetch; 0 is not written)."""
    import trimesh

    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.geometry import MeshGeometry
    from nasset_sdk.networks import mlp_onnx

    b = AssetBuilder("neupress", variant="surface")
    b.set_geometry(MeshGeometry.from_trimesh(trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)))
    core = b.component("core", required=True, purpose="evaluation")
    m = 4
    core.add_tensor("fourier", np.zeros((m, 7)), dtype="float32", layout="frequency,input")
    core.add_tensor("boundary", np.asarray(boundary, np.float64), dtype="float32", layout="parameter")
    core.add_network("appearance", mlp_onnx([np.zeros((2 * m, 3), np.float32)], [np.asarray(subsurface, np.float32)]))
    b.provenance = {"generator": "constant"}
    b.near_field_fetch = near_field_fetch
    return b.write(path)


def random_rna_asset(path, *, seed=0, size="tiny"):
    from nasset_sdk.examples import example_builder

    return example_builder("rna", size=size, seed=seed).write(path)


def constant_rna_fiber_asset(path, curves, widths, *, unshadowed=(1.0, 1.0, 1.0), shadowed=(0.25, 0.25, 0.25), h_probe=False,
                             near_field_fetch=0.0):
    """An rna fiber asset whose decoder returns constant transports (exact tests).

    ``curves``: list of [k, 3] polylines; ``widths``: one width per curve or per point. With
    ``h_probe`` the transports are affine in the network's h input instead: unshadowed
    ``(1 + h, 1 - h, 1)``, shadowed ``(0.5 + 0.5 h, 0.5 - 0.5 h, 0.5)``. ``near_field_fetch``: its f
    (spec/kinds/rna.md#near-field-fetch; 0 is not written)."""
    from nasset_sdk.asset import AssetBuilder
    from nasset_sdk.geometry import CurvesGeometry
    from nasset_sdk.networks import mlp_onnx

    pts = np.concatenate([np.asarray(c, np.float64).reshape(-1, 3) for c in curves]).astype(np.float32)
    counts = np.array([len(c) for c in curves], np.int32)
    w = np.asarray(widths, np.float32).reshape(-1)
    if w.size != len(pts):  # a scalar, or one width per curve
        w = np.repeat(np.broadcast_to(w, (len(counts),)), counts).astype(np.float32)
    b = AssetBuilder("rna", variant="fiber")
    b.set_geometry(CurvesGeometry(pts, counts, w))
    core = b.component("core", required=True, purpose="evaluation")
    ch = 4
    core.add_tensor("triplane", np.zeros((3, 8, 8, ch)), dtype="float16", layout="plane,v,u,channel")
    weights = np.zeros((ch + 13, 6), np.float32)
    if h_probe:
        weights[ch + 6] = [1.0, -1.0, 0.0, 0.5, -0.5, 0.0]  # the h column of the fiber input row
        bias = np.array([1.0, 1.0, 1.0, 0.5, 0.5, 0.5], np.float32)
    else:
        bias = np.array(list(unshadowed) + list(shadowed), np.float32)
    core.add_network("decoder", mlp_onnx([weights], [bias]))
    b.provenance = {"generator": "constant"}
    b.near_field_fetch = near_field_fetch
    return b.write(path)


def dense_hair_curves(n_strands: int = 20000, segments: int = 4, *, seed: int = 0, radius: float = 0.3,
                      length: float = 0.45, width: float = 0.004):
    """A dense synthetic hair cut: ``n_strands`` linear curves of ``segments`` segments each (CurvesGeometry).

    Roots are uniform on the upper half of a sphere of ``radius`` around the origin; each strand leaves
    its root along the normal and bends down under a parabolic droop, ``length`` long (scene units),
    tapering from ``width`` to ``width / 3``. Every ray through the cut crosses many fibres.
    """
    from nasset_sdk.geometry import CurvesGeometry

    rng = np.random.default_rng(seed)
    n = rng.normal(size=(n_strands, 3))
    n[:, 1] = np.abs(n[:, 1])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    t = np.linspace(0.0, 1.0, segments + 1)[None, :, None]
    droop = np.array([0.0, -1.0, 0.0]) * (0.8 * length * t**2)
    jitter = rng.normal(0.0, 0.03 * length, (n_strands, 1, 3)) * t
    pts = radius * n[:, None] + length * t * n[:, None] + droop + jitter
    widths = np.tile(width * np.linspace(1.0, 1.0 / 3.0, segments + 1), n_strands)
    return CurvesGeometry(pts.reshape(-1, 3).astype(np.float32), np.full(n_strands, segments + 1, np.int32),
                          widths.astype(np.float32))


def random_rna_fiber_asset(path, geometry, *, seed: int = 0, size: str = "tiny"):
    """An rna fiber asset with random networks on the given CurvesGeometry (throughput and query tests)."""
    from nasset_sdk.kinds import get_kind

    b = get_kind("rna").build_random(np.random.default_rng(seed), variant="fiber", size=size, geometry=geometry)
    return b.write(path)
