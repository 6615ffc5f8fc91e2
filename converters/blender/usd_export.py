"""``nasset convert-scene SCENE.blend``: a Blender scene (camera, lights, meshes, instances) -> a USD stage.

The same stage layout as the Mitsuba converter (converters/mitsuba/usd_export.py, whose stage
writer this reuses): ``/World/Geometry`` meshes bound to ``UsdPreviewSurface`` materials in
``/World/Looks`` (Image Texture nodes as ``UsdUVTexture``), instanceable prims of ``/Prototypes``
class prims for collection instances and linked duplicates, ``/World/Lights``, one camera, render
settings (``nasset:maxDepth``, ``nasset:pixelFilter``), and one NeuralAsset reference per ``--replace
OBJECT[,OBJECT]=ASSET`` in ``/World/Assets`` in place of those objects. The mapping table is in
spec/bake-blender.md#scene-conversion; everything not converted exactly is a warning.

Conventions: Blender world (+Z up) -> USD (+Y up) by :data:`nasset_converters.blender.Z_UP_TO_Y_UP`
(meshes are written in world space; cameras and lights keep their local frames: Blender cameras,
suns, spots and area lights look / emit down local -Z like USD's); Blender light units -> the
renderer's: sun ``strength`` = irradiance (DistantLight intensity, ``angle`` = Blender's angular
diameter); point/spot of power P and radius r -> SphereLight radiance P / (4 pi^2 r^2) (a point
light of intensity P / (4 pi) W/sr when r = 0; a spot is a point light with Cycles' cone,
``nasset:shaping:falloff = smoothstep``); area of power P and area A -> RectLight radiance
P / (pi A); point and area lights hidden from camera rays as in Cycles; world Background colour
x strength -> DomeLight (an Environment Texture becomes a
lat-long OpenEXR with Cycles' equirectangular orientation). Every choice here is measured against
Cycles by converters/blender/fidelity.py (docs/conversion-fidelity.md).
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
from pathlib import Path

import numpy as np

from nasset_converters.mitsuba.usd_export import (  # noqa: F401
    ColorPrimvar,
    ConvertResult,
    Glass,
    StageConverter,
    TextureMap,
    mean_color,
    parse_replace,
    report,
    usd_check,
)
from nasset_sdk.errors import NassetError, UsageError, error, path_arg
from nasset_sdk.images import atomic_output, output_folder
from nasset_sdk.safeopen import trust

from . import Z_UP_TO_Y_UP
from .evaluation import evaluate_as_render, hidden_original
from .scene import render_visible

_R4 = np.eye(4)
_R4[:3, :3] = Z_UP_TO_Y_UP
#: dome local axes (rows) in USD world that make the renderer's lat-long lookup equal Blender's
#: equirectangular one (spec/bake-blender.md#scene-conversion)
DOME_ROWS = np.array([[0.0, 0.0, 1.0, 0.0], [0.0, 1.0, 0.0, 0.0], [-1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])


def _row(ob, *, unit: bool = True) -> np.ndarray:
    """USD row-vector 4x4 of a Blender object's world matrix, in +Y-up space; scale removed when ``unit``."""
    m = _R4 @ np.array(ob.matrix_world, np.float64)
    if unit:
        s = np.linalg.norm(m[:3, :3], axis=0)
        m[:3, :3] /= np.where(s > 0, s, 1.0)[None, :]
    return m.T


def _socket(node, name, default):
    s = node.inputs.get(name)
    if s is None:
        return default, False
    v = s.default_value
    try:
        v = tuple(float(x) for x in v)
    except TypeError:
        v = float(v)
    return v, bool(s.is_linked)


class _Placed:
    """An object seen through one placement by an instancer: the object's own attributes, with the placement's
    world matrix and name (lights in instanced collections; before, they were skipped with a warning)."""

    def __init__(self, ob, matrix_world: np.ndarray, name: str) -> None:
        self._ob, self.matrix_world, self.name = ob, matrix_world, name

    def __getattr__(self, key):
        return getattr(self._ob, key)


@dataclasses.dataclass
class _Geometry:
    """A Geometry Nodes instance's mesh, read during the depsgraph walk (its temporary object is gone after it):
    object-space triangles and what :meth:`_BlenderConverter._mesh` writes with them."""

    name: str
    geo: object
    uvs: list
    slots: list
    colors: list
    materials: list


class _BlenderConverter(StageConverter):
    def __init__(self, bpy, scene_path: Path, output: Path, replace: dict, *, layer: Path) -> None:
        super().__init__(None, None, scene_path, output, replace, False, layer=layer)
        self.bpy = bpy
        self.bscene = bpy.context.scene
        self.emissive_materials: set[str] = set()
        self.baked_materials: set[str] = set()  # materials with an input baked by Cycles: written per object
        self.gn_meshes: dict = {}  # Geometry Nodes instance meshes read during the depsgraph walk
        self.instancers: set[str] = set()  # objects that place instances

    # -- camera -----------------------------------------------------------------------------
    def camera(self) -> None:
        from pxr import Gf, UsdGeom, UsdRender

        ob = self.bscene.camera
        if ob is None:
            self.warn("the scene has no active camera: no camera written (the reference renderer needs one)")
            return
        cam = ob.data
        r = self.bscene.render
        size = (int(r.resolution_x * r.resolution_percentage / 100), int(r.resolution_y * r.resolution_percentage / 100))
        if cam.type not in ("PERSP", "ORTHO"):
            self.warn(f"camera {ob.name}: {cam.type} projection is not converted (perspective and orthographic only)")
            return
        horizontal = cam.sensor_fit == "HORIZONTAL" or (cam.sensor_fit == "AUTO" and size[0] >= size[1])
        path = self._name("/World", ob.name)
        c = UsdGeom.Camera.Define(self.stage, path)
        # USD's lens and filmback unit is a tenth of a scene unit; Cycles reads Blender's millimetres as 1e-3 units
        fl = float(cam.lens) / 100.0
        if cam.type == "ORTHO":  # ortho_scale spans the fitted side of the frame, in scene units
            fitted = 10.0 * float(cam.ortho_scale)
            ha = fitted if horizontal else fitted * size[0] / size[1]
            c.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
            view = f"{0.1 * ha:.4g} units wide"
        else:
            if horizontal:
                x_fov = float(cam.angle if cam.sensor_fit == "AUTO" else cam.angle_x)
            else:
                y_fov = float(cam.angle if cam.sensor_fit == "AUTO" else cam.angle_y)
                x_fov = 2.0 * math.atan(math.tan(y_fov / 2.0) * size[0] / size[1])
            ha = 2.0 * fl * math.tan(x_fov / 2.0)
            c.CreateProjectionAttr(UsdGeom.Tokens.perspective)
            view = f"x_fov {math.degrees(x_fov):.4g} deg"
        c.CreateFocalLengthAttr(fl)
        c.CreateHorizontalApertureAttr(ha)
        c.CreateVerticalApertureAttr(ha * size[1] / size[0])
        if cam.shift_x or cam.shift_y:  # Blender's shift is in units of the fitted side of the frame
            fit = ha if horizontal else ha * size[1] / size[0]
            c.CreateHorizontalApertureOffsetAttr(float(cam.shift_x) * fit)
            c.CreateVerticalApertureOffsetAttr(float(cam.shift_y) * fit)
        if cam.dof.use_dof:
            self._depth_of_field(ob, c)
        exposure = float(getattr(self.bscene.cycles, "film_exposure", 1.0))
        if exposure != 1.0:  # Cycles' Film > Exposure multiplies the rendered image
            if exposure > 0:
                c.CreateExposureAttr(math.log2(exposure))
            else:
                c.CreateExposureTimeAttr(0.0)
                self.warn(f"film exposure {exposure:g}: a black image")
        c.CreateClippingRangeAttr(Gf.Vec2f(float(cam.clip_start), float(cam.clip_end)))
        self._xform(c.GetPrim(), _row(ob))
        self.record(path, f"camera {ob.name} ({cam.type.lower()}, {view})")
        self.result.resolution = size
        settings = UsdRender.Settings.Define(self.stage, "/Render/Settings")
        settings.CreateResolutionAttr(Gf.Vec2i(*size))
        settings.CreateCameraRel().SetTargets([path])
        settings.CreatePixelAspectRatioAttr(1.0)

    def _depth_of_field(self, ob, c) -> None:
        """Cycles' thin lens -> ``fStop``, ``focusDistance`` (spec/renderer.md#cameras): Cycles' lens radius is
        ``lens 1e-3 / (2 fstop)`` and USD's ``0.1 focalLength / (2 fStop)`` with ``focalLength = lens / 100``, so the
        f-number carries over; a focus object gives its distance along the view axis, as Cycles measures it."""
        cam = ob.data
        if cam.type != "PERSP":
            self.warn(f"camera {ob.name}: depth of field of an orthographic camera dropped")
            return
        dof = cam.dof
        focus = float(dof.focus_distance)
        if dof.focus_object is not None:
            view = -np.array(ob.matrix_world, np.float64)[:3, 2]
            to_target = np.array(dof.focus_object.matrix_world, np.float64)[:3, 3] - np.array(ob.matrix_world, np.float64)[:3, 3]
            focus = abs(float(view @ to_target) / max(float(np.linalg.norm(view)), 1e-30))
        if dof.aperture_blades >= 3 or abs(float(dof.aperture_ratio) - 1.0) > 1e-6:
            self.warn(f"camera {ob.name}: a polygonal or anamorphic aperture ({dof.aperture_blades} blades, ratio "
                      f"{dof.aperture_ratio:g}) written as a round one")
        if focus <= 0:
            self.warn(f"camera {ob.name}: depth of field without a focus distance dropped (pinhole)")
            return
        c.CreateFStopAttr(max(float(dof.aperture_fstop), 1e-5))  # Cycles clamps the f-number alike
        c.CreateFocusDistanceAttr(focus)

    def integrator(self) -> None:
        """Cycles' bounce limit -> ``nasset:maxDepth`` and its pixel filter -> ``nasset:pixelFilter`` on
        /Render/Settings (spec/bake-blender.md#scene-conversion)."""
        from pxr import Sdf, UsdRender

        c = self.bscene.cycles
        # Cycles counts bounces after the first hit (0: direct light only), the renderer scattering vertices
        depth = int(c.max_bounces) + 1
        self.result.integrator = {"type": "cycles", "max_bounces": int(c.max_bounces), "samples": int(c.samples),
                                  "renderer_max_depth": depth}
        lower = {k: int(getattr(c, f"{k}_bounces")) for k in ("diffuse", "glossy", "transmission")
                 if int(getattr(c, f"{k}_bounces")) < int(c.max_bounces)}
        if lower:
            self.warn(f"render settings: per-type bounce limits {lower} below max bounces {int(c.max_bounces)} dropped "
                      f"(the reference renderer stops every path after {depth} scattering vertices)")
        self._image_settings()
        prim = UsdRender.Settings.Define(self.stage, "/Render/Settings").GetPrim()
        prim.CreateAttribute("nasset:maxDepth", Sdf.ValueTypeNames.Int, custom=True).Set(depth)
        kind, stddev = cycles_pixel_filter(str(c.pixel_filter_type), float(c.filter_width))
        if kind == "box" and abs(float(c.filter_width) - 1.0) > 1e-6:
            self.warn(f"render settings: box pixel filter of width {c.filter_width:.3g} px written as 1 px")
        elif c.pixel_filter_type == "BLACKMAN_HARRIS":
            self.warn(f"render settings: Blackman-Harris pixel filter (width {c.filter_width:.3g} px) written as a "
                      f"Gaussian of the same standard deviation ({stddev:.3g} px)")
        prim.CreateAttribute("nasset:pixelFilter", Sdf.ValueTypeNames.Token, custom=True).Set(kind)
        if stddev is not None:
            prim.CreateAttribute("nasset:pixelFilterStddev", Sdf.ValueTypeNames.Float, custom=True).Set(stddev)

    def _image_settings(self) -> None:
        """Name the render settings that change Cycles' image and that the stage does not carry: its biased
        shortcuts (clamping, Filter Glossy, caustics off; the stage renders unbiased, as the fidelity suite's Cycles
        ground truth does), motion blur, a render border, non-square pixels. Before, they went without a word."""
        c, r = self.bscene.cycles, self.bscene.render
        biased = [f"{k.replace('sample_clamp_', '')} clamp {getattr(c, k):g}" for k in ("sample_clamp_direct",
                                                                                         "sample_clamp_indirect")
                  if float(getattr(c, k)) > 0]
        if float(c.blur_glossy) > 0:
            biased.append(f"Filter Glossy {c.blur_glossy:g}")
        biased += [f"{kind} caustics off" for kind in ("reflective", "refractive") if not getattr(c, f"caustics_{kind}")]
        if biased:
            self.warn(f"render settings: Cycles' {', '.join(biased)} not carried (the stage renders unclamped, unfiltered "
                      "light paths)")
        if r.use_motion_blur:
            self.warn("render settings: motion blur dropped (the stage is rendered at the current frame)")
        if r.use_border:
            self.warn(f"render settings: render border ({r.border_min_x:g}-{r.border_max_x:g} x {r.border_min_y:g}-"
                      f"{r.border_max_y:g}{', cropped' if r.use_crop_to_border else ''}) dropped: the whole frame is written")
        if abs(float(r.pixel_aspect_x) - float(r.pixel_aspect_y)) > 1e-6:
            self.warn(f"render settings: pixel aspect {r.pixel_aspect_x:g}:{r.pixel_aspect_y:g} written as square pixels")

    # -- lights -------------------------------------------------------------------------------
    def lights(self) -> None:
        from pxr import Sdf, UsdLux

        from nasset_sdk import stage_rules

        renders = render_visible(self.bpy.context.view_layer)
        placed = [ob for ob in self.bscene.objects if ob.type == "LIGHT" and renders(ob)]
        for inst in self.bpy.context.evaluated_depsgraph_get().object_instances:  # lights placed by instancers
            if not inst.is_instance or inst.object.type != "LIGHT" or inst.parent is None:
                continue
            ob, parent = inst.object.original, inst.parent.original
            if not renders(parent) or parent.name in self.replace or (parent.instance_type == "COLLECTION"
                                                                      and ob.hide_render):
                continue
            placed.append(_Placed(ob, np.array(inst.matrix_world, np.float64), f"{parent.name}_{ob.name}"))
        for ob in placed:
            lt = ob.data
            if lt.type == "AREA" and lt.cycles.is_portal:
                continue  # a portal guides Cycles' sampling of the world and emits nothing (measured): no light
            self._light_settings(ob)
            color = np.array(lt.color, np.float64) * self._light_nodes(ob)
            path = self._name("/World/Lights", ob.name)
            if lt.type == "SUN":
                light = UsdLux.DistantLight.Define(self.stage, path)
                light.CreateAngleAttr(math.degrees(float(lt.angle)))
                self._xform(light.GetPrim(), _row(ob))
                self._light_common(light, color * float(lt.energy), path, f"sun {ob.name} (angle {math.degrees(lt.angle):.3g} deg)")
            elif lt.type in ("POINT", "SPOT"):
                r = float(lt.shadow_soft_size)
                light = UsdLux.SphereLight.Define(self.stage, path)
                row = _row(ob)
                scale = float(np.cbrt(abs(np.linalg.det(_row(ob, unit=False)[:3, :3]))))
                if r * scale > 0 and getattr(lt, "use_soft_falloff", False):
                    self.warn(f"light {ob.name}: Soft Falloff (Blender's default) makes Cycles light each point from a "
                              f"disk of radius {r * scale:.3g} facing it, dimmer than the stage's sphere light by "
                              "d^2 / (d^2 + r^2) at distance d (measured: 17 % brighter converted with r = 0.3 at "
                              "0.5 m; switch Soft Falloff off for an exact conversion)")
                if r * scale > 0:
                    rw = r * scale
                    light.CreateRadiusAttr(rw)
                    light.CreateTreatAsPointAttr(False)
                    self._hidden_from_camera(light)
                    value = color * float(lt.energy) / (4.0 * math.pi * math.pi * rw * rw)
                else:
                    light.CreateRadiusAttr(0.0)
                    light.CreateTreatAsPointAttr(True)
                    value = color * float(lt.energy) / (4.0 * math.pi)
                self._xform(light.GetPrim(), row)
                what = f"{lt.type.lower()} {ob.name} ({lt.energy:.4g} W, radius {r:.3g})"
                if lt.type == "SPOT":
                    self._spot_shaping(light, ob)
                self._light_common(light, value, path, what)
            elif lt.type == "AREA":
                w = float(lt.size)
                h = float(lt.size_y) if lt.shape in ("RECTANGLE", "ELLIPSE") else w
                row = _row(ob, unit=False)
                sx, sy = np.linalg.norm(row[0, :3]), np.linalg.norm(row[1, :3])
                if lt.shape in ("DISK", "ELLIPSE"):  # a DiskLight of radius 0.5 scaled to the w x h ellipse
                    light = UsdLux.DiskLight.Define(self.stage, path)
                    light.CreateRadiusAttr(0.5)
                    row = np.diag([w, h, 1.0, 1.0]) @ row
                    area = math.pi * 0.25 * w * h * sx * sy
                else:
                    light = UsdLux.RectLight.Define(self.stage, path)
                    light.CreateWidthAttr(w)
                    light.CreateHeightAttr(h)
                    area = w * h * sx * sy
                self._xform(light.GetPrim(), row)
                spread = float(getattr(lt, "spread", math.pi))
                if spread < math.pi - 1e-6:  # Cycles' soft-box profile, the same in the renderers (renderer.md#lights)
                    if spread < stage_rules.MIN_SPREAD:
                        self.warn(f"light {ob.name}: area light spread {spread:.3g} rad written as the narrowest a "
                                  f"renderer reads, {stage_rules.MIN_SPREAD:g} rad (Cycles: a parallel beam)")
                    light.GetPrim().CreateAttribute("nasset:spread", Sdf.ValueTypeNames.Float, custom=True).Set(
                        max(spread, stage_rules.MIN_SPREAD))
                self._hidden_from_camera(light)
                self._light_common(light, color * float(lt.energy) / (math.pi * max(area, 1e-12)), path,
                                   f"area {ob.name} ({lt.energy:.4g} W, {w:.3g} x {h:.3g})")
            else:
                self.warn(f"light {ob.name}: type {lt.type} is not convertible: skipped")
                continue
            if getattr(lt, "use_temperature", False):  # Cycles' blackbody tint is UsdLux's colour temperature
                light.CreateEnableColorTemperatureAttr(True)
                light.CreateColorTemperatureAttr(float(lt.temperature))
        self.world()

    def _light_settings(self, ob) -> None:
        """Warn about a light's Cycles settings the stage's lights cannot carry: shadows off, ray visibility off, a
        bounce limit of its own below the scene's (before, dropped without a word)."""
        lt, off = ob.data, []
        if not lt.use_shadow:
            off.append("casts no shadows")
        rays = [k[len("visible_"):] for k in ("visible_diffuse", "visible_glossy", "visible_transmission",
                                               "visible_volume_scatter") if not getattr(ob, k, True)]
        if rays:
            off.append(f"invisible to {', '.join(rays)} rays")
        if int(lt.cycles.max_bounces) < int(self.bscene.cycles.max_bounces):
            off.append(f"max bounces {lt.cycles.max_bounces}")
        links = getattr(ob, "light_linking", None)
        if links is not None and (links.receiver_collection is not None or links.blocker_collection is not None):
            off.append("light linking (it lights or shadows only some objects)")
        if off:
            self.warn(f"light {ob.name}: {', '.join(off)} in Cycles: dropped (the stage's light lights every path and "
                      "casts shadows)")

    def _light_nodes(self, ob) -> np.ndarray:
        """The factor [3] a light's node tree (Use Nodes) puts on its colour x power: Cycles multiplies the light by
        the Emission node's Color x Strength on its Light Output (measured: Strength 3 triples a point, sun or area
        light); a Blackbody node on the Color gives its colour. Before, the node tree was ignored (a light three times
        too dark, or white instead of tinted). Other links and nodes (textures, IES, Light Falloff): warned, 1 used."""
        from .shader_graph import resolved_copy

        lt = ob.data
        if not getattr(lt, "use_nodes", False) or lt.node_tree is None:
            return np.ones(3)
        with resolved_copy(self.bpy, lt) as resolved:
            nodes = resolved.node_tree.nodes
            out = next((n for n in nodes if n.bl_idname == "ShaderNodeOutputLight" and n.is_active_output), None)
            if out is None or not out.inputs["Surface"].is_linked:
                return np.zeros(3)  # no emission closure: the light gives nothing
            em = out.inputs["Surface"].links[0].from_node
            if em.bl_idname != "ShaderNodeEmission":
                self.warn(f"light {ob.name}: its node tree's {em.bl_idname} is not converted (an Emission node is): "
                          "the light's own colour and power used")
                return np.ones(3)
            color, c_linked = _socket(em, "Color", (1.0, 1.0, 1.0, 1.0))
            strength, s_linked = _socket(em, "Strength", 1.0)
            if c_linked:
                body = _blackbody(em.inputs["Color"])
                if body is None:
                    self.warn(f"light {ob.name}: node tree Emission Color from "
                              f"{em.inputs['Color'].links[0].from_node.bl_idname} dropped (white used)")
                color = body or (1.0, 1.0, 1.0)
            if s_linked:
                self.warn(f"light {ob.name}: node tree Emission Strength from "
                          f"{em.inputs['Strength'].links[0].from_node.bl_idname} dropped (1 used)")
                strength = 1.0
            return np.array(color[:3], np.float64) * float(strength)

    @staticmethod
    def _hidden_from_camera(light) -> None:
        """Cycles does not show point/spot/area light surfaces to camera rays (BSDF rays do reach them)."""
        from pxr import Sdf

        light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool, custom=True).Set(False)

    def _spot_shaping(self, light, ob) -> None:
        """Cycles' spot cone on a point light: ``shaping:cone:angle`` = spot_size / 2, ``shaping:cone:softness`` =
        spot_blend, ``nasset:shaping:falloff`` = smoothstep (spec/renderer.md#spot-lights)."""
        from pxr import Sdf, UsdLux

        lt = ob.data
        cone = math.degrees(float(lt.spot_size)) / 2.0
        shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
        shaping.CreateShapingConeAngleAttr(cone)
        shaping.CreateShapingConeSoftnessAttr(float(np.clip(lt.spot_blend, 0.0, 1.0)))
        light.GetPrim().CreateAttribute("nasset:shaping:falloff", Sdf.ValueTypeNames.Token, custom=True).Set("smoothstep")
        sx, sy = np.linalg.norm(_row(ob, unit=False)[:2, :3], axis=1)
        if not np.isclose(sx, sy, rtol=1e-4):
            self.warn(f"light {ob.name}: elliptic spot cone (object scale {sx:.3g} x {sy:.3g}) written as a round cone")

    def world(self) -> None:
        from .shader_graph import resolved_copy

        world = self.bscene.world
        if world is None or not world.node_tree:
            if world is not None:
                self.warn(f"world {world.name}: colour without a node tree written as a constant dome")
                self._dome_constant(np.array(world.color, np.float64), world)
            return
        with resolved_copy(self.bpy, world) as resolved:  # reroutes, muted nodes and links, constants as Cycles reads them
            self._world_tree(world, resolved.node_tree)

    def _world_tree(self, world, tree) -> None:
        out = next((n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld" and n.is_active_output), None)
        if out is not None and out.inputs["Volume"].is_linked:
            self.warn(f"world {world.name}: its volume (fog filling the scene) is dropped")
        link = out.inputs["Surface"].links[0] if out is not None and out.inputs["Surface"].is_linked else None
        if link is None:
            return
        bg = link.from_node
        if bg.bl_idname != "ShaderNodeBackground":
            return self._world_rendered(world, tree, f"its surface is a {bg.bl_idname}")
        strength, s_linked = _socket(bg, "Strength", 1.0)
        if s_linked:
            return self._world_rendered(world, tree, "its Strength comes from nodes")
        col = bg.inputs["Color"]
        if not col.is_linked:
            rgb = np.array(col.default_value[:3], np.float64) * float(strength)
            if rgb.max() > 0:
                self._dome_constant(rgb, world)
            return
        src = col.links[0].from_node
        if src.bl_idname != "ShaderNodeTexEnvironment" or src.image is None:
            return self._world_rendered(world, tree, f"its colour comes from {src.bl_idname}")
        if src.projection != "EQUIRECTANGULAR":
            return self._world_rendered(world, tree, f"its environment has {src.projection} projection")
        turn = 0.0
        if src.inputs["Vector"].is_linked:
            turn, note = _environment_turn(src.inputs["Vector"].links[0])
            if note:
                return self._world_rendered(world, tree, note)
        img = src.image
        space = img.colorspace_settings.name
        if space != "sRGB" and space not in _LINEAR_SPACES:
            return self._world_rendered(world, tree, f"its environment image is in colour space {space}")
        wid, hei = img.size
        px = np.array(img.pixels[:], np.float32).reshape(hei, wid, img.channels)[::-1, :, :3]  # Blender rows bottom-up
        if img.channels < 3:
            px = np.repeat(px[..., :1], 3, -1)
        # coarse maps made ENVMAP_MIN_WIDTH wide: at 8x, a 16 x 8 map's nearest texels still showed as steps
        px = _upsampled(px, min_width=ENVMAP_MIN_WIDTH) if src.interpolation != "Closest" else px
        if space == "sRGB":  # an 8-bit (or sRGB-tagged) map: decoded after the resampling, as Cycles interpolates
            from nasset_reference_renderer.textures import srgb_to_linear  # 8-bit texels before decoding them

            px = srgb_to_linear(np.clip(px, 0.0, 1.0)).astype(np.float32)
        self._dome_map(world, px, float(strength), turn, f"environment {wid}x{hei}")
        if src.interpolation not in ("Linear", "Closest"):
            self.warn(f"world {world.name}: {src.interpolation} environment interpolation written as linear")
        if px.shape[:2] == (hei, wid) and src.interpolation != "Closest":
            self.warn(f"world {world.name}: environment {wid}x{hei} too large to resample: looked up with nearest "
                      "texels by the reference renderer (Cycles: linear)")

    def _world_rendered(self, world, tree, why: str) -> None:
        """A world whose nodes do not map to a constant or an Environment Texture: Cycles renders it into a lat-long
        map (:mod:`world_bake`), which becomes the dome. Before, such worlds were dropped with a warning (a scene lit
        by a Sky Texture rendered black)."""
        from .world_bake import WORLD_WIDTH, reads_light_path, render_world

        px = render_world(self.bpy, world)
        self.warn(f"world {world.name}: {why}: rendered by Cycles into a {WORLD_WIDTH} x {WORLD_WIDTH // 2} lat-long map"
                  + (" (it reads Light Path: the map is what camera rays see, also used for lighting)"
                     if reads_light_path(tree) else ""))
        self._dome_map(world, px, 1.0, 0.0, f"rendered {WORLD_WIDTH}x{WORLD_WIDTH // 2}")

    def _dome_map(self, world, px: np.ndarray, strength: float, turn: float, what: str) -> None:
        """A DomeLight of lat-long texels ``px`` [H, W, 3] (an Environment Texture's layout) times ``strength``,
        turned by ``turn`` about Blender's Z (:func:`_environment_turn`)."""
        from pxr import Gf, Sdf, Tf, UsdLux

        from nasset_reference_renderer.film import write_exr

        tex_dir = self.output.parent / f"{self.output.stem}_textures"
        tex_dir.mkdir(parents=True, exist_ok=True)
        tex = tex_dir / f"{Tf.MakeValidIdentifier(world.name)}.exr"
        write_exr(tex, np.nan_to_num(np.maximum(px, 0.0), nan=0.0, posinf=0.0))
        self.result.textures.append(str(tex))
        path = self._name("/World/Lights", world.name)
        light = UsdLux.DomeLight.Define(self.stage, path)
        self._dome_camera_visibility(light, world)
        light.CreateTextureFileAttr(Sdf.AssetPath("./" + tex.relative_to(self.output.parent).as_posix()))  # anchored
        light.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
        c, s_ = math.cos(DOME_TURN_SIGN * turn), math.sin(DOME_TURN_SIGN * turn)  # about USD +Y (Blender +Z)
        spin = np.array([[c, 0.0, -s_, 0.0], [0.0, 1.0, 0.0, 0.0], [s_, 0.0, c, 0.0], [0.0, 0.0, 0.0, 1.0]])
        self._xform(light.GetPrim(), DOME_ROWS @ spin)
        self._light_common(light, np.full(3, float(strength)), path, f"world {world.name} ({what})")
        light.GetColorAttr().Set(Gf.Vec3f(1.0, 1.0, 1.0))

    def _dome_camera_visibility(self, light, world) -> None:
        """Cycles' transparent film (Film > Transparent) and a world hidden from camera rays (its Ray Visibility >
        Camera off) leave the background black in the rendered colours while the world still lights the scene: the
        dome gets ``nasset:cameraVisibility = false``. Before, the converted render showed the sky behind everything."""
        if self.bscene.render.film_transparent or not world.cycles_visibility.camera:
            self._hidden_from_camera(light)

    def _dome_constant(self, rgb, world) -> None:
        from pxr import UsdLux

        name = world.name
        path = self._name("/World/Lights", name)
        light = UsdLux.DomeLight.Define(self.stage, path)
        self._dome_camera_visibility(light, world)
        self._light_common(light, rgb, path, f"world {name} (constant colour)")

    # -- materials ----------------------------------------------------------------------------
    def blender_material(self, mat, ob_name: str, ob=None) -> str:
        """The path of ``mat``'s UsdPreviewSurface, written once per material, or once per object (``ob``, the
        original mesh object) where an input is baked by Cycles (:meth:`_bake`)."""
        # name_full: a local and a linked datablock may share a name (Blender names are unique per library only)
        key = ("blender", mat.name_full if mat is not None else None, self.looks_root)
        if mat is not None and mat.name_full in self.baked_materials:
            key = (*key, ob_name)
        if key in self.materials:
            return self.materials[key]
        baked: list = []
        normals: dict = {}  # the material's normal bake: one per object, whichever of its shaders asks first

        def bake(resolved, socket, node, scalar: bool, notes: list, normal: bool = False):
            baked.append(socket.name)
            if normal and "map" in normals:
                return normals["map"]
            result = self._bake(ob, ob_name, mat, resolved, socket, node, scalar, notes, normal)
            if normal:
                normals["map"] = result
            return result

        inputs, notes = map_material(mat, bake)
        if baked:  # Generated coordinates, UV layouts: per object
            self.baked_materials.add(mat.name_full)
            key = (*key, ob_name)
        for name in ("diffuseColor", "specularColor"):  # UsdPreviewSurface colours are reflectances in [0, 1]
            value = inputs.get(name)
            top = value.image.max() if isinstance(value, TextureMap) else max(value) if isinstance(value, tuple) else 0.0
            if top > 1.0 + 1e-6:
                notes.append(f"material {mat.name if mat is not None else '(none)'}: {name} up to {top:.3g} clamped to 1 "
                             "(Cycles reflects more light than it receives there; UsdPreviewSurface cannot)")
        for n in notes:
            self.warn(f"object {ob_name}: {n}")
        path = self._write_material(f"{mat.name}_{ob_name}" if baked else mat.name if mat is not None else "Default",
                                    inputs)
        self.record(path, f"material {mat.name if mat is not None else '(none)'}" + (f" of object {ob_name}" if baked
                                                                                       else ""))
        self.materials[key] = path
        em = inputs.get("emissiveColor", (0.0,))
        if (em.image.max() if isinstance(em, TextureMap) else max(em)) > 0:
            self.emissive_materials.add(path)
        return path

    def _bake(self, ob, ob_name: str, mat, resolved, socket, node, scalar: bool, notes: list, normal: bool = False):
        """A :class:`TextureMap` of ``socket``'s value over ``ob``'s UV map, baked by Cycles (procedural_bake), or None
        with a note naming why not (no mesh object, no UV map, Cycles' error); UV islands of ``mat``'s faces that
        overlap are noted. ``normal``: the material's tangent-space shading normal instead (a normal map)."""
        import time

        from .procedural_bake import BAKE_MAX, bake_input, bake_size, reads_placement, uv_overlap, uv_triangles

        what = f"material {mat.name}: {socket.name} from {node.bl_idname}"
        if ob is None or ob.type != "MESH":
            notes.append(f"{what} dropped: only mesh objects are baked by Cycles (this is "
                         f"{'a Geometry Nodes instance' if ob is None else ob.type}); its default value used")
            return None
        evaluated = ob.evaluated_get(self.bpy.context.evaluated_depsgraph_get())
        data = evaluated.data
        uv = next((layer.name for layer in data.uv_layers if layer.active_render), None)  # read before the bake
        if uv is None:
            notes.append(f"{what} dropped: object {ob_name} has no UV map to bake into (add one; its default value used)")
            return None
        slots = [k for k, s in enumerate(evaluated.material_slots) if s.material is not None and s.material.original == mat]
        shared = uv_overlap(uv_triangles(data, uv, slots or [0], len(evaluated.material_slots)))
        if shared > OVERLAP_WARN:
            notes.append(f"{what}: UV map {uv!r} of object {ob_name} overlaps itself ({100 * shared:.0f} % of the texels "
                         "its faces cover are covered more than once, e.g. mirrored halves): those faces share one "
                         "baked value, where Cycles shades each by its own coordinates")
        if self.geometry_root.startswith("/Prototypes") and reads_placement(socket):
            notes.append(f"{what} reads where the object is placed (world position, camera): its instances differ in "
                         f"Cycles; baked for {ob_name} and used for every instance")
        size = min(2 * bake_size(self.bpy, ob), BAKE_MAX) if normal else bake_size(self.bpy, ob)
        start = time.perf_counter()
        try:
            rgb = bake_input(self.bpy, ob, resolved, socket, size, normal=normal)
        except (RuntimeError, AttributeError) as exc:  # Cycles' error; linked (read-only) data
            notes.append(f"{what} dropped: Cycles could not bake object {ob_name} ({str(exc).strip()}); its default "
                         "value used")
            return None
        notes.append(f"{what} baked by Cycles over UV map {uv!r} into a {size} x {size} "
                     f"{'tangent-space normal map' if normal else 'linear image'} ({time.perf_counter() - start:.1f} s)")
        if normal:
            return TextureMap(rgb, f"Cycles normal bake of {socket.name} from {node.bl_idname} ({size}x{size}, object "
                              f"{ob_name})", scale_bias=((2.0, 2.0, 2.0, 1.0), (-1.0, -1.0, -1.0, 0.0)), wrap="clamp")
        if scalar:  # a colour into a float socket: its luminance (Rec. 709)
            rgb = np.repeat((rgb @ np.array([0.2126, 0.7152, 0.0722]))[..., None], 3, -1)
        # clamped: a UV map within [0, 1] reads no texel of the far edge at its own edges (repeat blended them in)
        return TextureMap(rgb, f"Cycles bake of {socket.name} from {node.bl_idname} ({size}x{size}, object {ob_name})",
                          wrap="clamp")

    # -- geometry -----------------------------------------------------------------------------
    def libraries(self) -> None:
        """Warn about each library Blender could not read: its linked datablocks are empty placeholders (an object
        becomes an empty), which Cycles renders as nothing and the stage leaves out alike."""
        from .scene import missing_library_note

        for lib in self.bpy.data.libraries:
            if lib.is_missing:
                self.warn(missing_library_note(self.bpy, lib))

    def shapes(self) -> None:
        """Meshes of the view layer (world space), then instances: objects placed by collection instances
        (and other instancers) and linked duplicates (mesh objects sharing one mesh without modifiers) become
        instanceable Xforms referencing one class prim ``/Prototypes/NAME`` per mesh (object space)."""
        from .scene import SURFACE_TYPES, has_particle_hair

        bpy = self.bpy
        renders = render_visible(bpy.context.view_layer)
        objects = [ob for ob in bpy.context.view_layer.objects if renders(ob) and ob.name not in self.replace]
        for ob in objects:
            if has_particle_hair(ob):
                self.warn(f"object {ob.name}: particle hair dropped (bake it: --replace {ob.name}=ASSET)")
        # an instancer's own surface with Show Instancer for Render off, and the originals a parent instances on its
        # vertices or faces: Cycles leaves them out (before, they were written: one object too many)
        objects = [ob for ob in objects if not hidden_original(ob)]
        self.instancers = {inst.parent.original.name for inst in bpy.context.evaluated_depsgraph_get().object_instances
                           if inst.is_instance and inst.parent is not None}
        users: dict = {}
        for ob in objects:
            if ob.type == "MESH" and not ob.modifiers and not has_particle_hair(ob):
                users.setdefault(ob.data.name_full, []).append(ob)
        for ob in objects:
            if ob.type == "CURVES":
                self.warn(f"object {ob.name}: hair curves outside an asset are dropped (bake them: --replace {ob.name}=ASSET)")
                continue
            if ob.type in ("CAMERA", "LIGHT", "EMPTY"):
                continue
            if ob.type not in SURFACE_TYPES:
                self.warn(f"object {ob.name}: {ob.type} is not convertible (surfaces are: {', '.join(SURFACE_TYPES)}): "
                          "skipped")
                continue
            self._ray_visibility(ob)
            if len(users.get(ob.data.name_full, ())) > 1:
                self._instance(ob, np.array(ob.matrix_world, np.float64), ob.name, f"linked duplicate of mesh {ob.data.name}")
            else:
                self._mesh(ob, self._name(self.geometry_root, ob.name), local=False)
        dg = bpy.context.evaluated_depsgraph_get()
        skipped = set()
        placements = []  # written after the walk: writing materials adds datablocks, which re-evaluates the depsgraph
        for inst in dg.object_instances:
            if not inst.is_instance:
                continue
            ob, parent = inst.object.original, inst.parent.original if inst.parent is not None else None
            if parent is not None and parent.name in self.replace:
                continue  # the asset stands in for the instancer and what it places
            if parent is not None and not renders(parent):
                continue  # an instancer Cycles does not render places nothing
            if parent is not None and parent.instance_type == "COLLECTION" and ob.hide_render:
                continue  # Cycles leaves out a collection instance's objects disabled in renders (particles keep theirs)
            if parent is not None and parent.name == ob.name:
                if ob.type == "MESH":  # instances a Geometry Nodes tree makes (not realized): read while they exist
                    self._geometry_instance(inst, parent, placements, skipped)
                continue  # else a curve, text, surface or metaball's own evaluated mesh: written as the object itself
            if ob.name in self.replace:
                if ("replaced", ob.name) not in skipped:
                    skipped.add(("replaced", ob.name))
                    self.warn(f"object {ob.name}: its instances are not written (--replace places the asset once, "
                              "in world space)")
                continue
            if ob.type not in SURFACE_TYPES:
                if ob.type not in ("EMPTY", "CAMERA", "LIGHT") and ob.name not in skipped:  # lights: lights()
                    skipped.add(ob.name)
                    self.warn(f"object {ob.name}: instances of a {ob.type} are not convertible (surfaces are: "
                              f"{', '.join(SURFACE_TYPES)}): skipped")
                continue
            placements.append((ob, np.array(inst.matrix_world, np.float64), f"{parent.name if parent else 'instance'}_{ob.name}",
                               f"instance of {ob.name} placed by {parent.name if parent else '(unknown)'}"))
        for ob, matrix, name, what in placements:
            self._instance(ob, matrix, name, what)

    def _geometry_instance(self, inst, parent, placements: list, skipped: set) -> None:
        """Queue an instance of Geometry Nodes geometry (``inst.object`` is a temporary object holding it): its mesh is
        read now, once per mesh, into a :class:`_Geometry`. Before, such instances were dropped (the instancer called
        an object without faces)."""
        from .scene import mesh_geometry

        temp = inst.object
        if temp.type != "MESH":
            if (parent.name, temp.type) not in skipped:
                skipped.add((parent.name, temp.type))
                self.warn(f"object {parent.name}: Geometry Nodes instances of {temp.type} geometry are not converted "
                          "(mesh instances are): skipped")
            return
        key = ("geometry", temp.data.as_pointer())
        geometry = self.gn_meshes.get(key)
        if geometry is None:
            uvs: list = []
            slots: list = []
            colors: list = []
            dropped: list = []
            try:
                geo = mesh_geometry([temp], local=True, uv_out=uvs, slot_out=slots, color_out=colors, dropped_out=dropped)
                for note in dropped:
                    self.warn(f"{note} (a Geometry Nodes instance placed by {parent.name})")
            except NassetError as exc:
                self.warn(f"object {parent.name}: a Geometry Nodes instance: {exc.message}: skipped")
                geo = None
            mats = [s.material.original if s.material is not None else None for s in temp.material_slots]
            geometry = _Geometry(f"{parent.name}_{temp.data.name}", geo, uvs, slots, colors, mats)
            self.gn_meshes[key] = geometry
        if geometry.geo is not None:
            placements.append((geometry, np.array(inst.matrix_world, np.float64), geometry.name,
                               f"Geometry Nodes instance placed by {parent.name}"))

    def _ray_visibility(self, ob) -> None:
        """Warn about Cycles settings the stage cannot carry: ray visibility switched off, holdout, shadow catcher."""
        off = [k[len("visible_"):] for k in ("visible_camera", "visible_shadow", "visible_diffuse", "visible_glossy",
                                              "visible_transmission", "visible_volume_scatter") if not getattr(ob, k, True)]
        flags = [k for k in ("is_holdout", "is_shadow_catcher") if getattr(ob, k, False)]
        links = getattr(ob, "light_linking", None)
        if links is not None and (links.receiver_collection is not None or links.blocker_collection is not None):
            flags.append("light linking")
        if off or flags:
            self.warn(f"object {ob.name}: " + ", ".join(([f"invisible to {', '.join(off)} rays"] if off else []) + flags)
                      + " dropped (the stage shows it to every ray as an ordinary surface)")

    def _instance(self, ob, matrix_world, name: str, what: str) -> None:
        """An instanceable Xform (Blender world matrix ``matrix_world`` [4,4]) referencing the class prim of ``ob``'s
        mesh (written once per mesh and material set, in object space)."""
        from pxr import Sdf, Tf

        if isinstance(ob, _Geometry):
            key, mesh_name = ("geometry", id(ob)), ob.name
        else:
            mats = tuple(s.material.name_full if s.material else "" for s in ob.material_slots)
            key, mesh_name = (ob.data.name_full, mats), ob.data.name  # full names: linked data may share local names
        proto = self.prototypes.get(key)
        if proto is None:
            self.stage.CreateClassPrim("/Prototypes")  # abstract: rendered only through instances
            proto = self._name("/Prototypes", Tf.MakeValidIdentifier(mesh_name))
            self.stage.CreateClassPrim(proto)
            saved = (self.geometry_root, self.looks_root)
            self.geometry_root, self.looks_root = proto, f"{proto}/Looks"
            try:
                self._mesh(ob, self._name(proto, mesh_name), local=True)
            finally:
                self.geometry_root, self.looks_root = saved
            self.prototypes[key] = proto
            self.record(proto, f"mesh {mesh_name} (prototype)")
        path = self._name(self.geometry_root, name)
        prim = self.stage.DefinePrim(path, "Xform")
        prim.GetReferences().AddInternalReference(Sdf.Path(proto))
        prim.SetInstanceable(True)
        self._xform(prim, (_R4 @ matrix_world @ _R4.T).T)
        self.record(path, what)

    def _mesh(self, ob, path: str, *, local: bool) -> None:
        """A UsdGeom.Mesh at ``path`` of the evaluated mesh object ``ob`` (world or object space, +Y up) bound to its
        first slot's material, a ``materialBind`` GeomSubset per other slot in use, and, when a material is textured,
        the active render UV map as faceVarying primvar ``st``."""
        from pxr import Sdf, UsdGeom, UsdShade, Vt

        from nasset_reference_renderer.lights import MAX_MESH_LIGHT_TRIANGLES

        from .scene import mesh_geometry

        if isinstance(ob, _Geometry):  # read while the depsgraph walk held it
            geo, uvs, slots, colors, slot_mats = ob.geo, ob.uvs, ob.slots, ob.colors, ob.materials or [None]
        else:
            uvs, slots, colors, dropped = [], [], [], []
            try:
                geo = mesh_geometry([ob], local=local, uv_out=uvs, slot_out=slots, color_out=colors, dropped_out=dropped)
                for note in dropped:
                    self.warn(note)
            except NassetError as exc:  # no faces, or a degenerate transform
                if not (ob.name in self.instancers and "no faces" in exc.message):  # its instances are written
                    self.warn(f"object {ob.name}: {exc.message}: skipped")
                return
            # the evaluated object's slots, as Cycles reads them: a modifier may change them (geometry a Geometry
            # Nodes tree makes or realizes without materials shows the default surface, not the object's material)
            evaluated = ob.evaluated_get(self.bpy.context.evaluated_depsgraph_get())
            slot_mats = [s.material.original if s.material is not None else None
                         for s in evaluated.material_slots] or [None]
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(geo.points, np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(geo.faces), 3, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(geo.faces.ravel(), np.int32)))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(geo.normals, np.float32)))
        mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([geo.points.min(0), geo.points.max(0)])))
        # Cycles shades a triangle with its slot's material (slot indices past the last slot take the last one)
        tri_slot = np.minimum(slots[0] if slots else np.zeros(len(geo.faces), np.int32), len(slot_mats) - 1)
        used = np.unique(tri_slot)
        paths = {int(k): self.blender_material(slot_mats[k], ob.name, None if isinstance(ob, _Geometry) else ob)
                 for k in used}
        binding = UsdShade.MaterialBindingAPI.Apply(mesh.GetPrim())
        binding.Bind(UsdShade.Material(self.stage.GetPrimAtPath(paths[int(used[0])])))
        for k in used[1:]:  # the first slot in use is the mesh's binding, each other one a GeomSubset of its faces
            subset = binding.CreateMaterialBindSubset(f"slot_{int(k)}", Vt.IntArray.FromNumpy(
                np.nonzero(tri_slot == k)[0].astype(np.int32)), UsdGeom.Tokens.face)
            UsdShade.MaterialBindingAPI.Apply(subset.GetPrim()).Bind(UsdShade.Material(self.stage.GetPrimAtPath(paths[int(k)])))
        for k, mat_path in paths.items():
            n_tri = int((tri_slot == k).sum())
            if mat_path in self.emissive_materials and n_tri > MAX_MESH_LIGHT_TRIANGLES:
                self.warn(f"object {ob.name}: emissive mesh of {n_tri} triangles: the reference renderer "
                          f"light-samples emissive meshes of at most {MAX_MESH_LIGHT_TRIANGLES} triangles only; this one "
                          "is reached by BSDF rays only (right mean, more noise)")
        wanted = {self.color_primvars[p].primvar: self.color_primvars[p] for p in paths.values() if p in self.color_primvars}
        for name, want in wanted.items():  # colour attributes the materials read (renderer.md#primvar-colors)
            values = colors[0].get(want.attribute) if colors else None
            if values is None:
                self.warn(f"object {ob.name}: its material reads colour attribute {want.attribute or '(default)'!r}, which "
                          "the mesh lacks: the reader's fallback (grey) is used")
                continue
            pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(name, Sdf.ValueTypeNames.Color3fArray, UsdGeom.Tokens.faceVarying)
            pv.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(values.reshape(-1, 3) * want.scale, np.float32)))
        if any(p in self.textured_materials for p in paths.values()):
            uv = uvs[0] if uvs else None
            if uv is None:
                self.warn(f"object {ob.name}: textured material but the mesh has no UV map: the texture's corner texel "
                          "is used")
            else:
                pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray,
                                                             UsdGeom.Tokens.faceVarying)
                pv.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(uv.reshape(-1, 2), np.float32)))
        self.record(path, f"object {ob.name} (mesh, {len(geo.faces)} triangles)")

    def run(self) -> ConvertResult:
        from pxr import Gf

        self.camera()
        self.integrator()
        self.lights()
        self.libraries()
        self.shapes()
        self.assets()
        self.stage.GetRootLayer().customLayerData = {
            "nasset:convertedFrom": {"scene": self.scene_path.name, "converter": "nasset convert-scene",
                                     "blender": self.bpy.app.version_string, "integrator": dict(self.result.integrator),
                                     "resolution": Gf.Vec2i(*self.result.resolution)},
        }
        self.stage.GetRootLayer().Save()
        trust(self.stage.GetRootLayer().realPath)  # this process wrote it: rendered without a probe while unchanged
        if self.check_usd:
            self.result.usd_checks = usd_check(self.output)
        return self.result


#: image textures stored in sRGB are resampled to at most this many texels (see :func:`image_texture`)
TEXTURE_MAX_PIXELS = 1 << 20
#: a resampled environment map is made at least this wide (within ENVMAP_MAX_PIXELS)
ENVMAP_MIN_WIDTH = 1024


def _upsampled(px: np.ndarray, wrap_s: str = "repeat", wrap_t: str = "clamp", max_pixels: int | None = None,
               min_width: int = 0) -> np.ndarray:
    """An image [H, W, 3] (row 0 at the top) resampled bilinearly with these wrap modes at ENVMAP_UPSAMPLE x its
    size (more, by powers of two, up to ``min_width`` texels wide), or less so that it stays within
    ``max_pixels`` (default ENVMAP_MAX_PIXELS); unchanged when even 2x is too large. For a lat-long map
    (periodic in u, clamped at the poles) the renderer's nearest-texel lookup of the result then follows
    Cycles' linear interpolation."""
    from nasset_converters.mitsuba.usd_export import ENVMAP_MAX_PIXELS, ENVMAP_UPSAMPLE
    from nasset_reference_renderer.textures import ImageTexture

    h, w = px.shape[:2]
    limit = ENVMAP_MAX_PIXELS if max_pixels is None else max_pixels
    f = ENVMAP_UPSAMPLE
    while w * f < min_width:
        f *= 2
    while f > 1 and h * w * f * f > limit:
        f //= 2
    if f == 1:
        return px
    t, s = np.meshgrid(1.0 - (np.arange(h * f) + 0.5) / (h * f), (np.arange(w * f) + 0.5) / (w * f), indexing="ij")
    tex = ImageTexture(px, wrap_s=wrap_s, wrap_t=wrap_t)
    return tex.sample(np.stack([s.ravel(), t.ravel()], 1)).reshape(h * f, w * f, 3).astype(np.float32)


def cycles_pixel_filter(kind: str, width: float) -> tuple[str, float | None]:
    """(``nasset:pixelFilter``, stddev in pixels or None) for Cycles' ``pixel_filter_type`` and ``filter_width`` (px).

    Cycles tabulates its filters over [-width/2, width/2] and samples them separably: ``GAUSSIAN`` is
    exp(-2 (6 x / width)^2), a Gaussian of standard deviation width / 12; ``BLACKMAN_HARRIS`` the
    4-term window over that span, whose standard deviation (numerically 0.139 width) the Gaussian
    takes; ``BOX`` a box (the renderer's is 1 px).
    """
    if kind == "GAUSSIAN":
        return "gaussian", width / 12.0
    if kind == "BLACKMAN_HARRIS":
        x = np.linspace(-0.5, 0.5, 4001)
        v = 2.0 * np.pi * (x + 0.5)
        w = 0.35875 - 0.48829 * np.cos(v) + 0.14128 * np.cos(2 * v) - 0.01168 * np.cos(3 * v)
        return "gaussian", width * float(np.sqrt(np.sum(w * x * x) / np.sum(w)))
    return "box", None


#: Principled BSDF inputs that UsdPreviewSurface cannot carry: (input, "off" value)
_DROPPED = (("Subsurface Weight", 0.0), ("Transmission Weight", 0.0), ("Coat Weight", 0.0), ("Sheen Weight", 0.0),
            ("Anisotropic", 0.0), ("Thin Film Thickness", 0.0), ("Diffuse Roughness", 0.0),
            ("Specular Tint", (1.0, 1.0, 1.0, 1.0)))


def map_material(mat, bake=None) -> tuple[dict, list]:
    """UsdPreviewSurface inputs for a Blender material and notes on what the mapping loses. ``bake(resolved material,
    socket, node, scalar, notes)``: a TextureMap (or None) for a BSDF input fed by nodes no mapping converts, called
    with the temporary copy of the material whose links are resolved (:mod:`shader_graph`)."""
    grey = {"diffuseColor": (0.8, 0.8, 0.8), "roughness": 0.5, "metallic": 0.0}
    if mat is None:
        return dict(DEFAULT_SURFACE), []
    if not mat.node_tree:
        return {"diffuseColor": tuple(mat.diffuse_color[:3]), "roughness": float(mat.roughness),
                "metallic": float(mat.metallic)}, [f"material {mat.name}: viewport colours used (no node tree)"]
    from types import SimpleNamespace

    from . import load_bpy
    from .shader_graph import resolved_copy

    with resolved_copy(load_bpy(), mat) as resolved:  # reroutes, muted nodes and links, constants as Cycles reads them
        nodes = resolved.node_tree.nodes
        out = next((n for n in nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n.is_active_output), None)
        if out is None:
            return grey, [f"material {mat.name}: no material output node, grey used"]
        if not out.inputs["Surface"].is_linked:  # Cycles: no surface closure is an opaque black surface; with a
            if out.inputs["Volume"].is_linked:  # volume, a boundary light crosses
                return dict(NO_SURFACE, opacity=0.0), [f"material {mat.name}: volume shader dropped (the object is "
                                                       "written as its see-through boundary)"]
            return dict(NO_SURFACE), []
        notes: list = []
        if out.inputs["Volume"].is_linked:
            notes.append(f"material {mat.name}: volume shader dropped (the surface alone is written)")
        # ``bake`` rides on the material record that every mapping function receives (read by image_texture)
        record = SimpleNamespace(name=mat.name, bake=None if bake is None else
                                 (lambda socket, node, scalar, notes, normal=False:
                                  bake(resolved, socket, node, scalar, notes, normal)))
        inputs = _map_shader(record, out.inputs["Surface"].links[0].from_node, notes)
        if out.inputs["Displacement"].is_linked:
            if mat.displacement_method == "BUMP" and record.bake is not None and inputs is not None \
                    and "normal" not in inputs and not _emitter_only(inputs):
                # Cycles shades the surface with the displacement as a bump: the normal it makes, baked
                normal = record.bake(out.inputs["Displacement"], out.inputs["Displacement"].links[0].from_node, False,
                                     notes, normal=True)
                if normal is not None:
                    inputs["normal"] = normal
            else:
                notes.append(f"material {mat.name}: displacement ({mat.displacement_method.lower().replace('_', ' ')}) "
                             "dropped (the undisplaced, unbumped surface is written"
                             + ("; a bump-only displacement is baked into a normal map for mesh objects)"
                                if mat.displacement_method != "BUMP" else ")"))
    return (grey, notes) if inputs is None else (inputs, notes)


def _emitter_only(inputs: dict) -> bool:
    """Whether mapped ``inputs`` are an Emission shader's (black, no normal to shade with)."""
    return "emissiveColor" in inputs and inputs.get("diffuseColor") == (0.0, 0.0, 0.0)


#: Cycles' default surface, which it shows where no material is assigned: a Diffuse BSDF of colour 0.8 (before, the
#: converter wrote a grey UsdPreviewSurface with its default specular lobe: about 1 % too bright)
DEFAULT_SURFACE = {"diffuseColor": (0.8, 0.8, 0.8), "useSpecularWorkflow": 1, "specularColor": (0.0, 0.0, 0.0),
                   "roughness": 1.0}
#: a surface without a closure (an unlinked Surface, a muted shader), as Cycles renders it: opaque black
NO_SURFACE = {"diffuseColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 1, "specularColor": (0.0, 0.0, 0.0),
              "roughness": 1.0}


#: shader nodes :func:`_map_shader` converts
SHADER_NODES = ("ShaderNodeBsdfDiffuse", "ShaderNodeBsdfPrincipled", "ShaderNodeEmission", "ShaderNodeBsdfAnisotropic",
                "ShaderNodeMixShader", "ShaderNodeAddShader", "ShaderNodeBsdfTransparent")


#: BSDF nodes without a UsdPreviewSurface counterpart, written as the closest opaque surface (warned; before
#: 2026-12-07 each was grey 0.8 whatever its colour): their Color as a diffuse albedo (Subsurface Scattering: the far
#: field of its random walk; Toon), half of it (Translucent: the light it passes to the other side, shown on both), or
#: black with the Fresnel reflection of the IOR times Color (Glass, as convert-scene writes Mitsuba's dielectrics), or
#: black (Sheen: a grazing lobe of little albedo). A ball of each under a sun against Cycles (48², 64 spp, MSE / noise,
#: grey before -> now): Subsurface 36 -> 1.4, Translucent 521 -> 14 (diffuse 145, black 78), Sheen 760 -> 24, Toon
#: 272 -> 156, Glass 2.0 -> 1.9 (1.13 -> 0.86 of Cycles' mean: the light it lets through). Glass and Refraction are
#: now MaterialX glasses beside that opaque fallback (renderer.md#transmission); Refraction without its reflection
#: (specular_color 0): a lifted ball over a checker under a sky reads 0.93 of Cycles there, MSE / noise 7.0 (48², 128
#: spp; 0.92 at roughness 0.3), since Cycles' Refraction BSDF passes the light the Fresnel term would reflect (black
#: before: 0.55, MSE / noise 372)
APPROXIMATED_SHADERS = {"ShaderNodeSubsurfaceScattering": "diffuse", "ShaderNodeBsdfTranslucent": "half",
                        "ShaderNodeBsdfToon": "diffuse", "ShaderNodeBsdfGlass": "glass",
                        "ShaderNodeBsdfRefraction": "glass", "ShaderNodeBsdfSheen": "black"}


def _approximated_shader(mat, node, notes: list) -> dict:
    """UsdPreviewSurface inputs standing for a node of :data:`APPROXIMATED_SHADERS` (a note says what is lost)."""
    how = APPROXIMATED_SHADERS[node.bl_idname]
    col, linked = _socket(node, "Color", (0.8, 0.8, 0.8, 1.0))
    if linked:
        col = color_input(mat, node.inputs["Color"], notes) or col
    col = col if isinstance(col, (TextureMap, ColorPrimvar)) else tuple(float(c) for c in col[:3])
    name = node.bl_idname.replace("ShaderNodeBsdf", "").replace("ShaderNode", "")
    out = dict(NO_SURFACE)
    if how in ("diffuse", "half"):
        out["diffuseColor"] = col if how == "diffuse" else _scaled(col, 0.5)
        what = "a diffuse surface of its Color" + (" x 0.5" if how == "half" else "")
    elif how == "glass":
        ior, _ = _socket(node, "IOR", 1.5)
        rough, _ = _socket(node, "Roughness", 0.0)
        f0 = ((float(ior) - 1.0) / (float(ior) + 1.0)) ** 2
        tint = np.asarray(col if isinstance(col, tuple) else (1.0, 1.0, 1.0), np.float64)
        rough = float(np.clip(rough, 0.0, 1.0))
        # the UsdPreviewSurface keeps the opaque reflector for renderers that read only it; the MaterialX glass
        # (renderer.md#transmission) is what the renderers here read
        refraction = name == "Refraction"  # no reflection: the glass's specular colour 0, the fallback black
        colour = tuple(float(c) for c in np.clip(tint, 0.0, 1.0))
        out.update(specularColor=(0.0, 0.0, 0.0) if refraction else tuple(float(c) for c in np.clip(f0 * tint, 0.0, 1.0)),
                   roughness=rough, glass=Glass(1.0, colour, max(float(ior), 1e-3), rough, False,
                                                specular=(0.0, 0.0, 0.0) if refraction else colour))
        distribution = getattr(node, "distribution", "GGX")
        what = (f"a MaterialX glass (IOR {float(ior):.3g}, roughness {rough:.3g}, renderer.md#transmission), its Color "
                + ("on the transmission, no reflection (Cycles' Refraction BSDF also passes the light the Fresnel "
                   "term would reflect: about 7 % dark)" if refraction else "on both the transmission and the reflection")
                + (f"; GGX for its {distribution} distribution" if distribution not in ("GGX", "MULTI_GGX") else ""))
    else:
        what = "black (" + ("it only refracts" if name == "Refraction" else "a grazing lobe of little albedo") + ")"
    if (nmap := _linked_normal(mat, node, notes)) is not None:
        out["normal"] = nmap
    if how == "glass":
        notes.append(f"material {mat.name}: {name} BSDF written as {what}")
    else:
        notes.append(f"material {mat.name}: {name} BSDF has no counterpart (UsdPreviewSurface transmission and scattering "
                     f"are not rendered): written as {what}; bake the object into a neural asset (--replace)")
    return out


def _map_shader(mat, node, notes: list, depth: int = 0) -> dict | None:
    """UsdPreviewSurface inputs of the shader ``node`` (None, with a note, when it is not convertible). Mix and Add
    Shaders combine their inputs' parameters (:func:`_combine`)."""
    if node.bl_idname in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
        if depth >= 8:
            notes.append(f"material {mat.name}: shader mixes nested deeper than 8: grey")
            return None
        mix = node.bl_idname == "ShaderNodeMixShader"
        socks = [sk for sk in node.inputs if sk.type == "SHADER"]
        if mix and any(sk.is_linked and sk.links[0].from_node.bl_idname == "ShaderNodeBsdfTransparent" for sk in socks):
            return _presence_mix(mat, node, socks, notes, depth)
        fac, f_linked = _socket(node, "Factor", 0.5) if mix else (0.0, False)
        if f_linked:
            notes.append(f"material {mat.name}: linked Mix Shader Factor dropped (its default {fac:.3g} used)")
        fac = float(np.clip(fac, 0.0, 1.0))
        parts = []
        for k, sock in enumerate(s for s in node.inputs if s.type == "SHADER"):
            w = ((1.0 - fac) if k == 0 else fac) if mix else 1.0
            if not sock.is_linked or w <= 0.0:
                continue  # an empty shader slot adds nothing
            sub = _map_shader(mat, sock.links[0].from_node, notes, depth + 1)
            if sub is None:
                return None
            parts.append((w, sub))
        notes.append(f"material {mat.name}: {node.name} converted by combining its shaders' parameters (exact for "
                     "diffuse and emission, approximate for glossy lobes)")
        return _combine(parts, mat, notes)
    if node.bl_idname == "ShaderNodeBsdfAnisotropic":  # Blender's Glossy BSDF
        col, c_linked = _socket(node, "Color", (0.8, 0.8, 0.8, 1.0))
        rough, r_linked = _socket(node, "Roughness", 0.5)
        aniso, _ = _socket(node, "Anisotropy", 0.0)
        if c_linked or r_linked:
            notes.append(f"material {mat.name}: linked Glossy BSDF {'Color' if c_linked else 'Roughness'} dropped")
        rough = float(np.clip(rough, 0.0, 1.0))
        k = multiscatter_scale(rough, col[:3]) if node.distribution == "MULTI_GGX" else np.ones(3)
        beckmann = node.distribution == "BECKMANN"  # Cycles' alpha = roughness^2, as the renderer's
        notes.append(f"material {mat.name}: Glossy BSDF as a {'Beckmann' if beckmann else 'GGX'} lobe of specular colour "
                     "Color (Schlick Fresnel from it"
                     + (f"; x ({', '.join(f'{v:.3f}' for v in k)}) for Cycles' multiple-scattering GGX" if
                        node.distribution == "MULTI_GGX" else "") + ")"
                     + (", anisotropy dropped" if abs(aniso) > 1e-6 else ""))
        out = {"diffuseColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 1, "specularColor": _scaled(col[:3], k),
               "roughness": rough}
        if beckmann:  # renderer.md#materials (before 2026-12-07 a GGX of alpha x 0.82-0.93 stood in for it)
            out["microfacet"] = "beckmann"
        if (nmap := _linked_normal(mat, node, notes)) is not None:
            out["normal"] = nmap  # (before 2026-12-07 a Glossy BSDF's normal input was ignored without a word)
        return out
    if node.bl_idname == "ShaderNodeHoldout":  # Cycles: black to the camera (alpha 0), an absorbing black surface
        notes.append(f"material {mat.name}: Holdout written as a black surface (the film's alpha 0 is not carried)")
        return dict(NO_SURFACE)
    if node.bl_idname == "ShaderNodeBsdfTransparent":  # alone: nothing there (presence 0)
        return {"diffuseColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 1, "specularColor": (0.0, 0.0, 0.0),
                "roughness": 1.0, "opacity": 0.0}
    if node.bl_idname in APPROXIMATED_SHADERS:
        return _approximated_shader(mat, node, notes)
    if node.bl_idname not in SHADER_NODES:
        notes.append(f"material {mat.name}: {node.bl_idname} is not convertible ({', '.join(SHADER_NODES)} are): grey")
        return None
    if node.bl_idname == "ShaderNodeBsdfDiffuse":
        col, linked = _socket(node, "Color", (0.8, 0.8, 0.8, 1.0))
        if linked:
            col = color_input(mat, node.inputs["Color"], notes) or col
        rough, r_linked = _socket(node, "Roughness", 0.0)
        if r_linked or rough > 0:
            notes.append(f"material {mat.name}: Diffuse BSDF roughness {rough:.3g} dropped (Lambertian)")
        out = {"diffuseColor": col if isinstance(col, (TextureMap, ColorPrimvar)) else col[:3], "roughness": 1.0,
               "metallic": 0.0, "useSpecularWorkflow": 1, "specularColor": (0.0, 0.0, 0.0)}
        if (nmap := _linked_normal(mat, node, notes)) is not None:
            out["normal"] = nmap
        return out
    if node.bl_idname == "ShaderNodeEmission":
        col, c_linked = _socket(node, "Color", (1.0, 1.0, 1.0, 1.0))
        col, c_linked = _emission_color(mat, node.inputs["Color"], col, c_linked, notes)
        strength, s_linked = _socket(node, "Strength", 1.0)
        if c_linked or s_linked:
            notes.append(f"material {mat.name}: linked emission {'Color' if c_linked else 'Strength'} dropped (its "
                         "default used)")
        return {"diffuseColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 1, "specularColor": (0.0, 0.0, 0.0),
                "roughness": 1.0, "emissiveColor": _scaled(col if isinstance(col, TextureMap) else col[:3], float(strength))}
    vals = {}
    for name, default in (("Base Color", (0.8, 0.8, 0.8, 1.0)), ("Roughness", 0.5), ("Metallic", 0.0), ("IOR", 1.5),
                          ("Specular IOR Level", 0.5), ("Alpha", 1.0), ("Normal", None)):
        v, linked = _socket(node, name, default)
        vals[name] = v
        if linked and name == "Base Color":
            vals[name] = color_input(mat, node.inputs[name], notes) or v
        elif linked and name in ("Alpha", "Roughness", "Metallic"):
            vals[name] = image_texture(mat, node.inputs[name], notes, scalar=True) or v
        elif linked and name == "Normal":
            vals[name] = normal_map(mat, node.inputs[name], notes)
        elif linked:
            notes.append(f"material {mat.name}: linked {name} dropped (its default value used)")
    emission = None
    e_strength, es_linked = _socket(node, "Emission Strength", 0.0)
    e_color, ec_linked = _socket(node, "Emission Color", (1.0, 1.0, 1.0, 1.0))
    e_color, ec_linked = _emission_color(mat, node.inputs["Emission Color"], e_color, ec_linked, notes)
    if es_linked or ec_linked:
        notes.append(f"material {mat.name}: linked Principled emission dropped")
    elif e_strength > 0:
        emission = _scaled(e_color if isinstance(e_color, TextureMap) else e_color[:3], float(e_strength))
    transmission, t_linked = _socket(node, "Transmission Weight", 0.0)
    transmission = 0.0 if t_linked else float(np.clip(transmission, 0.0, 1.0))
    for name, off in _DROPPED:
        v, linked = _socket(node, name, off)
        if name == "Transmission Weight" and not linked:
            continue  # a constant weight scales the diffuse base below
        if linked or not np.allclose(np.ravel(v)[:3], np.ravel(off)[:3], rtol=0.0, atol=1e-6):
            notes.append(f"material {mat.name}: Principled {name} dropped (no UsdPreviewSurface counterpart; "
                         "bake the object into a neural asset)")
    base = vals["Base Color"]
    inputs = {"diffuseColor": base if isinstance(base, (TextureMap, ColorPrimvar)) else base[:3],
              "roughness": _scalar(vals["Roughness"]),
              "metallic": _scalar(vals["Metallic"])}
    if isinstance(vals["Normal"], TextureMap):
        inputs["normal"] = vals["Normal"]
    alpha = vals["Alpha"]  # Cycles' alpha is presence: UsdPreviewSurface opacity, threshold 0 (renderer.md#cutouts)
    if isinstance(alpha, TextureMap) or float(alpha) < 1.0:
        inputs["opacity"] = alpha if isinstance(alpha, TextureMap) else float(np.clip(alpha, 0.0, 1.0))
    if emission is not None:
        inputs["emissiveColor"] = emission
    if transmission > 0.0 and _mean(inputs["metallic"]) < 1.0:
        # Cycles' dielectric base is diffuse x (1 - t) + transmission x t under the specular layer: a MaterialX glass of
        # weight t x (1 - metallic) (renderer.md#transmission), tinted by the base colour, beside the opaque rest; the
        # UsdPreviewSurface alone keeps the diffuse base x (1 - t) for renderers that read only it
        metal, rough, base = _mean(inputs["metallic"]), _mean(inputs["roughness"]), inputs["diffuseColor"]
        colour = np.clip(mean_color(base), 0.0, 1.0)
        tint = np.sqrt(colour)  # Cycles tints a pass through (two refractions) by the base colour once
        ior, _ = _socket(node, "IOR", 1.5)
        inputs["glass"] = Glass(transmission * (1.0 - metal), tuple(float(c) for c in tint), max(float(ior), 1e-3),
                                float(np.clip(rough, 0.0, 1.0)), False, base=tuple(float(c) for c in colour),
                                metalness=metal / max(1.0 - transmission * (1.0 - metal), 1e-12))
        inputs["diffuseColor"] = _scaled(inputs["diffuseColor"], 1.0 - transmission)
        notes.append(f"material {mat.name}: Principled Transmission Weight {transmission:.3g}: a MaterialX glass of "
                     f"weight {transmission * (1.0 - metal):.3g} tinted by the square root of the base colour at each "
                     "refraction"
                     + (" (textured: its mean)" if isinstance(base, (TextureMap, ColorPrimvar)) else ""))
    metal = inputs["metallic"]
    if not isinstance(metal, TextureMap) and float(metal) > 0.0 and not isinstance(inputs["roughness"], TextureMap):
        base = inputs["diffuseColor"]
        mean = (base.image.reshape(-1, 3).mean(0) if isinstance(base, TextureMap) else
                np.full(3, 0.5) if isinstance(base, ColorPrimvar) else np.asarray(base, np.float64))
        k = 1.0 + float(metal) * (multiscatter_scale(float(inputs["roughness"]), mean) - 1.0)
        if np.max(np.abs(k - 1.0)) > 1e-3:
            inputs["diffuseColor"] = _scaled(base, k)
            top = float(np.max(mean * k))
            notes.append(f"material {mat.name}: Principled metal colour x ({', '.join(f'{v:.3f}' for v in k)}) for Cycles' "
                         "multiple-scattering GGX (the stage's lobe scatters once)"
                         + (f"; above 1 ({top:.3g}), clamped by UsdPreviewSurface: darker than Cycles" if top > 1.0 else ""))
    elif isinstance(metal, TextureMap) or isinstance(inputs["roughness"], TextureMap):
        if _mean(metal) > 0.0:
            notes.append(f"material {mat.name}: textured metal or roughness: Cycles' multiple-scattering GGX energy not "
                         "compensated (rough metal parts render darker)")
    level = float(vals["Specular IOR Level"])
    if level <= 1e-6 and _mean(inputs["metallic"]) <= 0.0:
        inputs.update(useSpecularWorkflow=1, specularColor=(0.0, 0.0, 0.0))
    else:
        inputs["ior"] = float(vals["IOR"])
        if abs(level - 0.5) > 1e-6:
            notes.append(f"material {mat.name}: Specular IOR Level {level:.3g} dropped (0.5 assumed)")
        if _mean(inputs["metallic"]) <= 0.0:
            inputs["diffuseColor"], how = _layered_diffuse(inputs["diffuseColor"], inputs["roughness"], inputs["ior"])
            notes.append(f"material {mat.name}: Principled base colour x {how} for the specular layer's albedo "
                         "(Cycles layers the lobes, UsdPreviewSurface adds them)")
    if "glass" in inputs and transmission < 1.0:  # the glass's opaque rest: the diffuse base as written, before x (1 - t)
        base = np.asarray(mean_color(inputs["diffuseColor"]), np.float64) / (1.0 - transmission)
        inputs["glass"] = dataclasses.replace(inputs["glass"], base=tuple(float(c) for c in np.clip(base, 0.0, 1.0)))
    return inputs


def _layered_diffuse(base, rough, ior: float) -> tuple:
    """(base colour x :func:`principled_diffuse_scale`, how): per texel of a roughness texture when the base colour is
    a constant or a texture of the same texels (before, the factor at the texture's mean roughness: a checker of
    0.15 / 0.8 rendered its smooth squares 3 % too bright, its rough ones 3 % too dark); else at the mean roughness."""
    same = isinstance(base, TextureMap) and isinstance(rough, TextureMap) and base.image.shape == rough.image.shape \
        and (base.uv, base.wrap) == (rough.uv, rough.wrap)
    if not isinstance(rough, TextureMap) or not (same or isinstance(base, tuple)):
        k = principled_diffuse_scale(_mean(rough), ior)
        return _scaled(base, k), (f"{k:.3f}" if not isinstance(rough, TextureMap) else f"{k:.3f} (at the roughness "
                                  "texture's mean: the base colour is not a texture of the same texels)")
    grid, table = _diffuse_scale_table(float(ior))
    k = np.interp(np.clip(rough.image[..., :1], 0.0, 1.0), grid, table)
    image = (base.image if same else np.asarray(base[:3], np.float64)) * k
    return (dataclasses.replace(rough, image=image, what=f"base colour x specular albedo per texel of {rough.what}"),
            f"{float(k.min()):.3f}-{float(k.max()):.3f} per roughness texel")


@functools.lru_cache(maxsize=8)
def _diffuse_scale_table(ior: float, n: int = 33) -> tuple:
    """:func:`principled_diffuse_scale` at ``n`` roughnesses over [0, 1] (it is smooth in roughness: interpolated)."""
    grid = np.linspace(0.0, 1.0, n)
    return grid, np.array([principled_diffuse_scale(r, ior) for r in grid])


def _presence_mix(mat, node, socks, notes: list, depth: int) -> dict | None:
    """A Mix Shader of a Transparent BSDF and a shader S: S with presence (UsdPreviewSurface ``opacity``, threshold 0;
    renderer.md#cutouts) = S's weight, the Factor or 1 - Factor, a texture where the Factor is an Image Texture's
    Alpha or Color (Cycles' classic cut-out leaf); times S's own opacity."""
    kinds = [sk.links[0].from_node.bl_idname if sk.is_linked else None for sk in socks]
    k_other = 1 if kinds[0] == "ShaderNodeBsdfTransparent" else 0
    if kinds[k_other] in (None, "ShaderNodeBsdfTransparent"):
        notes.append(f"material {mat.name}: {node.name} mixes a Transparent BSDF with nothing else: grey")
        return None
    transparent = socks[1 - k_other].links[0].from_node
    col, c_linked = _socket(transparent, "Color", (1.0, 1.0, 1.0, 1.0))
    if c_linked or min(col[:3]) < 1.0 - 1e-6:
        notes.append(f"material {mat.name}: Transparent BSDF colour {tuple(round(c, 3) for c in col[:3])} written as "
                     "colourless presence")
    sub = _map_shader(mat, socks[k_other].links[0].from_node, notes, depth + 1)
    if sub is None:
        return None
    fac, f_linked = _socket(node, "Factor", 0.5)
    weight = image_texture(mat, node.inputs["Factor"], notes, scalar=True) if f_linked else None
    if weight is None:
        fac = float(np.clip(fac, 0.0, 1.0))
        weight = fac if k_other == 1 else 1.0 - fac
    else:
        weight.image = np.clip(weight.image if k_other == 1 else 1.0 - weight.image, 0.0, 1.0)
    own = sub.get("opacity", 1.0)
    if isinstance(weight, TextureMap) and isinstance(own, TextureMap):
        if weight.image.shape == own.image.shape:
            weight.image = weight.image * own.image
        else:
            notes.append(f"material {mat.name}: two opacity textures of different sizes: the Mix Shader's kept")
    elif isinstance(own, TextureMap):
        weight = _scaled(own, float(weight))
    else:
        weight = _scaled(weight, float(own)) if isinstance(weight, TextureMap) else float(weight) * float(own)
    sub["opacity"] = weight
    return sub


def _scalar(v):
    """A Principled float input: its TextureMap, or its value as a float."""
    return v if isinstance(v, TextureMap) else float(v)


def _mean(v) -> float:
    """A float, or the mean of a one-channel TextureMap (inside shader mixes, which keep one value per lobe)."""
    return float(v.image[..., 0].mean()) if isinstance(v, TextureMap) else float(v)


def _specular_form(inputs: dict) -> tuple:
    """(kd, F0, roughness, emission) of converted inputs in the specular workflow (spec/renderer.md#materials:
    kd = diffuseColor (1 - metallic), F0 = lerp(((1 - ior) / (1 + ior))^2, diffuseColor, metallic)); kd may be a
    TextureMap, F0 of a textured metal is its mean colour."""
    base = inputs["diffuseColor"]
    emission = inputs.get("emissiveColor", (0.0, 0.0, 0.0))  # inside a mix a texture gives its mean
    emission = emission.image.reshape(-1, 3).mean(0) if isinstance(emission, TextureMap) else np.asarray(emission, np.float64)
    if inputs.get("useSpecularWorkflow"):
        return base, np.asarray(inputs.get("specularColor", (0.0, 0.0, 0.0)), np.float64), _mean(inputs["roughness"]), emission
    m, ior = _mean(inputs.get("metallic", 0.0)), float(inputs.get("ior", 1.5))
    mean = base.image.reshape(-1, 3).mean(0) if isinstance(base, TextureMap) else \
        np.full(3, 0.5 * base.scale) if isinstance(base, ColorPrimvar) else np.asarray(base, np.float64)
    f0 = ((1.0 - ior) / (1.0 + ior)) ** 2 * (1.0 - m) + mean * m
    return _scaled(base, 1.0 - m), f0, _mean(inputs["roughness"]), emission


def _combine(parts: list, mat, notes: list) -> dict:
    """Specular-workflow inputs of ``sum(w * shader)`` over ``parts`` [(w, inputs)]: kd, F0 and emission are the
    weighted sums (a texture is kept and the constant colours are added to its texels; of two textures the heavier
    one is kept, noted), the roughness is the mean weighted by each part's w x mean F0 (the lobes it shapes)."""
    glasses = [(w * inputs["glass"].weight, inputs["glass"]) for w, inputs in parts if "glass" in inputs]
    t = min(sum(w for w, _ in glasses), 1.0)  # the glass weight of the sum; the rest is (1 - t) x the opaque parts
    parts = [(w * (1.0 - inputs["glass"].weight if "glass" in inputs else 1.0) / max(1.0 - t, 1e-12), inputs)
             for w, inputs in parts]
    kd_tex, kd_sum, f0, em, rough_w, rough = None, np.zeros(3), np.zeros(3), np.zeros(3), 0.0, 0.0
    for w, inputs in parts:
        kd, f, r, e = _specular_form(inputs)
        if isinstance(kd, TextureMap):
            if kd_tex is None or w > kd_tex[0]:
                if kd_tex is not None:
                    notes.append(f"material {mat.name}: a mixed texture ({kd_tex[1].what}) dropped: one texture per input")
                kd_tex = (w, kd)
            else:
                notes.append(f"material {mat.name}: a mixed texture ({kd.what}) dropped: one texture per input")
        elif isinstance(kd, ColorPrimvar):  # one value per lobe here: the attribute's colour is lost
            notes.append(f"material {mat.name}: colour attribute {kd.attribute!r} inside a shader mix replaced by grey")
            kd_sum += w * 0.5 * kd.scale
        else:
            kd_sum += w * np.asarray(kd, np.float64)
        f0 += w * f
        em += w * e
        s = w * float(np.mean(f))
        rough_w, rough = rough_w + s, rough + s * float(r)
    if kd_tex is not None:
        w, tex = kd_tex
        kd = dataclasses.replace(tex, image=tex.image * w + kd_sum)
    else:
        kd = tuple(float(c) for c in kd_sum)
    out = {"diffuseColor": kd, "useSpecularWorkflow": 1, "specularColor": tuple(float(c) for c in f0),
           "roughness": rough / rough_w if rough_w > 0 else 1.0}
    # the microfacet distribution of the part that weighs most in the specular lobe
    heaviest = max(parts, key=lambda part: part[0] * float(np.mean(_specular_form(part[1])[1])), default=None)
    if heaviest is not None and heaviest[1].get("microfacet"):
        out["microfacet"] = heaviest[1]["microfacet"]
    em *= max(1.0 - t, 1e-12)  # emission is not part of the glass mixture: the parts' own weights
    if em.any():
        out["emissiveColor"] = tuple(float(c) for c in em)
    if glasses:  # of several glasses the heaviest one's IOR, tint and roughness; the base is the opaque parts'
        out["glass"] = dataclasses.replace(max(glasses, key=lambda g: g[0])[1], weight=t, base=mean_color(kd))
        if len(glasses) > 1:
            notes.append(f"material {mat.name}: {len(glasses)} glasses in a Mix / Add Shader written as the heaviest one")
    if any("opacity" in inputs for _, inputs in parts):
        notes.append(f"material {mat.name}: the opacity of a shader inside a Mix / Add Shader dropped (opaque; a Mix "
                     "with a Transparent BSDF is converted)")
    normals = [(w, inputs["normal"]) for w, inputs in parts if "normal" in inputs]
    if normals:  # one shading normal per material: the heaviest shader's (before 2026-12-07 dropped without a word)
        w, out["normal"] = max(normals, key=lambda p: p[0])
        if len(normals) < len(parts) or len({id(n) for _, n in normals}) > 1:
            notes.append(f"material {mat.name}: the normal map of one shader ({out['normal'].what}, weight {w:.3g}) "
                         "applied to the whole Mix / Add Shader (one shading normal per material)")
    return out


def principled_diffuse_scale(roughness: float, ior: float, n: int = 24) -> float:
    """Factor on a dielectric Principled BSDF's base colour for UsdPreviewSurface: Cycles attenuates the diffuse
    layer by the specular layer's albedo, UsdPreviewSurface adds the two lobes. Returns 1 - the cosine-weighted
    mean albedo of the renderer's own specular lobe (GGX, alpha = roughness^2, Schlick F0 of ``ior``), by
    stratified VNDF quadrature over ``n`` view angles x ``n`` x ``n`` samples (0.947 at roughness 0.5, IOR 1.5)."""
    from nasset_reference_renderer.bsdf import MIN_ALPHA, ggx_lambda, ggx_sample_vndf, reflect

    f0 = ((float(ior) - 1.0) / (float(ior) + 1.0)) ** 2
    alpha = max(float(roughness) ** 2, MIN_ALPHA)
    g = (np.arange(n) + 0.5) / n
    u = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    albedo = 0.0
    for mu in g:
        wo = np.tile([math.sqrt(1.0 - mu * mu), 0.0, mu], (len(u), 1))
        h = ggx_sample_vndf(wo, alpha, u)
        wi = reflect(wo, h)
        up = wi[:, 2] > 0
        fres = f0 + (1.0 - f0) * (1.0 - np.clip(np.einsum("ij,ij->i", wo, h), 0.0, 1.0)) ** 5
        lo, li = ggx_lambda(wo, alpha), ggx_lambda(np.where(up[:, None], wi, [[0.0, 0.0, 1.0]]), alpha)
        albedo += 2.0 * mu * float(np.mean(np.where(up, fres * (1.0 + lo) / (1.0 + lo + li), 0.0))) / n  # F G2/G1
    return float(np.clip(1.0 - albedo, 0.0, 1.0))


def _scaled(color, k):
    """A colour [3], TextureMap or ColorPrimvar times ``k`` (a number, or one per channel)."""
    if isinstance(color, TextureMap):
        return dataclasses.replace(color, image=color.image * k)
    if isinstance(color, ColorPrimvar):
        return dataclasses.replace(color, scale=color.scale * k)
    return tuple(float(c) * float(f) for c, f in zip(color, np.broadcast_to(k, 3), strict=False))


def multiscatter_scale(roughness: float, f0, n: int = 24) -> np.ndarray:
    """Per-channel factor [3] by which Cycles' Principled metal (multiple-scattering GGX) reflects more than the
    renderer's single-scattering GGX lobe of the same roughness and Schlick ``f0`` [3], averaged over view angles
    (cosine-weighted). Cycles scales its lobe by ``1 + F_ms (1 - E(mu)) / E(mu)`` (Turquin's energy compensation:
    ``E`` the lobe's directional albedo with F = 1, ``F_ms = F_ss E_avg / (1 - F_ss (1 - E_avg))``, ``F_ss`` the
    hemispherical mean of Schlick's Fresnel); the factor is the mean of that times the single-scattering albedo over
    the mean of the albedo, by the quadrature of :func:`principled_diffuse_scale` (1.04 / 1.10 / 1.77 in red for
    F0 0.8 at roughness 0.35 / 0.5 / 0.94)."""
    from nasset_reference_renderer.bsdf import MIN_ALPHA, ggx_lambda, ggx_sample_vndf, reflect

    f0 = np.clip(np.asarray(f0, np.float64)[:3], 0.0, 1.0)
    alpha = max(float(roughness) ** 2, MIN_ALPHA)
    g = (np.arange(n) + 0.5) / n
    u = np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    e, a = np.zeros(n), np.zeros((n, 3))
    for k, mu in enumerate(g):
        wo = np.tile([math.sqrt(1.0 - mu * mu), 0.0, mu], (len(u), 1))
        h = ggx_sample_vndf(wo, alpha, u)
        wi = reflect(wo, h)
        up = wi[:, 2] > 0
        lo, li = ggx_lambda(wo, alpha), ggx_lambda(np.where(up[:, None], wi, [[0.0, 0.0, 1.0]]), alpha)
        g2g1 = np.where(up, (1.0 + lo) / (1.0 + lo + li), 0.0)
        c = (1.0 - np.clip(np.einsum("ij,ij->i", wo, h), 0.0, 1.0)) ** 5
        e[k] = g2g1.mean()
        a[k] = [(np.where(up, f + (1.0 - f) * c, 0.0) * g2g1).mean() for f in f0]
    e_avg = 2.0 * float(np.mean(e * g))
    f_ss = f0 + (1.0 - f0) / 21.0
    f_ms = f_ss * e_avg / (1.0 - f_ss * (1.0 - e_avg))
    boost = 1.0 + f_ms[None, :] * ((1.0 - e) / np.maximum(e, 1e-6))[:, None]
    w = g[:, None] * a
    return (w * boost).sum(0) / np.maximum(w.sum(0), 1e-12)


#: a baked UV map sharing more than this fraction of its texels between faces is warned (procedural_bake.uv_overlap)
OVERLAP_WARN = 0.02
#: shader nodes and inputs whose unmappable node chains are baked by Cycles (procedural_bake)
BAKED_NODES = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeEmission")
BAKED_INPUTS = ("Base Color", "Color", "Roughness", "Metallic", "Emission Color", "Alpha")
#: Blender colour spaces whose texels are linear values as stored (others are decoded from sRGB or warned)
_LINEAR_SPACES = ("Non-Color", "Linear Rec.709", "Linear", "Raw", "Linear CIE-XYZ E", "Linear CIE-XYZ D65")
#: Image Texture extension -> UsdUVTexture wrap mode
_WRAP = {"REPEAT": "repeat", "EXTEND": "clamp", "CLIP": "black", "MIRROR": "mirror"}


def _emission_color(mat, socket, value, linked: bool, notes: list):
    """(colour or TextureMap, still linked) of an emission colour socket: a Blackbody node's colour, an Image Texture
    (renderer.md#textures: textured emission), else the socket's value, still linked."""
    if not linked:
        return value, False
    if (bb := _blackbody(socket)) is not None:
        return bb, False
    if socket.links[0].from_node.bl_idname == "ShaderNodeTexImage" or getattr(mat, "bake", None) is not None:
        tex = image_texture(mat, socket, notes)
        return (tex, False) if tex is not None else (value, True)
    return value, True


def _blackbody(socket) -> tuple | None:
    """The colour of a Blackbody node (unlinked Temperature) feeding ``socket``: USD's blackbody RGB, which is Blender's
    curve to 1e-4 (renderer.md#lights), else None."""
    node = socket.links[0].from_node
    if node.bl_idname != "ShaderNodeBlackbody" or node.inputs["Temperature"].is_linked:
        return None
    from pxr import UsdLux

    return tuple(float(c) for c in UsdLux.BlackbodyTemperatureAsRgb(float(node.inputs["Temperature"].default_value)))


def color_input(mat, socket, notes: list):
    """A colour socket fed by a Color Attribute node, or an Attribute node of geometry type, reading a colour attribute:
    a :class:`ColorPrimvar` (the mesh carries it, renderer.md#primvar-colors); else :func:`image_texture`."""
    node = socket.links[0].from_node
    if node.bl_idname == "ShaderNodeVertexColor" and socket.links[0].from_socket.name == "Color":
        return ColorPrimvar(node.layer_name)
    if node.bl_idname == "ShaderNodeAttribute" and node.attribute_type == "GEOMETRY" \
            and socket.links[0].from_socket.name == "Color":
        return ColorPrimvar(node.attribute_name)
    return image_texture(mat, socket, notes)


def image_texture(mat, socket, notes: list, *, scalar: bool = False) -> TextureMap | None:
    """A :class:`TextureMap` (linear texels, top row first) for an input ``socket`` fed by an Image Texture node's
    Color output, else None with a note. Colour space: ``sRGB`` texels are decoded from sRGB, ``Non-Color`` and
    linear spaces taken as stored; what the renderer does differently (closest/cubic interpolation, a linked
    Vector, box/sphere projection) is noted per texture. ``scalar`` (a float socket such as Alpha): the node's
    Alpha output (1 where the image has no alpha; never colour-decoded) or its Color output's luminance, repeated
    in the three channels."""
    from nasset_reference_renderer.textures import srgb_to_linear

    from .texel_ops import apply_chain, describe, texel_chain

    link, ops = texel_chain(socket)  # through colour and float nodes folded into the texels (texel_ops)
    if link is None:
        bake = getattr(mat, "bake", None)  # the converter's Cycles bake for one object (procedural_bake)
        if bake is not None and socket.node.bl_idname in BAKED_NODES and socket.name in BAKED_INPUTS:
            return bake(socket, ops, scalar, notes)
        notes.append(f"material {mat.name}: {socket.name} from {ops.bl_idname} dropped (Image Texture outputs are "
                     "converted, also through Mix, Math, Map Range, Color Ramp, Invert, Gamma, Brightness/Contrast, "
                     "Separate Color and RGB to BW nodes with constant other inputs; its default value used)")
        return None
    tex = link.from_node
    outputs = ("Color", "Alpha") if scalar or ops else ("Color",)
    if tex.image is None or link.from_socket.name not in outputs:
        notes.append(f"material {mat.name}: {socket.name} from {tex.bl_idname}.{link.from_socket.name} dropped (Image "
                     f"Texture {' / '.join(outputs)} outputs are converted; its default value used)")
        return None
    img = tex.image
    w, h = img.size
    if img.source in ("TILED", "SEQUENCE", "MOVIE"):  # img.pixels holds one tile or frame
        kind = {"TILED": "UDIM tiles: the first tile", "SEQUENCE": "an image sequence: its current frame",
                "MOVIE": "a movie: its current frame"}[img.source]
        notes.append(f"material {mat.name}: image {img.name} is {kind} only is written")
    if w * h == 0 or img.channels < 1:
        notes.append(f"material {mat.name}: image {img.name} has no pixels (missing file?): {socket.name} default used")
        return None
    px = np.array(img.pixels[:], np.float64).reshape(h, w, img.channels)[::-1]  # Blender rows bottom-up
    rgb = np.repeat(px[..., :1], 3, -1) if img.channels < 3 else px[..., :3]
    space = img.colorspace_settings.name
    what = f"image {img.name} ({w}x{h}, {space})"
    wrap = _WRAP.get(tex.extension, "repeat")
    if link.from_socket.name == "Alpha":  # straight alpha, linear whatever the colour space
        alpha = px[..., 3] if img.channels == 4 else np.ones((h, w))
        rgb, space, what = np.repeat(alpha[..., None], 3, -1), "Non-Color", f"alpha of image {img.name} ({w}x{h})"
    if tex.interpolation == "Closest":  # nearest texels: repeated up to 64x (within the budget), so that the
        f = 64  # renderer's bilinear lookup blends only the outer 1/128 of each texel
        while f > 1 and rgb.shape[0] * rgb.shape[1] * f * f > TEXTURE_MAX_PIXELS:
            f //= 2
        rgb = rgb.repeat(f, 0).repeat(f, 1)
    if space == "sRGB":
        # Cycles interpolates 8-bit sRGB texels before decoding them: resampled finer in sRGB, then decoded, the
        # renderer's bilinear lookup of linear texels follows that
        if not img.is_float and tex.interpolation == "Linear":
            rgb = _upsampled(np.clip(rgb, 0.0, 1.0), wrap, wrap, TEXTURE_MAX_PIXELS)
        rgb = srgb_to_linear(np.clip(rgb, 0.0, 1.0))
    elif space not in _LINEAR_SPACES:
        notes.append(f"material {mat.name}: image {img.name} in colour space {space} taken as linear")
    if tex.interpolation not in ("Linear", "Closest"):
        notes.append(f"material {mat.name}: image {img.name}: {tex.interpolation} interpolation looked up bilinearly")
    if tex.projection != "FLAT":
        notes.append(f"material {mat.name}: image {img.name}: {tex.projection} projection dropped (UV mapped)")
    uv = None
    if tex.inputs["Vector"].is_linked:
        uv, note = _uv_mapping(tex.inputs["Vector"].links[0])
        if note:
            notes.append(f"material {mat.name}: image {img.name}: {note} (the active render UV map used)")
    rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
    is_color = link.from_socket.name == "Color"
    if ops:
        rgb, is_color = apply_chain(ops, rgb, is_color)
        rgb = np.nan_to_num(rgb, nan=0.0, posinf=0.0, neginf=0.0)
        what = f"{what} through {describe(ops)}"
    if scalar and is_color:  # a colour into a float socket: its luminance (Rec. 709)
        rgb = np.repeat((rgb @ np.array([0.2126, 0.7152, 0.0722]))[..., None], 3, -1)
    return TextureMap(rgb, what, wrap=wrap, uv=uv)


def _linked_normal(mat, node, notes: list) -> TextureMap | None:
    """:func:`normal_map` of a shader node's Normal input where something is linked to it, else None."""
    socket = node.inputs.get("Normal")
    return normal_map(mat, socket, notes) if socket is not None and socket.is_linked else None


def normal_map(mat, socket, notes: list) -> TextureMap | None:
    """A tangent-space normal map for a Normal input, else None with a note. Fed by a tangent-space Normal Map node
    reading an Image Texture: its texels (n + 1) / 2 with the node's Strength folded in, n' = z + (n - z) strength in
    tangent space (Cycles mixes the world normals so; the renderer normalises), and UsdUVTexture scale 2, bias -1
    (renderer.md#normal-maps). Fed by anything else (a Bump node, a procedural normal map, a linked Strength): the
    normal Cycles shades with, baked per object in that tangent space where the material has a Cycles bake."""
    node = socket.links[0].from_node
    plain = node.bl_idname == "ShaderNodeNormalMap" and node.space == "TANGENT"
    strength, s_linked = _socket(node, "Strength", 1.0) if plain else (1.0, False)
    color = node.inputs["Color"] if plain else None
    tried: list = []
    tex = image_texture(mat, color, tried) if plain and not s_linked and color.is_linked else None
    bake = getattr(mat, "bake", None)  # the converter's Cycles bake for one object (procedural_bake)
    if tex is None and bake is not None:  # (the material is baked as it is: any BSDF node)
        return bake(socket, node, False, notes, normal=True)
    notes.extend(tried)
    if not plain:
        what = node.bl_idname if node.bl_idname != "ShaderNodeNormalMap" else f"a Normal Map in {node.space} space"
        notes.append(f"material {mat.name}: {socket.name} from {what} dropped (tangent-space Normal Map nodes are "
                     "converted, other normals are baked by Cycles for mesh objects; the mesh normals used)")
        return None
    if tex is None:
        if s_linked or not color.is_linked:
            notes.append(f"material {mat.name}: Normal Map {'Strength linked' if s_linked else 'without an image'} "
                         "dropped (the mesh normals used)")
        return None
    if color.links[0].from_node.bl_idname == "ShaderNodeTexImage" and \
            color.links[0].from_node.image.colorspace_settings.name == "sRGB":
        notes.append(f"material {mat.name}: normal map {tex.what} is in sRGB (decoded; normal maps are Non-Color)")
    n = 2.0 * tex.image - 1.0
    n = np.array([0.0, 0.0, 1.0]) + (n - np.array([0.0, 0.0, 1.0])) * max(float(strength), 0.0)
    if node.uv_map:
        notes.append(f"material {mat.name}: Normal Map UV map {node.uv_map!r} read as the active render UV map")
    return dataclasses.replace(tex, image=(n + 1.0) / 2.0, what=f"normal map {tex.what}",
                               scale_bias=((2.0, 2.0, 2.0, 1.0), (-1.0, -1.0, -1.0, 0.0)))


def _uv_mapping(link) -> tuple[tuple | None, str]:
    """(UsdTransform2d (scale [2], rotation in degrees, translation [2]) or None, note) of the Vector feeding an Image
    Texture: the UV output of a Texture Coordinate node, a UV Map node (identity), or a Point-type Mapping node on
    one of them, turning about Z only (scale, rotate, translate: the UsdTransform2d order). Anything else is noted
    and the UVs are used as they are."""
    node, out = link.from_node, link.from_socket.name

    def plain_uv(n, socket) -> bool:
        return (n.bl_idname == "ShaderNodeTexCoord" and socket == "UV") or (n.bl_idname == "ShaderNodeUVMap"
                                                                            and not getattr(n, "from_instancer", False))

    if plain_uv(node, out):
        return None, ""
    if node.bl_idname != "ShaderNodeMapping":
        return None, f"Vector from {node.bl_idname}.{out} dropped"
    linked = [k for k in ("Location", "Rotation", "Scale") if k in node.inputs and node.inputs[k].is_linked]
    vec = node.inputs["Vector"]
    if node.vector_type != "POINT" or linked or not vec.is_linked or not plain_uv(vec.links[0].from_node,
                                                                                   vec.links[0].from_socket.name):
        return None, (f"Mapping node ({node.vector_type}" + (f", linked {', '.join(linked)}" if linked else "")
                      + ") dropped: Point mappings of UVs with unlinked values convert")
    loc, rot, scale = (np.asarray(node.inputs[k].default_value, np.float64) for k in ("Location", "Rotation", "Scale"))
    if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6:
        return None, "Mapping node rotation about X or Y dropped"
    return ((float(scale[0]), float(scale[1])), math.degrees(float(rot[2])), (float(loc[0]), float(loc[1]))), ""


#: the dome turns about the up axis opposite to a Mapping node's Z rotation of the lookup direction
DOME_TURN_SIGN = -1.0


def _environment_turn(link) -> tuple[float, str]:
    """(angle about Blender's Z in radians, note) of the Mapping node feeding an Environment Texture's Vector:
    a Point (or Texture: inverted) mapping of the Generated (view) direction, or of nothing linked, turning about Z
    only, with unlinked values; its location shifts directions and is dropped, as is any other linked Vector (note).
    Before, every mapping was dropped (an HDRI turned by the artist lit the scene from the wrong side)."""
    node = link.from_node
    if node.bl_idname != "ShaderNodeMapping" or node.vector_type not in ("POINT", "TEXTURE"):
        return 0.0, f"environment Vector from {node.bl_idname} dropped (a Mapping node turning about Z converts)"
    if any(node.inputs[k].is_linked for k in ("Location", "Rotation", "Scale")):
        return 0.0, "a Mapping node with linked values on the environment dropped"
    vec = node.inputs["Vector"]
    if vec.is_linked and not (vec.links[0].from_node.bl_idname == "ShaderNodeTexCoord"
                              and vec.links[0].from_socket.name == "Generated"):
        return 0.0, (f"environment mapping of {vec.links[0].from_node.bl_idname}.{vec.links[0].from_socket.name} "
                     "dropped (the Generated direction converts)")
    rot = np.asarray(node.inputs["Rotation"].default_value, np.float64)
    scale = np.asarray(node.inputs["Scale"].default_value, np.float64)
    notes = []
    if abs(rot[0]) > 1e-6 or abs(rot[1]) > 1e-6:
        notes.append("environment rotation about X or Y dropped (about Z converts)")
    if not np.allclose(scale, scale[0]) or scale[0] <= 0:
        notes.append(f"environment mapping scale {tuple(round(float(v), 3) for v in scale)} dropped")
    if np.abs(np.asarray(node.inputs["Location"].default_value)).max() > 1e-6:
        notes.append("environment mapping location dropped")
    turn = float(rot[2]) if node.vector_type == "POINT" else -float(rot[2])
    return turn, "; ".join(notes)


def _check_replace(bpy, rep: dict, file: str) -> None:
    from nasset_reference_renderer.scene import is_asset_file

    from .scene import refuse_emitter

    names = sorted(o.name for o in bpy.context.scene.objects)
    for name, path in rep.items():
        if name not in names:
            raise error("CONVERT_SHAPE_UNKNOWN", f"--replace: no object named {name!r}; the scene has {names}", file=file)
        refuse_emitter(bpy.context.scene.objects[name], file=file)
        if not path.is_file() or not is_asset_file(str(path)):
            raise error("CONVERT_ASSET_REFERENCE", f"--replace {name}: {path} is not an existing neural asset file "
                        "(defaultPrim of type NeuralAsset)", file=str(path))


def convert_scene(scene, output, *, replace=None, check_usd: bool = True, example: str | None = None) -> ConvertResult:
    """Convert a .blend (or a built-in example, ``example``) to a USD stage (module docstring)."""
    from . import load_bpy
    from .scene import open_blend

    output = path_arg(output, "convert_scene: the output")
    if output.suffix not in (".usda", ".usdc", ".usd"):
        raise UsageError(f"output must end in .usda/.usdc/.usd, got {output.name!r}")
    rep = parse_replace(replace)
    bpy = load_bpy()
    if example is not None:
        from .examples import build_example

        build_example(example)
        label = Path(f"{example}.blend")
    else:
        open_blend(scene)
        label = Path(scene)
    viewport_notes = evaluate_as_render(bpy)
    _check_replace(bpy, rep, str(label))
    misfits = _replacement_misfits(rep, str(label))
    output_folder(output.parent)
    # written beside the output and renamed over it at the end: a failed conversion leaves an earlier output as it was
    with atomic_output(output, "converted scene") as tmp:
        os.unlink(tmp)  # USD creates the layer file itself
        converter = _BlenderConverter(bpy, label, output, rep, layer=Path(tmp))  # checked once renamed
        if len(bpy.data.scenes) > 1:  # Blender renders the file's active scene and view layer (as a command-line render)
            converter.warn(f"the file has scenes {sorted(sc.name for sc in bpy.data.scenes)}: scene "
                           f"{bpy.context.scene.name!r} (the active one), view layer {bpy.context.view_layer.name!r} converted")
        for note in viewport_notes + misfits:
            converter.warn(note)
        res = converter.run()
    if check_usd:
        res.usd_checks = usd_check(output)
    return res


def _replacement_misfits(rep: dict, file: str) -> list[str]:
    """A warning per ``--replace`` asset whose geometry's box lies off the replaced objects' by more than
    BOX_TOLERANCE of their diagonal (baked from other objects), as for Mitsuba scenes (``bench accuracy`` refuses it)."""
    from nasset_converters.mitsuba.scene import BOX_TOLERANCE, box_offset
    from nasset_sdk.asset import Asset

    from . import scene as bsc

    groups: dict[Path, list[str]] = {}
    for name, path in rep.items():
        groups.setdefault(Path(path), []).append(name)
    out = []
    for path, names in groups.items():
        try:
            _, geo, _ = bsc.asset_geometry(bsc.pick_objects(names, file=file), file=file)
        except NassetError:  # objects no bake takes (an empty, a lamp): nothing to compare
            continue
        src = np.asarray(geo.points, np.float64)
        off = box_offset(np.stack([src.min(0), src.max(0)]), Asset.open(path, load="none").geometry().points)
        if off > BOX_TOLERANCE:
            out.append(f"--replace {','.join(names)}: {path.name} was not baked from them: its bounds differ from theirs "
                       f"by {100 * off:.0f} % of their diagonal")
    return out


def run(args) -> int:
    """CLI entry: ``nasset convert-scene SCENE.blend -o SCENE.usda [--replace OBJ=ASSET ...] [--json]``."""
    scene, example = args.scene, args.example
    if bool(example) == bool(scene):
        raise UsageError("give a .blend scene or --example blender-surface|blender-hair|blender-hair-dense (not both)")
    res = convert_scene(scene, args.output, replace=args.replace, check_usd=not args.no_usd_checks, example=example)
    return report(res, as_json=args.json)
