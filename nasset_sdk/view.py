"""Preview an asset: its geometry shaded by its neural transport under one distant light (``nasset view``).

Conventions (object space, +Y up, unit vectors pointing away from the surface):

- ``light_dir`` is w_i, the direction from the asset towards a distant light of irradiance
  E = pi (measured perpendicular to w_i), so a white Lambertian surface facing it has radiance 1.
- ``view_dir`` is the direction from the asset's centre towards the camera. The camera is a pinhole
  (vertical field of view :data:`FOV_Y` degrees) looking at the centre of the bounds from far enough
  to frame them; w_o at a point is the unit vector from the point towards that eye.

Shading per kind (linear radiance, RGB):

- rna: L = E T(x, n, w_o, w_i), T the unshadowed branch unless a shadow ray from x towards w_i hits
  the asset's own triangles (then the shadowed branch). Fibers use the tangent as the frame, h = 0,
  and shadow rays against a tube mesh around the curves.
- neupress: L = E (S(x, w_o, w_i) + f_r(n, w_o, w_i) |n.w_i| V): subsurface network plus the analytic
  boundary reflection, V = 0 where self-shadowed (as the renderer does).
- rna and neupress go through the shared evaluator interface (``Evaluator.radiance``, spec/kinds/README.md).
- 8dna: the albedo network alpha(x, w_o) as colour (unitless; the light direction does not enter).
- ``fallback``: the bound UsdPreviewSurface diffuseColor rho as a Lambertian surface, L = rho max(n.w_i, 0)
  (fibers: rho sin(t, w_i), the Kajiya-Kay diffuse term), zero where self-shadowed.

Display transform (:func:`tonemap`): c = clamp(L 2^exposure, 0, 1), then the sRGB transfer curve,
rounded to 8 bits. No ambient term: surfaces facing away from the light are black unless the
asset's transport says otherwise.

Per vertex (default): the mesh (or fiber tubes) is drawn by pyvista with the colours above at its
vertices, interpolated across faces, lighting off. Per pixel: rays from the camera are cast at the
mesh with Embree and every hit is shaded; the image is written (or shown) as is. The triplane
channel view colour-maps channel K of the XY, YZ and ZX planes side by side (v up, u right).

pyvista is needed only to draw the per-vertex view (``pip install 'nasset-sdk[view]'``); it is
imported lazily. Without a display (no ``DISPLAY``) the picture goes to a PNG file off-screen.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from .curves import linear_segments
from .errors import UsageError
from .geometry import CurvesGeometry, MeshGeometry
from .images import write_png
from .kinds.query import Query

#: vertical field of view of the preview camera, degrees
FOV_Y = 30.0
#: irradiance of the preview light (perpendicular to w_i)
IRRADIANCE = float(np.pi)
DEFAULT_LIGHT = (0.5, 0.8, 0.6)
DEFAULT_VIEW = (0.3, 0.35, 1.0)
DEFAULT_SIZE = (800, 600)
#: sides of the tube mesh built around fibers (shadow rays and drawing)
TUBE_SIDES = 8
BACKGROUND = (0.12, 0.12, 0.14)


# ----------------------------------------------------------------------------------------
# small helpers


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    if not np.isfinite(v).all() or (n <= 1e-12).any():
        raise UsageError(f"direction {v.tolist()} must be finite and nonzero")
    return v / n


def tonemap(rgb, exposure: float = 0.0) -> np.ndarray:
    """Linear RGB -> uint8 sRGB: clamp(x 2^exposure, 0, 1), then the sRGB transfer curve. ``exposure`` in stops,
    finite and within +-64 (UsageError otherwise: NaN would turn every pixel into an undefined byte)."""
    if not (math.isfinite(float(exposure)) and abs(float(exposure)) <= 64.0):
        raise UsageError(f"exposure must be a finite number of stops within +-64, got {exposure}")
    x = np.clip(np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=1.0, neginf=0.0) * 2.0 ** float(exposure), 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


_VIRIDIS = np.array([
    [0.267, 0.005, 0.329], [0.283, 0.141, 0.458], [0.254, 0.265, 0.530], [0.207, 0.372, 0.553], [0.164, 0.471, 0.558],
    [0.128, 0.567, 0.551], [0.135, 0.659, 0.518], [0.267, 0.749, 0.441], [0.478, 0.821, 0.318],
    [0.741, 0.873, 0.150], [0.993, 0.906, 0.144],
])


def colormap(values, lo: float, hi: float) -> np.ndarray:
    """Scalar values -> uint8 RGB with a viridis ramp over [lo, hi]."""
    t = np.clip((np.asarray(values, np.float64) - lo) / max(hi - lo, 1e-30), 0.0, 1.0)
    t = np.nan_to_num(t)
    pos = t * (len(_VIRIDIS) - 1)
    i0 = np.minimum(pos.astype(np.int64), len(_VIRIDIS) - 2)
    f = (pos - i0)[..., None]
    rgb = _VIRIDIS[i0] * (1 - f) + _VIRIDIS[i0 + 1] * f
    return np.clip(np.round(rgb * 255), 0, 255).astype(np.uint8)


# ----------------------------------------------------------------------------------------
# camera


class Camera:
    """Pinhole camera looking at the centre of ``bounds`` from direction ``view_dir``."""

    def __init__(self, bounds, view_dir, size=DEFAULT_SIZE, fov_y: float = FOV_Y) -> None:
        lo, hi = (np.asarray(b, np.float64) for b in bounds)
        self.center = 0.5 * (lo + hi)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 1e-6)
        self.view_dir = _unit(view_dir)
        self.fov_y = float(fov_y)
        self.width, self.height = int(size[0]), int(size[1])
        if self.width < 1 or self.height < 1 or self.width * self.height > 16384 * 16384:
            raise UsageError(f"image size {size} must be positive (and at most 16384 x 16384)")
        half = np.radians(self.fov_y) / 2
        half_min = min(half, np.arctan(np.tan(half) * self.width / self.height))
        self.distance = radius / np.sin(half_min) * 1.05
        self.eye = self.center + self.view_dir * self.distance
        fwd = -self.view_dir
        up0 = np.array([0.0, 1.0, 0.0]) if abs(fwd[1]) < 0.99 else np.array([0.0, 0.0, -1.0])
        self.right = _unit(np.cross(fwd, up0))
        self.up = np.cross(self.right, fwd)
        self.forward = fwd

    def rays(self) -> tuple[np.ndarray, np.ndarray]:
        """Origins and unit directions [H W, 3] through pixel centres, row 0 at the top."""
        w, h = self.width, self.height
        t = np.tan(np.radians(self.fov_y) / 2)
        j, i = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
        sx = (2 * j / w - 1) * t * w / h
        sy = (1 - 2 * i / h) * t
        d = self.forward + sx[..., None] * self.right + sy[..., None] * self.up
        d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3)
        return np.broadcast_to(self.eye, d.shape).copy(), d


# ----------------------------------------------------------------------------------------
# geometry helpers


def vertex_normals(mesh: MeshGeometry) -> np.ndarray:
    """The mesh's authored normals, else area-weighted face normals summed at the vertices."""
    if mesh.normals is not None:
        return _safe_unit(np.asarray(mesh.normals, np.float64))
    p = np.asarray(mesh.points, np.float64)
    f = np.asarray(mesh.faces, np.int64)
    fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    vn = np.zeros_like(p)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    return _safe_unit(vn)


def _safe_unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    out = np.where(n > 1e-20, v / np.where(n > 1e-20, n, 1.0), 0.0)
    out[(n[:, 0] <= 1e-20)] = (0.0, 0.0, 1.0)
    return out


def curve_tangents(curves: CurvesGeometry) -> np.ndarray:
    """Unit tangent per curve point (central differences inside a curve, one-sided at its ends; ``np.gradient``
    along each curve, for all curves at once)."""
    p = np.asarray(curves.points, np.float64)
    c = np.asarray(curves.counts, np.int64)
    end = np.cumsum(c)
    first = np.zeros(len(p), bool)
    last = np.zeros(len(p), bool)
    first[(end - c)[c > 0]] = True
    last[(end - 1)[c > 0]] = True
    nxt = np.minimum(np.arange(len(p)) + 1, len(p) - 1)
    prv = np.maximum(np.arange(len(p)) - 1, 0)
    nxt[last] = np.arange(len(p))[last]  # one-sided at the ends (zero for a curve of one point)
    prv[first] = np.arange(len(p))[first]
    t = p[nxt] - p[prv]
    t[~first & ~last] *= 0.5
    return _safe_unit(t)


def tube_mesh(curves: CurvesGeometry, sides: int = TUBE_SIDES):
    """Triangles around each curve segment: (points [P sides, 3], faces [F, 3], owner [F, 2]).

    ``owner`` holds, for each triangle, the two curve points of its segment."""
    p = np.asarray(curves.points, np.float64)
    r = 0.5 * np.asarray(curves.widths, np.float64)
    t = curve_tangents(curves)
    a = np.where(np.abs(t[:, 1:2]) < 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    b1 = _safe_unit(np.cross(t, a))
    b2 = np.cross(t, b1)
    ang = 2 * np.pi * np.arange(sides) / sides
    ring = p[:, None] + r[:, None, None] * (np.cos(ang)[None, :, None] * b1[:, None] + np.sin(ang)[None, :, None] * b2[:, None])
    seg = linear_segments(curves.counts)[0]
    k = np.arange(sides)
    i0, i1 = seg[:, None] * sides + k, (seg[:, None] + 1) * sides + (k + 1) % sides  # [S, sides]
    j0, j1 = seg[:, None] * sides + (k + 1) % sides, (seg[:, None] + 1) * sides + k
    faces = np.stack([np.stack([i0, j0, i1], -1), np.stack([i0, i1, j1], -1)], 1).reshape(-1, 3)  # per segment: 2 x sides
    owner = np.repeat(np.stack([seg, seg + 1], 1), 2 * sides, axis=0)
    return ring.reshape(-1, 3), faces.astype(np.int64), owner.astype(np.int64)


class _Tracer:
    """Embree closest-hit queries over a triangle mesh (points [V,3], faces [F,3]); Embree reads the mesh in place
    (:mod:`nasset_sdk.embree`: no element-by-element copy, 5 s on a 20 000-strand groom's tubes)."""

    def __init__(self, points: np.ndarray, faces: np.ndarray) -> None:
        from .extras import require_extras

        require_extras("render", purpose="the per-pixel view (Embree ray casting)")
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh

        from .embree import attach_triangles, shared_buffers

        self.points, self.faces = shared_buffers(None, (np.asarray(points, np.float64), faces))
        self.scene = rtcore_scene.EmbreeScene()
        if not attach_triangles(self.scene, self.points, self.faces):
            TriangleMesh(self.scene, self.points[:-1], self.faces)

    def closest(self, o, d):
        """(t [N], prim [N] (-1 on a miss), u [N], v [N])."""
        n = len(o)
        if n == 0:
            return np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0)
        r = self.scene.run(np.ascontiguousarray(o, np.float32), np.ascontiguousarray(d, np.float32),
                           dists=np.full(n, 3.0e38, np.float32), output=1)
        prim = r["primID"].astype(np.int64)
        t = np.where(prim >= 0, r["tfar"].astype(np.float64), np.inf)
        return t, prim, r["u"].astype(np.float64), r["v"].astype(np.float64)

    def blocked(self, o, d, ignore, max_skips: int = 8) -> np.ndarray:
        """Whether rays o + t d (t > 0) hit a triangle other than those ``ignore(prim, rows)`` marks.

        Ignored hits are stepped over (the ray restarts just past them), at most ``max_skips`` times."""
        o = np.array(o, np.float64)
        d = np.asarray(d, np.float64)
        out = np.zeros(len(o), bool)
        rows = np.arange(len(o))
        scale = float(np.abs(self.points).max()) * 1e-6 + 1e-9
        for _ in range(max_skips + 1):
            if not len(rows):
                break
            t, prim, _, _ = self.closest(o[rows], d[rows])
            hit = prim >= 0
            skip = np.zeros(len(rows), bool)
            skip[hit] = ignore(prim[hit], rows[hit])
            out[rows[hit & ~skip]] = True
            rows, t = rows[skip], t[skip]
            o[rows] += d[rows] * (t[:, None] + scale)
        return out


def self_shadow_vertices(geo: MeshGeometry | CurvesGeometry, light_dir) -> np.ndarray:
    """Per vertex: is the ray from it towards ``light_dir`` blocked by the asset itself?

    Meshes: rays start at the vertex and skip the triangles that share it. Fibers: rays start on
    the centreline and skip the tube triangles of the segments that meet at the point."""
    wi = _unit(light_dir)
    if isinstance(geo, MeshGeometry):
        pts, faces = np.asarray(geo.points, np.float64), np.asarray(geo.faces, np.int64)
        owner = faces
    else:
        pts, faces, owner = tube_mesh(geo)
        pts_c = np.asarray(geo.points, np.float64)
    tracer = _Tracer(pts, faces)
    origins = np.asarray(geo.points, np.float64) if isinstance(geo, MeshGeometry) else pts_c
    ignore = lambda prim, rows: (owner[prim] == rows[:, None]).any(1)  # noqa: E731
    return tracer.blocked(origins, np.broadcast_to(wi, origins.shape), ignore)


# ----------------------------------------------------------------------------------------
# shading


def fallback_color(asset) -> np.ndarray:
    """diffuseColor of the UsdPreviewSurface bound to the geometry (0.5 grey if none is found)."""
    from pxr import UsdShade

    from .asset import GEOMETRY

    prim = asset.stage.GetPrimAtPath(GEOMETRY)
    if prim:
        material, _ = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()
        if material:
            shader = material.ComputeSurfaceSource()[0]
            if shader:
                inp = shader.GetInput("diffuseColor")
                value = inp.Get() if inp else None
                if value is not None:
                    c = np.asarray(value, np.float64).reshape(-1)
                    if c.shape == (3,) and np.isfinite(c).all():
                        return np.clip(c, 0.0, None)
    return np.array([0.5, 0.5, 0.5])


def shade_points(asset, x, frame, wo, light_dir, shadowed, *, evaluator=None, fallback: bool = False,
                 irradiance: float = IRRADIANCE) -> np.ndarray:
    """Linear RGB [N,3] at points x with frame (normal, or fiber tangent), w_o per point, one light.

    ``shadowed`` [N] bool: the asset blocks the light at that point (picks rna's branch; zeroes the
    fallback's Lambert term). See the module docstring for the per-kind formulas."""
    x = np.asarray(x, np.float32)
    n = len(x)
    frame = np.asarray(frame, np.float32)
    wo = np.asarray(wo, np.float32)
    wi = np.broadcast_to(_unit(light_dir).astype(np.float32), (n, 3)).copy()
    shadowed = np.asarray(shadowed, bool)
    if n == 0:
        return np.zeros((0, 3), np.float32)
    if fallback:
        cos = np.maximum((frame.astype(np.float64) * wi).sum(1), 0.0)
        if asset.variant == "fiber":  # Kajiya-Kay diffuse: sin of the angle to the tangent
            cos = np.sqrt(np.maximum(1.0 - (frame.astype(np.float64) * wi).sum(1) ** 2, 0.0))
        rgb = fallback_color(asset)[None] * (cos * ~shadowed)[:, None] * irradiance / np.pi
        return rgb.astype(np.float32)
    ev = evaluator if evaluator is not None else asset.evaluator()
    if asset.kind == "8dna":  # the distant-light radiance integrates the flow per point: too slow per pixel
        rgb = ev.albedo(x, wo)
    else:
        h = np.zeros(n) if asset.variant == "fiber" else None
        rgb = ev.radiance(Query(x, frame, wo, wi, shadowed=shadowed, h=h)) * irradiance
    rgb = np.nan_to_num(np.asarray(rgb, np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    return np.maximum(rgb, 0.0).astype(np.float32)


def shade_vertices(asset, light_dir=DEFAULT_LIGHT, view_dir=DEFAULT_VIEW, *, eye=None, fallback: bool = False,
                   evaluator=None, irradiance: float = IRRADIANCE) -> np.ndarray:
    """Linear RGB [V,3] at the asset's vertices (mesh points, or curve points for fibers).

    Frame: vertex normals (authored, else from the faces), or curve tangents with h = 0 for fibers.
    w_o: towards ``eye`` when given, else ``view_dir`` at every vertex (a distant viewer).
    Self-shadowing by a ray test against the asset's own triangles (tubes for fibers)."""
    geo = asset.geometry()
    x = np.asarray(geo.points, np.float64)
    frame = vertex_normals(geo) if isinstance(geo, MeshGeometry) else curve_tangents(geo)
    if eye is not None:
        wo = _safe_unit(np.asarray(eye, np.float64)[None] - x)
    else:
        wo = np.broadcast_to(_unit(view_dir), x.shape)
    shadowed = self_shadow_vertices(geo, light_dir)
    return shade_points(asset, x, frame, wo, light_dir, shadowed, evaluator=evaluator, fallback=fallback,
                        irradiance=irradiance)


def shade_pixels(asset, light_dir=DEFAULT_LIGHT, view_dir=DEFAULT_VIEW, size=DEFAULT_SIZE, *, fallback: bool = False,
                 evaluator=None, irradiance: float = IRRADIANCE) -> tuple[np.ndarray, np.ndarray]:
    """Ray-cast the mesh from the preview camera: (linear RGB [H, W, 3], hit mask [H, W]).

    Each hit is shaded with the interpolated vertex normal, w_o = -ray direction, and a shadow
    ray towards the light that skips the hit triangle."""
    geo = asset.geometry()
    if not isinstance(geo, MeshGeometry):
        raise UsageError("--per-pixel needs a surface (mesh) asset; fibers are drawn per vertex", file=str(asset.path))
    cam = Camera(geo.bounds(), view_dir, size)
    o, d = cam.rays()
    tracer = _Tracer(geo.points, geo.faces)
    t, prim, u, v = tracer.closest(o, d)
    hit = prim >= 0
    rgb = np.zeros((len(o), 3), np.float32)
    if hit.any():
        hp, pr = np.nonzero(hit)[0], prim[hit]
        faces = np.asarray(geo.faces, np.int64)[pr]
        bu, bv = u[hit][:, None], v[hit][:, None]
        x = o[hp] + d[hp] * t[hit][:, None]
        vn = vertex_normals(geo)
        n = _safe_unit((1 - bu - bv) * vn[faces[:, 0]] + bu * vn[faces[:, 1]] + bv * vn[faces[:, 2]])
        p = np.asarray(geo.points, np.float64)
        ng = _safe_unit(np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]]))
        wi = _unit(light_dir)
        eps = 1e-5 * float(np.linalg.norm(cam.center - cam.eye))
        origin = x + ng * np.sign((ng * wi).sum(1, keepdims=True) + 1e-30) * eps
        shadowed = tracer.blocked(origin, np.broadcast_to(wi, origin.shape), lambda pm, rows: pm == pr[rows])
        rgb[hp] = shade_points(asset, x, n, -d[hp], light_dir, shadowed, evaluator=evaluator, fallback=fallback,
                               irradiance=irradiance)
    return rgb.reshape(cam.height, cam.width, 3), hit.reshape(cam.height, cam.width)


def compose_pixels(rgb, mask, exposure: float = 0.0) -> np.ndarray:
    """Tone-mapped uint8 image, background colour where no ray hit."""
    img = tonemap(rgb, exposure)
    img[~np.asarray(mask, bool)] = np.round(np.asarray(BACKGROUND) * 255).astype(np.uint8)
    return img


# ----------------------------------------------------------------------------------------
# triplane channel


def triplane_channel(asset, channel: int) -> np.ndarray:
    """Channel ``channel`` of core/triplane as [3, R, R] float32 (planes XY, YZ, ZX; rows v, columns u)."""
    if asset.kind not in ("rna", "8dna"):
        raise UsageError(f"--channel needs a triplane (kinds rna, 8dna); this asset is {asset.kind!r}", file=str(asset.path))
    planes = np.asarray(asset.tensor("core", "triplane"), np.float32)
    c = planes.shape[-1]
    if not 0 <= int(channel) < c:
        raise UsageError(f"channel {channel} out of range: the triplane has {c} channels (0..{c - 1})", file=str(asset.path))
    return np.ascontiguousarray(planes[..., int(channel)])


def channel_image(planes: np.ndarray, *, min_size: int = 256, gap: int = 4) -> np.ndarray:
    """Three planes [3, R, R] -> one uint8 RGB image, XY | YZ | ZX left to right, one shared viridis scale.

    Each plane is shown with v growing upwards and scaled up by an integer factor to at least
    ``min_size`` pixels; ``gap`` background pixels separate the planes."""
    planes = np.asarray(planes, np.float64)
    k, r_v, r_u = planes.shape
    scale = max(1, -(-min_size // max(r_v, r_u)))
    lo, hi = float(np.nanmin(planes)), float(np.nanmax(planes))
    tiles = [np.repeat(np.repeat(colormap(p[::-1], lo, hi), scale, 0), scale, 1) for p in planes]
    bg = np.round(np.asarray(BACKGROUND) * 255).astype(np.uint8)
    h, w = r_v * scale, r_u * scale
    out = np.empty((h, k * w + (k - 1) * gap, 3), np.uint8)
    out[:] = bg
    for i, tile in enumerate(tiles):
        out[:, i * (w + gap):i * (w + gap) + w] = tile
    return out


# ----------------------------------------------------------------------------------------
# drawing (pyvista)


def _pyvista():
    try:
        import pyvista
    except ImportError:
        raise UsageError("the per-vertex view needs pyvista: pip install 'nasset-sdk[view]' (or use --per-pixel)") from None
    return pyvista


def _quiet_vtk() -> None:
    """Off-screen, VTK's X11 window class logs a warning when there is no X server; keep errors only."""
    try:
        from vtkmodules.vtkCommonCore import vtkLogger

        vtkLogger.SetStderrVerbosity(vtkLogger.VERBOSITY_ERROR)
    except (ImportError, AttributeError):
        pass


def _polydata(pv, geo, rgb8):
    if isinstance(geo, MeshGeometry):
        f = np.asarray(geo.faces, np.int64)
        poly = pv.PolyData(np.asarray(geo.points, np.float64), np.hstack([np.full((len(f), 1), 3), f]).ravel())
        poly.point_data["rgb"] = rgb8
        return poly
    lines, start = [], 0
    for c in np.asarray(geo.counts, np.int64):
        lines += [c, *range(start, start + c)]
        start += c
    poly = pv.PolyData(np.asarray(geo.points, np.float64), lines=np.asarray(lines, np.int64))
    poly.point_data["rgb"] = rgb8
    lo, hi = geo.bounds()
    radius = max(0.5 * float(np.median(geo.widths)), 2e-3 * float(np.linalg.norm(hi - lo)))
    return poly.tube(radius=radius, n_sides=TUBE_SIDES)


def draw_vertices(geo, rgb8: np.ndarray, cam: Camera, *, png=None, title: str = "nasset view"):
    """Draw the mesh / fiber tubes with per-vertex colours; PNG off-screen when ``png`` is given, else a window."""
    pv = _pyvista()
    if png is not None:
        _quiet_vtk()
    plotter = pv.Plotter(off_screen=png is not None, window_size=(cam.width, cam.height), title=title)
    plotter.set_background(BACKGROUND)
    plotter.add_mesh(_polydata(pv, geo, rgb8), scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
    plotter.camera.position = tuple(cam.eye)
    plotter.camera.focal_point = tuple(cam.center)
    plotter.camera.up = tuple(cam.up)
    plotter.camera.view_angle = cam.fov_y
    plotter.reset_camera_clipping_range()
    if png is not None:
        img = np.asarray(plotter.screenshot(None, return_img=True))[..., :3]
        plotter.close()
        return write_png(png, img)
    plotter.show()
    return None


def show_image(rgb8: np.ndarray, *, title: str = "nasset view") -> None:
    """Show an image in a pyvista window (2D view)."""
    pv = _pyvista()
    h, w, _ = rgb8.shape
    img = pv.ImageData(dimensions=(w, h, 1))
    img.point_data["rgb"] = np.ascontiguousarray(rgb8[::-1]).reshape(-1, 3)
    plotter = pv.Plotter(window_size=(min(w, 1600), min(h, 1000)), title=title)
    plotter.add_mesh(img, scalars="rgb", rgb=True, lighting=False, show_scalar_bar=False)
    plotter.view_xy()
    plotter.enable_image_style()
    plotter.show()


# ----------------------------------------------------------------------------------------
# CLI


def has_display() -> bool:
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def run(args) -> int:
    """CLI: nasset view ASSET [--light-dir X Y Z] [--view-dir X Y Z] [--png OUT] [--fallback] [--channel K] ..."""
    from .asset import Asset

    asset = Asset.open(args.file, load="required")
    light = _unit(args.light_dir)
    view = _unit(args.view_dir)
    size = tuple(args.size)
    png = args.png
    window = png is None and has_display()
    if png is None and not window:
        suffix = f".channel{args.channel}.png" if args.channel is not None else ".view.png"
        png = Path.cwd() / (Path(args.file).stem + suffix)
    title = f"nasset view: {Path(args.file).name}"
    if args.channel is not None:
        img = channel_image(triplane_channel(asset, args.channel))
        if window:
            show_image(img, title=title)
            return 0
    elif args.per_pixel:
        rgb, mask = shade_pixels(asset, light, view, size, fallback=args.fallback)
        img = compose_pixels(rgb, mask, args.exposure)
        if window:
            show_image(img, title=title)
            return 0
    else:
        geo = asset.geometry()
        cam = Camera(geo.bounds(), view, size)
        rgb = shade_vertices(asset, light, view, eye=cam.eye, fallback=args.fallback)
        if window:
            draw_vertices(geo, tonemap(rgb, args.exposure), cam, title=title)
            return 0
        draw_vertices(geo, tonemap(rgb, args.exposure), cam, png=png, title=title)
        print(f"wrote {png}")
        return 0
    write_png(png, img)
    print(f"wrote {png}")
    return 0
