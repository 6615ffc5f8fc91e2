"""Load a Mitsuba scene, pick the asset's shapes, and stage them in isolation for ground truth.

The asset is rendered alone (no ground, no other emitters, no environment): its shapes keep the
BSDFs and interior media the scene gave them. Two isolated scenes are built from the same shape
objects: ``geometry`` (asset only; primary hits, AOVs and the visibility of the light against the
asset) and ``lit`` (asset + one distant light of unit irradiance whose direction is updated per
group of pixels).

Distant light (spec/bake.md#light): ``angle_deg == 0`` is a delta directional light (exact but
unreachable from inside smooth dielectrics); ``angle_deg > 0`` is a far spherical area emitter
subtending that angular radius, with radiance 1 / (pi sin^2 theta) so the irradiance at normal
incidence is exactly 1.

Per-pixel lights (``angle_deg == 0``): a third scene, ``lane``, holds a directional emitter whose
direction is looked up per path from a table, indexed by the ray's ``time`` (nothing in an
isolated asset is animated, so time is free to carry it; every vertex of a path inherits it).
One Mitsuba call then renders every pixel under its own light (the paper's per-pixel random
light) at the cost of one light.
"""

from __future__ import annotations

import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nasset_sdk.errors import NassetError, UsageError, error
from nasset_sdk.geometry import CurvesGeometry, MeshGeometry

from .analytic import ANALYTIC_CLASSES, as_mesh, shape_class
from .sidedness import front_sign

#: BSDF classes through which a delta light is never reached by next-event estimation.
DELTA_BLOCKING_BSDFS = ("SmoothDielectric", "ThinDielectric")


def load_scene(mi, path: str | Path):
    """mi.Scene from an XML file, its shapes as the file has them (``optimize=False``: Mitsuba's default merges the
    meshes that share a BSDF into nameless ones, so a shape whose BSDF is a ``<ref>`` it shares could not be picked by
    its id); CONVERT_SCENE_MISSING / CONVERT_SCENE_LOAD on failure."""
    path = Path(path)
    if not path.is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(path))
    try:
        return mi.load_file(str(path), optimize=False)
    except Exception as exc:  # noqa: BLE001 - Mitsuba raises plain RuntimeErrors for every load failure
        raise error("CONVERT_SCENE_LOAD", load_failure(exc), file=str(path)) from None


def load_failure(exc: BaseException) -> str:
    """The CONVERT_SCENE_LOAD message for Mitsuba's load error ``exc`` (its last line); a ``$name`` parameter without a
    value gets the fix: these commands pass no parameters to the scene, so it needs a ``<default>``."""
    first = str(exc).strip().splitlines()[-1][:300] if str(exc).strip() else type(exc).__name__
    m = re.search(r"undefined parameter: \$(\w+)", first)
    hint = (f" (the scene reads ${m.group(1)} and these commands pass no scene parameters: give it a default, "
            f'<default name="{m.group(1)}" value="..."/>)') if m else ""
    return f"Mitsuba cannot load the scene: {first}{hint}"


#: integrators whose image is not radiance (a distance): nothing to measure an asset against; so is a wrapper
#: (``aov``, ...) with no integrator nested
NO_RADIANCE_INTEGRATORS = ("DepthIntegrator",)


def require_integrator(scene, file: str | Path) -> None:
    """CONVERT_SCENE_LOAD unless the scene names an integrator that renders radiance: Mitsuba 3 renders no scene
    without one, and ``depth`` or a wrapper with no integrator nested (``aov`` of AOVs alone) renders something
    else, so a benchmark has no reference to compare with (a bake needs none: it renders with its own)."""
    if scene.integrator() is None:
        raise error("CONVERT_SCENE_LOAD", "the scene has no <integrator>, and Mitsuba renders none without one: there is no "
                    "reference to measure against; add one, e.g. <integrator type=\"volpath\"/>", file=str(file))
    image = image_integrator(scene.integrator())
    if image in NO_RADIANCE_INTEGRATORS or image in _WRAPPER_INTEGRATORS or not str(image).endswith("Integrator"):
        raise error("CONVERT_SCENE_LOAD", f"the scene's integrator ({image}) renders no radiance (a depth or AOV image): "
                    "there is no reference to measure against; use <integrator type=\"volpath\"/> (or nest one in the "
                    "wrapper)", file=str(file))


def integrator_depths(integrator) -> dict:
    """``max_depth`` and ``rr_depth`` as a loaded Mitsuba integrator reports them (a key is absent when the
    integrator has no such setting, or is None). -1 is unbounded: Mitsuba stores the depth unsigned and prints
    -1 as 2^32 - 1, which is read back as -1 (any value >= 2^31)."""
    import re

    out = {}
    for key in ("max_depth", "rr_depth"):
        m = re.search(rf"\b{key}\s*=\s*(-?\d+)", str(integrator)) if integrator is not None else None
        if m:
            v = int(m.group(1))
            out[key] = -1 if v >= 2 ** 31 or v < 0 else v
    if "max_depth" not in out and integrator is not None and image_integrator(integrator) in FIXED_DEPTHS:
        out["max_depth"] = FIXED_DEPTHS[image_integrator(integrator)]
    return out


#: integrators of a fixed depth that state none: ``direct`` renders the emitters in view and direct light at the first
#: hit, Mitsuba's path of 2 segments (``direct_projective`` states max_depth 2)
FIXED_DEPTHS = {"DirectIntegrator": 2}


#: the depth training views are rendered with for a scene whose integrator is unbounded (Russian roulette ends paths)
UNBOUNDED_DEPTH = 1024


def training_depth(integrator, preset_depth: int) -> int:
    """max_depth of a bake's training renders: the preset's, or the scene integrator's where that is deeper, so that
    the ground truth is as deep as the scene's own (spec/accuracy.md); an unbounded one gives UNBOUNDED_DEPTH."""
    md = integrator_depths(integrator).get("max_depth")
    if md is None or 0 <= md <= preset_depth:
        return int(preset_depth)
    return UNBOUNDED_DEPTH if md < 0 else md


#: Mitsuba curve shapes an rna fiber asset can be baked from (spec/bake.md#mitsuba-curves)
CURVE_CLASSES = ("LinearCurve", "BSpline", "BSplineCurve")


def dielectric_eta(params) -> float:
    """The relative index of refraction of a (rough) dielectric from its ``mi.traverse`` parameters (Mitsuba's default
    1.5 when it does not expose one)."""
    return float(np.asarray(params["eta"]).ravel()[0]) if "eta" in params else 1.5


def ggx_dielectric(mi, shape, *, kind: str, file: str = "") -> tuple[float, float]:
    """(eta, GGX alpha) of a shape's ``roughdielectric`` boundary, as the ``kind``'s format stores it: one GGX lobe
    with one isotropic constant alpha. CONVERT_SHAPE_UNSUPPORTED for Mitsuba's default Beckmann distribution (its
    reflection differs from GGX's by 30-70 % of the lobe) and for an anisotropic or textured roughness."""
    bsdf = shape.bsdf()
    params = mi.traverse(bsdf)
    if "ggx" not in str(bsdf).lower():
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape.id()!r}: the {kind} boundary must use the GGX distribution "
                    "(the format's analytic reflection is GGX; Mitsuba's roughdielectric defaults to Beckmann, whose "
                    "reflection differs from GGX's by 30-70 % of its lobe: add <string name=\"distribution\" "
                    "value=\"ggx\"/> to the BSDF)", file=file)
    if "alpha.value" not in params:
        rough = sorted(k for k in params.keys() if k.startswith("alpha"))
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape.id()!r}: the {kind} boundary roughness must be one isotropic "
                    f"constant alpha (the format stores one GGX alpha); it has {rough}", file=file)
    alpha = float(np.asarray(params["alpha.value"]).ravel()[0])
    return dielectric_eta(params), alpha


def shapegroup_children(mi, scene, group: str) -> dict:
    """{child name: shape} of the ``shapegroup`` with id ``group``: the nodes whose parent is that group in the
    hierarchy of Mitsuba's scene parameters. Ids may hold dots (Blender's ``Cube.001``), so no parameter key is split
    on dots; an unnamed child is ``shape_N`` (N its place in the group), as an unnamed top-level shape."""
    children = {}
    for node, (parent, _depth) in mi.traverse(scene).hierarchy.items():
        if parent is not None and str(parent).startswith("ShapeGroup[") and parent.id() == group:
            children[node.id() or f"shape_{len(children)}"] = node
    return children


def no_such_shape(mi, scene, sid: str) -> str:
    """The message for a shape id that is not one of the scene's shapes: the ids it has, or, for a shape inside a
    ``shapegroup``, that the group places it through its instances (an asset is one object in the scene's world
    space, so a shape that the scene draws through instances is not one)."""
    ids = sorted(s.id() for s in scene.shapes() if s.id())
    groups = {}
    for node, (parent, _depth) in mi.traverse(scene).hierarchy.items():
        if parent is not None and str(parent).startswith("ShapeGroup[") and node.id() == sid:
            groups[parent.id()] = [s.id() or "(unnamed)" for s in scene.shapes()
                                   if str(s).startswith("Instance[") and f'name = "{parent.id()}"' in str(s)]
    if not groups:
        kind = next((what for what, objs in (("an emitter", scene.emitters()), ("a sensor", scene.sensors()))
                     if any(o.id() == sid for o in objs)), None)
        what = f"; {sid!r} is {kind}, and an asset is made of shapes" if kind else ""
        return f"no shape with id {sid!r}{what}; the scene has {ids}"
    group, instances = next(iter(groups.items()))
    return (f"shape {sid!r} is inside shapegroup {group!r}, which the scene draws through its instances {instances}: an "
            "asset is one object in the scene's world space; place one copy of the shape outside the group (with the "
            "instance's to_world) and bake that")


def refuse_emitter(shape, *, file: str | None = None) -> None:
    """CONVERT_SHAPE_UNSUPPORTED when a shape to bake or replace is an area emitter: a neural asset carries light
    transport (the response to light arriving, kinds/*.md), not emission, so its training targets would hold the
    emission as if it were lit, and replacing it would take its light out of the scene."""
    if shape.emitter() is not None:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {shape.id()!r} is an area emitter: a neural asset carries light "
                    "transport, not emission; keep the emitter in the scene and bake the shapes around it (a glass bulb "
                    "without its filament)", file=file)


def pick_shapes(scene, ids, *, file: str | None = None, curves: bool = False) -> list:
    """The scene's shapes with these ids, in the given order: triangle meshes (analytic shapes as their
    tessellation, :func:`.analytic.as_mesh`), or with ``curves`` also Mitsuba curves (``linearcurve``,
    ``bsplinecurve``; all of them then, not mixed with meshes)."""
    by_id = {s.id(): s for s in scene.shapes()}
    if not ids:
        raise error("CONVERT_SHAPE_UNKNOWN", f"no --asset shape id given; the scene has {sorted(by_id)}", file=file)
    if twice := sorted({i for i in ids if list(ids).count(i) > 1}):
        raise UsageError(f"--asset {twice} given more than once: each shape belongs to the asset once")
    out = []
    for i in ids:
        if i not in by_id:
            import mitsuba as mi

            raise error("CONVERT_SHAPE_UNKNOWN", no_such_shape(mi, scene, i), file=file)
        shape = by_id[i]
        refuse_emitter(shape, file=file)
        cls = shape_class(shape)
        if curves and cls in CURVE_CLASSES:
            out.append(shape)
            continue
        if cls in ANALYTIC_CLASSES:  # baked from its tessellation (spec/bake.md#analytic-shapes)
            import mitsuba as mi

            out.append(as_mesh(mi, shape))
            continue
        if cls == "Instance":
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {i!r} is an instance of a shapegroup, drawn wherever the scene "
                        "places the group: an asset is one object in the scene's world space; place a copy of the group's "
                        "shapes (triangle meshes or analytic shapes: "
                        f"{', '.join(c.lower() for c in ANALYTIC_CLASSES)}) outside the group (with this instance's "
                        "to_world) and bake those", file=file)
        if not shape.is_mesh():
            hint = ("; curves make rna fiber assets only (--kind rna)" if cls in CURVE_CLASSES
                    else "; convert it to ply/obj" + (" or a linearcurve" if curves else ""))
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"shape {i!r} is a Mitsuba {cls}, not a triangle mesh or an analytic shape "
                        f"({', '.join(c.lower() for c in ANALYTIC_CLASSES)}){hint}", file=file)
        out.append(shape)
    kinds = {shape_class(s) in CURVE_CLASSES for s in out}
    if len(kinds) > 1:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"shapes {list(ids)} mix curves and meshes: an asset is either fibers or a "
                    "surface; bake them as two assets", file=file)
    return out


def open_shapes(path: str | Path, ids, *, variant: str | None = None, threads: int = 0, curves: bool = False):
    """``(mi, shapes)``: Mitsuba loaded (``variant``; errors only in its log), ``threads`` > 0 limiting
    Dr.Jit's thread pool, the scene at ``path`` loaded and the shapes ``ids`` picked from it -- what a
    process that did not run a bake's first stage (a cluster worker) needs to render its views."""
    from . import load_mitsuba

    mi = load_mitsuba(variant)
    mi.set_log_level(mi.LogLevel.Error)
    if threads:
        import drjit as dr

        dr.set_thread_count(int(threads))
    return mi, pick_shapes(load_scene(mi, path), ids, file=str(path), curves=curves)


def asset_geometry(mi, shapes) -> tuple[str, MeshGeometry | CurvesGeometry]:
    """``(variant, geometry)`` of picked shapes: ("fiber", CurvesGeometry) for curves, else ("surface", MeshGeometry)."""
    if shape_class(shapes[0]) in CURVE_CLASSES:
        return "fiber", curves_geometry(mi, shapes)
    return "surface", mesh_geometry(mi, shapes)


def curves_geometry(mi, shapes) -> CurvesGeometry:
    """Mitsuba curves as linear fiber curves (asset object space = scene space; widths = 2 x Mitsuba's radius).

    A ``linearcurve`` is taken as it is. A ``bsplinecurve`` (uniform cubic B-spline, one span per four
    control points) becomes the polyline through its span ends, one segment per span: the same number of
    segments as Mitsuba intersects, off the smooth curve by at most its deviation within a span
    (spec/bake.md#mitsuba-curves); the bake records how many pixels the two disagree on."""
    pts, widths, counts = [], [], []
    for s in shapes:
        params = mi.traverse(s)
        cp = np.asarray(params["control_points"], np.float64).reshape(-1, 4)
        seg = np.asarray(params["segment_indices"], np.int64).ravel()
        if len(seg) == 0:
            raise error("CONVERT_SHAPE_UNSUPPORTED", f"curve shape {s.id()!r} has no segments")
        starts = np.concatenate([[0], np.nonzero(np.diff(seg) != 1)[0] + 1, [len(seg)]])
        bspline = shape_class(s).startswith("BSpline")
        for a, b in zip(starts[:-1], starts[1:], strict=True):
            first = int(seg[a])
            if bspline:  # span j's ends: (P_j + 4 P_j+1 + P_j+2) / 6 for j = first .. first + spans
                j = first + np.arange(b - a + 1)
                c = (cp[j] + 4.0 * cp[j + 1] + cp[j + 2]) / 6.0
            else:
                c = cp[first:first + (b - a) + 1]
            pts.append(c[:, :3])
            widths.append(2.0 * c[:, 3])
            counts.append(len(c))
    geo = CurvesGeometry(np.concatenate(pts).astype(np.float32), np.asarray(counts, np.int32),
                         np.concatenate(widths).astype(np.float32))
    try:
        geo.validate()
    except Exception as exc:  # noqa: BLE001 - the SDK's check names what is wrong; say which shapes
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"curve shapes {[s.id() for s in shapes]}: {exc}") from None
    return geo


def mesh_geometry(mi, shapes) -> MeshGeometry:
    """Merge the shapes' world-space triangles into one MeshGeometry (asset object space = scene space). Normals: the
    shapes' vertex normals; None when no shape has any (flat shading everywhere). Where only some have them, the
    others (``face_normals``, or a file without normals) get their vertices split per triangle with the face normal,
    so they stay flat and the smooth ones smooth."""
    meshes = []
    for s in shapes:
        params = mi.traverse(s)
        p = np.asarray(params["vertex_positions"], np.float32).reshape(-1, 3)
        f = np.asarray(params["faces"], np.int64).reshape(-1, 3)
        n = np.asarray(params["vertex_normals"], np.float32).reshape(-1, 3) if "vertex_normals" in params else None
        n = n if n is not None and n.size and n.shape == p.shape else None
        if len(f) and front_sign(mi, s, p, f, n) < 0:  # flip_normals: Mitsuba shades (and the data holds) the other side
            f, n = f[:, ::-1].copy(), None if n is None else -n
        meshes.append((p, f, n))
    some_normals = any(n is not None for _, _, n in meshes)
    pts, faces, normals, base = [], [], [], 0
    for p, f, n in meshes:
        if some_normals and n is None:  # flat: one vertex per triangle corner, carrying the face normal
            p = p[f].reshape(-1, 3)
            f = np.arange(len(p)).reshape(-1, 3)
            fn = np.cross(p[1::3] - p[0::3], p[2::3] - p[0::3]).astype(np.float64)
            fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)
            n = np.repeat(fn, 3, axis=0).astype(np.float32)
        pts.append(p)
        faces.append(f + base)
        normals.append(n)
        base += len(p)
    geo = MeshGeometry(
        np.concatenate(pts).astype(np.float32),
        np.concatenate(faces).astype(np.int32),
        np.concatenate(normals).astype(np.float32) if some_normals else None,
    )
    geo.validate()
    tri = geo.points[geo.faces]
    areas = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    if not np.isfinite(areas).all() or float(areas.sum()) <= 0.0:
        raise error("CONVERT_SHAPE_UNSUPPORTED", f"asset shapes {[s.id() for s in shapes]} have no surface area")
    if not is_closed(geo.faces, geo.points):
        warnings.warn(f"asset shapes {[s.id() for s in shapes]} do not form a closed surface: the asset is seen from "
                      "both sides, and light can pass through its holes", RuntimeWarning, stacklevel=2)
    return geo


def is_closed(faces: np.ndarray, points: np.ndarray | None = None) -> bool:
    """True when every undirected edge of the triangles [F,3] is shared by exactly two faces (a watertight mesh).
    With ``points`` [V,3], vertices at the same position count as one: a mesh split along its hard edges or UV seams
    (a Mitsuba ``cube``: 24 vertices) is closed when its surface is."""
    faces = np.asarray(faces)
    if points is not None:
        _, weld = np.unique(np.asarray(points), axis=0, return_inverse=True)
        faces = weld.reshape(-1)[faces]
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(e, axis=0, return_counts=True)
    return bool((counts == 2).all())


def bsdf_names(shapes) -> list[str]:
    return [str(s.bsdf()).split("[")[0].strip() for s in shapes]


def has_medium(shape) -> bool:
    """True when a Mitsuba shape has an interior or an exterior medium."""
    return shape.interior_medium() is not None or shape.exterior_medium() is not None


#: relative spread (max - min) / max of a medium's RGB extinction above which training renders use ``volpathmis``
#: (measured, spec/bake.md#data "Media": in variance x time spectral MIS wins 1.5-12x at 0.3, 0.9-2.7x at 0.2, and
#: loses 1.1-1.4x at 0.05)
CHROMATIC_SPREAD = 0.25


def chromatic_media(mi, shapes, points: int = 256, seed: int = 0) -> bool:
    """True when an interior or exterior medium of ``shapes`` has an extinction sigma_t whose RGB channels differ by
    more than CHROMATIC_SPREAD (relative to the largest) at any of ``points`` random points in the shape's bounding
    box (a grid medium is looked up there; a homogeneous one is constant).

    Mitsuba's ``volpath`` samples distances in one channel and weights the others by the ratio of transmittances,
    whose variance grows along the long walks of a high-albedo medium; ``volpathmis`` combines the channels by
    spectral MIS."""
    import drjit as dr

    rng = np.random.default_rng(seed)
    for shape in shapes:
        bbox = shape.bbox()
        lo, hi = np.asarray(bbox.min, np.float64), np.asarray(bbox.max, np.float64)
        p = lo + rng.random((points, 3)) * (hi - lo)
        for medium in (shape.interior_medium(), shape.exterior_medium()):
            if medium is None:
                continue
            mei = dr.zeros(mi.MediumInteraction3f, points)
            mei.p = mi.Point3f(np.ascontiguousarray(p.T, np.float32))
            _, _, sigma_t = medium.get_scattering_coefficients(mei)
            st = np.asarray(sigma_t, np.float64).reshape(3, -1).T  # [points, 3], or [1, 3] for a constant
            if (st.max(1) - st.min(1) > CHROMATIC_SPREAD * np.maximum(st.max(1), 1e-30)).any():
                return True
    return False


def _shapes_with_media(scene, ids) -> list:
    return [s for s in scene.shapes() if s.id() in ids and has_medium(s)]


def _ids_with_media(scene, ids) -> list[str]:
    return [s.id() for s in _shapes_with_media(scene, ids)]


#: the to_string names of Mitsuba's integrators that render participating media (volpath, volpathmis, prbvolpath)
_MEDIA_INTEGRATORS = re.compile(r"(Volumetric\w*|PRBVolpath)Integrator")
#: integrators that only wrap the one making the image (``aov``, ``stokes``; ``moment`` prints as ``Scene[``)
_WRAPPER_INTEGRATORS = ("AOVIntegrator", "StokesIntegrator", "MomentIntegrator")


def image_integrator(integrator) -> str | None:
    """The to_string class name of the integrator that renders a loaded Mitsuba integrator's image: itself, or for a
    wrapper (``aov``, ``stokes``, ``moment``) the first integrator nested in it; None for None."""
    if integrator is None:
        return None
    names = re.findall(r"\b(\w+)\[", str(integrator))
    inner = [n for n in names if n.endswith("Integrator") and n not in _WRAPPER_INTEGRATORS]
    return inner[0] if inner else (names[0] if names else str(integrator).strip())


def hides_emitters(mi, integrator) -> bool:
    """True when a loaded Mitsuba integrator has ``hide_emitters`` set: camera rays see no emitter (a black
    background, light sources not shown). Mitsuba's description of an integrator does not name the flag, so it is
    read off the integrator: the radiance it gives a ray escaping into a scene of one constant emitter (0 when
    hidden). False for an integrator that does not sample rays that way (``ptracer``, None)."""
    if integrator is None or not hasattr(integrator, "sample"):
        return False
    probe = mi.load_dict({"type": "scene", "sky": {"type": "constant"}})
    sampler = mi.load_dict({"type": "independent"})
    sampler.seed(0, 1)
    try:
        out = integrator.sample(probe, sampler, mi.Ray3f(mi.Point3f(0, 0, 0), mi.Vector3f(0, 0, 1)))
    except (RuntimeError, TypeError):  # an integrator that cannot render a ray by itself
        return False
    return float(np.max(np.asarray(out[0], np.float64))) <= 0.0


def ignored_media(scene, ids) -> str | None:
    """A warning when shapes ``ids`` have an interior or exterior medium that the scene's own integrator does not
    render: Mitsuba's ``path`` (and ``direct``, ``prb``, ...) shows such a shape as if it held no medium (a smooth
    dielectric boundary then looks like clear glass), while a bake renders the medium (spec/bake.md#data). None when the
    integrator renders media (``volpath``, ``volpathmis``, ``prbvolpath``), the scene has none, or no shape has a medium."""
    name = image_integrator(scene.integrator())
    if name is None or _MEDIA_INTEGRATORS.fullmatch(name):
        return None
    with_media = _ids_with_media(scene, ids)
    if not with_media:
        return None
    return (f"the scene's integrator ({name}) renders no participating media, so Mitsuba shows shape(s) {with_media} without "
            "their medium, while the asset holds it (bakes render the medium). Use <integrator type=\"volpath\"> for "
            "a scene that renders what the asset holds")


def truncated_media(scene, ids, baked_depth: int | None = None) -> str | None:
    """A warning when the scene's integrator stops paths at a bounded ``max_depth`` and shapes ``ids`` have a medium:
    light inside a high-albedo medium may take more bounces than the scene's depth allows, so the scene's own image
    lacks it, while bakes may trace deeper (spec/bake.md#data). None when the depth is unbounded, no shape has a
    medium, the integrator renders no media at all (:func:`ignored_media` says so), or the bake's own depth
    ``baked_depth`` (-1: unbounded) is no deeper than the scene's. A heuristic: how much a depth cuts depends on the
    medium (16 cut a third of a blob's light, 128 nothing measurable of the pebble's: spec/accuracy.md#in-scene-accuracy
    item 8)."""
    integrator = scene.integrator()
    depth = integrator_depths(integrator).get("max_depth")
    if depth is None or depth < 0 or not _MEDIA_INTEGRATORS.fullmatch(image_integrator(integrator) or ""):
        return None
    if baked_depth is not None and 0 <= baked_depth <= depth:
        return None
    with_media = _ids_with_media(scene, ids)
    if not with_media:
        return None
    return (f"the scene's integrator stops paths at max_depth {depth}: inside the medium of shape(s) {with_media} light may "
            "take more bounces than that, so the scene's image lacks it, while an asset baked deeper holds it and reads "
            "bright against that image. Use max_depth -1 (unbounded, Russian roulette) for a scene that renders what the "
            "asset holds")


def chromatic_volpath(mi, scene, ids) -> str | None:
    """A warning when the scene's integrator is Mitsuba's ``volpath`` and shapes ``ids`` have a chromatic medium
    (:func:`chromatic_media`): its image of them is heavy-tailed, so it converges slowly and a two-half estimate of its
    noise can read low; ``volpathmis`` renders the same expectation with 1.2-1000x less variance x time there
    (spec/bake.md#data, "Media"). None otherwise."""
    if image_integrator(scene.integrator()) != "VolumetricSimplePathIntegrator":
        return None
    shapes = _shapes_with_media(scene, ids)
    if not shapes or not chromatic_media(mi, shapes):
        return None
    return (f"the scene's volpath renders the chromatic medium of shape(s) {[s.id() for s in shapes]} (extinction "
            f"differing by more than {CHROMATIC_SPREAD:.0%} between channels) with heavy-tailed noise: the Mitsuba side "
            "converges slowly and its noise estimate can read low. <integrator type=\"volpathmis\"> renders the same "
            "image with far less noise")


def camera_medium(scene) -> str | None:
    """A warning when the scene's first sensor sits in a participating medium (fog around the camera): USD has no
    participating media and the in-scene benches render both sides from a sensor of their own, so neither image holds
    it. None otherwise."""
    sensors = scene.sensors()
    medium = sensors[0].get_medium() if sensors else None
    if medium is None:
        return None
    return (f"the scene's camera sits in a medium ({str(medium).split('[')[0].strip()}): the converted scene and the "
            "benches' images leave it out (USD has no participating media), so they show the scene without that fog")


def baked_depth(provenance: dict) -> int | None:
    """The depth an asset's training paths were traced to, from its bake provenance (rna and neupress ``data``,
    8dna ``sampler``); None when the provenance does not say (another baker, a hand-made asset)."""
    for section in ("data", "sampler"):
        part = provenance.get(section) if isinstance(provenance, dict) else None
        depth = part.get("max_depth") if isinstance(part, dict) else None
        if isinstance(depth, int) and not isinstance(depth, bool):
            return depth
    return None


def bake_media_warnings(scene, ids, baked_depth: int) -> list[str]:
    """What a bake of shapes ``ids`` at depth ``baked_depth`` says about their media: :func:`ignored_media` and
    :func:`truncated_media`, where the scene's own image will show less than the asset holds."""
    return [c for c in (ignored_media(scene, ids), truncated_media(scene, ids, baked_depth=baked_depth)) if c]


def media_caveats(mi, scene, replace: dict) -> list[str]:
    """The warnings of :func:`ignored_media`, :func:`truncated_media` and :func:`chromatic_volpath` that apply to
    ``replace`` (shape id -> asset file): where the scene's own image of the replaced shapes lacks light their asset
    holds, or is needlessly noisy; and :func:`camera_medium` (the in-scene benches' ``reference.warnings``). The depth warning is per asset,
    from the depth its provenance says it was baked at."""
    from nasset_sdk.asset import Asset

    ids = list(replace)
    out = [ignored_media(scene, ids)]
    groups: dict[str, list[str]] = {}
    for sid, file in replace.items():
        groups.setdefault(str(file), []).append(sid)
    for file, group in groups.items():
        try:
            depth = baked_depth(Asset.open(file, load="none").provenance)
        except (NassetError, OSError):  # an unreadable asset is reported by the bench itself
            depth = None
        out.append(truncated_media(scene, group, baked_depth=depth))
    out.append(chromatic_volpath(mi, scene, ids))
    out.append(camera_medium(scene))
    return [c for c in out if c]


def blocks_delta_light(shapes) -> bool:
    """True when a shape's BSDF is a smooth (delta) dielectric: delta lights cannot light its interior."""
    return any(any(b in str(s.bsdf()) for b in DELTA_BLOCKING_BSDFS) for s in shapes)


def scene_of(mi, shapes, **extra):
    """A Mitsuba scene of ``shapes`` (plus ``extra`` entries of its dict, e.g. ``light={...}``) that leaves the shapes'
    ids as they were: a shape put in another scene takes its key there as its id, and the user's ids would read
    ``asset_0`` afterwards (a neupress bake recorded its boundary shape so in the provenance)."""
    ids = [s.id() for s in shapes]
    scene = mi.load_dict({"type": "scene", **{f"asset_{k}": s for k, s in enumerate(shapes)}, **extra})
    for shape, sid in zip(shapes, ids, strict=True):
        shape.set_id(sid)
    return scene


#: how far (a share of the replaced shapes' box diagonal) an asset's geometry box may lie from theirs
BOX_TOLERANCE = 0.05


def bounds_offset(shapes, points) -> float:
    """The largest difference between the world bounding box of ``shapes`` and that of ``points`` [N, 3] (an asset's
    geometry), as a share of the shapes' box diagonal: above BOX_TOLERANCE the asset was not baked from them."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for s in shapes:
        b = s.bbox()
        lo = np.minimum(lo, np.asarray(list(b.min), np.float64))
        hi = np.maximum(hi, np.asarray(list(b.max), np.float64))
    return box_offset(np.stack([lo, hi]), points)


def box_offset(box, points) -> float:
    """:func:`bounds_offset` against a box ``[[lo], [hi]]`` (the replaced objects' own geometry's, Blender)."""
    box, pts = np.asarray(box, np.float64), np.asarray(points, np.float64)
    a = np.stack([pts.min(0), pts.max(0)])
    diag = float(np.linalg.norm(box[1] - box[0])) or 1.0
    return float(np.abs(a - box).max()) / diag


#: Mitsuba's secondary-ray offset, as a share of the asset's bounding radius, above which shapes lie far from the origin
FAR_OFFSET_SHARE = 0.01


def _far(mi, shapes) -> tuple[np.ndarray, np.ndarray, float, float] | None:
    """``(lo, hi, radius, offset)`` of ``shapes`` whose world box lies so far from the origin for its size that Mitsuba's
    self-intersection offset (1 + max |p|) x RayEpsilon (8.9e-5) along the normal exceeds FAR_OFFSET_SHARE of their
    bounding radius; None otherwise."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for s in shapes:
        b = s.bbox()
        lo = np.minimum(lo, np.asarray(list(b.min), np.float64))
        hi = np.maximum(hi, np.asarray(list(b.max), np.float64))
    if not np.isfinite(lo).all():
        return None
    radius = 0.5 * float(np.linalg.norm(hi - lo))
    offset = (1.0 + float(np.max(np.abs(np.stack([lo, hi]))))) * float(mi.math.RayEpsilon)
    return None if offset <= FAR_OFFSET_SHARE * radius else (lo, hi, radius, offset)


def _far_words(shapes, far) -> str:
    lo, hi, radius, offset = far
    return (f"shapes {[s.id() for s in shapes]} lie {float(np.max(np.abs(np.stack([lo, hi])))):.3g} units from the origin "
            f"for a radius of {radius:.3g}: Mitsuba offsets the rays it spawns off a surface by {offset:.3g} there "
            f"({100 * offset / radius:.0f} % of the radius)")


def far_from_origin(mi, shapes) -> str | None:
    """A warning when ``shapes`` lie so far from the origin for their size (:func:`_far`) that Mitsuba starts secondary
    rays off them through thin parts, so that their shadows on themselves and their interreflections go missing in its
    images of the scene (the in-scene benches' reference). Found on a 0.6-unit cube 10^4 units from the origin: an
    offset of 0.9 units. The bakers render the shapes moved to the origin instead (:func:`move_to_origin`)."""
    far = _far(mi, shapes)
    return None if far is None else (f"{_far_words(shapes, far)}, so their shadows on themselves and their "
                                     "interreflections are missing from its images of the scene (the reference); move "
                                     "the scene towards the origin")


def unmovable(shapes) -> str | None:
    """Why Mitsuba cannot render ``shapes`` translated as they are: an interior or exterior medium that is not
    homogeneous (a grid placed in world space, which traversal cannot move) or a BSDF that reads a volume (looked up at
    world positions); None when nothing of them depends on where they lie."""
    for s in shapes:
        for side, medium in (("interior", s.interior_medium()), ("exterior", s.exterior_medium())):
            if medium is not None and not medium.is_homogeneous():
                return f"shape {s.id()!r} has a heterogeneous {side} medium, placed in world space"
        if s.bsdf() is not None and "Volume" in str(s.bsdf()):
            return f"shape {s.id()!r} has a BSDF that reads a volume at world positions"
    return None


def far_for_bake(mi, shapes) -> str | None:
    """A bake's warning for ``shapes`` far from the origin (:func:`_far`) that :func:`move_to_origin` leaves in place
    (:func:`unmovable`): their training targets are Mitsuba's images there; None when not far, or when they move."""
    far = _far(mi, shapes)
    why = None if far is None else unmovable(shapes)
    return None if why is None else (f"{_far_words(shapes, far)}, and they cannot be rendered moved to the origin ({why}): "
                                     "their shadows on themselves and their interreflections are missing from the "
                                     "training targets; move the scene towards the origin")


def exact_origin(points: np.ndarray) -> np.ndarray:
    """A translation c [3] near the centre of the box of float32 ``points`` [N, 3] such that every ``p - c`` is a
    float32 number exactly, so ``(p - c) + c`` gives ``p`` back bit for bit: per axis the box centre rounded to a
    multiple of the float32 spacing at the axis's largest coordinate; an axis where that is not exact (an object that
    straddles 0 there, so not far along it) keeps c = 0."""
    p = np.asarray(points, np.float32).reshape(-1, 3)
    if not len(p):
        return np.zeros(3)
    lo, hi = p.min(0).astype(np.float64), p.max(0).astype(np.float64)
    step = np.spacing(np.maximum(np.abs(lo), np.abs(hi)).astype(np.float32)).astype(np.float64)
    c = np.round(0.5 * (lo + hi) / step) * step
    p64 = p.astype(np.float64)
    exact = ((p64 - c).astype(np.float32).astype(np.float64) + c == p64).all(0)
    return np.where(exact, c, 0.0)


def _positions(mi, shape) -> tuple[object, str, int]:
    """``(parameters, key, width)`` of a shape's positions: mesh vertices [N, 3] or curve control points [N, 4]."""
    params = mi.traverse(shape)
    key = "vertex_positions" if "vertex_positions" in params else "control_points"
    return params, key, 4 if key == "control_points" else 3


def render_origin(mi, shapes) -> np.ndarray:
    """Where :func:`move_to_origin` moves ``shapes`` from: c [3] when they lie far from the origin for their size
    (:func:`_far`) and nothing of them depends on where they lie (:func:`unmovable`), else zeros. c is
    :func:`exact_origin` of their positions (mesh vertices, curve control points)."""
    if _far(mi, shapes) is None or unmovable(shapes):
        return np.zeros(3)
    pts = []
    for s in shapes:
        params, key, width = _positions(mi, s)
        pts.append(np.asarray(params[key], np.float32).reshape(-1, width)[:, :3])
    return exact_origin(np.concatenate(pts))


def move_to_origin(mi, shapes) -> np.ndarray:
    """Translate ``shapes`` in place by ``-c`` (c = :func:`render_origin`; zeros: left where they are) and return c.

    Mitsuba offsets the rays it spawns off a surface by (1 + max |p|) x RayEpsilon: far out, through thin parts of the
    asset (a 0.6-unit two-part object 800 units out read +3.1 % of the energy of its held-out targets at the origin, a
    translucent slab -95 %, spec/bake.md#far-from-the-origin). Moved, the asset renders as at the origin: callers give
    rays in the scene's frame minus c and add c to the points Mitsuba returns (:class:`IsolatedAsset` ``origin``). c
    keeps every position exact, so the moved shapes are the same float32 surface; directions, normals and media do not
    change (a mesh's vertex normals are put back: Mitsuba recomputes them when its positions change). Call it once per
    loaded scene: it moves the shapes again on a second call."""
    c = render_origin(mi, shapes)
    if not c.any():
        return c
    for s in shapes:
        params, key, width = _positions(mi, s)
        p = np.asarray(params[key], np.float64).reshape(-1, width)
        p[:, :3] -= c
        normals = np.array(params["vertex_normals"], np.float32) if "vertex_normals" in params else None
        params[key] = mi.Float(p.astype(np.float32).ravel())
        params.update()
        if normals is not None and normals.size:
            params["vertex_normals"] = mi.Float(normals)
            params.update()
    return c


def mirror_shapes(mi, shapes) -> list[str]:
    """Ids of ``shapes`` whose BSDF scatters light along mirror directions only (no smooth lobe, nothing transmitted:
    ``conductor``, a ``twosided`` one) and that hold no medium: a distant light reaches a camera off them along one
    direction alone, so every rna training pixel is black, and what they mirror of the scene no network holds
    (spec/bake.md#mirrors)."""
    flags = mi.BSDFFlags
    out = []
    for s in shapes:
        f = s.bsdf().flags() if s.bsdf() is not None else 0
        if not (mi.has_flag(f, flags.Smooth) or mi.has_flag(f, flags.Transmission) or mi.has_flag(f, flags.Null)
                or has_medium(s)):
            out.append(s.id())
    return out


#: the share of straight-through light above which a shape counts as see-through (:func:`see_through`)
SEE_THROUGH_SHARE = 0.01


def see_through(mi, shapes, rays: int = 256, samples: int = 16, seed: int = 0) -> list[str]:
    """Ids of ``shapes`` that light crosses without scattering: a BSDF with a delta or null transmission (``dielectric``,
    ``thindielectric``, ``mask``, ``null``, a ``blendbsdf`` of one) and an interior medium that lets more than
    SEE_THROUGH_SHARE of it through in its thinnest channel, averaged over ``rays`` random chords (optical depth from
    ``samples`` lookups of sigma_t along each; no interior medium: all of it).

    rna stores smooth transport T(x, wo, wi) (spec/kinds/rna.md): what such a shape shows of the scene behind it is
    a delta in wi, which neither its training views (lit by one distant light) nor its continuation rays can hold."""
    import drjit as dr

    found = []
    rng = np.random.default_rng(seed)
    for shape in shapes:
        bsdf = shape.bsdf()
        flags = bsdf.flags() if bsdf is not None else 0
        if not (mi.has_flag(flags, mi.BSDFFlags.DeltaTransmission) or mi.has_flag(flags, mi.BSDFFlags.Null)):
            continue
        medium = shape.interior_medium()
        if medium is None or _straight_through(mi, dr, shape, medium, rng, rays, samples) > SEE_THROUGH_SHARE:
            found.append(shape.id())
    return found


def _straight_through(mi, dr, shape, medium, rng, rays: int, samples: int) -> float:
    """Mean over random chords through ``shape`` of exp(-optical depth of ``medium``) in its thinnest channel."""
    bbox = shape.bbox()
    lo, hi = np.asarray(bbox.min, np.float64), np.asarray(bbox.max, np.float64)
    reach = float(np.linalg.norm(hi - lo)) + 1e-6
    d = rng.normal(size=(rays, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = lo + rng.random((rays, 3)) * (hi - lo) - 2.0 * reach * d
    alone = scene_of(mi, [shape])

    def first_hit(origin, direction):
        ray = mi.Ray3f(mi.Point3f(np.ascontiguousarray(origin.T, np.float32)),
                       mi.Vector3f(np.ascontiguousarray(direction.T, np.float32)))
        si = alone.ray_intersect(ray)
        return np.asarray(si.is_valid(), bool).reshape(-1), np.asarray(si.t, np.float64).reshape(-1)

    hit, t_in = first_hit(o, d)
    if not hit.any():
        return 0.0
    o, d, t_in = o[hit], d[hit], t_in[hit]
    entry = o + (t_in[:, None] + 1e-4 * reach) * d
    out, t_out = first_hit(entry, d)
    chord = np.where(out, t_out, 0.0)  # [n] length inside the shape
    frac = (np.arange(samples) + 0.5) / samples
    pts = entry[:, None, :] + chord[:, None, None] * frac[None, :, None] * d[:, None, :]  # [n, samples, 3]
    mei = dr.zeros(mi.MediumInteraction3f, pts.shape[0] * samples)
    mei.p = mi.Point3f(np.ascontiguousarray(pts.reshape(-1, 3).T, np.float32))
    _, _, sigma_t = medium.get_scattering_coefficients(mei)
    st = np.broadcast_to(np.asarray(sigma_t, np.float64).reshape(3, -1).T, (pts.shape[0] * samples, 3))
    depth = st.reshape(-1, samples, 3).mean(axis=1) * chord[:, None]  # [n, 3]
    return float(np.exp(-depth.min(axis=1)).mean())


_LANE_PLUGIN = "nasset_lane_directional"
_registered: set = set()


def register_lane_emitter(mi) -> str:
    """Register (once per variant) the per-path directional emitter; returns its plugin name."""
    if mi.variant() in _registered:
        return _LANE_PLUGIN
    import drjit as dr

    class LaneDirectional(mi.Emitter):
        """Unit-irradiance delta directional light; direction = table[ray time] (see module doc)."""

        def __init__(self, props) -> None:
            mi.Emitter.__init__(self, props)
            self.m_flags = mi.EmitterFlags.DeltaDirection | mi.EmitterFlags.Infinite
            self.table = mi.Float([0.0, 0.0, 1.0])  # flattened [K, 3] directions towards the light
            self.dist = 1e4

        def set_scene(self, scene) -> None:
            self.dist = 4.0 * max(float(dr.norm(scene.bbox().extents())), 1e-3)

        def sample_direction(self, it, sample, active=True):
            d = dr.gather(mi.Vector3f, self.table, mi.UInt32(it.time), active)
            ds = dr.zeros(mi.DirectionSample3f)
            ds.p = it.p + d * self.dist
            ds.n = -d
            ds.time = it.time
            ds.pdf = mi.Float(1.0)
            ds.delta = mi.Bool(True)
            ds.d = d
            ds.dist = mi.Float(self.dist)
            ds.emitter = mi.EmitterPtr(self)
            return ds, mi.Spectrum(1.0)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return mi.Spectrum(0.0)

        def eval(self, si, active=True):
            return mi.Spectrum(0.0)

        def sample_wavelengths(self, si, sample, active=True):
            return mi.Spectrum(1.0), mi.Spectrum(1.0)

        def bbox(self):
            return mi.ScalarBoundingBox3f()

        def traverse(self, callback) -> None:
            pass

        def parameters_changed(self, keys) -> None:
            pass

        def to_string(self) -> str:
            return "LaneDirectional[]"

    mi.register_emitter(_LANE_PLUGIN, lambda props: LaneDirectional(props))
    _registered.add(mi.variant())
    return _LANE_PLUGIN


def _frame_to_world(mi, z: np.ndarray, origin: np.ndarray | None = None, scale: float = 1.0):
    z = np.asarray(z, np.float64)
    z = z / max(float(np.linalg.norm(z)), 1e-12)
    up = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(up, z)
    x /= max(float(np.linalg.norm(x)), 1e-12)
    y = np.cross(z, x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x * scale, y * scale, z * scale
    if origin is not None:
        m[:3, 3] = origin
    return mi.ScalarTransform4f(m.tolist())


@dataclass
class IsolatedAsset:
    """The asset's shapes alone, plus a unit-irradiance distant light (see module docstring). ``center`` is in the
    scene's frame; ``origin``: where the shapes were moved from (:func:`move_to_origin`; default none), so that a point
    p of the scene is ``p - origin`` in the Mitsuba scenes here (:meth:`to_render`, :meth:`to_scene`)."""

    mi: object
    shapes: list
    center: np.ndarray
    radius: float
    angle_deg: float = 0.0
    max_depth: int = 24
    origin: np.ndarray | None = None
    geometry_scene: object = field(init=False)
    lit_scene: object = field(init=False)
    lane_scene: object = field(init=False, default=None)
    integrator: object = field(init=False)

    def __post_init__(self) -> None:
        mi = self.mi
        self.origin = np.zeros(3) if self.origin is None else np.asarray(self.origin, np.float64)
        self.geometry_scene = scene_of(mi, self.shapes)
        if self.angle_deg > 0:
            theta = math.radians(self.angle_deg)
            self._dist = 1000.0 * max(self.radius, 1e-3)
            self._light_radius = self._dist * math.sin(theta)
            radiance = 1.0 / max(math.pi * math.sin(theta) ** 2, 1e-30)
            light = {
                "type": "sphere",
                "to_world": self._sphere_to_world(np.array([0.0, 0.0, 1.0])),
                "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}},
            }
        else:
            light = {"type": "directional", "direction": [0.0, 0.0, -1.0], "irradiance": {"type": "rgb", "value": [1.0] * 3}}
        self.lit_scene = scene_of(mi, self.shapes, light=light)
        self._params = mi.traverse(self.lit_scene)
        if self.angle_deg == 0 and not mi.variant().startswith("scalar"):
            plugin = register_lane_emitter(mi)
            self.lane_scene = scene_of(mi, self.shapes, light={"type": plugin})
        has_media = any(has_medium(s) for s in self.shapes)
        kind = ("volpathmis" if chromatic_media(mi, self.shapes) else "volpath") if has_media else "path"
        self.integrator = mi.load_dict({"type": kind, "max_depth": int(self.max_depth), "rr_depth": 8})

    def to_render(self, p) -> np.ndarray:
        """Points [N, 3] of the scene's frame in the frame of the Mitsuba scenes here (float64)."""
        return np.asarray(p, np.float64) - self.origin

    def to_scene(self, p) -> np.ndarray:
        """Points [N, 3] Mitsuba returned here back in the scene's frame (float64)."""
        return np.asarray(p, np.float64) + self.origin

    def _sphere_to_world(self, wi: np.ndarray):
        pos = self.to_render(self.center) + self._dist * np.asarray(wi, np.float64)
        return self.mi.ScalarTransform4f().translate(pos.tolist()) @ self.mi.ScalarTransform4f().scale(self._light_radius)

    def set_light(self, wi) -> None:
        """Point the light so that it arrives from direction ``wi`` (unit, towards the light)."""
        wi = np.asarray(wi, np.float64)
        if self.angle_deg > 0:
            self._params["light.to_world"] = self._sphere_to_world(wi)
        else:
            self._params["light.to_world"] = _frame_to_world(self.mi, -wi)
        self._params.update()


    @property
    def per_path_lights(self) -> bool:
        """True when ``set_light_table`` + ray time can give every path its own light."""
        return self.lane_scene is not None

    def set_light_table(self, dirs: np.ndarray) -> None:
        """Directions [K, 3] (unit, towards the light) that ray time k selects in ``lane_scene``."""
        dirs = np.ascontiguousarray(np.asarray(dirs, np.float32).reshape(-1, 3))
        self.lane_scene.emitters()[0].table = self.mi.Float(dirs.ravel())


def bounding_sphere(geo: MeshGeometry | CurvesGeometry) -> tuple[np.ndarray, float]:
    """(centre [3], radius) of a sphere holding the geometry (curves: their points plus half their width)."""
    lo, hi = geo.bounds()
    c = 0.5 * (np.asarray(lo, np.float64) + np.asarray(hi, np.float64))
    r = float(np.linalg.norm(np.asarray(geo.points, np.float64) - c, axis=1).max())
    if isinstance(geo, CurvesGeometry):
        r += 0.5 * float(np.max(geo.widths))
    return c, max(r, 1e-6)
