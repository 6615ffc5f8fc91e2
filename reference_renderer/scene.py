"""USD stage -> renderer arrays: camera, triangles with instance/material ids, lights, assets.

Neural assets are found by what composition brings to a prim (nasset_sdk.references): the asset's
root, whatever the referencing prim's type (``def Xform`` is the recommended pattern; untyped and
``def NeuralAsset`` prims work too), also inside usdz packages, through search paths and in
flattened scenes. Their subtree is not traversed further (the asset's own Geometry and fallback
material are for tools without neural support). Each distinct asset is opened once (components
are loaded later, by the plan); every referencing prim is an instance with its own transform.
"""

from __future__ import annotations

import contextlib
import os
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np

from nasset_sdk import curves, stage_rules
from nasset_sdk.errors import NassetError, SceneError, UsageError, error, usd_reason
from nasset_sdk.images import local_image_copy, packaged_name
from nasset_sdk.implicit import IMPLICIT_PRIMS, implicit_mesh
from nasset_sdk.process import single_threaded_blas

from .bsdf import MIN_ALPHA, MaterialTable
from .camera import LENS_UNIT, Camera
from .film import MAX_IMAGE_PIXELS
from .lights import (
    MAX_MESH_LIGHT_TRIANGLES,
    SPOT_FALLOFFS,
    CylinderLight,
    DiskLight,
    DistantLight,
    DomeLight,
    Light,
    MeshLight,
    PointLight,
    RectLight,
    SphereLight,
)
from .sampling import box3, face_normals
from .shaders import rna_fiber
from .textures import WRAP_MODES, ImageTexture, Opacity, PrimvarColor, TexturedMaterial, srgb_to_linear, transform2d

#: Bounds the renderer checks on scene values (spec/renderer.md#limits).
MAX_TRANSFORM = 1e15  # |entry| of a world transform
MAX_INSTANCED_TRIANGLES = 1 << 24  # triangles a PointInstancer's instances may add (a small file must not fill memory)
MAX_INSTANCES = 1 << 20  # instances of one PointInstancer (each costs a matrix and a loop step before any triangle)
MAX_WORLD_COORDINATE = 1e12  # |world coordinate| of any triangle vertex or the camera (float32 ray casting)
MIN_ASSET_SIZE = 1e-9  # world bounding-box diagonal of a NeuralAsset instance, absolute ...
MIN_ASSET_SIZE_RATIO = 1e-4  # ... and relative to the scene scale S (10x the ray offset 1e-5 S)
#: UsdUVTexture files the renderer reads (spec/renderer.md#textures): OpenEXR, and 8/16-bit PNG and JPEG
TEXTURE_SUFFIXES = (".exr", ".png", ".jpg", ".jpeg")
#: UsdPreviewSurface inputs the renderer reads from a UsdUVTexture, with the texture outputs it accepts for each
TEXTURED_INPUTS = {"diffuseColor": ("rgb",), "roughness": ("r", "g", "b", "a"), "metallic": ("r", "g", "b", "a"),
                   "opacity": ("a", "r", "g", "b"), "normal": ("rgb",), "emissiveColor": ("rgb",)}
MAX_EXPOSURE_SCALE = 1e30  # the camera's linear exposure scale
CAMERA_RATIO = (1e-6, 1e6)  # horizontalAperture / focalLength and verticalAperture / horizontalAperture
MAX_LIGHT_EXPOSURE = 1000.0  # stops
MAX_LIGHT_SCALE = 1e30  # intensity * 2^exposure * color, per channel


class SceneWarning(UserWarning):
    """Something in the scene is ignored or approximated; the render still runs."""


#: surface shader ids read with UsdPreviewSurface's inputs
PREVIEW_SURFACES = stage_rules.PREVIEW_SURFACES
#: MaterialX surfaces mapped to UsdPreviewSurface: inputs in the order (base weight, base colour, metalness,
#: specular roughness, specular IOR, emission weight, emission colour) with their MaterialX defaults, and the
#: lobes whose weight is warned when on
SUPPORTED_LIGHTS = ("DistantLight", "SphereLight", "RectLight", "DiskLight", "CylinderLight", "DomeLight", "DomeLight_1")
PREVIEW_DEFAULTS = {
    "diffuseColor": (0.18, 0.18, 0.18), "emissiveColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 0,
    "specularColor": (0.0, 0.0, 0.0), "metallic": 0.0, "roughness": 0.5, "ior": 1.5, "opacity": 1.0,
    "clearcoat": 0.0, "clearcoatRoughness": 0.01, "opacityThreshold": 0.0, "normal": None,
    "displacement": 0.0, "occlusion": 1.0, "opacityMode": None,
}
_LIGHT_COMMON = {"inputs:intensity", "inputs:exposure", "inputs:color", "inputs:normalize",
                 "inputs:enableColorTemperature", "inputs:colorTemperature", "inputs:diffuse", "inputs:specular",
                 "inputs:shadow:enable",
                 "nasset:cameraVisibility", "nasset:opaqueSurface"}
_LIGHT_INPUTS = {
    "DistantLight": {"inputs:angle"},
    "SphereLight": {"inputs:radius", "treatAsPoint", "inputs:shaping:cone:angle", "inputs:shaping:cone:softness",
                    "nasset:shaping:falloff"},
    "RectLight": {"inputs:width", "inputs:height", "nasset:spread"},
    "DiskLight": {"inputs:radius", "nasset:spread"},
    "CylinderLight": {"inputs:radius", "inputs:length", "treatAsLine"},
    "DomeLight": {"inputs:texture:file", "inputs:texture:format", "guideRadius"},
    "DomeLight_1": {"inputs:texture:file", "inputs:texture:format", "guideRadius", "poleAxis"},
}
_IGNORED_PREFIXES = ("xformOp", "visibility", "purpose", "extent", "proxyPrim", "collection:", "light:", "primvars:",
                     "physics", "doubleSided")


@dataclass
class NeuralAssetData:
    """One asset file, opened once; ``evaluator`` is built after the plan loads components."""

    path: Path
    asset: object
    points: np.ndarray  # object space [V,3]
    faces: np.ndarray  # [F,3]
    normals: np.ndarray | None  # [V,3] object space or None
    evaluator: object = None
    prims: list = field(default_factory=list)
    fiber: object = None  # shaders.rna_fiber.FiberTubes of an rna fiber asset (points/faces are then its prisms)
    used_points: object = None  # points referenced by faces (an index array, or slice(None) for all), set at load
    near_field_fetch: float = 0.0  # f of an rna / neupress asset: where its hits fetch their light (kinds/rna.md)


@dataclass
class Instance:
    kind: str  # "mesh" | "neural"
    prim: str
    first_tri: int
    n_tri: int
    to_world: np.ndarray  # 4x4 row-vector convention
    asset: int = -1  # index into Scene.assets
    material: int = -1
    planar: bool = False
    one_sided: bool = False  # doubleSided authored false: black seen from the back (spec/renderer.md#sidedness)
    back_material: int = -1  # nasset:backMaterial: the material seen from the back (-1: the bound one)
    box: tuple | None = None  # (lo [3], hi [3]) of its world triangles; None without triangles
    corner_offset: int = 0  # mesh instances: triangle ``prim``'s row in Scene.tri_normals / tri_st is prim + corner_offset

    def __post_init__(self):
        # only neural instances shade in object space (their transforms are checked to be regular); a plain mesh may be
        # flattened or collapsed by a singular transform (a scale of 0), which USD allows: its pseudo-inverse then
        if self.kind == "neural" or abs(np.linalg.det(self.to_world[:3, :3])) > 0:
            self.to_object = np.linalg.inv(self.to_world)
        else:
            self.to_object = np.linalg.pinv(self.to_world)


@dataclass
class Scene:
    file: str
    camera: Camera
    triangles: np.ndarray  # [F,3,3] world
    tri_inst: np.ndarray  # [F]
    tri_local: np.ndarray  # [F] face index inside its instance's source geometry
    tri_normals: np.ndarray  # [F_mesh,3,3] world shading normals at the corners of mesh triangles (geometric where
    # none); neural instances have no rows (their shaders never read them): see corner_rows
    instances: list
    materials: MaterialTable
    lights: list
    assets: list
    warnings: list = field(default_factory=list)
    tri_st: np.ndarray | None = None  # [F_mesh,3,2] texture coordinates at the corners of mesh triangles (zeros
    # where a mesh has none), rows as tri_normals
    tri_color: np.ndarray | None = None  # [F_mesh,3,3] primvar colours at the corners of mesh triangles, rows as
    # tri_normals; None when no material reads one (spec/renderer.md#primvar-colors)
    tri_ng: np.ndarray | None = None  # [F,3] unit geometric normals of all triangles (zero for degenerate ones, and for
    # fibre prisms: a fibre hit takes no surface normal, spec/renderer.md#fibers; 8.4 M of them took 0.5-2 CPU s)
    render_settings: dict = field(default_factory=dict)  # nasset:* values of the UsdRender.Settings prim (spec/renderer.md#render-settings)
    #: ray-casting structures built for this scene (integrator.scene_accel): built once per scene, not per render
    #: (the geometry arrays above are not changed after loading)
    accel_cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def bounds(self):
        """(lo [3], hi [3]) of the world triangles, from the instances' boxes (zeros without triangles)."""
        boxes = [i.box for i in self.instances if i.box is not None]
        if not boxes:
            return np.zeros(3), np.zeros(3)
        return np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)

    @cached_property
    def corner_offsets(self) -> np.ndarray:
        """[n_instances] Instance.corner_offset of every instance."""
        return np.array([i.corner_offset for i in self.instances], np.int64)

    def world_mesh(self, i: int) -> tuple | None:
        """Neural instance ``i``'s triangles as (world points [V,3], faces [k,3], quads), computed as the loader computed
        them (the same bits); quads: (quads [Q,4], tri [Q,2], corners [Q,2,2]) the same triangles in pairs, as Embree
        may hold them (fibre prisms: ``FiberTubes.quads``; embree.quads_of_pairs), or None. None for other instances."""
        inst = self.instances[i]
        if inst.kind != "neural":
            return None
        data = self.assets[inst.asset]
        fiber = data.fiber
        quads = None if fiber is None or fiber.quads is None else (fiber.quads, fiber.quad_tri, fiber.quad_corners)
        return world_points(data.points, inst.to_world), data.faces, quads

    def corner_rows(self, prim: np.ndarray, inst: np.ndarray) -> np.ndarray:
        """Rows of tri_normals / tri_st [n] of mesh triangles ``prim`` [n] on instances ``inst`` [n]."""
        return prim + self.corner_offsets[inst]


def world_points(points: np.ndarray, M: np.ndarray) -> np.ndarray:
    """World positions [V,3] of object-space ``points`` [V,3] under the 4x4 row-vector transform ``M``."""
    return points @ M[:3, :3] + M[3, :3]


def _matrix(xformable, cache):
    """World transform of ``xformable`` from a ``UsdGeom.XformCache``: each prim's parent's is remembered, so a mesh at
    depth N costs O(1), not the O(N) of ``ComputeLocalToWorldTransform``."""
    return np.array(cache.GetLocalToWorldTransform(xformable.GetPrim()), np.float64)


def _warn(scene_warnings: list, message: str) -> None:
    scene_warnings.append(message)
    warnings.warn(message, SceneWarning, stacklevel=3)


def open_stage(path: str, context=None):
    """Open a scene file after checking every layer it reaches; ``context``: an Ar resolver context
    (nasset_sdk.references.resolver_context) bound while checking and composing."""
    from pxr import Ar, Tf, Usd

    from nasset_sdk.plugin import register_schema

    register_schema()
    from nasset_sdk.paths import check_layer_tree, ensure_regular_file, problems_error

    p = Path(path)
    if not p.is_file():
        raise SceneError("SCENE_INVALID", "scene file does not exist", file=str(p))
    ensure_regular_file(p, code="SCENE_INVALID")
    # the scene and every layer it reaches are checked before anything composes (spec/security.md#paths)
    context = context if context is not None else Ar.GetResolver().CreateDefaultContextForAsset(str(p))
    with Ar.ResolverContextBinder(context):
        problems = check_layer_tree(p, scene=True)
    if problems:
        raise problems_error(problems, p, code="SCENE_INVALID")
    try:
        stage = Usd.Stage.Open(str(p), context, Usd.Stage.LoadNone)
    except Tf.ErrorException as exc:
        raise SceneError("SCENE_INVALID", f"USD cannot open it: {usd_reason(exc)}", file=str(p)) from None
    if stage is None:
        raise SceneError("SCENE_INVALID", "USD cannot open it", file=str(p))
    stage_rules.load_scene_payloads(stage)
    return stage


def is_asset_file(path: str) -> bool:
    """True when ``path`` is a neural asset itself (defaultPrim of type NeuralAsset)."""
    from pxr import Sdf

    from nasset_sdk.safeopen import ensure_safe

    if not os.path.isfile(str(path)):  # regular files only (stat): a pipe or device is never opened
        return False  # never open a pipe or device, even alone; open_stage reports it
    try:
        ensure_safe(path)  # the guarded probe first: a file that would crash usd-core or decode without bound is never opened here
    except NassetError:  # not readable as USD within the bounds: not an asset (open_stage's own probe reports why)
        return False
    try:
        layer = Sdf.Layer.FindOrOpen(str(path))
    except Exception:  # noqa: BLE001 - an unreadable file is not an asset; open_stage reports it
        return False
    if layer is None or not layer.defaultPrim:
        return False
    spec = layer.GetPrimAtPath("/" + layer.defaultPrim)
    return spec is not None and spec.typeName == "NeuralAsset"


def load_scene(source, *, time=None, search_paths=None) -> Scene:
    """Load a scene from a path or an opened ``Usd.Stage`` (which keeps its own resolver context).

    ``search_paths``: folders where USD's resolver looks up bare asset paths (``chair.usdc``) of a scene file. numpy's
    BLAS runs on one thread meanwhile (:func:`nasset_sdk.process.single_threaded_blas`: the tessellation's products
    are [n, 3] rows by 3 x 3 matrices)."""
    from pxr import Ar

    from nasset_sdk.references import resolver_context

    if isinstance(source, (str, os.PathLike)):
        if is_asset_file(str(source)):
            from .studio import studio_stage

            stage = studio_stage(str(source))
            file = str(source)
        else:
            stage = open_stage(str(source), resolver_context(search_paths))
            file = str(source)
    else:
        from pxr import Usd

        if not isinstance(source, Usd.Stage):
            raise UsageError(f"load_scene: source must be a path or a Usd.Stage, got {type(source).__name__}")
        stage = source
        file = stage.GetRootLayer().realPath or stage.GetRootLayer().identifier
    with Ar.ResolverContextBinder(stage.GetPathResolverContext()), single_threaded_blas():
        return _Loader(stage, file, render_time(stage, time)).load()


def render_time(stage, time=None):
    """The ``Usd.TimeCode`` a scene renders at (nasset_sdk.stage_rules.render_time)."""
    return stage_rules.render_time(stage, time)


class _Loader:
    def __init__(self, stage, file: str, time) -> None:
        from pxr import UsdGeom

        self.stage, self.file, self.time = stage, file, time
        self._xforms = UsdGeom.XformCache(time)  # world transforms at the render time, each parent's remembered
        self._primvars = stage_rules.InheritedPrimvars()  # inherited constant primvars, each parent's remembered
        self._bindings = stage_rules.MaterialBindings()  # bound materials, each parent's bindings remembered
        self._said: set[str] = set()
        self._placement: np.ndarray | None = None  # inv(prototype root) @ instance @ PointInstancer, while expanding one
        self.warnings: list[str] = []
        self.tris: list = []
        self.n_tri = 0  # triangles in self.tris, and corner rows in self.tri_normals (kept as they grow)
        self.n_corner_rows = 0
        self._implicit_meshes: dict = {}  # (type, sizes, axis) -> implicit_mesh(...): one tessellation per shape
        self.tri_local: list = []
        self.tri_normals: list = []
        self.tri_ng: list = []
        self.tri_inst: list = []
        self.tri_st: list = []
        self.tri_color: list = []  # per mesh instance [k,3,3] or None
        self._inst_st: dict = {}  # instance index -> its triangles' texture coordinates [k,3,2] (emissive textures)
        self._purposes = stage_rules.Purposes(frozenset({"default", "render"}), "full")  # of the render settings, load()
        self._st_fallback: dict = {}  # st primvar name -> the first UsdPrimvarReader_float2 fallback read for it
        self._mesh_sources: dict = {}  # prim path -> _mesh_source of a PointInstancer's prototype meshes
        self.instances: list[Instance] = []
        self.mat_rows: list = []
        self.mat_index: dict = {}
        self.images: dict = {}  # resolved texture file -> [H, W, 3] image
        self.lights: list[Light] = []
        self.assets: list[NeuralAssetData] = []
        self.asset_index: dict = {}

    def err(self, code, msg, prim=None, attribute=None):
        return error(code, msg, file=self.file, prim=None if prim is None else str(prim), attribute=attribute)

    def matrix(self, xformable) -> np.ndarray:
        """The prim's world transform (4x4, row vectors); ``SCENE_INVALID`` when it is not finite or exceeds
        MAX_TRANSFORM (a NaN transform would otherwise pass every later test and render nothing)."""
        M = _matrix(xformable, self._xforms)
        if self._placement is not None:  # a PointInstancer's prototype: relative to its root, then the instance
            M = M @ self._placement
        if not np.isfinite(M).all() or np.abs(M).max() > MAX_TRANSFORM:
            raise self.err("SCENE_INVALID", f"world transform is not finite or has an entry above {MAX_TRANSFORM:g}",
                           xformable.GetPrim().GetPath(), "xformOpOrder")
        return M

    @contextlib.contextmanager
    def _reading(self, prim):
        """``SCENE_INVALID`` naming ``prim`` for a value Python cannot use where a number or an array of one is read
        (a hand-written file may give a schema attribute another type: ``string inputs:intensity = "x"``)."""
        try:
            yield
        except (ValueError, TypeError, OverflowError, IndexError) as exc:
            raise self.err("SCENE_INVALID", f"a value of the wrong type or shape ({type(exc).__name__}: "
                           f"{str(exc).strip()[:160]})", prim) from None

    def warn(self, msg, prim=None):
        text = f"{self.file}:{prim}: {msg}" if prim else f"{self.file}: {msg}"
        if text not in self._said:  # once each (a PointInstancer repeats its prototypes' warnings per instance)
            self._said.add(text)
            _warn(self.warnings, text)

    # -- traversal -------------------------------------------------------------------------
    def load(self) -> Scene:
        from pxr import Usd, UsdGeom, UsdLux

        from nasset_sdk.references import asset_source

        broken = self._composition_errors()
        # a camera is rendered through whatever its visibility or purpose (they hide its gizmo in a viewport)
        cameras = stage_rules.stage_cameras(self.stage)
        settings = self._settings_prim()
        self._purposes = stage_rules.settings_purposes(settings, self.time, self.warn)
        hiding = stage_rules.Hiding(self.time, self._purposes)
        unknown: set = set()  # prim type names without a schema
        it = iter(Usd.PrimRange.Stage(self.stage, Usd.TraverseInstanceProxies()))
        for prim in it:
            path = str(prim.GetPath())
            if hiding.is_hidden(prim):
                it.PruneChildren()
                continue
            tname = str(prim.GetTypeName())
            with self._reading(path):
                source = asset_source(prim)
                if source is not None or tname == "NeuralAsset" or (not tname and path in broken and self._reference_paths(prim)):
                    self._neural(prim, source, broken.get(path))
                    it.PruneChildren()
                elif prim.HasAPI(UsdLux.LightAPI) or tname.endswith("Light") or tname.startswith("DomeLight"):
                    n = len(self.lights)
                    self._light(prim, tname)
                    for name, field_name in (("nasset:cameraVisibility", "camera_visible"), ("nasset:opaqueSurface", "opaque")):
                        attr = prim.GetAttribute(name)  # spec/renderer.md#light-surfaces
                        if attr and attr.HasAuthoredValue() and self.lights[n:]:
                            if not isinstance(attr.Get(self.time), bool):
                                raise self.err("SCENE_INVALID", f"{name} must be a bool", str(prim.GetPath()), name)
                            setattr(self.lights[n], field_name, bool(attr.Get(self.time)))
                elif tname == "Mesh":
                    self._mesh(prim)
                elif tname in IMPLICIT_PRIMS:
                    self._implicit(prim, tname)
                elif tname == "PointInstancer":
                    self._point_instancer(prim)
                    it.PruneChildren()  # prototypes beneath it render only as its instances
                elif tname in ("BasisCurves", "Points"):
                    self._curves_or_points(prim, tname)
                elif prim.IsA(UsdGeom.Gprim):  # NurbsCurves, NurbsPatch, TetMesh, Volume, Cylinder_1, ...
                    raise self.err("SCENE_UNSUPPORTED", f"geometry type {tname} is not supported (Mesh, BasisCurves, "
                                   f"Points and the implicit {', '.join(IMPLICIT_PRIMS)} are)", path)
                elif tname and not prim.GetPrimTypeInfo().GetSchemaType() and tname not in unknown:
                    unknown.add(tname)  # a DCC's own type, its plugin not here: said once per type
                    self.warn(f"prim type {tname!r} has no schema here (a plugin's type, {path} the first): its prims "
                              "are not rendered themselves, their children are traversed", None)
        chosen = stage_rules.render_camera(self.stage, settings, self.file, self.warn, cameras)
        with self._reading(str(chosen.GetPath())):
            camera = self._camera(chosen, settings)
        if not self.lights and not any(r[3].any() for r in self.mat_rows):
            self.warn("the scene has no lights and no emissive materials; the image will be black")
        self._mesh_lights()
        n = len(self.tris)
        tris = np.concatenate(self.tris) if n else np.zeros((0, 3, 3))
        self._check_world_bounds()
        self._clipping_warning(camera)
        mats = self.mat_rows or [(np.zeros(3), np.zeros(3), 1.0, np.zeros(3), "none")]
        table = MaterialTable(np.array([m[0] for m in mats]), np.array([m[1] for m in mats]),
                              np.array([m[2] for m in mats]), np.array([m[3] for m in mats]), [m[4] for m in mats],
                              textures=[m[5] if len(m) > 5 else None for m in mats],
                              opacities=[m[6] if len(m) > 6 else None for m in mats],
                              emission_textures=[m[7][0] if len(m) > 7 and m[7] is not None else None for m in mats],
                              **_glass_columns([m[8] if len(m) > 8 else None for m in mats]),
                              beckmann=_beckmann_column([len(m) > 9 and m[9] == "beckmann" for m in mats]))
        return Scene(
            file=self.file, camera=camera, triangles=tris,
            tri_inst=np.concatenate(self.tri_inst) if n else np.zeros(0, np.int64),
            tri_local=np.concatenate(self.tri_local) if n else np.zeros(0, np.int64),
            tri_normals=np.concatenate(self.tri_normals) if self.tri_normals else np.zeros((0, 3, 3)),
            instances=self.instances, materials=table, lights=self.lights, assets=self.assets, warnings=self.warnings,
            tri_st=np.concatenate(self.tri_st) if self.tri_st else np.zeros((0, 3, 2)),
            tri_color=None if all(c is None for c in self.tri_color) else np.concatenate(
                [np.zeros((len(st), 3, 3)) if c is None else c for c, st in zip(self.tri_color, self.tri_st, strict=True)]),
            tri_ng=np.concatenate(self.tri_ng) if n else np.zeros((0, 3)),
            render_settings=self._render_settings(settings),
        )

    def _mesh_lights(self) -> None:
        """A MeshLight for every emissive mesh instance of at most MAX_MESH_LIGHT_TRIANGLES triangles
        (spec/renderer.md#mesh-lights); larger ones stay reachable by BSDF rays only, with a warning."""
        for i, inst in enumerate(self.instances):
            if inst.kind != "mesh" or inst.material < 0:
                continue
            front = np.asarray(self.mat_rows[inst.material][3], np.float64)
            back = (np.zeros(3) if inst.one_sided else
                    front if inst.back_material < 0 else np.asarray(self.mat_rows[inst.back_material][3], np.float64))
            if not (front.any() or back.any()):
                continue
            if inst.n_tri > MAX_MESH_LIGHT_TRIANGLES:
                self.warn(f"emissive mesh of {inst.n_tri} triangles (> {MAX_MESH_LIGHT_TRIANGLES}) is not light-sampled: "
                          "reached by BSDF rays only", inst.prim)
                continue
            st = self._inst_st.get(i)
            textures = [None if st is None or m < 0 or len(self.mat_rows[m]) < 8 or self.mat_rows[m][7] is None
                        else self.mat_rows[m][7][0] for m in (inst.material, inst.back_material)]
            if inst.back_material < 0 and not inst.one_sided:
                textures[1] = textures[0]
            self.lights.append(MeshLight(self.tris[i], front, back_radiance=back, instance=i, prim=inst.prim,
                                         textures=None if st is None or textures == [None, None] else (st, *textures)))

    def _check_world_bounds(self) -> None:
        """``SCENE_INVALID`` for a world coordinate above MAX_WORLD_COORDINATE, or a NeuralAsset instance whose world
        bounding-box diagonal is below MIN_ASSET_SIZE or MIN_ASSET_SIZE_RATIO x the scene scale S (it would vanish
        in float32 ray casting or under the ray offsets, spec/renderer.md#limits). From the instances' boxes."""
        boxed = [i for i in self.instances if i.box is not None]
        if not boxed:
            return
        for inst in boxed:
            big = float(max(np.abs(inst.box[0]).max(), np.abs(inst.box[1]).max()))
            if big > MAX_WORLD_COORDINATE:
                raise self.err("SCENE_INVALID", f"world coordinates up to {big:.3g} exceed the bound "
                               f"{MAX_WORLD_COORDINATE:g} (float32 ray casting)", inst.prim, "xformOpOrder")
        lo, hi = np.min([i.box[0] for i in boxed], 0), np.max([i.box[1] for i in boxed], 0)
        scene_scale = float(max(np.abs(lo).max(), np.abs(hi).max()) + (hi - lo).max())  # S of spec/renderer.md#ray-offsets
        for inst in boxed:
            if inst.kind != "neural":
                continue
            diag = float(np.linalg.norm(inst.box[1] - inst.box[0]))
            if diag < MIN_ASSET_SIZE or diag < MIN_ASSET_SIZE_RATIO * scene_scale:
                raise self.err("SCENE_INVALID", f"the asset's world size {diag:.3g} is below {MIN_ASSET_SIZE:g} or "
                               f"{MIN_ASSET_SIZE_RATIO:g} x the scene scale {scene_scale:.3g}: it would not render", inst.prim,
                               "xformOpOrder")

    def _add(self, inst: Instance, tris_world, normals_world, local_ids, st=None, *, ng=None, box=None, color=None):
        """Append an instance's world triangles [k,3,3]; ``normals_world`` [k,3,3] corner normals, ``st`` [k,3,2] and
        ``color`` [k,3,3] primvar colours (meshes; None for neural instances), ``ng`` [k,3] unit geometric normals and
        ``box`` (lo, hi) when the caller has them."""
        inst.first_tri = self.n_tri
        inst.n_tri = len(tris_world)
        self.n_tri += inst.n_tri
        if inst.n_tri:
            inst.box = box if box is not None else box3(tris_world.reshape(-1, 3))
        self.instances.append(inst)
        self.tris.append(tris_world)
        self.tri_ng.append(face_normals(tris_world) if ng is None else ng)
        if normals_world is not None:
            inst.corner_offset = self.n_corner_rows - inst.first_tri
            self.n_corner_rows += len(normals_world)
            self.tri_normals.append(normals_world)
            self.tri_st.append(np.zeros((len(tris_world), 3, 2)) if st is None else st)
            self.tri_color.append(color)
            if st is not None:
                self._inst_st[len(self.instances) - 1] = st
        self.tri_local.append(local_ids.astype(np.int64))
        self.tri_inst.append(np.full(len(tris_world), len(self.instances) - 1, np.int64))

    # -- camera ----------------------------------------------------------------------------
    def _camera(self, prim, settings=None) -> Camera:
        """The camera of spec/renderer.md#cameras: projection, apertures, lens shift, thin lens, exposure."""
        from pxr import UsdGeom

        cam = UsdGeom.Camera(prim)
        path = prim.GetPath()
        proj = cam.GetProjectionAttr().Get(self.time)
        if proj and proj not in (UsdGeom.Tokens.perspective, UsdGeom.Tokens.orthographic):
            raise self.err("SCENE_UNSUPPORTED", f"camera projection {proj!r} (perspective or orthographic)", path, "projection")
        ortho = proj == UsdGeom.Tokens.orthographic
        vals = {}
        for name, attr, fallback, positive in (("focalLength", cam.GetFocalLengthAttr(), 50.0, True),
                                               ("horizontalAperture", cam.GetHorizontalApertureAttr(), 20.955, True),
                                               ("verticalAperture", cam.GetVerticalApertureAttr(), 15.2908, True),
                                               ("fStop", cam.GetFStopAttr(), 0.0, False),
                                               ("focusDistance", cam.GetFocusDistanceAttr(), 0.0, False)):
            with self._reading(path):
                v = attr.Get(self.time) if attr else None  # None only when nothing is authored: the schema fallback
                v = fallback if v is None else float(v)
            if not (np.isfinite(v) and (v > 0 if positive else v >= 0) and v <= MAX_WORLD_COORDINATE / LENS_UNIT):
                raise self.err("SCENE_INVALID", f"camera {name} = {v!r} must be finite, {'> 0' if positive else '>= 0'} "
                               f"and <= {MAX_WORLD_COORDINATE / LENS_UNIT:g}", path, name)
            vals[name] = v
        fl, ha, va = vals["focalLength"], vals["horizontalAperture"], vals["verticalAperture"]
        if not ortho and not CAMERA_RATIO[0] <= ha / fl <= CAMERA_RATIO[1]:
            raise self.err("SCENE_INVALID", f"horizontalAperture / focalLength = {ha / fl:.3g} outside {CAMERA_RATIO[0]:g} .. "
                           f"{CAMERA_RATIO[1]:g} (field of view too narrow or too wide to trace)", path, "focalLength")
        if not CAMERA_RATIO[0] <= va / ha <= CAMERA_RATIO[1]:
            raise self.err("SCENE_INVALID", f"verticalAperture / horizontalAperture = {va / ha:.3g} outside {CAMERA_RATIO[0]:g} .. "
                           f"{CAMERA_RATIO[1]:g}", path, "verticalAperture")
        offsets = []
        unit, unit_name = (ha, "horizontalAperture") if ortho else (fl, "focalLength")
        for name, attr in (("horizontalApertureOffset", cam.GetHorizontalApertureOffsetAttr()),
                           ("verticalApertureOffset", cam.GetVerticalApertureOffsetAttr())):
            with self._reading(path):
                v = attr.Get(self.time) if attr else None
                v = 0.0 if v is None else float(v)
            if not (np.isfinite(v) and abs(v) <= CAMERA_RATIO[1] * unit):
                raise self.err("SCENE_INVALID", f"camera {name} = {v!r} must be finite and at most {CAMERA_RATIO[1]:g} x "
                               f"{unit_name}", path, name)
            offsets.append(v)
        lens_radius, focus = 0.0, vals["focusDistance"]
        if vals["fStop"] > 0:
            if ortho:
                self.warn("fStop on an orthographic camera ignored (no depth of field)", path)
            elif focus == 0:
                self.warn(f"fStop {vals['fStop']:g} without a focusDistance: no depth of field (pinhole)", path)
            else:
                lens_radius = LENS_UNIT * fl / (2.0 * vals["fStop"])
                if not lens_radius <= MAX_WORLD_COORDINATE:  # a tiny f-number: a lens wider than the world's bound
                    raise self.err("SCENE_INVALID", f"fStop {vals['fStop']!r} gives a lens radius of {lens_radius:.3g} "
                                   f"(focalLength {fl:g}), beyond {MAX_WORLD_COORDINATE:g}", path, "fStop")
        M = self.matrix(cam)
        if abs(np.linalg.det(M[:3, :3])) < 1e-12:
            raise self.err("SCENE_INVALID", "camera transform is singular", path, "xformOpOrder")
        if np.abs(M[3, :3]).max() > MAX_WORLD_COORDINATE:
            raise self.err("SCENE_INVALID", f"camera position {M[3, :3].tolist()} beyond |coordinate| <= {MAX_WORLD_COORDINATE:g}",
                           path, "xformOpOrder")
        camera = Camera(M, fl, ha, va, str(path), self._render_resolution(settings), *offsets, orthographic=ortho,
                        lens_radius=lens_radius, focus_distance=focus, exposure_scale=self._exposure_scale(cam))
        stage_rules.conform_warning(settings, self.time, camera.resolution, camera.horizontal_aperture,
                                    camera.vertical_aperture, self.warn)
        return camera

    def _clipping_warning(self, camera: Camera) -> None:
        """Clipping is not rendered (spec/renderer.md#cameras): a warning naming the camera when its
        ``clippingPlanes`` are authored, or when triangle vertices in front of it lie nearer than its
        ``clippingRange`` near distance or beyond its far one (a view USD would cut, the whole scene here)."""
        from pxr import UsdGeom

        cam = UsdGeom.Camera(self.stage.GetPrimAtPath(camera.prim))
        with self._reading(camera.prim):
            planes = cam.GetClippingPlanesAttr().Get(self.time)
            near, far = (float(v) for v in (cam.GetClippingRangeAttr().Get(self.time) or (1.0, 1e6)))
        if planes is not None and len(planes):
            self.warn(f"{len(planes)} clippingPlanes ignored: nothing is clipped", camera.prim)
        M = camera.to_world
        # the camera-space depth -z of each vertex: one column of the inverse, per coordinate column (a [3F,3] matrix
        # product took 3.5 s on the 8.4 M triangles of a dense groom)
        w = -np.linalg.inv(M[:3, :3])[:, 2]
        lo, hi = np.inf, -np.inf
        for inst, tris in zip(self.instances, self.tris, strict=True):
            if not len(tris):
                continue
            if inst.kind == "neural":  # its corners are the world points its faces use: a fibre's are 5x fewer
                data = self.assets[inst.asset]
                vertices = world_points(data.points[data.used_points], inst.to_world)
            else:
                vertices = tris.reshape(-1, 3)
            depth = vertices[:, 0] * w[0]
            depth += vertices[:, 1] * w[1]
            depth += vertices[:, 2] * w[2]
            depth -= float(M[3, :3] @ w)
            depth = depth[depth > 0]
            if len(depth):
                lo, hi = min(lo, float(depth.min())), max(hi, float(depth.max()))
        if lo <= hi and (lo < near or hi > far):
            self.warn(f"clippingRange ({near:g}, {far:g}) ignored: geometry in front of the camera lies at depths "
                      f"{lo:.4g} to {hi:.4g}, and nothing is clipped", camera.prim)

    def _exposure_scale(self, cam) -> float:
        """The camera's linear exposure scale (``UsdGeomCamera::ComputeLinearExposureScale``: 2^exposure x
        responsivity x time x iso / 100 / exposure:fStop^2; 1 when nothing is authored)."""
        path = cam.GetPrim().GetPath()
        with self._reading(path):
            scale = float(cam.ComputeLinearExposureScale(self.time))
        if not (np.isfinite(scale) and 0.0 <= scale <= MAX_EXPOSURE_SCALE):
            raise self.err("SCENE_INVALID", f"camera exposure scale {scale!r} (2^exposure x responsivity x time x iso / 100 "
                           f"/ exposure:fStop^2) must be finite and in [0, {MAX_EXPOSURE_SCALE:g}]", path, "exposure")
        return scale

    def _settings_prim(self):
        """The stage's render settings (spec/renderer.md#image-size; nasset_sdk.stage_rules.settings_prim)."""
        return stage_rules.settings_prim(self.stage, self.warn)

    def _render_resolution(self, settings) -> tuple[int, int] | None:
        """Resolution of the render settings (nasset_sdk.stage_rules.settings_resolution)."""
        return stage_rules.settings_resolution(self.stage, settings, self.time, self.warn, MAX_IMAGE_PIXELS)

    def _render_settings(self, settings) -> dict:
        """The custom attributes of the render settings (nasset_sdk.stage_rules.nasset_settings)."""
        return stage_rules.nasset_settings(settings, self.time, self.warn)

    # -- meshes and materials --------------------------------------------------------------
    def _material(self, prim, *, varying_colors: bool = True) -> int:
        """Material id of a prim's bound material, else of its displayColor (``varying_colors`` False: the mean of
        several values, for prims whose triangles carry no primvar colours)."""

        mat = self._bound_material(prim)
        if not mat:
            dc, do = (self._primvars.find(prim, n) for n in ("displayColor", "displayOpacity"))  # or an ancestor's
            with self._reading(prim.GetPath()):
                val = dc.Get(self.time) if dc is not None else None
                val = np.asarray(val, np.float64).reshape(-1, 3) if val is not None and len(val) else None
                opacity = do.Get(self.time) if do is not None else None
                opacity = np.asarray(opacity, np.float64).ravel() if opacity is not None and len(opacity) else None
            presence = None  # displayOpacity as the presence of the fallback surface (spec #cutouts)
            if opacity is not None and np.isfinite(opacity).all() and opacity.mean() < 1.0:
                if len(opacity) > 1:
                    self.warn(f"displayOpacity of {len(opacity)} values read as their mean", prim.GetPath())
                presence = Opacity(float(np.clip(opacity.mean(), 0.0, 1.0)), 0.0)
            if val is not None and len(val) > 1 and varying_colors:  # interpolated per hit (spec #primvar-colors)
                key = ("display", "primvar", presence and presence.value)
                if key not in self.mat_index:
                    self.mat_index[key] = len(self.mat_rows)
                    material = TexturedMaterial("st", PrimvarColor("displayColor", np.full(3, 0.18)), np.asarray(0.5),
                                                np.asarray(0.0), np.zeros(3), 0.04, MIN_ALPHA)
                    kd, f0, alpha = material.constants()
                    self.mat_rows.append((kd, f0, alpha, np.zeros(3), "displayColor (primvar)", material, presence))
                return self.mat_index[key]
            color = tuple(np.clip(val.mean(0), 0, 1)) if val is not None and np.isfinite(val).all() else (0.18,) * 3
            key = ("display", color, presence and presence.value)
            if key not in self.mat_index:
                self.mat_index[key] = len(self.mat_rows)
                self.mat_rows.append((np.array(color), np.full(3, 0.04), 0.25, np.zeros(3), f"displayColor{color}", None,
                                      presence))
            return self.mat_index[key]
        return self._material_of(mat)

    def _bound_material(self, prim):
        """The material the render settings' ``materialBindingPurposes`` bind to ``prim`` (spec/renderer.md#materials;
        nasset_sdk.stage_rules.bound_material)."""
        return stage_rules.bound_material(prim, self._purposes, self.warn, self._bindings)

    def _back_material(self, prim) -> int:
        """Material id of the ``nasset:backMaterial`` relationship (the back side's material, -1 when absent)."""
        from pxr import UsdShade

        rel = prim.GetRelationship("nasset:backMaterial")
        targets = rel.GetForwardedTargets() if rel else []
        if not targets:
            return -1
        mat = UsdShade.Material(self.stage.GetPrimAtPath(targets[0]))
        if not mat:
            raise self.err("SCENE_INVALID", f"nasset:backMaterial target {targets[0]} is not a Material", prim.GetPath(),
                           "nasset:backMaterial")
        return self._material_of(mat)

    def _material_of(self, mat) -> int:
        mpath = str(mat.GetPath())
        if mpath in self.mat_index:
            return self.mat_index[mpath]
        shader = stage_rules.surface_shader(mat)  # outputs:surface, else outputs:mtlx:surface
        if shader is None:
            others = sorted(o.GetFullName() for o in mat.GetSurfaceOutputs() if o.HasConnectedSource())
            raise self.err("SCENE_UNSUPPORTED", "material has no surface shader on outputs:surface or outputs:mtlx:surface"
                           + (f" (only {', '.join(others)}: another renderer's shading)" if others else ""), mpath)
        sid = shader.GetIdAttr().Get()
        if sid not in PREVIEW_SURFACES and sid not in stage_rules.MTLX_SURFACES:
            source = shader.GetImplementationSource()  # id, sourceAsset (MDL, OSL) or sourceCode
            assets = [f"{a.GetName()} {a.Get().path}" for a in shader.GetPrim().GetAuthoredAttributes()
                      if a.GetName().startswith("info:") and a.GetName().endswith(":sourceAsset")]
            what = f"has id {sid!r}" if source == "id" else f"is implemented by {', '.join(assets) or source}"
            raise self.err("SCENE_UNSUPPORTED", f"surface shader {shader.GetPath()} {what}; supported: "
                           f"{', '.join(PREVIEW_SURFACES + tuple(stage_rules.MTLX_SURFACES))}", mpath)
        vals = dict(PREVIEW_DEFAULTS)
        textures = {}  # input name -> (ImageTexture, st primvar name)
        primvar_color = None  # diffuseColor from a UsdPrimvarReader_float3
        if sid in stage_rules.MTLX_SURFACES:
            vals.update(self._mtlx_surface(shader, sid))
        for inp in shader.GetInputs() if sid in PREVIEW_SURFACES else ():
            name = inp.GetBaseName()
            if name not in PREVIEW_DEFAULTS:
                self.warn(f"unknown UsdPreviewSurface input {name!r} ignored", shader.GetPath())
                continue
            producer, v = self._read_input(inp)
            if producer is not None:  # fed by a shader's output (a texture, a primvar reader)
                if name == "diffuseColor" and (reader := self._primvar_reader(producer, shader.GetPath())) is not None:
                    primvar_color = reader
                elif name in TEXTURED_INPUTS:
                    tex = self._uv_texture(inp, shader.GetPath(), outputs=TEXTURED_INPUTS[name])
                    if tex is not None:
                        textures[name] = tex
                    elif (fallback := self._texture_fallback(producer)) is not None:
                        v = fallback  # an unread UsdUVTexture gives its authored inputs:fallback
                else:
                    self.warn(f"input {name!r} is connected (only {', '.join(TEXTURED_INPUTS)} textures are rendered); "
                              "its own value is used", shader.GetPath())
            if v is not None:
                default = PREVIEW_DEFAULTS[name]
                vals[name] = v if default is None else self._finite(v, default, shader.GetPath(), name)
        varnames = {v[1] for v in textures.values()}
        if len(varnames) > 1:
            self.warn(f"textures read different primvars {sorted(varnames)}; all are read at {textures[next(iter(textures))][1]!r}",
                      shader.GetPath())
        varname = textures[next(iter(textures))][1] if textures else "st"
        opacity = self._opacity(vals, textures.get("opacity"), varname)
        if float(vals["clearcoat"]) > 0.0:
            self.warn("clearcoat is ignored", shader.GetPath())
        emission = np.maximum(np.asarray(vals["emissiveColor"], np.float64), 0)
        emission_texture = textures.get("emissiveColor")  # (ImageTexture, st primvar): emission per hit
        if emission_texture is not None:
            emission = np.maximum(emission_texture[0].mean, 0.0)
        specular_workflow = bool(int(vals["useSpecularWorkflow"]))
        ior = float(vals["ior"])
        if not ior > 0.0:  # spec/renderer.md#materials, input ranges (in the metallic workflow F0 has a pole at -1)
            raise self.err("SCENE_INVALID", f"ior = {ior!r} must be > 0", shader.GetPath(), "inputs:ior")

        def value(name):
            if name == "diffuseColor" and primvar_color is not None:
                return primvar_color
            return textures[name][0] if name in textures else np.clip(np.asarray(vals[name], np.float64), 0, 1)

        material = TexturedMaterial(varname, value("diffuseColor"), value("roughness"),
                                    None if specular_workflow else value("metallic"),
                                    np.clip(np.asarray(vals["specularColor"], np.float64), 0, 1),
                                    ((1.0 - ior) / (1.0 + ior)) ** 2, MIN_ALPHA,
                                    textures["normal"][0] if "normal" in textures else None)
        kd, f0, alpha = material.constants()
        textured = material if set(textures) - {"opacity", "emissiveColor"} or primvar_color is not None else None
        glass = None  # (weight, colour [3], ior, thin, reflection tint [3]) of a transmitting MaterialX surface
        if vals.get("transmission", 0.0) > 0.0:  # (spec/renderer.md#transmission)
            glass = (vals["transmission"], np.asarray(vals["transmissionColor"], np.float64), ior, vals["thinWalled"],
                     np.asarray(vals["specularTint"], np.float64))
        microfacet = stage_rules.shader_microfacet(shader, self.time, self.file)
        self.mat_index[mpath] = len(self.mat_rows)
        self.mat_rows.append((kd, f0, alpha, emission, mpath, textured, opacity,
                              None if emission_texture is None else (emission_texture[0], varname), glass, microfacet))
        return self.mat_index[mpath]

    def _primvar_reader(self, producer, where) -> PrimvarColor | None:
        """The :class:`PrimvarColor` of a ``UsdPrimvarReader_float3`` feeding diffuseColor (its ``varname``, string or
        token, fallback ``displayColor``; its ``fallback`` value, else 0.18 grey), None for another producer."""
        node, _ = producer
        if node.GetIdAttr().Get() != "UsdPrimvarReader_float3":
            return None
        varname = str(self._value(node.GetInput("varname")) or "displayColor")
        fallback = self._finite(self._value(node.GetInput("fallback")), (0.18, 0.18, 0.18), node.GetPath(), "fallback")
        return PrimvarColor(varname, np.clip(fallback, 0.0, 1.0))

    @staticmethod
    def _opacity(vals: dict, texture, varname: str) -> Opacity | None:
        """The material's presence (spec/renderer.md#cutouts; both ``opacityMode`` values), None where it is
        everywhere opaque."""
        op, threshold = (float(np.clip(vals[k], 0.0, 1.0)) for k in ("opacity", "opacityThreshold"))
        if texture is None and (op >= 1.0 or (threshold > 0 and op >= threshold)):
            return None
        return Opacity(op, threshold) if texture is None else Opacity(op, threshold, texture[0], varname)

    def _mtlx_surface(self, shader, sid: str) -> dict:
        """UsdPreviewSurface values of a MaterialX surface (nasset_sdk.stage_rules.mtlx_preview_values)."""
        return stage_rules.mtlx_preview_values(shader, sid, self.time, self.warn,
                                               lambda v, default, name: self._finite(v, default, shader.GetPath(), name))

    def _read_input(self, inp) -> tuple:
        """(producer, value) of a shader input (nasset_sdk.stage_rules.input_source)."""
        return stage_rules.input_source(inp, self.time)

    def _value(self, inp):
        """The value feeding a shader input (:meth:`_read_input`); None when unset or fed by a shader's output."""
        producer, v = self._read_input(inp)
        return None if producer else v

    def _finite(self, value, default, shader_path, name: str, bound: float = np.inf) -> np.ndarray:
        """``value`` (``default`` when None) as float64 of the default's shape; ``SCENE_INVALID`` naming the shader
        input when it is not a number of that shape, not finite, or beyond ``bound`` in magnitude."""
        try:
            out = np.broadcast_to(np.asarray(default if value is None else value, np.float64), np.shape(default))
        except (TypeError, ValueError):
            out = None
        if out is None or not np.isfinite(out).all() or np.abs(out).max(initial=0.0) > bound:
            raise self.err("SCENE_INVALID", f"{name} = {value!r} is not a finite value of its type"
                           + (f" within {bound:g}" if np.isfinite(bound) else ""), shader_path, f"inputs:{name}")
        return out

    def _texture_fallback(self, producer):
        """The authored ``inputs:fallback`` of a UsdUVTexture (its ``rgb`` or one channel, as the output it feeds
        through), the value USD gives a texture it cannot read; None when not authored or not a UsdUVTexture."""
        node, out = producer
        inp = node.GetInput("fallback") if node.GetIdAttr().Get() == "UsdUVTexture" else None
        value = self._value(inp) if inp else None
        if value is None:
            return None
        with self._reading(node.GetPath()):  # a shorter value keeps the schema fallback (0, 0, 0, 1) of the rest
            v = np.asarray(value, np.float64).ravel()[:4]
        rgba = self._finite(np.concatenate([v, [0.0, 0.0, 0.0, 1.0][len(v):]]), np.zeros(4), node.GetPath(), "fallback")
        return rgba[:3] if str(out) == "rgb" else float(rgba["rgba".find(str(out))])

    def _uv_texture(self, inp, where, outputs=("rgb",)):
        """(ImageTexture, st primvar name) behind a connected input, or None with a warning (the input's own
        value is then used): a ``UsdUVTexture``'s output (one of ``outputs``: ``rgb``, or a channel ``r``, ``g``,
        ``b``, ``a``, whose value the texture then repeats in its three colours) whose ``st`` reads a
        ``UsdPrimvarReader_float2``."""
        producer = self._read_input(inp)[0]
        node, out = producer if producer else (None, None)
        nid = node.GetIdAttr().Get() if node else None
        if nid != "UsdUVTexture" or str(out) not in outputs:
            self.warn(f"input {inp.GetBaseName()!r} is connected to {nid!r} output {out!r} (only a UsdUVTexture's "
                      f"{' / '.join(outputs)} output is rendered); its own value is used", where)
            return None
        tpath = node.GetPath()

        def value(name, default):
            v = self._value(node.GetInput(name))
            return default if v is None else v

        unread = ("its inputs:fallback is used" if self._texture_fallback(producer) is not None
                  else "the connected input's own value is used")
        asset = value("file", None)
        if asset is None or not asset.path:
            self.warn(f"UsdUVTexture without inputs:file; {unread}", tpath)
            return None
        resolved = asset.resolvedPath or ""
        if "<UDIM>" in asset.path:  # a tile set (1001 + u + 10 v), not one image
            self.warn(f"UDIM texture {asset.path} is not read (one image per texture); {unread}", tpath)
            return None
        if not resolved:
            self.warn(f"texture {asset.path} not found; {unread}", tpath)
            return None
        if not (packaged_name(resolved) or resolved).lower().endswith(TEXTURE_SUFFIXES):
            self.warn(f"texture {asset.path}: only OpenEXR, PNG and JPEG textures are read; {unread}", tpath)
            return None
        if resolved not in self.images:  # one decode per file
            self.images[resolved] = self._read_image(asset, tpath, "inputs:file", "UsdUVTexture texture", ldr=True)
        rgba, bits = self.images[resolved]
        channel = "rgba".find(str(out)) if str(out) != "rgb" else -1
        image = rgba[..., :3] if channel < 0 else np.repeat(rgba[..., channel:channel + 1], 3, -1)
        space = str(value("sourceColorSpace", "auto"))
        if channel == 3:
            pass  # alpha is linear whatever the colour space
        elif space == "sRGB" or (space == "auto" and bits == 8):  # UsdPreviewSurface: auto is sRGB for 8-bit images
            image = srgb_to_linear(image)
        elif space not in ("auto", "raw"):
            self.warn(f"sourceColorSpace {space!r} read as raw (linear)", tpath)
        wraps = []
        for name in ("wrapS", "wrapT"):
            mode = str(value(name, "useMetadata"))
            if mode == "useMetadata":
                mode = "black"  # OpenEXR, PNG and JPEG carry no wrap metadata: UsdUVTexture's rule then gives black
            if mode not in WRAP_MODES:
                self.warn(f"{name} {mode!r} unknown: black", tpath)
                mode = "black"
            wraps.append(mode)
        def float4(name, fallback):  # a shorter value keeps the fallbacks of the channels it lacks
            v = np.asarray(value(name, fallback), np.float64).ravel()[:4]
            return np.concatenate([v, fallback[len(v):]])

        with self._reading(tpath):
            scale, bias = float4("scale", np.ones(4)), float4("bias", np.zeros(4))
        if not (np.isfinite(scale).all() and np.isfinite(bias).all()):
            raise self.err("SCENE_INVALID", "UsdUVTexture scale / bias must be finite", tpath, "inputs:scale")
        scale, bias = (scale[:3], bias[:3]) if channel < 0 else (np.full(3, scale[channel]), np.full(3, bias[channel]))
        varname, uv_matrix = "st", None

        def source_of(shader, name):
            producer = self._read_input(shader.GetInput(name))[0]
            return producer[0] if producer else None

        rnode = source_of(node, "st")
        if rnode and rnode.GetIdAttr().Get() == "UsdTransform2d":  # st through a 2D transform (texture tiling)
            vals = []
            for name, default in (("scale", (1.0, 1.0)), ("rotation", 0.0), ("translation", (0.0, 0.0))):
                vals.append(self._finite(self._value(rnode.GetInput(name)), default, rnode.GetPath(), name, bound=1e9))
            uv_matrix = transform2d(vals[0], float(vals[1]), vals[2])
            rnode = source_of(rnode, "in")
        if rnode and rnode.GetIdAttr().Get() == "UsdPrimvarReader_float2":
            varname = str(self._value(rnode.GetInput("varname")) or "st")
            self._st_fallback.setdefault(varname, self._finite(self._value(rnode.GetInput("fallback")), (0.0, 0.0),
                                                               rnode.GetPath(), "fallback", bound=1e9))
        else:
            self.warn("UsdUVTexture st is not read from a UsdPrimvarReader_float2 (directly or through a "
                      "UsdTransform2d); primvar 'st' is used", tpath)
        return ImageTexture(image, wraps[0], wraps[1], scale, bias, str(tpath), uv_matrix), varname

    def _read_image(self, asset, prim, attribute: str, what: str, *, ldr: bool = False):
        """[H, W, 3] float32 from an OpenEXR file named by an asset-path value (resolved by USD; the scene's
        paths were checked when it was opened): ``SCENE_INVALID`` when missing or not finite and >= 0,
        ``SCENE_UNSUPPORTED`` for another format, ``IMAGE_INVALID`` beyond the image bounds. ``ldr``: PNG and JPEG
        files are read too, and the result is (image, bits per channel: 32 for OpenEXR, 8 or 16)."""
        from nasset_sdk.images import read_png_jpeg

        from .film import read_exr

        resolved = asset.resolvedPath or ""
        packaged = packaged_name(resolved)
        if not resolved or not (packaged or os.path.isfile(resolved)):
            raise self.err("SCENE_INVALID", f"{what} not found: {asset.path}", prim, attribute)
        name = (packaged or resolved).lower()
        exr = name.endswith(".exr")
        if not exr and not (ldr and name.endswith(TEXTURE_SUFFIXES)):
            raise self.err("SCENE_UNSUPPORTED", f"{what} {asset.path}: only OpenEXR images", prim, attribute)
        try:
            with local_image_copy(resolved) as local:  # textures (ldr) keep their alpha: [H, W, 4]
                image, bits = (read_exr(local, alpha=ldr), 32) if exr else read_png_jpeg(local, alpha=ldr)
        except NassetError as exc:
            raise self.err("IMAGE_INVALID", f"{what} {resolved}: {exc.message}", prim, attribute) from None
        if not np.isfinite(image).all() or (image < 0).any():
            raise self.err("SCENE_INVALID", f"{what} holds NaN/Inf or negative values", prim, attribute)
        return (image, bits) if ldr else image

    def _primvar_corners(self, prim, varname: str, width: int, tri, corner, face_of_tri, n_points, n_faces, n_corners):
        """Values [T,3,width] of primvar ``varname`` at the triangles' corners, or None when it is missing or unusable
        (not finite, another width, or a length its interpolation does not give)."""

        pv = self._primvars.find(prim, varname)  # a constant one may be an ancestor's
        with self._reading(prim.GetPath()):
            vals = pv.ComputeFlattened(self.time) if pv is not None else None
            v = np.asarray(vals, np.float64) if vals is not None and len(vals) else None
        interp = pv.GetInterpolation() if pv else None
        if v is None or v.size % width or not np.isfinite(v).all():
            return None
        v = v.reshape(-1, width)
        if interp in ("vertex", "varying") and len(v) == n_points:
            return v[tri]
        if interp == "faceVarying" and len(v) == n_corners:
            return v[corner]
        if interp == "uniform" and len(v) == n_faces:
            return np.repeat(v[face_of_tri][:, None], 3, 1)
        if interp == "constant" and len(v) == 1:
            return np.broadcast_to(v[0], (len(tri), 3, width)).copy()
        return None

    def _mesh(self, prim):
        """A UsdGeom.Mesh as one instance per material group: its local data (:meth:`_mesh_source`, read once per
        prim while a PointInstancer places it again and again) placed by its world transform."""
        if self._placement is None:
            src = self._mesh_source(prim)
        else:
            key = str(prim.GetPath())
            if key not in self._mesh_sources:
                self._mesh_sources[key] = self._mesh_source(prim)
            src = self._mesh_sources[key]
        if src is not None:
            self._place_mesh(prim, src)

    def _mesh_source(self, prim) -> dict | None:
        """Everything of a mesh that does not depend on where it is placed (object space, corners in authored
        winding): points, triangles, corner normals, texture coordinates and primvar colours, material groups; None
        for a mesh without points or faces (warned)."""
        from pxr import UsdGeom

        from nasset_sdk.references import fallback_owner

        mesh = UsdGeom.Mesh(prim)
        path = str(prim.GetPath())
        owner = fallback_owner(prim)
        if owner:
            self.warn(f"renders the grey fallback mesh of the neural asset {owner} as an ordinary mesh: the prim "
                      "reaches the asset's geometry without its root; reference the asset file's default prim "
                      "(spec/format.md#referencing-an-asset)", path)
        pts = mesh.GetPointsAttr().Get(self.time)
        counts = mesh.GetFaceVertexCountsAttr().Get(self.time)
        idx = mesh.GetFaceVertexIndicesAttr().Get(self.time)
        if pts is None or counts is None or idx is None or len(pts) == 0 or len(counts) == 0:
            self.warn("mesh without points or faces skipped", path)
            return None
        pts = np.asarray(pts, np.float64).reshape(-1, 3)
        counts = np.asarray(counts, np.int64)
        idx = np.asarray(idx, np.int64)
        if (counts < 3).any() or counts.sum() != len(idx) or idx.min() < 0 or idx.max() >= len(pts):
            raise self.err("SCENE_INVALID", "mesh topology invalid (counts/indices)", path, "faceVertexIndices")
        if not np.isfinite(pts).all():
            raise self.err("SCENE_INVALID", "mesh points are not finite", path, "points")
        scheme = mesh.GetSubdivisionSchemeAttr().Get(self.time)
        subdivided = scheme not in (None, UsdGeom.Tokens.none)
        if subdivided:
            self.warn(f"subdivisionScheme {scheme!r}: rendered as its control cage", path)
        starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
        nt = counts - 2
        face_of_tri = np.repeat(np.arange(len(counts)), nt)
        k = np.arange(nt.sum()) - np.repeat(np.cumsum(nt) - nt, nt)
        base = starts[face_of_tri]
        corner = np.stack([base, base + k + 1, base + k + 2], 1)  # face-vertex slots
        tri = idx[corner]
        # shading normals, object space
        normals = None
        nattr = mesh.GetNormalsAttr()
        pv = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
        nvals, interp = None, None
        if pv and pv.HasAuthoredValue():
            nvals, interp = pv.ComputeFlattened(self.time), pv.GetInterpolation()
            if nvals is None:  # USD flattens nothing when an index is out of range
                self.warn("primvars:normals has indices outside its values: ignored", path)
        elif nattr and nattr.HasAuthoredValue():
            nvals, interp = nattr.Get(self.time), mesh.GetNormalsInterpolation()
        if nvals is not None and len(nvals):
            nv = np.asarray(nvals, np.float64).reshape(-1, 3)
            if interp in ("vertex", "varying") and len(nv) == len(pts):
                normals = nv[tri]
            elif interp == "faceVarying" and len(nv) == len(idx):
                normals = nv[corner]
            elif interp == "uniform" and len(nv) == len(counts):
                normals = np.repeat(nv[face_of_tri][:, None], 3, 1)
            else:
                self.warn(f"normals with interpolation {interp!r} and {len(nv)} values ignored", path)
        smooth = normals is None and subdivided
        if smooth:  # a subdivision surface's cage shades smooth, as usdview draws it
            normals = stage_rules.smooth_vertex_normals(pts, counts, idx, False)[tri]
        back = self._back_material(prim)
        groups = self._face_groups(mesh, len(counts))  # [(prim path, material, faces or None)]
        varname = self._st_varname([g[1] for g in groups] + [back])
        layout = (tri, corner, face_of_tri, len(pts), len(counts), len(idx))
        st = None if varname is None else self._primvar_corners(prim, varname, 2, *layout)
        if varname is not None and st is None:  # the primvar reader's fallback, as UsdPrimvarReader defines it
            fallback = self._st_fallback.get(varname, np.zeros(2))
            st = np.broadcast_to(fallback, (len(tri), 3, 2)).copy()
            self.warn(f"textured material but no usable primvar {varname!r} (float2, finite, vertex / faceVarying / "
                      f"uniform / constant): its reader's fallback {tuple(fallback.tolist())} is used", prim.GetPath())
        # the colours of its first material that reads a primvar colour (spec/renderer.md#primvar-colors)
        reader = next((t.diffuse for m in [g[1] for g in groups] + [back] if m >= 0 for t in self.mat_rows[m][5:6]
                       if t is not None and t.reads_colors), None)
        color = None if reader is None else self._primvar_corners(prim, reader.varname, 3, *layout)
        if reader is not None and color is None:
            color = np.broadcast_to(np.asarray(reader.fallback, np.float64), (len(tri), 3, 3)).copy()
            if reader.varname != "displayColor":
                self.warn(f"no usable color primvar {reader.varname!r} (float3, finite): its reader's fallback is used",
                          prim.GetPath())
        return {"pts": pts, "tri": tri, "face_of_tri": face_of_tri, "normals": normals, "st": st, "color": color,
                "groups": groups, "back": back, "one_sided": self._one_sided(mesh), "smooth": smooth}

    def _place_mesh(self, prim, src: dict) -> None:
        """A mesh source (:meth:`_mesh_source`) in the world: triangles wound as the prim's effective orientation says
        (spec/renderer.md#sidedness), normals by the inverse transpose, one instance per material group."""
        from pxr import UsdGeom

        mesh = UsdGeom.Mesh(prim)
        M = self.matrix(mesh)
        reverse = self._reversed(mesh, M)
        flip = [0, 2, 1] if reverse else [0, 1, 2]
        tri = src["tri"][:, flip]
        pw = src["pts"] @ M[:3, :3] + M[3, :3]
        tris = pw[tri]
        nn = face_normals(tris)
        normals = src["normals"]
        if normals is None:
            normals = np.repeat(nn[:, None], 3, 1)
        else:
            normals = normals[:, flip] @ stage_rules.normal_matrix(M[:3, :3])  # the inverse transpose, or its limit
            normals /= np.maximum(np.linalg.norm(normals, axis=-1, keepdims=True), 1e-300)
            if src["smooth"] and reverse:  # computed ones follow the winding's front, as the geometric normals do
                normals = -normals
        st = None if src["st"] is None else src["st"][:, flip]
        color = None if src["color"] is None else src["color"][:, flip]
        tol = 1e-9 * (1 + np.abs(pw).max())
        planar = bool(np.all(np.abs(nn @ nn[0]) > 1 - 1e-9) and np.all(np.abs((pw - pw[0]) @ nn[0]) < tol))
        for where, mat, faces in src["groups"]:
            sel = slice(None) if faces is None else np.isin(src["face_of_tri"], faces)
            ids = np.arange(len(tri))[sel]
            if not len(ids):
                continue
            inst = Instance("mesh", where, 0, 0, M, material=mat, planar=planar, one_sided=src["one_sided"],
                            back_material=src["back"])
            self._add(inst, tris[sel], normals[sel], ids, None if st is None else st[sel], ng=nn[sel],
                      color=None if color is None else color[sel])

    def _st_varname(self, materials) -> str | None:
        """The st primvar of the first of ``materials`` (ids, -1 none) with an image texture (colour, roughness,
        metallic, normal, opacity or emission), None when none reads texture coordinates."""
        for m in materials:
            row = self.mat_rows[m] if m >= 0 else ()
            textured, opacity, emission = (tuple(row[5:8]) + (None, None, None))[:3]
            if isinstance(textured, TexturedMaterial) and textured.reads_st:
                return textured.varname
            if isinstance(opacity, Opacity) and opacity.texture is not None:
                return opacity.varname
            if emission is not None:
                return emission[1]
        return None

    def _face_groups(self, mesh, n_faces: int) -> list:
        """The mesh's faces by material: [(prim path, material id, face indices)] (spec/renderer.md#materials).
        A ``GeomSubset`` of element type ``face`` in the ``materialBind`` family with a bound material shades its
        faces (the first such subset holding a face wins); the other faces take the mesh's binding; faces listed in
        ``holeIndices`` are left out. One group with faces None: every face, the mesh's material."""
        from pxr import UsdGeom, UsdShade

        path = str(mesh.GetPath())
        holes = np.asarray(mesh.GetHoleIndicesAttr().Get(self.time) or [], np.int64)
        owner = np.full(n_faces, -1, np.int64)
        groups = []
        for subset in UsdShade.MaterialBindingAPI(mesh.GetPrim()).GetMaterialBindSubsets():
            sub_path = str(subset.GetPath())
            if subset.GetElementTypeAttr().Get(self.time) != UsdGeom.Tokens.face:
                self.warn("GeomSubset of an element type other than face ignored", sub_path)
                continue
            mat = self._bound_material(subset.GetPrim())
            if not mat:
                continue
            ind = np.asarray(subset.GetIndicesAttr().Get(self.time) or [], np.int64)
            if len(ind) and (ind.min() < 0 or ind.max() >= n_faces):
                raise self.err("SCENE_INVALID", f"GeomSubset face indices outside the mesh's {n_faces} faces", sub_path,
                               "indices")
            free = ind[owner[ind] < 0]
            owner[free] = len(groups)
            groups.append((sub_path, self._material_of(mat)))
        if len(holes):
            if holes.min() < 0 or holes.max() >= n_faces:
                raise self.err("SCENE_INVALID", f"hole indices outside the mesh's {n_faces} faces", path, "holeIndices")
            owner[holes] = -2
        if not groups and not len(holes):
            return [(path, self._material(mesh.GetPrim()), None)]
        out = [(where, mat, np.nonzero(owner == k)[0]) for k, (where, mat) in enumerate(groups)]
        rest = np.nonzero(owner == -1)[0]
        return out + ([(path, self._material(mesh.GetPrim()), rest)] if len(rest) else [])

    def _reversed(self, gprim, M) -> bool:
        """True when the prim's front side is the left-hand side of its winding in world space: ``orientation``
        ``leftHanded``, or a world transform that mirrors (det M3 < 0), but not both (USD's effective orientation,
        spec/renderer.md#sidedness). The loader then reverses its triangles, so that ``(v1 - v0) x (v2 - v0)`` of
        every world triangle points to its front."""
        left = gprim.GetOrientationAttr().Get(self.time) == "leftHanded"
        return bool(np.linalg.det(M[:3, :3]) < 0) != left

    def _one_sided(self, gprim) -> bool:
        """True when ``doubleSided`` is authored false (spec/renderer.md#sidedness); unauthored keeps both sides."""
        attr = gprim.GetDoubleSidedAttr()
        return bool(attr and attr.HasAuthoredValue() and not attr.Get(self.time))

    def _point_instancer(self, prim) -> None:
        """Every instance of a PointInstancer whose prototypes are meshes, curves, points and implicit prims
        (spec/renderer.md#geometry; lights in prototypes are warned about, other geometry types refused):
        each prototype prim placed by ``ComputeInstanceTransformsAtTime`` (the prototype root's own transform
        included) under the instancer's world transform; masked (``invisibleIds``) instances are left out."""
        from pxr import Usd, UsdGeom, UsdLux

        from nasset_sdk.references import asset_source

        pi = UsdGeom.PointInstancer(prim)
        path = str(prim.GetPath())
        protos = [self.stage.GetPrimAtPath(p) for p in pi.GetPrototypesRel().GetForwardedTargets()]
        indices = np.asarray(pi.GetProtoIndicesAttr().Get(self.time) or [], np.int64)
        if len(indices) > MAX_INSTANCES:  # before USD computes a matrix for each
            raise self.err("SCENE_INVALID", f"{len(indices)} instances, more than {MAX_INSTANCES}", path, "protoIndices")
        xforms = pi.ComputeInstanceTransformsAtTime(self.time, self.time, UsdGeom.PointInstancer.IncludeProtoXform,
                                                    UsdGeom.PointInstancer.IgnoreMask)  # the mask is applied below
        if xforms is None or len(xforms) != len(indices):
            raise self.err("SCENE_INVALID", "PointInstancer instances cannot be computed (protoIndices, positions, "
                           "orientations, scales or the prototypes disagree)", path, "protoIndices")
        if len(indices) and (indices.min() < 0 or indices.max() >= len(protos) or not all(protos)):
            raise self.err("SCENE_INVALID", "protoIndices name a prototype that is missing", path, "protoIndices")
        mask = np.asarray(pi.ComputeMaskAtTime(self.time) or [True] * len(indices), bool)
        world = self.matrix(pi)
        parts = {k: [] for k in range(len(protos))}  # prototype -> [(prim, type name)]
        for k, root in enumerate(protos):
            walk = iter(Usd.PrimRange(root, Usd.TraverseInstanceProxies()))
            for p in walk:
                img = UsdGeom.Imageable(p)
                if img and (img.GetVisibilityAttr().Get(self.time) == UsdGeom.Tokens.invisible
                            or img.GetPurposeAttr().Get(self.time) not in self._purposes.included):
                    walk.PruneChildren()
                    continue
                t = str(p.GetTypeName())
                if asset_source(p) is not None or t in ("NeuralAsset", "PointInstancer"):
                    raise self.err("SCENE_UNSUPPORTED", f"a {t or 'neural asset'} as a PointInstancer prototype (meshes, "
                                   "curves, points and implicit prims are rendered)", str(p.GetPath()))
                if t in ("Mesh", "BasisCurves", "Points") or t in IMPLICIT_PRIMS:
                    parts[k].append((p, t))
                elif p.IsA(UsdGeom.Gprim):
                    raise self.err("SCENE_UNSUPPORTED", f"geometry type {t} in a PointInstancer prototype is not supported",
                                   str(p.GetPath()))
                elif p.HasAPI(UsdLux.LightAPI) or t.endswith("Light"):
                    self.warn("a light in a PointInstancer prototype is not instanced: it does not light the scene",
                              str(p.GetPath()))
        roots = [_matrix(UsdGeom.Xformable(root), self._xforms) for root in protos]
        for root, m in zip(protos, roots, strict=True):
            if not np.isfinite(m).all() or abs(np.linalg.det(m[:3, :3])) < 1e-30:
                raise self.err("SCENE_INVALID", "a prototype root's transform is singular or not finite", root.GetPath(),
                               "xformOpOrder")
        inv_roots = [np.linalg.inv(m) for m in roots]
        before = self.n_tri
        for i in np.nonzero(mask)[0]:
            k = int(indices[i])
            self._placement = inv_roots[k] @ np.array(xforms[int(i)], np.float64) @ world
            try:
                for p, t in parts[k]:
                    if t == "Mesh":
                        self._mesh(p)
                    elif t in IMPLICIT_PRIMS:
                        self._implicit(p, t)
                    else:
                        self._curves_or_points(p, t)
            finally:
                self._placement = None
            if self.n_tri - before > MAX_INSTANCED_TRIANGLES:
                raise self.err("SCENE_INVALID", f"the instances add more than {MAX_INSTANCED_TRIANGLES} triangles", path,
                               "protoIndices")

    def _implicit(self, prim, tname):
        """An implicit prim as the mesh of :func:`implicit.implicit_mesh` (spec/renderer.md#implicit-prims)."""
        from pxr import UsdGeom

        size = {}
        for name, fallback in IMPLICIT_PRIMS[tname].items():
            attr = prim.GetAttribute(name)
            v = attr.Get(self.time) if attr else None
            v = fallback if v is None else float(v)
            if not (np.isfinite(v) and 0 < v <= MAX_WORLD_COORDINATE):
                raise self.err("SCENE_INVALID", f"{tname} {name} = {v!r} must be finite and > 0", prim.GetPath(), name)
            size[name] = v
        axis_attr = prim.GetAttribute("axis")
        axis = str(axis_attr.Get(self.time)) if axis_attr and axis_attr.Get(self.time) is not None else "Z"
        if axis not in ("X", "Y", "Z"):
            raise self.err("SCENE_INVALID", f"{tname} axis {axis!r} (X, Y or Z)", prim.GetPath(), "axis")
        key = (tname, tuple(size.items()), axis)
        if key not in self._implicit_meshes:
            self._implicit_meshes[key] = implicit_mesh(tname, size, axis)
        pts, faces, nrm = self._implicit_meshes[key]
        M = self.matrix(UsdGeom.Xformable(prim))
        pw = pts @ M[:3, :3] + M[3, :3]
        if self._reversed(UsdGeom.Gprim(prim), M):
            faces, nrm = faces[:, [0, 2, 1]], nrm[:, [0, 2, 1]]
        if UsdGeom.Gprim(prim).GetOrientationAttr().Get(self.time) == "leftHanded":
            nrm = -nrm  # the front of a left-handed prim is its inside
        tris = pw[faces]
        n = nrm @ stage_rules.normal_matrix(M[:3, :3])
        n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        self.warn(f"implicit {tname} tessellated into {len(faces)} triangles", prim.GetPath())
        inst = Instance("mesh", str(prim.GetPath()), 0, 0, M, material=self._material(prim),
                        one_sided=self._one_sided(UsdGeom.Gprim(prim)), back_material=self._back_material(prim))
        self._add(inst, tris, n, np.arange(len(faces)))

    def _curves_or_points(self, prim, tname):
        """BasisCurves as tubes and Points as spheres of their widths (nasset_sdk.curves, spec/renderer.md#curves-and-points)."""
        from pxr import UsdGeom

        path = prim.GetPath()
        geom = UsdGeom.BasisCurves(prim) if tname == "BasisCurves" else UsdGeom.Points(prim)

        def tessellate(points, counts, widths):
            tubes = rna_fiber.tessellate(points, counts, widths, curves.TUBE_SIDES)
            return tubes.points, tubes.faces, tubes.tri_seg, tubes.p0, tubes.p1

        try:
            with self._reading(path):
                mesh = curves.curves_or_points_mesh(prim, tname, self.time, tessellate, lambda m: self.warn(m, path),
                                                    MAX_INSTANCED_TRIANGLES)
        except SceneError as exc:
            raise self.err(exc.code, exc.message, path, exc.attribute) from None
        if mesh is None:
            return
        local, faces, nrm = mesh
        M = self.matrix(geom)
        if np.linalg.det(M[:3, :3]) < 0:  # mirrored: keep the triangles wound about their outward normals
            faces, nrm = faces[:, [0, 2, 1]], nrm[:, [0, 2, 1]]
        tris = (local @ M[:3, :3] + M[3, :3])[faces]
        n = nrm @ stage_rules.normal_matrix(M[:3, :3])
        n = n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-300)
        self.warn(f"{tname} tessellated into {len(faces)} triangles", path)
        inst = Instance("mesh", str(path), 0, 0, M, material=self._material(prim, varying_colors=False),
                        back_material=self._back_material(prim))
        self._add(inst, tris, n, np.arange(len(faces)))

    # -- neural assets ---------------------------------------------------------------------
    @staticmethod
    def _reference_paths(prim) -> list:
        out = []
        for spec in prim.GetPrimStack():
            for listop in (spec.referenceList, spec.payloadList):
                items = list(listop.explicitItems) + list(listop.prependedItems) + list(listop.appendedItems)
                for ref in items:
                    if ref.assetPath:
                        out.append(spec.layer.ComputeAbsolutePath(ref.assetPath))
        return out

    def _composition_errors(self) -> dict:
        """USD's composition errors (a reference, payload or sublayer that cannot be opened, an unresolved prim path),
        each warned about naming its prim: {prim path: USD's message}. USD composes the scene without what failed."""
        out: dict = {}
        for where, text in stage_rules.composition_errors(self.stage):
            out.setdefault(where, text)
            self.warn(f"composed without a layer or prim USD cannot reach: {text[:300]}", where if where != "/" else None)
        return out

    def _neural(self, prim, source, composition_error=None):
        from pxr import UsdGeom

        from nasset_sdk.references import embedded_asset_file, open_source

        path = str(prim.GetPath())
        if source is None:
            refs = self._reference_paths(prim)
            if not refs:
                raise self.err("SCENE_INVALID", "NeuralAsset prim does not reference an asset file", path)
            why = f" ({composition_error})" if composition_error else ""
            raise self.err("SCENE_INVALID", f"referenced asset file not found, or it is not a neural asset: {refs[0]}{why}",
                           path)
        file = Path(source.display)
        # one asset per file; instances embedded in a flattened scene share one when their specs are the same
        key = (embedded_asset_file(source) if source.embedded else source.display if "[" in source.display
               else os.path.realpath(source.layer))
        if key not in self.asset_index:
            try:
                asset = open_source(source, load="none")
            except NassetError as exc:
                raise self.err("SCENE_INVALID", f"referenced asset {file} is invalid: {exc}", path) from None
            if asset.kind not in ("rna", "neupress", "8dna"):
                raise self.err("SCENE_UNSUPPORTED", f"asset kind {asset.kind!r}: this renderer integrates kinds 'rna', "
                               "'neupress' and '8dna'", path)
            fiber = asset.kind == "rna" and asset.variant == "fiber"
            if asset.variant != "surface" and not fiber:
                raise self.err("SCENE_UNSUPPORTED", f"{asset.kind} variant {asset.variant!r} (surface is rendered, and "
                               "fiber for rna)", path)
            try:
                geo = asset.geometry()
                fetch = asset.near_field_fetch  # NEAR_FIELD_INVALID for a bad value, or one on another kind
            except NassetError as exc:
                raise self.err("SCENE_INVALID", f"referenced asset {file} is invalid: {exc}", path) from None
            self.asset_index[key] = len(self.assets)
            if fiber:  # curves as closed prisms around each segment (spec/renderer.md#fibers)
                from .shaders.rna_fiber import tessellate

                tubes = tessellate(geo.points, geo.counts, geo.widths)
                self.assets.append(NeuralAssetData(file, asset, tubes.points, tubes.faces, None, fiber=tubes,
                                                   near_field_fetch=fetch))
            else:
                nrm = None if geo.normals is None else np.asarray(geo.normals, np.float64)
                self.assets.append(NeuralAssetData(file, asset, np.asarray(geo.points, np.float64),
                                                   np.asarray(geo.faces, np.int64), nrm, near_field_fetch=fetch))
        ai = self.asset_index[key]
        data = self.assets[ai]
        data.prims.append(path)
        M = self.matrix(UsdGeom.Xformable(prim))
        if abs(np.linalg.det(M[:3, :3])) < 1e-12:
            raise self.err("SCENE_INVALID", "NeuralAsset transform is singular", path)
        stage_rules.units_warning(self.stage, float(data.asset.stage.GetMetadata("metersPerUnit") or 1.0), M, path,
                                  self.warn)
        pw = world_points(data.points, M)
        tris = pw[data.faces]
        if data.used_points is None:  # the box of the triangles is that of the points they use
            used = np.zeros(len(data.points), bool)
            used[data.faces.ravel()] = True
            data.used_points = slice(None) if used.all() else np.nonzero(used)[0]
        inst = Instance("neural", path, 0, 0, M, asset=ai)
        box = box3(pw[data.used_points]) if len(data.faces) else None
        ng = np.zeros((len(tris), 3)) if data.fiber is not None else face_normals(tris)
        self._add(inst, tris, None, np.arange(len(data.faces)), ng=ng, box=box)

    # -- lights ----------------------------------------------------------------------------
    def _shaping(self, prim, M) -> dict:
        """Spot parameters of a point light with ``UsdLux.ShapingAPI`` (spec/renderer.md#spot-lights): the axis is
        the prim's -Z, ``shaping:cone:angle`` the half-angle (degrees), ``shaping:cone:softness`` in [0, 1]."""
        from pxr import UsdLux

        if not prim.HasAPI(UsdLux.ShapingAPI):
            return {}
        api = UsdLux.ShapingAPI(prim)
        get = lambda a, d: (a.Get(self.time) if a and a.Get(self.time) is not None else d)  # noqa: E731
        cone, soft = float(get(api.GetShapingConeAngleAttr(), 90.0)), float(get(api.GetShapingConeSoftnessAttr(), 0.0))
        if not (np.isfinite(cone) and np.isfinite(soft)):
            raise self.err("SCENE_INVALID", "shaping:cone:angle and softness must be finite", prim.GetPath(),
                           "inputs:shaping:cone:angle")
        for a in ("inputs:shaping:focus", "inputs:shaping:ies:file"):
            at = prim.GetAttribute(a)
            if at and at.HasAuthoredValue():
                self.warn(f"{a} is ignored", prim.GetPath())
        falloff = prim.GetAttribute("nasset:shaping:falloff")
        kind = str(falloff.Get(self.time)) if falloff and falloff.HasAuthoredValue() else "linear"
        if kind not in SPOT_FALLOFFS:
            raise self.err("SCENE_INVALID", f"nasset:shaping:falloff {kind!r} is not one of {', '.join(SPOT_FALLOFFS)}",
                           prim.GetPath(), "nasset:shaping:falloff")
        return {"axis": -M[2, :3], "cone_deg": cone, "softness": soft, "falloff": kind}

    def _light(self, prim, tname):
        from pxr import Usd, UsdGeom, UsdLux

        path = str(prim.GetPath())
        if tname == "PortalLight":  # a sampling aid of dome lights: no light of its own
            self.warn("PortalLight ignored (it guides a renderer's sampling of dome lights and emits nothing)", path)
            return
        if tname not in SUPPORTED_LIGHTS:
            raise self.err("SCENE_UNSUPPORTED", f"light type {tname or 'untyped'} is not supported "
                           f"(supported: {', '.join(SUPPORTED_LIGHTS)})", path)
        known = _LIGHT_COMMON | _LIGHT_INPUTS[tname]
        for attr in prim.GetAuthoredAttributes():
            n = attr.GetName()
            if n in known or n.startswith(_IGNORED_PREFIXES):
                continue
            self.warn(f"attribute {n!r} is not used by the renderer", path)
        connected = sorted(a.GetName() for a in prim.GetAuthoredAttributes() if a.HasAuthoredConnections())
        if connected:  # a light shader network (a texture, a primvar reader) feeding the light's inputs
            self.warn(f"{', '.join(connected)} connected: the input's own value (else its fallback) is used", path)
        filters = prim.GetRelationship("light:filters")
        if filters and filters.GetForwardedTargets():
            self.warn(f"light:filters {', '.join(map(str, filters.GetForwardedTargets()))} ignored: the light is "
                      "rendered unfiltered", path)
        unhonoured = stage_rules.unrendered_light_inputs(prim, self.time)
        if unhonoured:
            self.warn(f"{unhonoured} not rendered: the light lights every response and casts shadows", path)
        for link in ("lightLink", "shadowLink"):  # a collection that leaves objects out: every object is lit all the same
            coll = Usd.CollectionAPI(prim, link)
            include_root = coll.GetIncludeRootAttr().Get(self.time) if coll.GetIncludeRootAttr() else None
            if coll.GetExcludesRel().GetTargets() or (coll.GetIncludesRel().GetTargets() and include_root is False):
                self.warn(f"{link} collection ignored: the light {'lights' if link == 'lightLink' else 'shadows'} every "
                          "object", path)
        api = UsdLux.LightAPI(prim)
        g = lambda a, d: (a.Get(self.time) if a and a.Get(self.time) is not None else d)  # noqa: E731
        intensity = float(g(api.GetIntensityAttr(), 1.0))
        exposure = float(g(api.GetExposureAttr(), 0.0))
        color = np.asarray(g(api.GetColorAttr(), (1.0, 1.0, 1.0)), np.float64)
        if not (np.isfinite(exposure) and abs(exposure) <= MAX_LIGHT_EXPOSURE):
            raise self.err("SCENE_INVALID", f"exposure {exposure!r} must be finite with |exposure| <= {MAX_LIGHT_EXPOSURE:g} stops",
                           path, "inputs:exposure")
        normalize = bool(g(api.GetNormalizeAttr(), False))
        if bool(g(api.GetEnableColorTemperatureAttr(), False)):  # UsdLux: color x the blackbody's RGB (spec #lights)
            with self._reading(path):
                kelvin = float(g(api.GetColorTemperatureAttr(), 6500.0))
            if not (np.isfinite(kelvin) and 0.0 < kelvin <= MAX_LIGHT_SCALE):
                raise self.err("SCENE_INVALID", f"colorTemperature {kelvin!r} must be finite and > 0 (kelvin)", path,
                               "inputs:colorTemperature")
            color = color * np.asarray(UsdLux.BlackbodyTemperatureAsRgb(kelvin), np.float64)
        for a in ("inputs:diffuse", "inputs:specular"):
            at = prim.GetAttribute(a)
            if at and at.HasAuthoredValue() and float(at.Get(self.time)) != 1.0:
                self.warn(f"{a} != 1 is ignored", path)
        with np.errstate(over="ignore", invalid="ignore"):
            scale = np.float64(intensity) * np.exp2(np.float64(exposure)) * color
        if not np.isfinite(scale).all() or (scale < 0).any() or scale.max(initial=0.0) > MAX_LIGHT_SCALE:
            raise self.err("SCENE_INVALID", f"intensity * 2^exposure * color = {scale.tolist()} must be finite, >= 0 and <= "
                           f"{MAX_LIGHT_SCALE:g}", path, "inputs:intensity")
        for name in ("inputs:angle", "inputs:radius", "inputs:width", "inputs:height", "inputs:length"):
            at = prim.GetAttribute(name)
            v = at.Get(self.time) if at and at.HasAuthoredValue() else None
            if v is not None and not np.isfinite(float(v)):
                raise self.err("SCENE_INVALID", f"{name} = {v!r} must be finite", path, name)
        M = self.matrix(UsdGeom.Xformable(prim))
        if prim.HasAPI(UsdLux.ShapingAPI) and tname != "SphereLight":
            self.warn("UsdLux.ShapingAPI is only applied to sphere and point lights: ignored", path)
        if tname == "DistantLight":
            angle = float(g(UsdLux.DistantLight(prim).GetAngleAttr(), 0.53))
            self.lights.append(DistantLight(M[2, :3], scale, angle, path))
        elif tname == "SphereLight":
            sl = UsdLux.SphereLight(prim)
            r = float(g(sl.GetRadiusAttr(), 0.5))
            as_point = bool(g(sl.GetTreatAsPointAttr(), False))
            sc = float(np.cbrt(abs(np.linalg.det(M[:3, :3]))))
            if r < 0:
                raise self.err("SCENE_INVALID", "radius must be >= 0", path, "inputs:radius")
            if r * sc == 0 or as_point:
                self.lights.append(PointLight(M[3, :3], scale, path, **self._shaping(prim, M)))
            else:
                rw = r * sc
                L = scale / (4.0 * np.pi * rw * rw) if normalize else scale
                self.lights.append(SphereLight(M[3, :3], rw, L, path, **self._shaping(prim, M)))
        elif tname == "RectLight":
            rl = UsdLux.RectLight(prim)
            w = float(g(rl.GetWidthAttr(), 1.0))
            h = float(g(rl.GetHeightAttr(), 1.0))
            tex = rl.GetTextureFileAttr().Get(self.time) if rl.GetTextureFileAttr() else None
            if tex is not None and tex.path:
                self.warn("RectLight texture:file is ignored", path)
            ex, ey = w * M[0, :3], h * M[1, :3]
            area = float(np.linalg.norm(np.cross(ex, ey)))
            L = scale / area if normalize and area > 0 else scale
            self.lights.append(RectLight(M[3, :3], ex, ey, L, path, stage_rules.light_spread(prim, self.time, self.file)))
        elif tname == "CylinderLight":
            cl = UsdLux.CylinderLight(prim)
            r, length = float(g(cl.GetRadiusAttr(), 0.5)), float(g(cl.GetLengthAttr(), 1.0))
            if r < 0 or length < 0:
                raise self.err("SCENE_INVALID", "radius and length must be >= 0", path, "inputs:radius")
            if bool(g(cl.GetTreatAsLineAttr(), False)):
                self.warn("treatAsLine ignored: rendered as the cylinder of its radius", path)
            across = np.linalg.norm(M[1:3, :3], axis=1)  # the scale across the axis (rows: images of local y, z)
            if not np.isclose(across[0], across[1], rtol=1e-4):
                self.warn(f"non-uniform scale across the axis: a round cylinder of the mean radius scale {across.mean():.4g}",
                          path)
            rw, lw = r * float(across.mean()), length * float(np.linalg.norm(M[0, :3]))
            area = 2.0 * np.pi * rw * lw
            L = scale / area if normalize and area > 0 else scale
            self.lights.append(CylinderLight(M[3, :3], M[0, :3], rw, lw, L, path))
        elif tname == "DiskLight":
            r = float(g(UsdLux.DiskLight(prim).GetRadiusAttr(), 0.5))
            if r < 0:
                raise self.err("SCENE_INVALID", "radius must be >= 0", path, "inputs:radius")
            ex, ey = r * M[0, :3], r * M[1, :3]
            area = float(np.pi * np.linalg.norm(np.cross(ex, ey)))
            L = scale / area if normalize and area > 0 else scale
            self.lights.append(DiskLight(M[3, :3], ex, ey, L, path, stage_rules.light_spread(prim, self.time, self.file)))
        else:
            dl = UsdLux.DomeLight(prim)
            fmt = g(dl.GetTextureFormatAttr(), "automatic")
            if fmt not in ("automatic", "latlong"):
                raise self.err("SCENE_UNSUPPORTED", f"DomeLight texture:format {fmt!r} (only latlong)", path,
                               "inputs:texture:format")
            tex = dl.GetTextureFileAttr().Get(self.time)
            image = None
            if tex is not None and tex.path:
                image = self._read_image(tex, path, "inputs:texture:file", "DomeLight texture")
            R = M[:3, :3]
            u, _, vt = np.linalg.svd(R)
            rotation = u @ vt
            if tname == "DomeLight_1":  # poleAxis: the texture's top pole along +Y, +Z, or the stage's up axis
                pole = str(g(prim.GetAttribute("poleAxis"), "scene"))
                if pole not in ("scene", "Y", "Z"):
                    raise self.err("SCENE_INVALID", f"poleAxis {pole!r} (scene, Y or Z)", path, "poleAxis")
                if pole == "Z" or (pole == "scene" and UsdGeom.GetStageUpAxis(self.stage) == UsdGeom.Tokens.z):
                    rotation = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]) @ rotation  # +Y -> +Z first
            self.lights.append(DomeLight(scale, image, rotation, path))


def _beckmann_column(flags: list) -> np.ndarray | None:
    """MaterialTable.beckmann: [M] bool, None when every material's lobe is GGX."""
    return np.array(flags, bool) if any(flags) else None


def _glass_columns(rows: list) -> dict:
    """MaterialTable's glass columns (transmission, transmission_color, eta, thin, reflection_color) from
    per-material (weight, colour, ior, thin, reflection tint) or None; no columns when no material transmits."""
    if all(r is None for r in rows):
        return {}
    rows = [(0.0, np.ones(3), 1.5, False, np.ones(3)) if r is None else r for r in rows]
    return {"transmission": np.array([r[0] for r in rows], np.float64),
            "transmission_color": np.array([r[1] for r in rows], np.float64),
            "eta": np.array([r[2] for r in rows], np.float64), "thin": np.array([bool(r[3]) for r in rows]),
            "reflection_color": np.array([r[4] for r in rows], np.float64)}
