"""Mitsuba scenes holding neural assets.

Python cannot register Mitsuba shapes, so an asset instance is its fallback mesh (a ``ply`` shape,
written once per asset file to a cache folder) carrying the ``nasset`` marker BSDF:

- :func:`asset_shape` returns the scene-dict entry of one instance (``to_world`` as in Mitsuba);
- :func:`load_file` loads a Mitsuba XML scene in which ``<shape type="nasset">`` holds
  ``<string name="filename" value="A.usdc"/>`` and optionally ``<transform name="to_world">``;
- :func:`usd_scene` turns a nasset USD scene (spec/renderer.md#scene-input) into a scene dict.
"""

from __future__ import annotations

import atexit
import copy
import hashlib
import itertools
import math
import os
import re
import shutil
import tempfile
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from nasset_sdk.errors import error, path_arg
from nasset_sdk.safeopen import file_identity

from . import lights as lights_jit
from . import preview, textures
from .plugins import BSDF, HIDDEN_PREFIX, INTEGRATOR, LIGHT_SURFACE_PREFIX, OPAQUE_MARK, asset_for, register
from .variant import jit_mitsuba

_PLY_DIR: list[str] = []
_PLY_NUMBERS = itertools.count()  # names of the scene meshes' PLY files, unique in the process


def _cache_dir() -> Path:
    """This process's folder of PLY files (Mitsuba scene dicts name meshes by file), removed at exit."""
    if not _PLY_DIR:
        folder = tempfile.mkdtemp(prefix="nasset_mitsuba_")
        atexit.register(shutil.rmtree, folder, True)
        _PLY_DIR.append(folder)
    return Path(_PLY_DIR[0])


def fallback_ply(mi, filename: str) -> str:
    """Path of a PLY file holding the asset's object-space mesh (with its normals when it has them)."""
    asset = asset_for(mi, filename)
    g = asset.geometry
    version = repr(file_identity(filename))  # a file rewritten in place gets a new mesh file
    out = _cache_dir() / (hashlib.sha256(f"{os.path.abspath(filename)}|{version}".encode()).hexdigest()[:16] + ".ply")
    if not out.exists():
        pts = np.ascontiguousarray(g.points, np.float32)
        faces = np.ascontiguousarray(g.faces, np.uint32)
        mesh = mi.Mesh("nasset_fallback", len(pts), len(faces), has_vertex_normals=g.normals is not None)
        prm = mi.traverse(mesh)
        prm["vertex_positions"] = mi.Float(pts.ravel())
        prm["faces"] = mi.UInt32(faces.ravel())
        if g.normals is not None:
            prm["vertex_normals"] = mi.Float(np.ascontiguousarray(g.normals, np.float32).ravel())
        prm.update()
        tmp = out.with_suffix(".tmp.ply")
        mesh.write_ply(str(tmp))
        os.replace(tmp, out)  # atomic: a concurrent reader never sees half a file
    return str(out)


def asset_shape(filename: str, to_world=None, *, mi=None) -> dict:
    """Scene-dict entry of an asset instance: its fallback mesh with the ``nasset`` BSDF.

    ``to_world``: 4x4 (column-vector convention, like Mitsuba's) or a ``mi.ScalarTransform4f``; identity by default."""
    mi = mi or jit_mitsuba()
    register(mi)
    filename = os.path.abspath(str(filename))
    t = mi.ScalarTransform4f() if to_world is None else (
        to_world if isinstance(to_world, mi.ScalarTransform4f) else mi.ScalarTransform4f(np.asarray(to_world, np.float64).tolist()))
    has_normals = asset_for(mi, filename).geometry.normals is not None
    return {"type": "ply", "filename": fallback_ply(mi, filename), "to_world": t, "face_normals": not has_normals,
            "bsdf": {"type": BSDF, "filename": filename, "to_world": t}}


#: integrators that only wrap the one that makes the image
_WRAPPERS = ("aov", "stokes", "moment")


def _warn_unless_nasset_path(root, file: str) -> None:
    """A RuntimeWarning when the scene's integrator (the one a wrapper nests) is not ``nasset_path``: any other shades
    an asset instance's ``nasset`` BSDF as black (it reflects nothing by itself; found on a user scene with
    ``<integrator type="path">``: the assets rendered black without a word). Silent without an integrator (Mitsuba
    asks for one when rendering)."""
    import warnings

    node = root.find("integrator")
    while node is not None and node.get("type") in _WRAPPERS:
        node = node.find("integrator")
    if node is not None and node.get("type") != INTEGRATOR:
        warnings.warn(f"{file}: the scene's integrator {node.get('type')!r} does not shade neural assets: rendered with "
                      f'it they are black. Use <integrator type="{INTEGRATOR}"> in the scene, or pass a {INTEGRATOR} '
                      "integrator to mi.render and load with own_integrator=True", RuntimeWarning, stacklevel=3)


def load_file(path: str, *, mi=None, replace: dict | None = None, own_integrator: bool = False, **params):
    """Load a Mitsuba XML scene whose ``<shape type="nasset">`` elements are asset instances (see module doc).

    ``replace``: {shape id: asset file}: those shapes are left out and each asset file is added once as an
    instance with the identity transform (an asset baked from a scene's shapes has their world space as
    its object space, spec/bake.md#stages). ``own_integrator``: the caller renders with a ``nasset_path`` of its
    own, so the scene's integrator is not checked (otherwise one that is not ``nasset_path`` is warned about: it
    renders the assets black). ``params``: XML ``$name`` parameters."""
    path = path_arg(path, "load_file: the scene")
    for sid, file in (replace or {}).items():
        path_arg(file, f"load_file: replace[{sid!r}]")
    mi = mi or jit_mitsuba()
    register(mi)
    preview.register(mi)
    lights_jit.register(mi)
    if not path.is_file():
        raise error("FILE_NOT_FOUND", "no such scene file", file=str(path))
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise error("SCENE_INVALID", f"not XML: {exc}", file=str(path)) from None
    if replace:  # a replaced shape may be declared in an included file
        _inline_includes(root, path.parent.resolve(), str(path))
        _replace_shapes(root, replace, str(path))
    assets = [shape for shape in root.iter("shape") if shape.get("type") == "nasset"]
    for shape in assets:
        _expand_asset(mi, shape, path)
    if assets and not own_integrator:  # replaced shapes are nasset shapes by now
        _warn_unless_nasset_path(root, str(path))
    resolver = mi.file_resolver()  # the scene's relative paths (meshes, textures) resolve next to it
    if str(path.parent.resolve()) not in [str(p) for p in resolver]:
        resolver.prepend(str(path.parent.resolve()))
    try:
        return mi.load_string(ET.tostring(root, encoding="unicode"), **params)
    except Exception as exc:  # Mitsuba reports XML and plugin errors as RuntimeError
        raise mitsuba_failure(exc, "Mitsuba could not load the scene", str(path)) from None


#: a nasset error raised inside a plugin, as the last line of the traceback Mitsuba's message carries
_INNER_ERROR = re.compile(r"^\w+(?:\.\w+)*Error: \[([A-Z0-9_]+)\] (.*)$")


def mitsuba_failure(exc: Exception, what: str, file: str):
    """The typed error for an exception of ``mi.load_*``: the nasset error a plugin raised inside it
    (its code and message), else SCENE_INVALID naming ``file`` with Mitsuba's first line."""
    from nasset_sdk.errors import CODES

    for line in reversed(str(exc).splitlines()):
        m = _INNER_ERROR.match(line.strip())
        if m and m.group(1) in CODES:
            return error(m.group(1), m.group(2))
    return error("SCENE_INVALID", f"{what}: {str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__}", file=file)


#: Mitsuba's limit on nested includes
MAX_INCLUDE_DEPTH = 15


def _inline_includes(root, folder: Path, scene_file: str, depth: int = 0) -> None:
    """Replace each ``<include filename="F"/>`` under ``root`` by the elements of F's ``<scene>`` (F next to the
    including file, ``folder``), recursively, as Mitsuba's parser includes them, so that ``replace`` finds shapes that
    included files declare. The included elements' relative ``filename`` values that name files next to F are made
    absolute (Mitsuba resolves them there). SCENE_INVALID for an unreadable file or more than Mitsuba's 15 levels."""
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag != "include":
                continue
            file = (folder / child.get("filename", "")).resolve()
            if depth >= MAX_INCLUDE_DEPTH:
                raise error("SCENE_INVALID", f"includes nested deeper than {MAX_INCLUDE_DEPTH} levels (at {file.name})",
                            file=scene_file)
            try:
                included = ET.parse(file).getroot()
            except (OSError, ET.ParseError) as exc:
                raise error("SCENE_INVALID", f"included file {child.get('filename')!r}: {exc}", file=scene_file) from None
            _inline_includes(included, file.parent, scene_file, depth + 1)
            for el in included.iter():
                value = el.get("value")
                if el.get("name") == "filename" and value and not Path(value).is_absolute() \
                        and (file.parent / value).exists():
                    el.set("value", str(file.parent / value))
            at = list(parent).index(child)
            parent.remove(child)
            for k, el in enumerate(list(included)):
                parent.insert(at + k, el)


def _replace_shapes(root, replace: dict, scene_file: str) -> None:
    """Drop the shapes whose id is a key of ``replace`` and add one ``nasset`` shape per asset file.
    CONVERT_SHAPE_UNSUPPORTED for an area-emitter shape: an asset carries light transport, not emission, so
    replacing it would take its light out of the scene (spec/bake.md#errors)."""
    found = set()
    for parent in list(root.iter()):
        for child in list(parent):
            if child.tag == "shape" and child.get("id") in replace:
                if parent.tag == "shape" and parent.get("type") == "shapegroup":
                    raise error("CONVERT_SHAPE_UNKNOWN", f"shape {child.get('id')!r} is inside shapegroup "
                                f"{parent.get('id')!r}, which the scene draws through its instances: an asset is one "
                                "object in the scene's world space (spec/bake.md#errors)", file=scene_file)
                if child.find("emitter") is not None:
                    raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {child.get('id')!r} is an area emitter: a neural "
                                "asset carries light transport, not emission; keep the emitter in the scene",
                                file=scene_file)
                parent.remove(child)
                found.add(child.get("id"))
    missing = sorted(set(replace) - found)
    if missing:
        raise error("CONVERT_SHAPE_UNKNOWN", f"no shape with id {', '.join(map(repr, missing))} in the scene", file=scene_file)
    for k, file in enumerate(dict.fromkeys(str(Path(f).resolve()) for f in replace.values())):
        shape = ET.SubElement(root, "shape", type="nasset", id=f"nasset_asset_{k}")
        ET.SubElement(shape, "string", name="filename", value=file)


def _expand_asset(mi, shape, path: Path) -> None:
    """``<shape type="nasset">`` -> its fallback ``ply`` with the ``nasset`` BSDF (in place)."""
    names = {c.get("name"): c for c in shape}
    fn = names.get("filename")
    if fn is None or fn.tag != "string":
        raise error("SCENE_INVALID", "<shape type=\"nasset\"> needs <string name=\"filename\" value=\"...\"/>", file=str(path),
                    prim=shape.get("id"))
    asset_file = str((path.parent / fn.get("value", "")).resolve())
    has_normals = asset_for(mi, asset_file).geometry.normals is not None
    shape.set("type", "ply")
    fn.set("value", fallback_ply(mi, asset_file))
    ET.SubElement(shape, "boolean", name="face_normals", value="true" if not has_normals else "false")
    bsdf = ET.SubElement(shape, "bsdf", type=BSDF)
    ET.SubElement(bsdf, "string", name="filename", value=asset_file)
    if "to_world" in names:
        bsdf.append(copy.deepcopy(names["to_world"]))


def usd_scene(path: str, width: int | None = None, height: int | None = None, *, mi=None) -> dict:
    """Scene dict of a nasset USD scene: meshes (UsdPreviewSurface as the ``nasset_preview`` BSDF; emissive
    ones area lights), asset instances, point / spot / distant (delta or cone) / sphere / rect / disk / cylinder / dome lights,
    the camera (its film filtered as the render settings say, spec/renderer.md#render-settings)."""
    return usd_scene_settings(path, width, height, mi=mi)[0]


def usd_scene_settings(path: str, width: int | None = None, height: int | None = None, *, mi=None) -> tuple[dict, dict]:
    """(:func:`usd_scene`'s dict, the scene's authored render settings: ``max_depth``, ``pixel_filter``,
    ``pixel_filter_stddev`` where authored)."""
    from nasset_mitsuba_renderer.lights import ConeDistantLight, DomeLight, MitsubaLight, SpotLight, build_lights
    from nasset_mitsuba_renderer.render import mi_mesh, sensor_dict
    from nasset_mitsuba_renderer.usdscene import read_scene

    mi = mi or jit_mitsuba()
    register(mi)
    preview.register(mi)
    lights_jit.register(mi)
    desc = read_scene(path)
    recentre(desc)
    rescale_tiny(desc)
    expose(desc)
    w, h = desc.camera.resolution(width, height)
    entries: dict = {"type": "scene", "sensor": sensor_dict(mi, desc.camera, w, h)}
    rs = dict(desc.render_settings)
    if rs.get("pixel_filter") == "gaussian":  # Mitsuba's gaussian: the spec's filter, radius 4 stddev
        entries["sensor"]["film"]["rfilter"] = {"type": "gaussian", "stddev": float(rs.get("pixel_filter_stddev", 0.5))}
    powers: dict = {}  # emitter entry -> its power (lights.light_power), by which Mitsuba picks an emitter
    emissive = []  # (mesh index, front and back emission, emissive texture or None) of the emissive meshes
    for k, m in enumerate(desc.meshes):
        front, back = _emission_sides(m)
        corners = _corner_attributes(m)
        unwelded = corners or m.corner_st is not None
        mesh = _corner_mesh(mi, f"mesh_{k}", m, corners) if unwelded else mi_mesh(mi, f"mesh_{k}", m.points, m.faces)
        bsdf = mi.load_dict({"type": preview.NAME, **_preview_props(mi, m),
                             "normals": NORMALS_ATTRIBUTE if NORMALS_ATTRIBUTE in corners else ""})
        hit = m.material.per_hit
        if hit is not None and hit.varies_material:
            bsdf.per_hit = textures.PerHitInputs(mi, hit)
        if hit is not None and "normal" in hit.textures:
            bsdf.normal_map = textures.ImageLookup(mi, hit.textures["normal"])
        if m.material.presence is not None:  # a cut-out: rays pass where it is absent (plugins.PassThrough)
            bsdf.presence = textures.Presence(mi, *m.material.presence, None if hit is None else hit.textures.get("opacity"))
        entries[f"mesh_{k}"] = {"type": "ply", "filename": _mesh_ply(mi, mesh), "bsdf": bsdf, "face_normals": True}
        if np.any(front > 0) or np.any(back > 0):
            tri = m.points[m.faces]
            area = 0.5 * float(np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum())
            powers[f"mesh_{k}"] = math.pi * area * (lights_jit.luminance(front) + lights_jit.luminance(back))
            emissive.append((k, front, back, hit.textures.get("emissiveColor") if hit is not None else None))
    for j, inst in enumerate(desc.assets):  # transforms checked by the reader (finite, |det M3| >= 1e-12)
        entries[f"asset_{j}"] = asset_shape(inst.file, np.asarray(inst.to_world, np.float64).T, mi=mi)  # rows -> columns
    lights, light_entries = build_lights(desc.lights, str(path))
    radius = _scene_radius(mi, desc)
    for k, lt in enumerate(lights):
        visible = bool(getattr(lt.desc, "camera_visible", True))  # nasset:cameraVisibility (spec/renderer.md#light-surfaces)
        key = lt.key if isinstance(lt, MitsubaLight) else f"cone_{k}" if isinstance(lt, ConeDistantLight) else f"dome_{k}"
        if isinstance(lt, ConeDistantLight):
            light_entries[key] = {"type": lights_jit.NAME, "direction": mi.ScalarVector3f(lt.axis.tolist()), "angle": float(lt.desc.angle),
                                  "irradiance": mi.ScalarColor3f(np.asarray(lt.desc.radiance, np.float64).tolist()),
                                  "camera_visible": visible}
        elif isinstance(lt, DomeLight):
            light_entries[key] = {**_dome_entry(mi, lt), "camera_visible": visible}
        elif isinstance(lt, SpotLight):  # Mitsuba's point emitter without its cone: the plugin's nasset_spot
            cone, soft, profile = lt.desc.shaping
            light_entries[key] = {"type": lights_jit.SPOT, "position": mi.ScalarPoint3f(*lt.mi_dict["position"]),
                                  "intensity": mi.ScalarColor3f(np.asarray(lt.desc.radiance, np.float64).tolist()),
                                  "axis": mi.ScalarVector3f(lt.axis.tolist()), "cone": float(cone), "softness": float(soft),
                                  "profile": str(profile)}
        elif not isinstance(lt, MitsubaLight):
            raise error("SCENE_UNSUPPORTED", "the Mitsuba plugin renders point, spot, distant, sphere, rect, disk, cylinder and "
                        f"dome lights, not {type(lt).__name__}", file=str(path), prim=lt.desc.prim)
        elif lt.has_shape:  # a light surface: rays pass it (spec/renderer.md#light-surfaces), but for opaque ones
            mark = OPAQUE_MARK if getattr(lt.desc, "opaque", False) else ""
            key = (LIGHT_SURFACE_PREFIX if visible else HIDDEN_PREFIX) + mark + lt.key
            light_entries[key] = light_entries.pop(lt.key)
            profile = _emission_profile(mi, lt)
            if profile:  # a spread or a spot cone (spec/renderer.md#lights, #spot-lights); lt.mi_dict is kept as built
                ent = light_entries[key]
                light_entries[key] = {**ent, "emitter": {"type": lights_jit.PROFILED, **profile,
                                                         "radiance": mi.ScalarColor3f(*ent["emitter"]["radiance"]["value"])}}
        powers[key] = lights_jit.light_power(lt, radius)
    infinite = [k for k, ent in light_entries.items() if ent.get("type") in (lights_jit.NAME, lights_jit.DOME)]
    if len(infinite) > 1:  # Mitsuba keeps one environment emitter: a dome and angular suns become their sum
        powers["sky"] = sum(powers.pop(k) for k in infinite)
        light_entries["sky"] = {"type": lights_jit.SKY, **{f"part_{i}": light_entries.pop(k) for i, k in enumerate(infinite)}}
    weights = lights_jit.selection_weights(powers)  # Mitsuba picks one emitter per light sample, by these
    for key, ent in light_entries.items():
        (ent["emitter"] if "emitter" in ent else ent)["sampling_weight"] = weights[key]
    for k, front, back, texture in emissive:
        m = desc.meshes[k]
        sides = _material_sides(m) if texture is not None else (False, False)
        emitter = mi.load_dict({"type": lights_jit.AREA, "front": mi.ScalarColor3f(front.tolist()),
                                "back": mi.ScalarColor3f(back.tolist()), "textured_front": sides[0],
                                "textured_back": sides[1], "sampling_weight": weights[f"mesh_{k}"]})
        if texture is not None:
            emitter.texture = textures.ImageLookup(mi, texture)
        entries[f"mesh_{k}"]["emitter"] = emitter
    for ent in light_entries.values():
        if "emitter" in ent:  # a light surface reflects nothing (spec/renderer.md#light-surfaces: rays go on past it)
            ent.setdefault("bsdf", {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}})
    entries.update(light_entries)
    return entries, rs


#: the mesh attribute of world corner normals the ``nasset_preview`` BSDF reads (Mitsuba interpolates it)
NORMALS_ATTRIBUTE = "vertex_nasset_ns"


def _corner_attributes(mesh) -> dict:
    """{attribute name: values [F, 3, 3]} a mesh's BSDF reads at its triangles' corners: world shading normals (zero ones
    kept: the BSDF normalises their barycentric sum as spec/renderer.md#shading-normals does; Mitsuba's own vertex
    normals would be normalised per corner, a zero one to NaN), primvar colours. (Texture coordinates are the mesh's
    own, ``vertex_texcoords``: hits and an emitter's position samples carry them as ``uv``.)"""
    out = {}
    if mesh.corner_normals is not None:
        out[NORMALS_ATTRIBUTE] = np.nan_to_num(np.asarray(mesh.corner_normals, np.float64))
    if mesh.corner_colors is not None:
        out[textures.COLOR_ATTRIBUTE] = np.asarray(mesh.corner_colors, np.float64)
    return out


def _corner_mesh(mi, name: str, mesh, attributes: dict):
    """A ``mi.Mesh`` of a mesh's world triangles, unwelded (3 vertices per triangle), carrying its corner texture
    coordinates (``corner_st``) as texcoords and ``attributes`` ({name: [F, 3, 3]}) per corner: Mitsuba interpolates
    both with a hit's barycentrics (``si.uv``, ``eval_attribute_3``)."""
    faces = np.asarray(mesh.faces, np.int64)
    pts = np.asarray(mesh.points, np.float64)[faces].reshape(-1, 3)
    out = mi.Mesh(name, len(pts), len(faces), has_vertex_texcoords=mesh.corner_st is not None)
    prm = mi.traverse(out)
    prm["vertex_positions"] = mi.Float(np.ascontiguousarray(pts, np.float32).ravel())
    prm["faces"] = mi.UInt32(np.arange(len(pts), dtype=np.uint32))
    if mesh.corner_st is not None:
        prm["vertex_texcoords"] = mi.Float(np.ascontiguousarray(np.clip(mesh.corner_st, -1e30, 1e30), np.float32).ravel())
    prm.update()
    for key, values in attributes.items():
        out.add_attribute(key, 3, mi.Float(np.ascontiguousarray(values, np.float32).ravel()))
    return out


def _material_sides(mesh) -> tuple[bool, bool]:
    """(the winding's side, the other side) of a mesh: whether its material (not its back material, nor nothing on a
    one-sided prim's back) shades that side, as :func:`_emission_sides` assigns them."""
    back = not mesh.one_sided and mesh.back_material is None
    return (True, back) if mesh.front_sign > 0 else (back, True)


def _emission_sides(mesh) -> tuple:
    """(emission on the side its world triangles' winding faces, on the other side) of a mesh (spec/renderer.md#sidedness):
    the front emits its material's emissiveColor, the back its back material's, nothing on a one-sided prim, the
    material's own otherwise; ``front_sign`` < 0 (a mirroring transform or leftHanded) puts the front against the winding."""
    front = np.asarray(mesh.material.emission, np.float64)
    if mesh.one_sided:
        back = np.zeros(3)
    elif mesh.back_material is not None:
        back = np.asarray(mesh.back_material.emission, np.float64)
    else:
        back = front
    return (front, back) if mesh.front_sign > 0 else (back, front)


def _preview_props(mi, mesh) -> dict:
    """``nasset_preview`` properties of a mesh: its material, and its sides (spec/renderer.md#sidedness)."""
    def material(mat, prefix=""):
        return {f"{prefix}kd": mi.ScalarColor3f(np.clip(mat.kd, 0, 1).tolist()),
                f"{prefix}f0": mi.ScalarColor3f(np.clip(mat.f0, 0, 1).tolist()), f"{prefix}alpha": float(mat.alpha),
                f"{prefix}beckmann": bool(mat.beckmann)}

    props = {**material(mesh.material), "one_sided": bool(mesh.one_sided), "front_sign": float(mesh.front_sign)}
    if mesh.back_material is not None and not mesh.one_sided:
        props.update(material(mesh.back_material, "back_"))
    if mesh.material.glass is not None:  # spec/renderer.md#transmission (the front material's, on both sides)
        t, tint, ior, thin, reflect = mesh.material.glass
        props.update({"glass": float(t), "glass_tint": mi.ScalarColor3f(np.clip(tint, 0, 1).tolist()),
                      "glass_reflect": mi.ScalarColor3f(np.clip(reflect, 0, 1).tolist()), "glass_ior": float(ior),
                      "glass_thin": bool(thin)})
    return props


def _column_transform(m3_rows: np.ndarray) -> list:
    """4x4 column-vector matrix (Mitsuba's) of a 3x3 linear map in USD's row-vector convention."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(m3_rows, np.float64).T
    return m.tolist()


def _dome_entry(mi, lt) -> dict:
    """``nasset_dome`` entry of a DomeLight read by the second implementation (its orientation: the polar factor of M3)."""
    ent = {"type": lights_jit.DOME, "radiance": mi.ScalarColor3f(np.asarray(lt.desc.radiance, np.float64).tolist()),
           "to_world": mi.ScalarTransform4f(_column_transform(lt.m3))}
    if lt.tex is not None:
        ent["bitmap"] = mi.Bitmap(np.ascontiguousarray(lt.tex[..., :3], np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB)
    return ent


def _scene_radius(mi, desc) -> float:
    """Half the diagonal of the box around the scene's geometry: its meshes' points and its asset instances' geometry
    (world); 1 for a scene without any."""
    boxes = [(m.points.min(0), m.points.max(0)) for m in desc.meshes if len(m.points)]
    for inst in desc.assets:
        pts = np.asarray(asset_for(mi, os.path.abspath(inst.file)).geometry.points, np.float64).reshape(-1, 3)
        if len(pts):
            w = pts @ np.asarray(inst.to_world, np.float64)[:3, :3] + np.asarray(inst.to_world, np.float64)[3, :3]
            boxes.append((w.min(0), w.max(0)))
    if not boxes:
        return 1.0
    lo, hi = np.min([b[0] for b in boxes], 0), np.max([b[1] for b in boxes], 0)
    r = 0.5 * float(np.linalg.norm(hi - lo))
    return r if np.isfinite(r) and r > 0 else 1.0


def recentre(desc) -> np.ndarray:
    """Translate a scene description that lies far from the origin (its bounding box's centre farther than
    the box's extent) so that the box is centred on the origin, in place; returns the translation
    (zeros: unchanged). Mesh points, instance, light and camera origins move; nothing else changes.

    Mitsuba offsets spawned rays by ``(1 + max |p|) * RayEpsilon`` (about 0.09 at 1000 units): in a
    scene of unit size far from the origin that loses contact shadows and self-shadowing; the image
    does not depend on where the scene lies (asset inputs are object-space, x M^-1)."""
    pts = [np.asarray(m.points, np.float64).reshape(-1, 3) for m in desc.meshes if len(m.points)]
    pts += [a.to_world[3:, :3] for a in desc.assets] + [lt.to_world[3:, :3] for lt in desc.lights]
    pts.append(desc.camera.to_world[3:, :3])
    allp = np.concatenate(pts)
    lo, hi = allp.min(0), allp.max(0)
    centre = 0.5 * (lo + hi)
    if not np.abs(centre).max() > max(float((hi - lo).max()), 1e-30):
        return np.zeros(3)
    for m in desc.meshes:
        m.points = m.points - centre
    for obj in [*desc.assets, *desc.lights, desc.camera]:
        mw = np.array(obj.to_world, np.float64)
        mw[3, :3] -= centre
        obj.to_world = mw
    return -centre


#: scenes whose coordinates all lie within this distance of the origin are scaled up to unit size
TINY_EXTENT = 1e-2


def rescale_tiny(desc) -> float:
    """Scale a tiny scene description (all points, instance and light origins, camera within
    :data:`TINY_EXTENT` of the origin) uniformly to unit size, in place; returns the factor (1: unchanged).

    Mitsuba offsets spawned rays by ``(1 + max |p|) * RayEpsilon``, an absolute minimum that is a large
    part of a tiny scene. The image is unchanged by the scaling: directions, radiance and rna transport
    (per world steradian, object-space inputs) do not depend on it, and the radiance of lights whose
    emission is per area or falls off with distance (point lights, normalised sphere and rect lights)
    is multiplied by s^2 so that the scene's irradiance stays the same."""
    pts = [np.abs(m.points).max() for m in desc.meshes if len(m.points)]
    pts += [np.abs(a.to_world[3, :3]).max() for a in desc.assets]
    pts += [np.abs(lt.to_world[3, :3]).max() for lt in desc.lights]
    pts.append(np.abs(desc.camera.to_world[3, :3]).max())
    ext = max(pts)
    if not 0 < ext < TINY_EXTENT:
        return 1.0
    s = 1.0 / ext
    scale = np.diag([s, s, s, 1.0])
    for m in desc.meshes:
        m.points = m.points * s
    for a in desc.assets:
        a.to_world = a.to_world @ scale
    for lt in desc.lights:
        lt.to_world = lt.to_world @ scale
        point = lt.type == "SphereLight" and lt.radius <= 0
        if point or (lt.normalize and lt.type in ("SphereLight", "RectLight")):
            lt.radiance = np.asarray(lt.radiance, np.float64) * s * s
    cam = desc.camera.to_world.copy()
    cam[3, :3] *= s
    desc.camera.to_world = cam
    c = desc.camera  # lengths of the lens and of an orthographic window scale too (a perspective view keeps its ratios)
    c.lens_radius, c.focus_distance = c.lens_radius * s, c.focus_distance * s
    if c.orthographic:
        c.h_aperture, c.v_aperture, c.h_offset, c.v_offset = (v * s for v in (c.h_aperture, c.v_aperture, c.h_offset, c.v_offset))
    return s


def expose(desc) -> None:
    """Fold the camera's exposure scale (spec/renderer.md#cameras) into every emitter, in place: light transport is
    linear in the emission, so the image scales by the same factor (Mitsuba's film has no gain)."""
    e = float(desc.camera.exposure)
    if e == 1.0:
        return
    for lt in desc.lights:
        lt.radiance = np.asarray(lt.radiance, np.float64) * e
    for mat in {id(m.material): m.material for m in desc.meshes}.values():  # a shared material once
        mat.emission = np.asarray(mat.emission, np.float64) * e
    desc.camera.exposure = 1.0


def _emission_profile(mi, lt) -> dict:
    """Properties of the plugin's ``nasset_profiled`` emitter for a light surface whose emission depends on direction:
    a RectLight's or DiskLight's ``nasset:spread`` below pi, a SphereLight's spot cone (its prim's -Z); {} for neither."""
    out = {}
    if lt.desc.spread < math.pi:
        out["spread"] = float(lt.desc.spread)
    if lt.desc.shaping is not None:
        cone, soft, profile = lt.desc.shaping
        axis = -np.asarray(lt.desc.to_world[2, :3], np.float64)
        out.update({"axis": mi.ScalarVector3f(*(axis / max(float(np.linalg.norm(axis)), 1e-300)).tolist()),
                    "cone": float(cone), "softness": float(soft), "profile": str(profile)})
    return out


def _mesh_ply(mi, mesh) -> str:
    """A world-space plain mesh written to the cache folder (scene dicts cannot attach a BSDF to a Mesh object)."""
    out = _cache_dir() / f"mesh_{next(_PLY_NUMBERS)}.ply"  # was numbered by listing the folder: quadratic in meshes
    mesh.write_ply(str(out))
    return str(out)
