"""Open a .blend, pick the asset objects, export their geometry (spec/bake-blender.md#geometry).

Geometry is taken from Blender's *evaluated* objects (modifiers applied, as Cycles renders them),
in world space, converted to +Y up (:func:`nasset_converters.blender.to_y_up`); asset object space is
that world space (like the Mitsuba bake). Meshes become triangles with smooth vertex normals
(flat-shaded faces get their face normal); hair becomes linear curves with widths = 2 x radius:

* new ``Curves`` objects (hair curves): the ``position`` and ``radius`` point attributes (radius
  0.005 where the attribute is absent, Blender's default); non-poly curve types are sampled at
  their control points (a warning);
* particle hair on a mesh (``ParticleSystem`` of type HAIR): every strand's evaluated path points
  (``co_hair``), widths from the particle settings' root/tip radius x radius scale, linear from root
  to tip (Cycles' curve shape).

An asset is all meshes (variant ``surface``) or all hair (variant ``fiber``); a mix is
CONVERT_SHAPE_UNSUPPORTED.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from nasset_sdk.errors import UsageError, error
from nasset_sdk.geometry import CurvesGeometry, MeshGeometry

from . import load_bpy, quiet_stdout, to_y_up
from .evaluation import evaluate_as_render
from .shader_graph import resolved_copy

#: Blender's default curve radius (m) where a Curves object has no ``radius`` attribute
DEFAULT_RADIUS = 0.005


def open_blend(path):
    """Open a .blend file (replacing the session's data); CONVERT_SCENE_MISSING / CONVERT_SCENE_LOAD."""
    bpy = load_bpy()
    path = Path(path)
    if not path.is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(path))
    try:
        with quiet_stdout():
            bpy.ops.wm.open_mainfile(filepath=str(path.resolve()), load_ui=False)
    except Exception as exc:  # noqa: BLE001 - bpy raises RuntimeError for every load failure
        msg = str(exc).strip().splitlines()[-1][:300] if str(exc).strip() else type(exc).__name__
        raise error("CONVERT_SCENE_LOAD", f"Blender cannot load the file: {msg}", file=str(path)) from None
    evaluate_as_render(bpy)  # geometry as Cycles renders it, not as the viewport shows it
    return bpy.context.scene


#: object types whose evaluated geometry is a mesh, as Cycles renders them: meshes, and curves (bevelled or
#: extruded), NURBS surfaces, metaballs and text
SURFACE_TYPES = ("MESH", "CURVE", "SURFACE", "META", "FONT")


def render_visible(view_layer):
    """A predicate: does Cycles render object ``ob`` of the scene in ``view_layer``? Not when the object is disabled
    in renders (``hide_render``), nor when none of its collections is reached from the scene collection through
    layer collections that are not excluded and collections that are not disabled in renders. (Objects placed by
    collection instances render whatever their source collection says: only their instancer is asked.)"""
    rendered = {view_layer.layer_collection.collection.as_pointer()}

    def walk(layer):
        for child in layer.children:
            if child.exclude or child.collection.hide_render:
                continue
            rendered.add(child.collection.as_pointer())
            walk(child)

    walk(view_layer.layer_collection)
    return lambda ob: not ob.hide_render and any(c.as_pointer() in rendered for c in ob.users_collection)


def missing_library_note(bpy, lib) -> str:
    """What a library Blender could not read leaves out: its objects, named, are empty placeholders."""
    objects = sorted(o.name for o in bpy.data.objects if o.library == lib)
    return (f"library {lib.name} ({lib.filepath}, resolved {bpy.path.abspath(lib.filepath, library=lib.library)}) is "
            f"missing: its linked data are empty placeholders, as Blender renders them (objects not written: "
            f"{', '.join(objects[:20]) or 'none'}{' ...' if len(objects) > 20 else ''})")


def pick_objects(names, *, file: str | None = None) -> list:
    """The scene's objects with these names, in order; each must have a surface (SURFACE_TYPES), be a hair Curves
    object or a mesh carrying particle hair."""
    bpy = load_bpy()
    objs = bpy.context.scene.objects
    have = sorted(o.name for o in objs if o.type in (*SURFACE_TYPES, "CURVES"))
    if not names:
        raise error("CONVERT_SHAPE_UNKNOWN", f"no --asset object name given; the scene has {have}", file=file)
    if twice := sorted({n for n in names if list(names).count(n) > 1}):
        raise UsageError(f"--asset {twice} given more than once: each object belongs to the asset once")
    out = []
    for n in names:
        ob = objs.get(n)
        if ob is None:
            raise error("CONVERT_SHAPE_UNKNOWN", f"no object named {n!r}; the scene has {have}", file=file)
        if ob.library is not None and ob.library.is_missing:
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"object {n!r}: {missing_library_note(bpy, ob.library)}", file=file)
        if ob.type not in (*SURFACE_TYPES, "CURVES"):
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"object {n!r} is a {ob.type}, not a surface (mesh, curve, "
                        "surface, metaball, text) or hair curves", file=file)
        refuse_emitter(ob, file=file)
        out.append(ob)
    return out


def _emits(node) -> bool:
    """Whether a shader node used in a material adds light: an Emission node, or a Principled BSDF with emission
    (strength and colour each linked or non-zero)."""
    def live(name, default):
        sock = node.inputs.get(name)
        if sock is None:
            return False
        if sock.is_linked:
            return True
        value = getattr(sock, "default_value", default)
        return any(float(v) > 0 for v in (value[:3] if hasattr(value, "__len__") else (value,)))

    if not any(out.is_linked for out in node.outputs):
        return False
    if node.bl_idname == "ShaderNodeEmission":
        return live("Strength", 1.0) and live("Color", (1.0, 1.0, 1.0))
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        return live("Emission Strength", 0.0) and (live("Emission Color", (0.0, 0.0, 0.0)) or live("Emission", (0.0, 0.0, 0.0)))
    return False


def refuse_emitter(ob, *, file: str | None = None) -> None:
    """CONVERT_SHAPE_UNSUPPORTED when an object to bake or replace has an emitting material (:func:`_emits`): a
    neural asset carries light transport, not emission (the Mitsuba side: ``scene.refuse_emitter``)."""
    for slot in getattr(ob, "material_slots", ()):
        mat = slot.material
        if mat is None or mat.node_tree is None:
            continue
        with resolved_copy(load_bpy(), mat) as resolved:  # node groups, reroutes, muted nodes as Cycles reads them
            for node in resolved.node_tree.nodes:
                if _emits(node):
                    raise error("CONVERT_SHAPE_UNSUPPORTED", f"object {ob.name!r} emits light (material {mat.name!r}, "
                                f"node {node.name!r}): a neural asset carries light transport, not emission; keep the "
                                "emitter in the scene and bake the objects around it", file=file)


#: roughness below which Cycles' glass, refraction or Principled transmission passes light along (near) one direction
SHARP_ROUGHNESS = 0.01
_VOLUME_NODES = ("ShaderNodeVolumeScatter", "ShaderNodeVolumeAbsorption", "ShaderNodeVolumePrincipled")


def _clear_lobe(node) -> str | None:
    """What in a shader node used in a material lets light through unscattered (a Transparent BSDF, a Principled
    alpha below 1, a sharp glass, refraction or Principled transmission), or None. Linked inputs count as not clear."""
    if not any(out.is_linked for out in node.outputs):
        return None

    def value(name, default):
        sock = node.inputs.get(name)
        if sock is None:
            return default
        return None if sock.is_linked else float(sock.default_value)

    rough = value("Roughness", 0.0)
    sharp = rough is not None and rough < SHARP_ROUGHNESS
    if node.bl_idname == "ShaderNodeBsdfTransparent":
        return "Transparent BSDF"
    if node.bl_idname in ("ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction") and sharp:
        return f"{node.bl_label} of roughness {rough:g}"
    if node.bl_idname == "ShaderNodeBsdfPrincipled":
        alpha, transmission = value("Alpha", 1.0), value("Transmission Weight", 0.0)
        if alpha is not None and alpha < 1.0:
            return f"Principled alpha {alpha:g}"
        if transmission is not None and transmission > 0.0 and sharp:
            return f"Principled transmission {transmission:g} of roughness {rough:g}"
    return None


#: the share of light crossing unscattered above which an object counts as see-through (as on the Mitsuba side)
SEE_THROUGH_SHARE = 0.01


def see_through(objects, share: float = SEE_THROUGH_SHARE) -> list[str]:
    """Names of mesh ``objects`` light crosses without scattering (the Mitsuba side: ``scene.see_through``): a
    material with a clear lobe (:func:`_clear_lobe`) and no volume, or volume nodes whose summed Density (1/m)
    lets more than ``share`` through along the object's mean chord 4 V / S (Cauchy's formula for a convex body;
    a linked density counts as opaque)."""
    found = []
    for ob in objects:
        for slot in getattr(ob, "material_slots", ()):
            mat = slot.material
            if mat is None or mat.node_tree is None:
                continue
            with resolved_copy(load_bpy(), mat) as resolved:  # node groups, reroutes, muted nodes as Cycles reads them
                nodes = resolved.node_tree.nodes
                clear = next((c for c in map(_clear_lobe, nodes) if c), None)
                density = 0.0
                for node in nodes if clear is not None else ():
                    if node.bl_idname in _VOLUME_NODES and any(out.is_linked for out in node.outputs):
                        sock = node.inputs.get("Density")
                        density += math.inf if sock is None or sock.is_linked else float(sock.default_value)
            if clear is None:
                continue
            if density > 0.0:
                geo = mesh_geometry([ob])
                tri = geo.points[geo.faces].astype(np.float64)
                area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
                volume = abs(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum()) / 6.0
                if math.exp(-density * 4.0 * volume / max(area, 1e-30)) <= share:
                    continue
            found.append(f"{ob.name} ({clear})")
            break
    return found


def has_particle_hair(ob) -> bool:
    """Whether a mesh carries particle hair Cycles renders as strands (a hair system rendered as Path; one rendered
    as Object or Collection places instances, which the depsgraph lists)."""
    return ob.type == "MESH" and any(ps.settings.type == "HAIR" and ps.settings.render_type == "PATH"
                                     for ps in ob.particle_systems)


def variant_of(objects, *, file: str | None = None) -> str:
    """``surface`` for meshes, ``fiber`` for hair; a mix is CONVERT_SHAPE_UNSUPPORTED."""
    kinds = {"fiber" if (o.type == "CURVES" or has_particle_hair(o)) else "surface" for o in objects}
    if len(kinds) > 1:
        raise error("CONVERT_SHAPE_UNSUPPORTED", "an asset is either meshes or hair, not both: "
                    f"{[o.name for o in objects]}", file=file)
    return kinds.pop()


def _mesh_world(ob, depsgraph, *, local: bool = False, uv_out: list | None = None, slot_out: list | None = None,
                color_out: list | None = None, dropped_out: list | None = None):
    """(points [V,3] world Blender, faces [F,3], normals [V,3] world) of an evaluated mesh; object space when
    ``local``. The normals are Blender's corner normals, as Cycles shades them: a vertex is split where its corners
    differ (flat faces, sharp edges, Smooth by Angle, custom normals), so a cube shades flat and a smooth sphere
    keeps one normal per vertex. ``uv_out`` (a list) receives the active render UV map per triangle corner
    [F,3,2], or None. The faces wind counter-clockwise about the normals also for a mirrored object (negative
    scale), as Cycles renders it. ``slot_out`` (a list) receives each triangle's material slot [F]. ``color_out`` (a
    list) receives {colour attribute name: linear RGB per triangle corner [F,3,3]}, the render default also under
    ""."""
    ev = ob.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        me.calc_loop_triangles()
        nv, nt = len(me.vertices), len(me.loop_triangles)
        loops = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("loops", loops)
        if slot_out is not None:
            slots = np.empty(nt, np.int32)
            me.loop_triangles.foreach_get("material_index", slots)
            slot_out.append(slots)
        if uv_out is not None:
            layer = next((u for u in me.uv_layers if u.active_render), me.uv_layers.active)
            uv = None
            if layer is not None and nt:
                all_uv = np.empty(len(me.loops) * 2, np.float32)
                layer.data.foreach_get("uv", all_uv)
                uv = all_uv.reshape(-1, 2)[loops].reshape(nt, 3, 2).astype(np.float64)
            uv_out.append(uv)
        if color_out is not None:
            colors = {}
            vidx = np.empty(len(me.loops), np.int32)
            me.loops.foreach_get("vertex_index", vidx)
            for attr in me.color_attributes:
                n = len(attr.data)
                rgba = np.empty(n * 4, np.float32)
                attr.data.foreach_get("color", rgba)  # linear whatever the storage (BYTE_COLOR is sRGB-encoded)
                rgba = rgba.reshape(-1, 4).astype(np.float64)
                at = loops if attr.domain == "CORNER" else vidx[loops] if attr.domain == "POINT" else None
                if at is not None and nt:
                    colors[attr.name] = rgba[at, :3].reshape(nt, 3, 3)
            default = me.color_attributes.default_color_name
            if default in colors:
                colors[""] = colors[default]
            color_out.append(colors)
        co = np.empty(nv * 3, np.float32)
        me.vertices.foreach_get("co", co)
        tri = np.empty(nt * 3, np.int32)
        me.loop_triangles.foreach_get("vertices", tri)
        cn = np.empty(len(me.loops) * 3, np.float32)
        me.corner_normals.foreach_get("vector", cn)
        corner_n = cn.reshape(-1, 3)[loops].astype(np.float64)  # [F*3, 3] the normal of each triangle corner
    finally:
        ev.to_mesh_clear()
    # one vertex per distinct (position, corner normal): normals equal to float32 precision share a vertex
    key = np.concatenate([tri[:, None].astype(np.float64), corner_n], axis=1)
    _, first, corner_vertex = np.unique(key, axis=0, return_index=True, return_inverse=True)
    M = np.eye(4) if local else np.array(ob.matrix_world, np.float64)
    lin = M[:3, :3]
    if not np.isfinite(M).all() or abs(np.linalg.det(lin)) <= 1e-12 * max(np.abs(lin).max(), 1e-30) ** 3:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"object {ob.name!r} has a degenerate transform (a scale of 0 along "
                    "some axis, or non-finite): its surface has no area or no normals")
    p = co.reshape(-1, 3).astype(np.float64)[tri[first]] @ lin.T + M[:3, 3]
    n = corner_n[first] @ np.linalg.inv(lin)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    tri = corner_vertex.reshape(-1, 3).astype(np.int32)
    if np.linalg.det(lin) < 0:  # a mirrored object: keep the winding counter-clockwise about the normals
        tri = tri[:, ::-1].copy()
        if uv_out is not None and uv_out[-1] is not None:
            uv_out[-1] = uv_out[-1][:, ::-1].copy()
        if color_out is not None:
            color_out[-1] = {k: v[:, ::-1].copy() for k, v in color_out[-1].items()}
    from nasset_reference_renderer.scene import MAX_WORLD_COORDINATE

    # a non-finite point makes the whole mesh invalid USD, a huge one (Blender stores inf as 3.4e38) a scene the
    # renderer refuses: Cycles draws the rest
    bad = ~(np.isfinite(p).all(axis=1) & np.isfinite(n).all(axis=1)) | (np.abs(p) > MAX_WORLD_COORDINATE).any(axis=1)
    if bad.any():
        keep = ~bad[tri].any(axis=1)
        tri = tri[keep]
        p[bad], n[bad] = 0.0, (0.0, 0.0, 1.0)
        for out in (uv_out, slot_out):
            if out is not None and out[-1] is not None:
                out[-1] = out[-1][keep]
        if color_out is not None:
            color_out[-1] = {k: v[keep] for k, v in color_out[-1].items()}
        if dropped_out is not None:
            dropped_out.append(f"object {ob.name}: {int((~keep).sum())} triangles with non-finite vertex positions "
                               f"or normals, or coordinates beyond {MAX_WORLD_COORDINATE:g}, dropped")
    return p, tri, n


def mesh_geometry(objects, *, local: bool = False, uv_out: list | None = None, slot_out: list | None = None,
                  color_out: list | None = None, dropped_out: list | None = None) -> MeshGeometry:
    """World-space (+Y up) triangles of the evaluated meshes, merged; object space (+Y up) when ``local``.
    ``uv_out`` receives each object's UVs per triangle corner ([F,3,2] or None), ``slot_out`` each object's material
    slot per triangle ([F]; see :func:`_mesh_world`). Triangles with a non-finite vertex position or normal are left
    out (Cycles draws the rest), with a note in ``dropped_out``."""
    bpy = load_bpy()
    dg = bpy.context.evaluated_depsgraph_get()
    pts, faces, normals, base = [], [], [], 0
    for ob in objects:
        p, f, n = _mesh_world(ob, dg, local=local, uv_out=uv_out, slot_out=slot_out, color_out=color_out,
                              dropped_out=dropped_out)
        pts.append(p)
        faces.append(f + base)
        normals.append(n)
        base += len(p)
    geo = MeshGeometry(to_y_up(np.concatenate(pts)).astype(np.float32), np.concatenate(faces).astype(np.int32),
                       to_y_up(np.concatenate(normals)).astype(np.float32))
    if len(geo.faces) == 0:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"objects {[o.name for o in objects]} have no faces")
    return geo


@dataclass
class HairStrands:
    """Blender-space strands: points [P,3] world, counts [C], radius [P] (m)."""

    points: np.ndarray
    counts: np.ndarray
    radius: np.ndarray
    notes: list


def _curves_strands(ob, depsgraph) -> HairStrands:
    ev = ob.evaluated_get(depsgraph)
    cv = ev.data
    n_pts, n_cur = len(cv.points), len(cv.curves)
    pos = np.empty(n_pts * 3, np.float32)
    cv.attributes["position"].data.foreach_get("vector", pos)
    off = np.empty(n_cur + 1, np.int32)
    cv.curve_offset_data.foreach_get("value", off)
    if "radius" in cv.attributes:
        rad = np.empty(n_pts, np.float32)
        cv.attributes["radius"].data.foreach_get("value", rad)
    else:
        rad = np.full(n_pts, DEFAULT_RADIUS, np.float32)
    notes = []
    if "curve_type" in cv.attributes:
        ct = np.empty(n_cur, np.int8)
        cv.attributes["curve_type"].data.foreach_get("value", ct)
        if (ct != 1).any():  # 1 = CURVE_TYPE_POLY
            notes.append(f"{ob.name}: non-poly curves are stored as linear curves through their control points")
    M = np.array(ob.matrix_world, np.float64)
    scale = float(np.cbrt(abs(np.linalg.det(M[:3, :3]))))
    p = pos.reshape(-1, 3).astype(np.float64) @ M[:3, :3].T + M[:3, 3]
    return HairStrands(p, np.diff(off).astype(np.int32), rad.astype(np.float64) * scale, notes)


#: ParticleSettings fields the viewport evaluates by, and the render fields Cycles uses instead (its strands)
_RENDER_AS_VIEWPORT = (("display_step", "render_step"), ("child_percent", "rendered_child_count"))


def _particle_strands(ob) -> HairStrands:
    """The strands Cycles renders of ``ob``'s hair particle systems: parents and children, 2^render_step + 1 points
    each. The depsgraph here evaluates for the viewport (its display steps, display child amount and display
    percentage of parents), so those settings are set to the render ones while the strands are read, then put back:
    before, a hair with interpolated children exported its parents only (50 of the 1 050 strands Cycles rendered)."""
    bpy = load_bpy()
    systems = [ps.settings for ps in ob.particle_systems if ps.settings.type == "HAIR"]
    saved = [{k: getattr(st, k) for k, _ in _RENDER_AS_VIEWPORT} | {"display_percentage": st.display_percentage}
             for st in systems]
    try:
        for st in systems:
            for viewport, render in _RENDER_AS_VIEWPORT:
                setattr(st, viewport, getattr(st, render))
            st.display_percentage = 100
        bpy.context.view_layer.update()
        return _read_strands(ob.evaluated_get(bpy.context.evaluated_depsgraph_get()))
    finally:
        for st, values in zip(systems, saved, strict=True):
            for key, value in values.items():
                setattr(st, key, value)
        bpy.context.view_layer.update()


def _read_strands(ev) -> HairStrands:
    """Every strand (parents, then children) of the evaluated object's hair particle systems, as evaluated."""
    pts, counts, rad = [], [], []
    for ps in ev.particle_systems:
        st = ps.settings
        if st.type != "HAIR":
            continue
        steps = 2 ** int(st.display_step) + 1
        r_root = 0.5 * float(st.root_radius) * float(st.radius_scale)
        r_tip = 0.5 * float(st.tip_radius) * float(st.radius_scale)
        # Cycles' particle hair width: root/tip radius x radius scale (diameter convention in the UI is x2)
        for i in range(len(ps.particles) + len(ps.child_particles)):  # co_hair numbers the children after the parents
            strand = np.array([tuple(ps.co_hair(ev, particle_no=i, step=s)) for s in range(steps)], np.float64)
            if len(strand) < 2 or not np.isfinite(strand).all():
                continue
            pts.append(strand)
            counts.append(len(strand))
            rad.append(r_root + (r_tip - r_root) * np.linspace(0.0, 1.0, len(strand)))
    if not pts:
        return HairStrands(np.zeros((0, 3)), np.zeros(0, np.int32), np.zeros(0), [])
    return HairStrands(np.concatenate(pts), np.array(counts, np.int32), np.concatenate(rad), [])


def hair_strands(objects) -> HairStrands:
    """All strands of the hair objects (Curves objects and particle hair), Blender world space."""
    bpy = load_bpy()
    dg = bpy.context.evaluated_depsgraph_get()
    parts = []
    for ob in objects:
        parts.append(_curves_strands(ob, dg) if ob.type == "CURVES" else _particle_strands(ob))
    pts = np.concatenate([p.points for p in parts]) if parts else np.zeros((0, 3))
    return HairStrands(pts, np.concatenate([p.counts for p in parts]).astype(np.int32),
                       np.concatenate([p.radius for p in parts]), [n for p in parts for n in p.notes])


def curves_geometry(objects) -> tuple[CurvesGeometry, list]:
    """(CurvesGeometry in +Y-up world space with widths = 2 radius, notes). Degenerate strands are dropped."""
    s = hair_strands(objects)
    if len(s.counts) == 0:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"objects {[o.name for o in objects]} have no hair strands")
    keep = s.counts >= 2
    starts = np.concatenate([[0], np.cumsum(s.counts)[:-1]])
    idx = np.concatenate([np.arange(a, a + c) for a, c, k in zip(starts, s.counts, keep, strict=True) if k])
    widths = np.maximum(2.0 * s.radius[idx], 1e-6)
    geo = CurvesGeometry(to_y_up(s.points[idx]).astype(np.float32), s.counts[keep].astype(np.int32), widths.astype(np.float32))
    geo.validate()
    return geo, s.notes


def asset_geometry(objects, *, file: str | None = None):
    """(variant, MeshGeometry | CurvesGeometry, notes) of the asset objects."""
    variant = variant_of(objects, file=file)
    if variant == "surface":
        return variant, mesh_geometry(objects), []
    geo, notes = curves_geometry(objects)
    return variant, geo, notes


def bounding_sphere(geo) -> tuple[np.ndarray, float]:
    lo, hi = geo.bounds()
    c = 0.5 * (np.asarray(lo, np.float64) + np.asarray(hi, np.float64))
    pts = np.asarray(geo.points, np.float64)
    r = float(np.max(np.linalg.norm(pts - c, axis=1)))
    if isinstance(geo, CurvesGeometry):
        r += float(np.max(geo.widths)) * 0.5
    return c, max(r, 1e-6)


def material_names(objects) -> list[str]:
    out = []
    for ob in objects:
        for slot in ob.material_slots:
            if slot.material is not None and slot.material.name not in out:
                out.append(slot.material.name)
        for ps in getattr(ob, "particle_systems", []):
            m = ps.settings.material_slot
            if m and m not in out:
                out.append(m)
    return out


def _include(layer, wanted: set) -> bool:
    """Include (not excluded, not disabled in renders) every layer collection on the way to each collection in
    ``wanted`` (pointers), those collections too; True when ``layer`` leads to one."""
    found = layer.collection.as_pointer() in wanted
    for child in layer.children:
        if _include(child, wanted):
            child.exclude = False
            child.collection.hide_render = False
            found = True
    return found


def isolate(objects) -> None:
    """Make only the asset objects renderable: every other object hidden from render (lights too),
    particle emitters' own surfaces kept only when they are asset meshes; world black."""
    bpy = load_bpy()
    keep = {o.name for o in objects}
    for ob in bpy.context.scene.objects:
        ob.hide_render = ob.name not in keep
    renders = render_visible(bpy.context.view_layer)
    for ob in objects:  # an asset object in a collection disabled in renders (or excluded) is rendered all the same
        if not renders(ob):
            _include(bpy.context.view_layer.layer_collection, {c.as_pointer() for c in ob.users_collection})
    for ob in objects:
        if has_particle_hair(ob):  # keep the hair, not the emitter mesh
            ob.show_instancer_for_render = False
    world = bpy.data.worlds.new("nasset_black")
    if world.node_tree is None:
        world.use_nodes = True
    bg = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeBackground")
    bg.inputs["Strength"].default_value = 0.0
    bpy.context.scene.world = world
