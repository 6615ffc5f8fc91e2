"""USD scene -> plain description (spec/renderer.md#scene-input, #materials, #lights)."""

from __future__ import annotations

import os
import warnings
from dataclasses import dataclass, field

import numpy as np

from nasset_sdk import curves, stage_rules
from nasset_sdk.errors import SceneError
from nasset_sdk.images import packaged_name
from nasset_sdk.implicit import IMPLICIT_PRIMS, implicit_mesh

from .usdtextures import PER_HIT_INPUTS, PerHit, TextureReader, at_corners, corner_values, primvar_color, texture_fallback

_STRUCTURAL = {"", "Xform", "Scope", "Material", "Shader", "NodeGraph", "GeomSubset", "Camera", "RenderSettings", "RenderProduct", "RenderVar"}
MAX_SETTINGS_PIXELS = 1 << 26  # a render settings' resolution above it is ignored, as in the reference renderer
_LIGHTS = {"DistantLight", "SphereLight", "RectLight", "DiskLight", "CylinderLight", "DomeLight", "DomeLight_1"}


@dataclass
class Material:
    kd: np.ndarray
    f0: np.ndarray
    alpha: float
    emission: np.ndarray
    specular: bool  # the GGX lobe is present (always: Schlick F is non-zero at grazing angles even for F0 = 0)
    per_hit: PerHit | None = None  # textured inputs / primvar colours (spec/renderer.md#textures); kd, f0, alpha: constants
    presence: tuple | None = None  # (opacity, opacityThreshold) in [0, 1] of a cut-out (spec/renderer.md#cutouts); None: opaque
    #: (weight, transmission colour [3], ior, thin, reflection colour [3]) of a transmitting MaterialX surface
    #: (spec/renderer.md#transmission); None: no transmission
    glass: tuple | None = None
    beckmann: bool = False  # the specular lobe's microfacets are Beckmann's (nasset:microfacet; the glass lobe stays GGX)


@dataclass
class Mesh:
    prim: str
    points: np.ndarray  # world space [V, 3]
    faces: np.ndarray  # [F, 3]
    material: Material
    corner_normals: np.ndarray | None = None  # [F, 3, 3] world shading normals at the triangle corners
    one_sided: bool = False  # doubleSided authored false (spec/renderer.md#sidedness)
    back_material: Material | None = None  # nasset:backMaterial
    front_sign: float = 1.0  # -1 where the front is against (v1 - v0) x (v2 - v0) of the world triangle
    corner_st: np.ndarray | None = None  # [F, 3, 2] texture coordinates at the corners (a textured material)
    corner_colors: np.ndarray | None = None  # [F, 3, 3] primvar colours at the corners (spec/renderer.md#primvar-colors)


@dataclass
class Light:
    prim: str
    type: str
    radiance: np.ndarray  # intensity * 2^exposure * color (RGB)
    to_world: np.ndarray  # 4x4 row-vector
    angle: float = 0.0
    radius: float = 0.0
    width: float = 0.0
    height: float = 0.0
    length: float = 0.0  # CylinderLight (along its local X)
    normalize: bool = False
    texture: np.ndarray | None = None  # [H, W, 3] lat-long
    camera_visible: bool = True  # nasset:cameraVisibility (spec/renderer.md#light-surfaces)
    opaque: bool = False  # nasset:opaqueSurface: rays end on its surface (Mitsuba's emitter shapes)
    shaping: tuple | None = None  # (cone angle, softness, profile) of UsdLux.ShapingAPI (spec/renderer.md#spot-lights)
    spread: float = float(np.pi)  # nasset:spread of a RectLight or DiskLight, radians (spec/renderer.md#lights)


@dataclass
class AssetInstance:
    prim: str
    file: str
    to_world: np.ndarray


@dataclass
class Camera:
    prim: str
    to_world: np.ndarray
    focal: float
    h_aperture: float
    v_aperture: float
    h_offset: float = 0.0  # horizontalApertureOffset (lens shift), the aperture's units
    v_offset: float = 0.0
    orthographic: bool = False
    lens_radius: float = 0.0  # thin lens (perspective): aperture radius in scene units; 0 is a pinhole
    focus_distance: float = 0.0  # scene units
    exposure: float = 1.0  # linear factor on the image
    settings_resolution: tuple[int, int] | None = None  # of the stage's render settings (spec/renderer.md#image-size)

    def resolution(self, width: int | None, height: int | None) -> tuple[int, int]:
        aspect = self.v_aperture / self.h_aperture
        if width is None and height is None:
            if self.settings_resolution is not None:
                return self.settings_resolution
            width = 256
        if width is None:
            width = max(1, int(round(height / aspect)))
        if height is None:
            height = max(1, int(round(width * aspect)))
        return int(width), int(height)


@dataclass
class SceneDesc:
    path: str
    camera: Camera
    meshes: list[Mesh] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    assets: list[AssetInstance] = field(default_factory=list)
    render_settings: dict = field(default_factory=dict)  # max_depth, pixel_filter, pixel_filter_stddev where authored


def _float_attr(prim, name: str, default: float, t) -> float:
    """Attribute ``name`` of ``prim`` as a float (``default`` when unauthored), NaN when it is not a number."""
    attr = prim.GetAttribute(name)
    v = attr.Get(t) if attr else None
    try:
        return float(default if v is None else v)
    except (TypeError, ValueError):
        return float("nan")


def _read_camera(prim, to_world, path, t) -> Camera:
    """spec/renderer.md#cameras: lens and apertures in tenths of a scene unit, focusDistance in scene units."""
    from pxr import UsdGeom

    cam = UsdGeom.Camera(prim)
    ppath = str(prim.GetPath())

    def get(name, default):
        v = _float_attr(prim, name, default, t)
        if not np.isfinite(v):
            raise SceneError("SCENE_INVALID", f"camera {name} is not a finite number", file=path, prim=ppath, attribute=name)
        return v

    projection = cam.GetProjectionAttr().Get(t) or "perspective"
    if projection not in ("perspective", "orthographic"):
        raise SceneError("SCENE_UNSUPPORTED", f"camera projection {projection!r}", file=path, prim=ppath)
    focal, ha = get("focalLength", 50.0), get("horizontalAperture", 20.955)
    va = get("verticalAperture", 15.2908)
    f_stop, focus = get("fStop", 0.0), get("focusDistance", 0.0)
    for name, v, positive in (("focalLength", focal, True), ("horizontalAperture", ha, True), ("verticalAperture", va, True),
                              ("fStop", f_stop, False), ("focusDistance", focus, False)):
        if v < 0 or (positive and v == 0):
            raise SceneError("SCENE_INVALID", f"camera {name} = {v!r} must be {'> 0' if positive else '>= 0'}", file=path,
                             prim=ppath, attribute=name)
    thin = projection == "perspective" and f_stop > 0 and focus > 0
    exposure = (2.0 ** get("exposure", 0.0) * get("exposure:responsivity", 1.0) * get("exposure:time", 1.0)
                * get("exposure:iso", 100.0) / 100.0 / get("exposure:fStop", 1.0) ** 2)
    if not (np.isfinite(exposure) and exposure >= 0):
        raise SceneError("SCENE_INVALID", "camera exposure scale is not finite and >= 0", file=path, prim=ppath)
    return Camera(ppath, to_world, focal, ha, va, get("horizontalApertureOffset", 0.0), get("verticalApertureOffset", 0.0),
                  projection == "orthographic", (0.05 * focal / f_stop) if thin else 0.0, focus if thin else 0.0, exposure)


def _m4(gf) -> np.ndarray:
    return np.array([[gf[i][j] for j in range(4)] for i in range(4)], np.float64)


#: bounds of spec/renderer.md#limits: |entry| of a world transform, |world coordinate| of a triangle vertex, a light's
#: exposure (stops) and intensity * 2^exposure * color (per channel)
MAX_TRANSFORM = 1e15
MAX_WORLD_COORDINATE = 1e12
MAX_LIGHT_EXPOSURE = 1000.0
MAX_LIGHT_SCALE = 1e30


def _checked_world(m: np.ndarray, path: str, prim: str, *, regular: bool = False) -> np.ndarray:
    """The world transform ``m`` [4, 4] of ``prim``, SCENE_INVALID unless finite with every entry <= MAX_TRANSFORM and,
    where ``regular`` (cameras, neural assets), |det M3| >= 1e-12 (spec/renderer.md#limits)."""
    if not np.isfinite(m).all() or np.abs(m).max() > MAX_TRANSFORM:
        raise SceneError("SCENE_INVALID", f"world transform is not finite or has an entry above {MAX_TRANSFORM:g}", file=path,
                         prim=prim, attribute="xformOpOrder")
    if regular and abs(np.linalg.det(m[:3, :3])) < 1e-12:
        raise SceneError("SCENE_INVALID", "world transform is singular", file=path, prim=prim, attribute="xformOpOrder")
    return m


def _world(cache, prim, path: str, *, regular: bool = False) -> np.ndarray:
    """:func:`_checked_world` transform of ``prim`` from the XformCache ``cache``."""
    return _checked_world(_m4(cache.GetLocalToWorldTransform(prim)), path, str(prim.GetPath()), regular=regular)


def _input(shader, name, default, t=None, per_hit: dict | None = None, textures: TextureReader | None = None):
    """A UsdPreviewSurface input's value, followed through connections to a material's or node graph's interface
    input (nasset_sdk.stage_rules.input_source). One fed by a shader output gives its own authored value, else
    ``default``; where that output is one :mod:`.usdtextures` reads per hit (a UsdUVTexture on diffuseColor, roughness or
    metallic, a UsdPrimvarReader_float3 on diffuseColor), it goes into ``per_hit`` (its Texture, or ("color", (primvar,
    fallback))) and a texture that cannot be read gives its authored fallback; any other is warned about."""
    from pxr import Usd

    producer, v = stage_rules.input_source(shader.GetInput(name), Usd.TimeCode.Default() if t is None else t)
    if producer is None:
        return default if v is None else v
    node, output = producer[0], str(producer[1])
    nid = node.GetIdAttr().Get()
    if per_hit is not None and textures is not None:
        if name == "diffuseColor" and nid == "UsdPrimvarReader_float3":
            per_hit["color"] = primvar_color(node, textures.t, textures.scene)
            return default if v is None else v
        if nid == "UsdUVTexture" and output in PER_HIT_INPUTS.get(name, ()):
            tex = textures.read(node, output)
            if tex is not None:
                per_hit[name] = tex
            else:
                fallback = texture_fallback(node, output, textures.t)
                v = v if fallback is None else fallback
            return default if v is None else v
    # spec/renderer.md#limits, unsupported shading: the input's own value, else the fallback
    warnings.warn(f"{shader.GetPath()}.inputs:{name} is connected to {node.GetPath()}.outputs:{output}; it is not rendered "
                  "here (the input's own value, else the fallback, is used)", stacklevel=3)
    return default if v is None else v


#: surface shaders read as UsdPreviewSurface (spec/renderer.md#limits, surface shaders)
PREVIEW_SURFACES = stage_rules.PREVIEW_SURFACES


def _checked(value, n: int, name: str, path: str, shader: str, top: float = np.inf) -> np.ndarray:
    """A shader input as ``n`` float64 values clamped to [0, top] (spec/renderer.md#limits, input ranges; ``ior`` and
    ``useSpecularWorkflow`` unclamped); ``SCENE_INVALID`` naming the input when it is not finite numbers."""
    try:
        v = np.asarray(value, np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.full(1, np.nan)
    if len(v) != n or not np.isfinite(v).all():
        raise SceneError("SCENE_INVALID", f"{name} = {value!r} is not {n} finite number(s)", file=path, prim=shader,
                         attribute=f"inputs:{name}")
    if name in ("ior", "useSpecularWorkflow"):
        return v
    return np.clip(v, 0.0, top)


def _display_opacity(prim, say, t, primvars: stage_rules.InheritedPrimvars) -> tuple | None:
    """An unbound prim's presence (spec/renderer.md#cutouts): its ``displayOpacity`` (its mean, warned when several
    values), as an opacity without a threshold; None where it is opaque."""
    do = primvars.find(prim, "displayOpacity")
    opacity = do.Get(t) if do is not None else None
    opacity = np.asarray(opacity, np.float64).ravel() if opacity is not None and len(opacity) else None
    if opacity is None or not np.isfinite(opacity).all() or opacity.mean() >= 1.0:
        return None
    if len(opacity) > 1:
        say(f"displayOpacity of {len(opacity)} values read as their mean", str(prim.GetPath()))
    return float(np.clip(opacity.mean(), 0.0, 1.0)), 0.0


def _display_color(prim, say, t, primvars: stage_rules.InheritedPrimvars, per_hit: dict | None = None) -> np.ndarray:
    """An unbound prim's diffuse colour (spec/renderer.md#limits, unbound meshes): its ``displayColor`` primvar, else a
    constant one of an ancestor; 0.18 grey without one. Several values are their mean; with ``per_hit`` they are also
    interpolated per hit (``per_hit["color"]``, spec/renderer.md#primvar-colors), else warned about."""
    dc = primvars.find(prim, "displayColor")
    val = dc.Get(t) if dc is not None else None
    val = np.asarray(val, np.float64).reshape(-1, 3) if val is not None and len(val) else None
    if val is None or not np.isfinite(val).all():
        return np.full(3, 0.18)
    if len(val) > 1 and per_hit is not None:
        per_hit["color"] = ("displayColor", np.full(3, 0.18))
    elif len(val) > 1:
        say(f"displayColor of {len(val)} values read as their mean (not interpolated per hit)", str(prim.GetPath()))
    return np.clip(val.mean(0), 0.0, 1.0)


def _say(path: str):
    """The ``warn(message, prim)`` of nasset_sdk.stage_rules for the scene ``path``."""
    def say(message: str, prim: str | None) -> None:
        warnings.warn(f"{path}:{prim}: {message}" if prim else f"{path}: {message}", stacklevel=3)
    return say


def read_material(prim, path, t=None, purposes: stage_rules.Purposes | None = None, material=None,
                  primvars: stage_rules.InheritedPrimvars | None = None,
                  bindings: stage_rules.MaterialBindings | None = None, textures: TextureReader | None = None) -> Material:
    """The material bound to ``prim`` (or the UsdShade.Material ``material`` itself); ``primvars`` and ``bindings``:
    the scene's inherited primvars and material bindings, remembered across the meshes of one traversal; ``textures``:
    the scene's texture reader (without it, inputs fed by textures are warned about and read as their own values)."""
    say = _say(path)
    kd = np.array([0.18, 0.18, 0.18])
    spec, rough, metal, use_spec, ior = np.zeros(3), 0.5, 0.0, 0, 1.5
    emis = np.zeros(3)
    per_hit: dict = {}
    mat = material
    if mat is None:
        mat = stage_rules.bound_material(prim, purposes or DEFAULT_PURPOSES, say, bindings)
    presence = glass = None
    if not mat:
        kd = _display_color(prim, say, t, primvars or stage_rules.InheritedPrimvars(), per_hit if textures else None)
        presence = _display_opacity(prim, say, t, primvars or stage_rules.InheritedPrimvars())
    else:
        shader = stage_rules.surface_shader(mat)
        if shader is None:
            raise SceneError("SCENE_UNSUPPORTED", "material has no surface shader on outputs:surface or outputs:mtlx:surface",
                             file=path, prim=str(mat.GetPath()))
        sid = shader.GetIdAttr().Get()
        if sid not in PREVIEW_SURFACES and sid not in stage_rules.MTLX_SURFACES:
            raise SceneError("SCENE_UNSUPPORTED", f"shader {sid!r} is not one of "
                             f"{', '.join(PREVIEW_SURFACES + tuple(stage_rules.MTLX_SURFACES))}", file=path,
                             prim=str(shader.GetPath()))
        where = str(shader.GetPath())
    if mat and sid in stage_rules.MTLX_SURFACES:  # read as UsdPreviewSurface values (spec/renderer.md#materials)
        def finite(v, default, name):
            out = _checked(default if v is None else v, int(np.size(default)), name, path, where)
            return out if np.size(default) > 1 else float(out[0])

        vals = stage_rules.mtlx_preview_values(shader, sid, t, say, finite)
        kd = np.asarray(vals["diffuseColor"], np.float64)
        rough, metal = (float(np.clip(vals[k], 0.0, 1.0)) for k in ("roughness", "metallic"))
        ior, emis = vals["ior"], np.asarray(vals["emissiveColor"], np.float64)
        if ior <= 0:
            raise SceneError("SCENE_INVALID", f"ior = {ior!r} must be > 0", file=path, prim=where, attribute="inputs:specular_IOR")
        if vals["transmission"] > 0.0:
            glass = (vals["transmission"], np.asarray(vals["transmissionColor"], np.float64), float(ior),
                     bool(vals["thinWalled"]), np.asarray(vals["specularTint"], np.float64))
    elif mat:
        kd = _checked(_input(shader, "diffuseColor", kd, t, per_hit, textures), 3, "diffuseColor", path, where, 1.0)
        spec = _checked(_input(shader, "specularColor", spec, t), 3, "specularColor", path, where, 1.0)
        rough = float(_checked(_input(shader, "roughness", rough, t, per_hit, textures), 1, "roughness", path, where, 1.0)[0])
        metal = float(_checked(_input(shader, "metallic", metal, t, per_hit, textures), 1, "metallic", path, where, 1.0)[0])
        use_spec = int(_checked(_input(shader, "useSpecularWorkflow", use_spec, t), 1, "useSpecularWorkflow", path, where)[0])
        ior = float(_checked(_input(shader, "ior", ior, t), 1, "ior", path, where)[0])
        if ior <= 0:
            raise SceneError("SCENE_INVALID", f"ior = {ior!r} must be > 0", file=path, prim=where, attribute="inputs:ior")
        emis = _checked(_input(shader, "emissiveColor", emis, t, per_hit, textures), 3, "emissiveColor", path, where)
        if "emissiveColor" in per_hit:  # spec/renderer.md#textures: its mean is the material's constant
            tex = per_hit["emissiveColor"]
            emis = np.maximum(tex.image.reshape(-1, 3).mean(0, dtype=np.float64) * tex.scale + tex.bias, 0.0)
        if shader.GetInput("normal"):  # a tangent-space normal map (spec/renderer.md#normal-maps), else warned
            _input(shader, "normal", None, t, per_hit, textures)
        opacity = float(_checked(_input(shader, "opacity", 1.0, t, per_hit, textures), 1, "opacity", path, where, 1.0)[0])
        threshold = float(_checked(_input(shader, "opacityThreshold", 0.0, t), 1, "opacityThreshold", path, where, 1.0)[0])
        if "opacity" in per_hit or opacity < (threshold if threshold > 0 else 1.0):  # spec/renderer.md#cutouts
            presence = (opacity, threshold)
    beckmann = bool(mat) and stage_rules.shader_microfacet(shader, t, path) == "beckmann"
    r0 = ((1.0 - ior) / (1.0 + ior)) ** 2
    if use_spec == 1:
        k, f0 = kd.copy(), spec
    else:
        k = kd * (1.0 - metal)
        f0 = r0 * (1.0 - metal) + kd * metal
    hit = None
    if per_hit:
        color = per_hit.pop("color", None)
        textured = {name: per_hit[name] for name in PER_HIT_INPUTS if name in per_hit and not (name == "diffuseColor" and color)}
        varnames = sorted({tex.varname for tex in textured.values()})
        if len(varnames) > 1:
            say(f"textures read different primvars {varnames}; all are read at {next(iter(textured.values())).varname!r}",
                str(mat.GetPath()) if mat else str(prim.GetPath()))
        hit = PerHit(np.asarray(kd, np.float64), rough, None if use_spec == 1 else metal, np.asarray(spec, np.float64), r0,
                     textured, color)
    return Material(kd=k, f0=np.asarray(f0, np.float64), alpha=max(rough * rough, 1e-3), emission=emis, specular=True,
                    per_hit=hit, presence=presence, glass=glass, beckmann=beckmann)


DEFAULT_PURPOSES = stage_rules.Purposes(frozenset({"default", "render"}), "full")


def _asset_target(prim) -> str | None:
    """File of the first reference/payload on ``prim`` with an asset path (resolved against its layer)."""
    from pxr import Sdf

    for spec in prim.GetPrimStack():
        for key in ("references", "payload"):
            if not spec.HasInfo(key):
                continue
            op = spec.GetInfo(key)
            items = list(op.explicitItems) + list(op.prependedItems) + list(op.appendedItems) + list(op.addedItems)
            for it in items:
                if it.assetPath:
                    return os.path.normpath(Sdf.ComputeAssetPathRelativeToLayer(spec.layer, it.assetPath))
    return None


def _asset_to_world(prim, cache) -> np.ndarray:
    """Local-to-world of an asset prim. With its payload unloaded an untyped prim is not (yet) a
    UsdGeom.Xformable, so UsdGeom's cache would ignore its xformOps: read them explicitly."""
    from pxr import Usd, UsdGeom

    xf = UsdGeom.Xformable(prim)
    local = _m4(xf.GetLocalTransformation(Usd.TimeCode.Default()))
    if xf.GetResetXformStack():
        return local
    return local @ _m4(cache.GetLocalToWorldTransform(prim.GetParent()))


def _units_warning(stage, file: str, to_world, prim: str, say) -> None:
    """nasset_sdk.stage_rules.units_warning with the metersPerUnit of the asset's layer (already open: composed)."""
    from pxr import Sdf

    layer = Sdf.Layer.FindOrOpen(file) if os.path.isfile(file) else None
    if layer is not None:
        stage_rules.units_warning(stage, float(layer.pseudoRoot.GetInfo("metersPerUnit") or 1.0), to_world, prim, say)


def _looks_like_asset(file: str) -> bool:
    from pxr import Sdf

    from nasset_sdk.safeopen import ensure_safe

    if not os.path.isfile(file):  # never open a pipe or device
        return False
    ensure_safe(file)  # probed in a child first (spec/security.md#bounds)
    try:
        layer = Sdf.Layer.FindOrOpen(file)
    except Exception:
        return False
    if layer is None or not layer.defaultPrim:
        return False
    spec = layer.GetPrimAtPath("/" + layer.defaultPrim)
    return spec is not None and spec.typeName == "NeuralAsset"


def _read_exr(path: str, light_prim: str, scene: str) -> np.ndarray:
    """A dome texture [H, W, 3] float64 through the SDK's bounded reader (nasset_sdk.images.read_exr: header, size
    and chunk table checked before OpenEXR decodes): ``IMAGE_INVALID`` for a file it refuses, ``SCENE_INVALID`` for
    pixels that are not finite and >= 0, as the reference renderer."""
    from nasset_sdk.errors import NassetError
    from nasset_sdk.images import local_image_copy, read_exr

    where = dict(file=scene, prim=light_prim, attribute="inputs:texture:file")
    try:
        with local_image_copy(path) as local:  # a file inside a package (usdz): a temporary copy
            img = read_exr(local)
    except NassetError as exc:
        raise SceneError("IMAGE_INVALID", f"dome texture {path}: {exc.message}", **where) from None
    if not np.isfinite(img).all() or (img < 0).any():
        raise SceneError("SCENE_INVALID", f"dome texture {path} holds NaN/Inf or negative values", **where)
    return img.astype(np.float64)


def read_scene(path: str) -> SceneDesc:
    from pxr import Tf, Usd, UsdGeom, UsdLux

    import nasset_sdk  # noqa: F401  (registers the codeless schema so NeuralAsset is a known type)
    from nasset_sdk.paths import open_checked_stage
    from nasset_sdk.references import asset_source, embedded_asset_file

    path = str(path)
    if not os.path.exists(path):
        raise SceneError("SCENE_INVALID", "scene file does not exist", file=path)
    try:
        # untrusted input (spec/security.md#paths): every layer the scene reaches is probed and its paths checked first
        stage = open_checked_stage(path, Usd.Stage.LoadNone, scene=True)
    except Tf.ErrorException as exc:
        raise SceneError("SCENE_INVALID", f"scene does not open: {str(exc).splitlines()[0][:200]}", file=path) from None
    if stage is None:
        raise SceneError("SCENE_INVALID", "USD cannot open it", file=path)
    stage_rules.load_scene_payloads(stage)  # plain geometry placed with a payload is part of the scene
    # the render time of spec/renderer.md#traversal: the stage's start, else each attribute's default or first sample
    t = stage_rules.render_time(stage)
    cache = UsdGeom.XformCache(t)
    say = _say(path)
    broken: dict = {}
    for where, text in stage_rules.composition_errors(stage):  # USD composes the stage without what failed
        broken.setdefault(where, text)
        say(f"composed without a layer or prim USD cannot reach: {text[:300]}", where if where != "/" else None)
    settings = stage_rules.settings_prim(stage, say)  # spec/renderer.md#image-size
    purposes = stage_rules.settings_purposes(settings, t, say)
    hiding = stage_rules.Hiding(t, purposes)
    inherited = stage_rules.InheritedPrimvars()  # displayColor of unbound meshes, O(1) per mesh however deep
    bindings = stage_rules.MaterialBindings()  # bound materials, O(1) per mesh however deep
    reading = _Reading(path, t, purposes, inherited, bindings, TextureReader(path, t, say), {}, say)
    cameras = stage_rules.stage_cameras(stage)  # whatever their visibility and purpose
    meshes, lights, assets = [], [], []
    # unloaded payload prims (assets placed with a payload arc) are not "loaded": traverse them too
    it = iter(Usd.PrimRange(stage.GetPseudoRoot(), Usd.TraverseInstanceProxies(Usd.PrimIsActive & Usd.PrimIsDefined & ~Usd.PrimIsAbstract)))
    for prim in it:
        if prim.IsPseudoRoot():
            continue
        if hiding.is_hidden(prim):  # invisible, or a purpose the settings leave out
            it.PruneChildren()
            continue
        tn = prim.GetTypeName()
        ppath = str(prim.GetPath())
        source = asset_source(prim)  # the asset's root reached through composition, whatever the prim's type
        if source is not None or tn == "NeuralAsset" or (tn == "" and (prim.HasAuthoredReferences() or prim.HasAuthoredPayloads())):
            if source is not None and source.embedded:  # a flattened scene: the asset is read from a copy of its specs
                file = embedded_asset_file(source)
            else:
                file = source.layer if source is not None else _asset_target(prim)
            if source is None and tn == "" and ppath in broken:  # spec/renderer.md#scene-input
                raise SceneError("SCENE_INVALID", f"referenced asset file not found, or it is not a neural asset: {file} "
                                 f"({broken[ppath]})", file=path, prim=ppath)
            if source is not None or tn == "NeuralAsset" or (file and _looks_like_asset(file)):
                it.PruneChildren()
                if not file:
                    raise SceneError("SCENE_INVALID", "NeuralAsset prim references no asset file", file=path, prim=ppath)
                assets.append(AssetInstance(ppath, file, _checked_world(_asset_to_world(prim, cache), path, ppath, regular=True)))
                _units_warning(stage, file, assets[-1].to_world, ppath, say)
                continue
        if tn == "Camera":
            continue
        if tn in _LIGHTS:
            lights.append(_read_light(prim, tn, _world(cache, prim, path), path, t))
            continue
        if tn == "Mesh" or tn in ("BasisCurves", "Points") or tn in IMPLICIT_PRIMS:
            meshes.extend(_gprim_meshes(prim, tn, _world(cache, prim, path), reading))
            continue
        if tn == "PointInstancer":  # its subtree renders only as its instances (spec/renderer.md#geometry)
            it.PruneChildren()
            meshes.extend(_point_instancer(prim, cache, reading))
            continue
        if tn in _STRUCTURAL:
            continue
        if prim.HasAPI(UsdLux.LightAPI) or tn.endswith("Light") or prim.IsA(UsdGeom.Gprim):
            raise SceneError("SCENE_UNSUPPORTED", f"prim type {tn!r} is not supported", file=path, prim=ppath)
        warnings.warn(f"{ppath}: prim type {tn!r} ignored", stacklevel=2)
    for mesh in meshes:  # spec/renderer.md#limits: float32 ray casting
        big = float(np.abs(mesh.points).max(initial=0.0))
        if big > MAX_WORLD_COORDINATE:
            raise SceneError("SCENE_INVALID", f"world coordinates up to {big:.3g} exceed the bound {MAX_WORLD_COORDINATE:g}",
                             file=path, prim=mesh.prim, attribute="xformOpOrder")
    chosen = stage_rules.render_camera(stage, settings, path, say, cameras)
    camera = _read_camera(chosen, _world(cache, chosen, path, regular=True), path, t)
    camera.settings_resolution = stage_rules.settings_resolution(stage, settings, t, say, MAX_SETTINGS_PIXELS)
    stage_rules.conform_warning(settings, t, camera.settings_resolution, camera.h_aperture, camera.v_aperture, say)
    return SceneDesc(path, camera, meshes, lights, assets, stage_rules.nasset_settings(settings, t, say))


@dataclass
class _Reading:
    """What the geometry readers of one :func:`read_scene` share."""
    path: str  # the scene file
    t: object  # the render time (Usd.TimeCode)
    purposes: stage_rules.Purposes
    primvars: stage_rules.InheritedPrimvars
    bindings: stage_rules.MaterialBindings
    textures: TextureReader  # each image decoded once
    tessellations: dict  # (type, sizes, axis) -> implicit_mesh(...)
    say: object  # warn(message, prim path)


def _gprim_meshes(prim, tn: str, mw, r: _Reading) -> list[Mesh]:
    """The meshes of a Mesh (one per material group), BasisCurves, Points or implicit prim placed by ``mw`` (4x4, row
    vectors: its world transform, or a PointInstancer prototype part's); [] when it draws nothing (warned)."""
    from pxr import UsdGeom

    path, t, ppath = r.path, r.t, str(prim.GetPath())
    if tn in ("BasisCurves", "Points"):  # tubes and spheres (spec/renderer.md#curves-and-points)
        mesh = _curves_or_points(prim, tn, mw, t, r.say)
        if mesh is None:
            return []
        mesh.back_material = _sidedness(prim, np.eye(4), path, t, r.purposes)[1]
        mesh.material = read_material(prim, path, t, r.purposes, primvars=r.primvars, bindings=r.bindings)
        return [mesh]
    if tn in IMPLICIT_PRIMS:
        mesh = _implicit_mesh(prim, tn, mw, path, t, r.tessellations)
        mesh.one_sided, mesh.back_material, mesh.front_sign = _sidedness(prim, mw, path, t, r.purposes)
        mesh.material = read_material(prim, path, t, r.purposes, primvars=r.primvars, bindings=r.bindings, textures=r.textures)
        if mesh.material.per_hit is not None:
            n = len(mesh.faces)
            layout = (mesh.faces, np.arange(3 * n).reshape(n, 3), np.arange(n), len(mesh.points), 3 * n, n)
            _per_hit_corners(mesh, prim, mesh.material.per_hit, layout, slice(None), r.primvars, t, r.say)
        r.say(f"implicit {tn} tessellated into {len(mesh.faces)} triangles", ppath)
        return [mesh]
    m = UsdGeom.Mesh(prim)
    pts = np.asarray(m.GetPointsAttr().Get(t) or [], np.float64).reshape(-1, 3)
    counts = np.asarray(m.GetFaceVertexCountsAttr().Get(t) or [], np.int64)
    idx = np.asarray(m.GetFaceVertexIndicesAttr().Get(t) or [], np.int64)
    if len(pts) == 0 or len(counts) == 0:
        warnings.warn(f"{ppath}: empty mesh ignored", stacklevel=3)
        return []
    if counts.sum() != len(idx) or np.any(counts < 3) or idx.min() < 0 or idx.max() >= len(pts):
        raise SceneError("SCENE_INVALID", "mesh topology is invalid", file=path, prim=ppath, attribute="faceVertexIndices")
    if not np.isfinite(pts).all():
        raise SceneError("SCENE_INVALID", "mesh points are not finite", file=path, prim=ppath, attribute="points")
    faces, corners, face_of = [], [], []
    start = 0
    for fi, c in enumerate(counts):  # fan triangulation
        f = idx[start:start + c]
        faces.extend([(f[0], f[k], f[k + 1]) for k in range(1, c - 1)])
        corners.extend([(start, start + k, start + k + 1) for k in range(1, c - 1)])
        face_of.extend([fi] * (c - 2))
        start += c
    wp = pts @ mw[:3, :3] + mw[3, :3]
    one_sided, back, sign = _sidedness(prim, mw, path, t, r.purposes)
    faces = np.asarray(faces, np.int64)
    face_of = np.asarray(face_of, np.int64)
    layout = (faces, np.asarray(corners, np.int64), face_of, len(pts), len(idx), len(counts))
    cn = _corner_normals(prim, layout, (pts, counts, idx), mw, t, sign)
    out = []
    for where, binding, sel in _face_groups(m, face_of, len(counts), path, t, r.purposes, r.bindings):
        material = read_material(binding, path, t, r.purposes, primvars=r.primvars, bindings=r.bindings, textures=r.textures)
        mesh = Mesh(where, *_used_points(wp, faces[sel]), material, None if cn is None else cn[sel], one_sided, back, sign)
        if material.per_hit is not None:
            _per_hit_corners(mesh, prim, material.per_hit, layout, sel, r.primvars, t, r.say)
        out.append(mesh)
    return out


def _used_points(points: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the points ``faces`` use, the faces renumbered to them): a material group of a mesh carries its own points only,
    so a mesh of many GeomSubsets does not repeat all its points per subset (and per instance when instanced)."""
    if len(faces) and len(points) <= 3 * len(faces) and np.bincount(faces.ravel(), minlength=len(points)).all():
        return points, faces  # every point used: nothing to drop
    used, renumbered = np.unique(faces, return_inverse=True)
    return points[used], renumbered.reshape(faces.shape).astype(faces.dtype)


#: instances of one PointInstancer, checked before USD computes their transforms; triangles its instances may add
#: (the reference renderer's bounds, spec/renderer.md#limits)
MAX_INSTANCES = 1 << 20
MAX_INSTANCED_TRIANGLES = 1 << 24


def _point_instancer(prim, cache, r: _Reading) -> list[Mesh]:
    """The instances of a PointInstancer (spec/renderer.md#geometry): each instance whose mask entry is true renders
    its prototype's meshes, curves, points and implicit prims (visible, not of a purpose left out, by their own
    attributes), placed by ``M_prim · M_root⁻¹ · X_i · M_instancer``. A prototype's parts are read once, placed
    relative to its root, and the instances of a part are one Mesh (two where some of them mirror: the front sign is
    per mesh). A neural asset, a nested PointInstancer or another geometry type in a prototype is
    ``SCENE_UNSUPPORTED``; a light in one is warned about (it is not instanced)."""
    from pxr import Usd, UsdGeom, UsdLux

    from nasset_sdk.references import asset_source

    path, t, ppath = r.path, r.t, str(prim.GetPath())
    where = dict(file=path, prim=ppath, attribute="protoIndices")
    pi = UsdGeom.PointInstancer(prim)
    protos = [prim.GetStage().GetPrimAtPath(p) for p in pi.GetPrototypesRel().GetForwardedTargets()]
    indices = np.asarray(pi.GetProtoIndicesAttr().Get(t) or [], np.int64)
    if len(indices) > MAX_INSTANCES:
        raise SceneError("SCENE_INVALID", f"{len(indices)} instances, more than {MAX_INSTANCES}", **where)
    xforms = pi.ComputeInstanceTransformsAtTime(t, t, UsdGeom.PointInstancer.IncludeProtoXform,
                                                UsdGeom.PointInstancer.IgnoreMask)  # the mask is applied below
    if xforms is None or len(xforms) != len(indices):
        raise SceneError("SCENE_INVALID", "PointInstancer instances cannot be computed (protoIndices, positions, "
                         "orientations, scales or the prototypes disagree)", **where)
    if len(indices) and (indices.min() < 0 or indices.max() >= len(protos) or not all(protos)):
        raise SceneError("SCENE_INVALID", "protoIndices name a prototype that is missing", **where)
    mask = np.asarray(pi.ComputeMaskAtTime(t) or [True] * len(indices), bool)
    placements = np.asarray(xforms, np.float64).reshape(-1, 4, 4) @ _world(cache, prim, path)
    if not np.isfinite(placements[mask]).all() or (len(placements) and np.abs(placements[mask]).max(initial=0) > MAX_TRANSFORM):
        raise SceneError("SCENE_INVALID", f"an instance transform is not finite or has an entry above {MAX_TRANSFORM:g} "
                         "(positions, orientations or scales)", file=path, prim=ppath, attribute="positions")
    out, added = [], 0
    for k, root in enumerate(protos):
        parts = []
        walk = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies()))
        for p in walk:
            img = UsdGeom.Imageable(p)
            if img and (img.GetVisibilityAttr().Get(t) == UsdGeom.Tokens.invisible
                        or img.GetPurposeAttr().Get(t) not in r.purposes.included):
                walk.PruneChildren()
                continue
            tn = str(p.GetTypeName())
            if asset_source(p) is not None or tn in ("NeuralAsset", "PointInstancer"):
                raise SceneError("SCENE_UNSUPPORTED", f"a {tn or 'neural asset'} as a PointInstancer prototype (meshes, "
                                 "curves, points and implicit prims are rendered)", file=path, prim=str(p.GetPath()))
            if tn in ("Mesh", "BasisCurves", "Points") or tn in IMPLICIT_PRIMS:
                parts.append((p, tn))
            elif p.IsA(UsdGeom.Gprim):
                raise SceneError("SCENE_UNSUPPORTED", f"geometry type {tn} in a PointInstancer prototype is not supported",
                                 file=path, prim=str(p.GetPath()))
            elif p.HasAPI(UsdLux.LightAPI) or tn.endswith("Light"):
                r.say("a light in a PointInstancer prototype is not instanced: it does not light the scene", str(p.GetPath()))
        chosen = placements[mask & (indices == k)]
        if not parts or not len(chosen):
            continue
        root_m = _m4(cache.GetLocalToWorldTransform(root))
        if not np.isfinite(root_m).all() or abs(np.linalg.det(root_m[:3, :3])) < 1e-30:
            raise SceneError("SCENE_INVALID", "a prototype root's transform is singular or not finite", file=path,
                             prim=str(root.GetPath()), attribute="xformOpOrder")
        to_root = np.linalg.inv(root_m)
        for p, tn in parts:
            for mesh in _gprim_meshes(p, tn, _world(cache, p, path) @ to_root, r):
                added += len(mesh.faces) * len(chosen)
                if added > MAX_INSTANCED_TRIANGLES:
                    raise SceneError("SCENE_INVALID", f"the instances add more than {MAX_INSTANCED_TRIANGLES} triangles",
                                     **where)
                out.extend(_placed(mesh, chosen))
    return out


def _placed(mesh: Mesh, placements: np.ndarray) -> list[Mesh]:
    """``mesh`` (placed relative to its prototype root) moved by each of ``placements`` [n, 4, 4] (row vectors), as
    one Mesh of n copies, or two when some placements mirror and others do not (a mirroring placement flips the
    front sign, as a mirroring world transform does)."""
    out = []
    mirrors = np.linalg.det(placements[:, :3, :3]) < 0
    for flip in (False, True):
        P = placements[mirrors == flip]
        if not len(P):
            continue
        n, v = len(P), len(mesh.points)
        points = (mesh.points[None] @ P[:, :3, :3] + P[:, None, 3, :3]).reshape(-1, 3)
        faces = (mesh.faces[None] + v * np.arange(n)[:, None, None]).reshape(-1, 3)
        normals = None
        if mesh.corner_normals is not None:  # by each placement's inverse transpose (or its limit), then unit length again
            nrm = (mesh.corner_normals[None].reshape(1, -1, 3) @ stage_rules.normal_matrix(P[:, :3, :3])).reshape(-1, 3, 3)
            normals = nrm / np.maximum(np.linalg.norm(nrm, axis=-1, keepdims=True), 1e-300)
        out.append(Mesh(mesh.prim, points, faces, mesh.material, normals, mesh.one_sided, mesh.back_material,
                        -mesh.front_sign if flip else mesh.front_sign, _tiled(mesh.corner_st, n), _tiled(mesh.corner_colors, n)))
    return out


def _tiled(corner_values: np.ndarray | None, n: int) -> np.ndarray | None:
    """Per-corner values [F, 3, C] of one copy repeated for n copies [n * F, 3, C]."""
    return None if corner_values is None else np.tile(corner_values, (n, 1, 1))


def _sidedness(prim, mw, path, t, purposes):
    """(one-sided, back material or None, front sign) of a mesh (spec/renderer.md#sidedness): ``doubleSided`` authored
    false; the Material of ``nasset:backMaterial`` (another target is SCENE_INVALID); the front is the world winding's
    normal, reversed when ``orientation`` is leftHanded or the world transform mirrors (not both)."""
    from pxr import UsdGeom, UsdShade

    gp = UsdGeom.Gprim(prim)
    attr = gp.GetDoubleSidedAttr()
    one_sided = bool(attr and attr.HasAuthoredValue() and not attr.Get(t))
    back = None
    rel = prim.GetRelationship("nasset:backMaterial")
    targets = rel.GetForwardedTargets() if rel else []
    if targets:
        mat = UsdShade.Material(prim.GetStage().GetPrimAtPath(targets[0]))
        if not mat:
            raise SceneError("SCENE_INVALID", f"nasset:backMaterial {targets[0]} is not a Material", file=path, prim=str(prim.GetPath()),
                             attribute="nasset:backMaterial")
        back = read_material(prim, path, t, purposes, material=mat)
    left = (gp.GetOrientationAttr().Get(t) or UsdGeom.Tokens.rightHanded) == UsdGeom.Tokens.leftHanded
    mirrored = float(np.linalg.det(mw[:3, :3])) < 0
    return one_sided, back, -1.0 if left != mirrored else 1.0


def _face_groups(mesh, face_of, n_faces: int, path: str, t, purposes: stage_rules.Purposes,
                 bindings: stage_rules.MaterialBindings | None = None) -> list:
    """[(prim path, prim whose binding shades them, triangle mask)] of a mesh (spec/renderer.md#materials): the faces of
    each ``materialBind`` GeomSubset of element type face with a bound material (the first subset listing a face
    wins), the rest under the mesh's own binding; ``holeIndices`` faces left out."""
    from pxr import UsdGeom, UsdShade

    owner = np.full(n_faces, -1, np.int64)
    groups = []
    for subset in UsdShade.MaterialBindingAPI(mesh.GetPrim()).GetMaterialBindSubsets():
        if subset.GetElementTypeAttr().Get(t) != UsdGeom.Tokens.face:
            _say(path)("GeomSubset of an element type other than face ignored", str(subset.GetPath()))
            continue
        if not stage_rules.bound_material(subset.GetPrim(), purposes, _say(path), bindings):
            continue
        ind = np.asarray(subset.GetIndicesAttr().Get(t) or [], np.int64)
        if len(ind) and (ind.min() < 0 or ind.max() >= n_faces):
            raise SceneError("SCENE_INVALID", "GeomSubset face indices outside the mesh", file=path, prim=str(subset.GetPath()),
                             attribute="indices")
        free = ind[owner[ind] < 0]
        owner[free] = len(groups)
        groups.append((str(subset.GetPath()), subset.GetPrim()))
    holes = np.asarray(mesh.GetHoleIndicesAttr().Get(t) or [], np.int64)
    if len(holes):
        if holes.min() < 0 or holes.max() >= n_faces:
            raise SceneError("SCENE_INVALID", "hole indices outside the mesh", file=path, prim=str(mesh.GetPath()),
                             attribute="holeIndices")
        owner[holes] = -2
    out = [(where, prim, owner[face_of] == k) for k, (where, prim) in enumerate(groups)]
    rest = owner[face_of] == -1
    out.append((str(mesh.GetPath()), mesh.GetPrim(), rest))
    return [g for g in out if g[2].any()]


#: triangles one curves or points prim may add (the reference renderer's bound)
MAX_CURVE_TRIANGLES = 1 << 24


def _curves_or_points(prim, tname: str, mw, t, say) -> Mesh | None:
    """A BasisCurves or Points prim as its tubes or spheres in the world (nasset_sdk.curves, this package's fiber
    tessellation), corner normals outward (its front: a mirroring transform winds the triangles the other way); None,
    warned, when it has nothing to draw. Material and back material are the caller's."""
    from .rna import fiber_tubes

    def tessellate(points, counts, widths):
        return fiber_tubes(points, counts, widths, curves.TUBE_SIDES)[:5]

    where = str(prim.GetPath())
    mesh = curves.curves_or_points_mesh(prim, tname, t, tessellate, lambda m: say(m, where), MAX_CURVE_TRIANGLES)
    if mesh is None:
        return None
    local, faces, normals = mesh
    say(f"{tname} tessellated into {len(faces)} triangles", where)
    n = normals @ stage_rules.normal_matrix(mw[:3, :3])
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    front = -1.0 if float(np.linalg.det(mw[:3, :3])) < 0 else 1.0
    return Mesh(where, local @ mw[:3, :3] + mw[3, :3], faces, None, n, front_sign=front)


def _implicit_mesh(prim, tname: str, mw, path: str, t, tessellations: dict) -> Mesh:
    """An implicit prim (spec/renderer.md#implicit-prims) as the SDK's reference tessellation in the world, its corner
    normals on its front (a leftHanded prim's front is its inside); material and sides are the caller's to fill."""
    from pxr import UsdGeom

    size = {}
    for name, fallback in IMPLICIT_PRIMS[tname].items():
        v = _float_attr(prim, name, fallback, t)
        if not (np.isfinite(v) and 0 < v <= 1e12):  # the reference renderer's bound on world coordinates
            raise SceneError("SCENE_INVALID", f"{tname} {name} = {v!r} must be finite and > 0", file=path,
                             prim=str(prim.GetPath()), attribute=name)
        size[name] = v
    attr = prim.GetAttribute("axis")
    axis = str(attr.Get(t)) if attr and attr.Get(t) is not None else "Z"
    if axis not in ("X", "Y", "Z"):
        raise SceneError("SCENE_INVALID", f"{tname} axis {axis!r} (X, Y or Z)", file=path, prim=str(prim.GetPath()),
                         attribute="axis")
    key = (tname, tuple(size.items()), axis)
    if key not in tessellations:
        tessellations[key] = implicit_mesh(tname, size, axis)
    pts, faces, normals = tessellations[key]
    if UsdGeom.Gprim(prim).GetOrientationAttr().Get(t) == UsdGeom.Tokens.leftHanded:
        normals = -normals
    n = normals @ stage_rules.normal_matrix(mw[:3, :3])
    n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
    return Mesh(str(prim.GetPath()), pts @ mw[:3, :3] + mw[3, :3], faces, None, n)


def _per_hit_corners(mesh: Mesh, prim, hit: PerHit, layout: tuple, sel, primvars, t, say) -> None:
    """The texture coordinates and primvar colours at the corners of ``mesh`` (the faces ``sel`` of ``prim``) that its
    material reads per hit; a primvar that is missing or unusable gives its reader's fallback, with a warning."""
    where = str(prim.GetPath())
    if hit.textures:
        st = corner_values(primvars.find(prim, hit.varname), 2, layout, t)
        if st is None:
            say(f"textured material but no usable primvar {hit.varname!r} (float2, finite, vertex / faceVarying / uniform / "
                "constant): its reader's fallback is used", where)
            st = np.broadcast_to(next(iter(hit.textures.values())).st_fallback, (len(layout[0]), 3, 2))
        mesh.corner_st = np.ascontiguousarray(st[sel], np.float64)
    if hit.color is not None:
        varname, fallback = hit.color
        colors = corner_values(primvars.find(prim, varname), 3, layout, t)
        if colors is None:
            if varname != "displayColor":
                say(f"no usable colour primvar {varname!r} (float3, finite): its reader's fallback is used", where)
            colors = np.broadcast_to(fallback, (len(layout[0]), 3, 3))
        mesh.corner_colors = np.ascontiguousarray(colors[sel], np.float64)


def _corner_normals(prim, layout, polygons, mw, t, front_sign: float = 1.0):
    """World shading normals per triangle corner [F, 3, 3] (spec/renderer.md#shading-normals): the authored ones
    (primvars:normals, else normals; vertex, varying, faceVarying or uniform), else for a subdivision surface the
    smooth normals of its cage (on the front side: times ``front_sign``), else None. ``layout``: as
    :func:`.usdtextures.corner_values`'; ``polygons``: the mesh's (points, faceVertexCounts, faceVertexIndices)."""
    from pxr import UsdGeom

    pts, counts, idx = polygons
    pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
    vals, interp = None, None
    if pv and pv.HasAuthoredValue():
        vals, interp = pv.ComputeFlattened(t), pv.GetInterpolation()
        if vals is None:
            warnings.warn(f"{prim.GetPath()}: primvars:normals has indices outside its values: ignored", stacklevel=3)
    else:
        a = UsdGeom.Mesh(prim).GetNormalsAttr()
        if a and a.HasAuthoredValue():
            vals, interp = a.Get(t), UsdGeom.Mesh(prim).GetNormalsInterpolation()
    n = None
    if vals is not None and len(vals):
        v = np.asarray(vals, np.float64).reshape(-1, 3)
        n = at_corners(v, interp, layout, ("vertex", "varying", "faceVarying", "uniform"))
        if n is None:
            warnings.warn(f"{prim.GetPath()}: normals with interpolation {interp!r} and {len(v)} values ignored", stacklevel=3)
    if n is None:
        scheme = UsdGeom.Mesh(prim).GetSubdivisionSchemeAttr().Get(t)
        if scheme in (None, UsdGeom.Tokens.none):
            return None
        n = stage_rules.smooth_vertex_normals(pts, counts, idx, front_sign < 0)[layout[0]]  # a cage shades smooth, as usdview draws it
    n = n @ stage_rules.normal_matrix(mw[:3, :3])
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)


def _unhonoured_light_features(prim, path, t) -> None:
    """Warnings naming the light features this implementation does not render: light filters, diffuse and specular
    multipliers, shadows turned off (spec/renderer.md#lights)."""
    from pxr import UsdLux

    say = _say(path)
    where = str(prim.GetPath())
    filters = UsdLux.LightAPI(prim).GetFiltersRel().GetForwardedTargets() if prim.HasAPI(UsdLux.LightAPI) else []
    if filters:
        say(f"light:filters {', '.join(map(str, filters))} ignored", where)
    unhonoured = stage_rules.unrendered_light_inputs(prim, t)
    if unhonoured:
        say(f"{unhonoured} not rendered: the light lights every response and casts shadows", where)


def _shaping(prim, get, path, t) -> tuple | None:
    """(cone angle in degrees, softness in [0, 1], profile) of a light's UsdLux.ShapingAPI (spec/renderer.md#spot-lights),
    or None without it; ``shaping:focus`` and IES profiles are warned as ignored; a ``nasset:shaping:falloff`` other
    than ``linear`` / ``smoothstep`` is SCENE_INVALID. Whether the light is a point light is decided with its world
    radius (lights.build_lights)."""
    from pxr import UsdLux

    if not prim.HasAPI(UsdLux.ShapingAPI):
        return None
    say, where = _say(path), str(prim.GetPath())
    cone = float(get("shaping:cone:angle", 90.0))
    soft = float(np.clip(float(get("shaping:cone:softness", 0.0)), 0.0, 1.0))
    if not (np.isfinite(cone) and np.isfinite(soft)):
        raise SceneError("SCENE_INVALID", "shaping:cone:angle and shaping:cone:softness must be finite", file=path, prim=where)
    attr = prim.GetAttribute("nasset:shaping:falloff")
    profile = str(attr.Get(t)) if attr and attr.HasAuthoredValue() else "linear"
    if profile not in ("linear", "smoothstep"):
        raise SceneError("SCENE_INVALID", f"nasset:shaping:falloff {profile!r}: linear or smoothstep", file=path, prim=where,
                         attribute="nasset:shaping:falloff")
    if float(get("shaping:focus", 0.0)) != 0.0:
        say("shaping:focus ignored", where)
    ies = get("shaping:ies:file", None)
    if ies is not None and str(getattr(ies, "path", ies)):
        say("shaping:ies:file (IES profile) ignored", where)
    return cone, soft, profile


def _light_flag(prim, name: str, fallback: bool, path, t) -> bool:
    """A bool flag of a light (``nasset:cameraVisibility``, ``nasset:opaqueSurface``: spec/renderer.md#light-surfaces):
    ``fallback`` when unauthored; another type is SCENE_INVALID naming the attribute."""
    attr = prim.GetAttribute(name)
    if not attr or not attr.HasAuthoredValue():
        return fallback
    v = attr.Get(t)
    if not isinstance(v, bool):
        raise SceneError("SCENE_INVALID", f"{name} must be a bool (got {attr.GetTypeName()} {v!r})", file=path,
                         prim=str(prim.GetPath()), attribute=name)
    return v


def _read_light(prim, tn, mw, path, t) -> Light:
    from pxr import Sdf

    ppath = str(prim.GetPath())

    def get(name, default):
        a = prim.GetAttribute("inputs:" + name)
        if not a:
            a = prim.GetAttribute(name)
        v = a.Get(t) if a else None
        return default if v is None else v

    def invalid(message, attribute):
        return SceneError("SCENE_INVALID", message, file=path, prim=ppath, attribute=attribute)

    exposure = float(get("exposure", 0.0))
    if not (np.isfinite(exposure) and abs(exposure) <= MAX_LIGHT_EXPOSURE):  # spec/renderer.md#limits
        raise invalid(f"exposure {exposure!r} must be finite with |exposure| <= {MAX_LIGHT_EXPOSURE:g} stops", "inputs:exposure")
    color = np.asarray(get("color", (1.0, 1.0, 1.0)), np.float64)
    if bool(get("enableColorTemperature", False)):  # USD's own blackbody curve (spec/renderer.md#lights)
        from pxr import UsdLux

        kelvin = float(get("colorTemperature", 6500.0))
        if not (np.isfinite(kelvin) and 0 < kelvin <= MAX_LIGHT_SCALE):
            raise invalid(f"colorTemperature {kelvin!r} must be finite and > 0 (kelvin)", "inputs:colorTemperature")
        color = color * np.asarray(UsdLux.BlackbodyTemperatureAsRgb(kelvin), np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        rad = float(get("intensity", 1.0)) * np.exp2(exposure) * color
    if not np.isfinite(rad).all() or (rad < 0).any() or rad.max(initial=0.0) > MAX_LIGHT_SCALE:
        raise invalid(f"intensity * 2^exposure * color = {rad.tolist()} must be finite, >= 0 and <= {MAX_LIGHT_SCALE:g}",
                      "inputs:intensity")
    for name in ("angle", "radius", "width", "height", "length"):
        v = get(name, None)
        if v is not None and not np.isfinite(float(v)):
            raise invalid(f"inputs:{name} = {v!r} must be finite", f"inputs:{name}")
    lt = Light(ppath, tn, rad, mw, normalize=bool(get("normalize", False)))
    _unhonoured_light_features(prim, path, t)
    lt.camera_visible = _light_flag(prim, "nasset:cameraVisibility", True, path, t)
    lt.opaque = _light_flag(prim, "nasset:opaqueSurface", False, path, t)
    if tn == "DistantLight":
        lt.angle = float(get("angle", 0.53))
    elif tn == "SphereLight":
        lt.radius = float(get("radius", 0.5))
        if lt.radius < 0:
            raise invalid("radius must be >= 0", "inputs:radius")
        if bool(get("treatAsPoint", False)):
            lt.radius = 0.0
    elif tn == "DiskLight":
        lt.radius = float(get("radius", 0.5))
        if lt.radius < 0:
            raise invalid("radius must be >= 0", "inputs:radius")
        lt.spread = stage_rules.light_spread(prim, t, path)
    elif tn == "CylinderLight":
        lt.radius, lt.length = float(get("radius", 0.5)), float(get("length", 1.0))
        if lt.radius < 0 or lt.length < 0:
            raise invalid("radius and length must be >= 0", "inputs:radius")
        if bool(get("treatAsLine", False)):
            _say(path)("treatAsLine ignored: rendered as the cylinder of its radius", ppath)
    elif tn == "RectLight":
        lt.width, lt.height = float(get("width", 1.0)), float(get("height", 1.0))
        lt.spread = stage_rules.light_spread(prim, t, path)
        if get("texture:file", None):  # spec/renderer.md#lights: ignored, as the reference renderer does
            _say(path)("RectLight texture:file is ignored", ppath)
    elif tn in ("DomeLight", "DomeLight_1"):
        if tn == "DomeLight_1":  # poleAxis: the texture's top pole along +Y, +Z, or the stage's up axis
            from pxr import UsdGeom

            pole = str(get("poleAxis", "scene"))
            if pole not in ("scene", "Y", "Z"):
                raise SceneError("SCENE_INVALID", f"poleAxis {pole!r} (scene, Y or Z)", file=path, prim=ppath, attribute="poleAxis")
            if pole == "Z" or (pole == "scene" and UsdGeom.GetStageUpAxis(prim.GetStage()) == UsdGeom.Tokens.z):
                lt.to_world = lt.to_world.copy()
                lt.to_world[:3, :3] = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]) @ lt.to_world[:3, :3]
            lt.type = "DomeLight"
        tex = get("texture:file", None)
        fmt = str(get("texture:format", "automatic"))
        if tex is not None and str(tex.path if isinstance(tex, Sdf.AssetPath) else tex):
            if fmt not in ("automatic", "latlong"):
                raise SceneError("SCENE_UNSUPPORTED", f"dome texture format {fmt!r} (latlong only)", file=path, prim=ppath)
            resolved = tex.resolvedPath if isinstance(tex, Sdf.AssetPath) and tex.resolvedPath else None
            if not resolved:
                raw = tex.path if isinstance(tex, Sdf.AssetPath) else str(tex)
                resolved = raw if os.path.isabs(raw) else os.path.join(os.path.dirname(os.path.abspath(path)), raw)
            if not (packaged_name(resolved) or os.path.exists(resolved)):
                raise SceneError("SCENE_INVALID", f"dome texture {resolved} does not exist", file=path, prim=ppath,
                                 attribute="inputs:texture:file")
            lt.texture = _read_exr(resolved, ppath, path)
    lt.shaping = _shaping(prim, get, path, t)
    if lt.shaping is not None and tn != "SphereLight":  # a point light's or a sphere's spot cone (#spot-lights)
        _say(path)("UsdLux.ShapingAPI ignored: a spot cone applies to sphere and point lights only", ppath)
        lt.shaping = None
    return lt
