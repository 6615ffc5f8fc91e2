"""UsdLux lights: sampling, pdfs and emitted radiance (spec/renderer.md#lights).

Every light is sampled at every shading vertex (no light selection), so its MIS weight only
involves its own pdf and the BSDF's. Conventions (radiance L, irradiance E, all RGB and
multiplied by ``color * 2^exposure``):

* DistantLight: ``intensity`` is the irradiance E at normal incidence. ``angle`` (degrees, the
  full apex angle) > 0 makes a uniform cone of half-angle t with L = E / (pi sin^2 t), sampled
  uniformly in the cone; angle 0 is a delta light. Light arrives from the prim's +Z axis.
* SphereLight: radiance L = intensity from a sphere of ``radius`` (sampled by the cone it
  subtends); radius 0 (or ``treatAsPoint``) is a point light of radiant intensity I = intensity
  (E = I / d^2). With ``UsdLux.ShapingAPI`` a point light is a spot (spec/renderer.md#spot-lights):
  I(w) = intensity * falloff(theta), theta the angle between w and the prim's -Z axis, falloff 1 up
  to the beam angle cone * (1 - softness), linear in theta down to 0 at the cone angle (``nasset:shaping:falloff``
  ``smoothstep``: Cycles' smoothstep in cos(theta) instead).
* RectLight: radiance L = intensity from a ``width`` x ``height`` rectangle in the local XY
  plane, emitting toward local -Z only; sampled uniformly by area.
* DomeLight: radiance L(d) = intensity * texture(d) (or constant without a texture).
  Lat-long lookup in the dome's local frame: u = 0.5 + atan2(d.x, -d.z) / 2pi,
  v = acos(d.y) / pi (v = 0 is the top row); importance-sampled by luminance * sin(theta).
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.stage_rules import MAX_SPREAD, spread_profile

from .sampling import (
    INV_4PI,
    Distribution2D,
    barycentric,
    dot,
    frame,
    luminance,
    normalize,
    square_to_uniform_cone,
    square_to_uniform_disk,
    square_to_uniform_sphere,
    to_world,
)

INF = np.inf


class Light:
    """Interface. ``sample(p, u)`` -> (wi, dist, Li, pdf); delta lights return pdf 1."""

    delta = False
    infinite = False  # reached by escaping rays
    area = False  # has a shape that rays can hit
    camera_visible = True  # False: camera rays pass through the shape (``nasset:cameraVisibility``)
    opaque = False  # True: camera and continuation rays end on the shape (``nasset:opaqueSurface``, Mitsuba's emitters)
    prim = ""

    def sample(self, p, u):
        raise NotImplementedError

    def pdf(self, p, wi):
        return np.zeros(len(p))

    def le_escaped(self, d):
        """Radiance toward -d for rays that escape the scene along d."""
        return np.zeros((len(d), 3))

    def intersect(self, o, d):
        """(t [N], Le [N,3]) of the light's own shape; t = inf on a miss."""
        return np.full(len(o), INF), np.zeros((len(o), 3))

    def bounding_sphere(self):
        """(centre [3], radius) of a sphere holding the light's shape, or None (no shape, or not bounded)."""
        return None

    def power_is_zero(self) -> bool:
        return False


class DistantLight(Light):
    infinite = True

    def __init__(self, direction, irradiance, angle_deg: float, prim: str = "") -> None:
        self.w = normalize(np.asarray(direction, np.float64)[None])[0]  # toward the light
        self.E = np.asarray(irradiance, np.float64)
        self.prim = prim
        half = min(np.radians(max(float(angle_deg), 0.0)) * 0.5, np.pi)  # an apex angle >= 360 degrees: the whole sphere
        one_minus_cos = 2.0 * np.sin(0.5 * half) ** 2  # 1 - cos(half) without cancellation in narrow cones
        self.delta = half <= 0.0 or np.cos(half) >= 1.0  # a cone narrower than float64 directions resolve is a delta light
        if not self.delta:
            self.cos_max = float(np.cos(half))
            self.cone_pdf = 1.0 / (2.0 * np.pi * one_minus_cos)
            self.L = self.E / (np.pi * np.sin(half) ** 2)
            self.t, self.b = (a[0] for a in frame(self.w[None]))

    def power_is_zero(self):
        return not (self.E > 0).any()

    def sample(self, p, u):
        n = len(p)
        if self.delta:
            return np.broadcast_to(self.w, (n, 3)).copy(), np.full(n, INF), np.broadcast_to(self.E, (n, 3)).copy(), np.ones(n)
        loc = square_to_uniform_cone(u, self.cos_max)
        wi = loc[:, 0:1] * self.t + loc[:, 1:2] * self.b + loc[:, 2:3] * self.w
        pdf = np.full(n, self.cone_pdf)
        return wi, np.full(n, INF), np.broadcast_to(self.L, (n, 3)).copy(), pdf

    def pdf(self, p, wi):
        if self.delta:
            return np.zeros(len(wi))
        return np.where(wi @ self.w >= self.cos_max, self.cone_pdf, 0.0)

    def le_escaped(self, d):
        if self.delta:
            return np.zeros((len(d), 3))
        return np.where((d @ self.w >= self.cos_max)[:, None], self.L, 0.0)


#: ``nasset:shaping:falloff`` values: how a spot fades between the beam and the cone angle
SPOT_FALLOFFS = ("linear", "smoothstep")


def spot_falloff(cos_theta: np.ndarray, cone_deg: float, softness: float, kind: str = "linear") -> np.ndarray:
    """Spot falloff [N] at cos(theta) [N] from the spot axis, ``cone_deg`` the half-angle (degrees), 0 beyond it.

    ``linear`` (Mitsuba's ``spot``): 1 inside the beam angle ``cone * (1 - softness)``, then linear in theta to 0 at
    ``cone``. ``smoothstep`` (Cycles' spot): smoothstep((cos theta - cos cone) / ((1 - cos cone) softness)),
    a step at the cone when softness is 0.
    """
    cutoff = np.radians(np.clip(cone_deg, 0.0, 180.0))
    soft = float(np.clip(softness, 0.0, 1.0))
    cos_theta = np.clip(cos_theta, -1.0, 1.0)
    if kind == "smoothstep":
        span = (1.0 - np.cos(cutoff)) * soft
        x = (cos_theta - np.cos(cutoff)) / span if span > 0 else np.where(cos_theta > np.cos(cutoff), 1.0, 0.0)
        x = np.clip(x, 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)
    beam = cutoff * (1.0 - soft)
    theta = np.arccos(cos_theta)
    ramp = (cutoff - theta) / max(cutoff - beam, 1e-12)
    return np.where(theta <= beam, 1.0, np.where(theta < cutoff, np.clip(ramp, 0.0, 1.0), 0.0))


class PointLight(Light):
    delta = True

    def __init__(self, position, intensity, prim: str = "", *, axis=None, cone_deg: float = 180.0,
                 softness: float = 0.0, falloff: str = "linear") -> None:
        """``axis`` [3]: the direction the spot emits along (None: omnidirectional); ``cone_deg``, ``softness``,
        ``falloff`` as in :func:`spot_falloff`."""
        self.c = np.asarray(position, np.float64)
        self.I = np.asarray(intensity, np.float64)
        self.prim = prim
        self.axis = None if axis is None or cone_deg >= 180.0 else normalize(np.asarray(axis, np.float64)[None])[0]
        self.cone_deg, self.softness, self.falloff = float(cone_deg), float(softness), falloff

    def power_is_zero(self):
        return not (self.I > 0).any() or (self.axis is not None and self.cone_deg <= 0.0)

    def sample(self, p, u):
        v = self.c - p
        d2 = np.maximum(dot(v, v), 1e-300)
        dist = np.sqrt(d2)
        wi = v / dist[:, None]
        li = self.I / d2[:, None]
        if self.axis is not None:
            li = li * spot_falloff(-(wi @ self.axis), self.cone_deg, self.softness, self.falloff)[:, None]
        return wi, dist, li, np.ones(len(p))


class SphereLight(Light):
    area = True

    def __init__(self, center, radius: float, radiance, prim: str = "", *, axis=None, cone_deg: float = 180.0,
                 softness: float = 0.0, falloff: str = "linear") -> None:
        """``axis`` [3]: a spot's direction (UsdLux.ShapingAPI: each emitted direction's radiance times
        :func:`spot_falloff` of it; None: the same in every direction); ``cone_deg``, ``softness``, ``falloff`` as there."""
        self.c = np.asarray(center, np.float64)
        self.r = float(radius)
        self.L = np.asarray(radiance, np.float64)
        self.prim = prim
        self.axis = None if axis is None or cone_deg >= 180.0 else normalize(np.asarray(axis, np.float64)[None])[0]
        self.cone_deg, self.softness, self.falloff = float(cone_deg), float(softness), falloff

    def power_is_zero(self):
        return not (self.L > 0).any() or (self.axis is not None and self.cone_deg <= 0.0)

    def _radiance(self, emitted):
        """Radiance [N, 3] along the unit directions ``emitted`` [N, 3] leaving the sphere (a spot's cone)."""
        if self.axis is None:
            return np.broadcast_to(self.L, (len(emitted), 3))
        return spot_falloff(emitted @ self.axis, self.cone_deg, self.softness, self.falloff)[:, None] * self.L

    def _cone(self, p):
        v = self.c - p
        d2 = dot(v, v)
        dist = np.sqrt(d2)
        outside = d2 > self.r * self.r * (1 + 1e-9)
        sin2 = np.where(outside, self.r * self.r / np.where(outside, d2, 1.0), 1.0)
        cos_max = np.sqrt(np.maximum(0.0, 1.0 - sin2))
        axis = v / np.maximum(dist, 1e-300)[:, None]
        return axis, cos_max, outside

    def sample(self, p, u):
        axis, cos_max, outside = self._cone(p)
        t, b = frame(axis)
        wi = to_world(square_to_uniform_cone(u, cos_max), t, b, axis)
        pdf = np.where(outside, 1.0 / (2.0 * np.pi * np.maximum(1.0 - cos_max, 1e-300)), 0.0)
        tt = self._hit(p, wi)
        ok = outside & np.isfinite(tt)
        return wi, np.where(ok, tt, INF), np.where(ok[:, None], self._radiance(-wi), 0.0), np.where(ok, pdf, 0.0)

    def pdf(self, p, wi):
        axis, cos_max, outside = self._cone(p)
        inside_cone = dot(wi, axis) >= cos_max
        return np.where(outside & inside_cone, 1.0 / (2.0 * np.pi * np.maximum(1.0 - cos_max, 1e-300)), 0.0)

    def _hit(self, o, d):
        oc = o - self.c
        b = dot(oc, d)
        c = dot(oc, oc) - self.r * self.r
        disc = b * b - c
        sq = np.sqrt(np.maximum(disc, 0.0))
        t0 = -b - sq
        ok = (disc >= 0) & (c > 0) & (t0 > 0)  # outside, hitting the front (emitting) side
        return np.where(ok, t0, INF)

    def intersect(self, o, d):
        t = self._hit(o, d)
        return t, np.where(np.isfinite(t)[:, None], self._radiance(-d), 0.0)

    def bounding_sphere(self):
        return self.c, self.r


class _SurfaceLight(Light):
    """An analytic light surface sampled uniformly by area (``A``, radiance ``L``): subclasses give its points
    (``_point``), the cosine at the light toward ``-wi`` (``_cos``) and the ray hit (``_hit``)."""

    area = True
    spread = MAX_SPREAD  # nasset:spread of a RectLight or DiskLight (radians; pi: Lambertian)

    def power_is_zero(self):
        return not (self.L > 0).any() or self.A <= 0

    def _radiance(self, cos_l):
        """Radiance [N, 3] toward directions at cos_l [N] from the emitting normal (the spread's profile)."""
        if self.spread >= MAX_SPREAD:
            return np.broadcast_to(self.L, (len(cos_l), 3))
        return spread_profile(cos_l, self.spread)[:, None] * self.L

    def sample(self, p, u):
        q = self._point(u)
        v = q - p
        d2 = np.maximum(dot(v, v), 1e-300)
        dist = np.sqrt(d2)
        wi = v / dist[:, None]
        cos_l = self._cos(wi, q)
        ok = cos_l > 1e-9  # the emitting side faces p
        pdf = np.where(ok, d2 / (np.maximum(cos_l, 1e-300) * self.A), 0.0)
        return wi, dist, np.where(ok[:, None], self._radiance(cos_l), 0.0), pdf

    def pdf(self, p, wi):
        t = self._hit(p, wi)
        ok = np.isfinite(t)
        tt = np.where(ok, t, 0.0)
        cos_l = self._cos(wi, p + wi * tt[:, None])
        ok &= cos_l > 1e-9
        return np.where(ok, tt * tt / (np.maximum(cos_l, 1e-300) * self.A), 0.0)

    def intersect(self, o, d):
        t = self._hit(o, d)
        hit = np.isfinite(t)
        if self.spread >= MAX_SPREAD:
            return t, np.where(hit[:, None], self.L, 0.0)
        cos_l = self._cos(d, o + d * np.where(hit, t, 0.0)[:, None])
        return t, np.where(hit[:, None], self._radiance(cos_l), 0.0)


class CylinderLight(_SurfaceLight):
    """UsdLux.CylinderLight: the side of a cylinder (no caps) of world ``radius`` around the unit ``axis`` through
    ``center``, ``length`` long, emitting outward; sampled uniformly by area, hit only from outside."""

    def __init__(self, center, axis, radius: float, length: float, radiance, prim: str = "") -> None:
        self.c = np.asarray(center, np.float64)
        self.a = np.asarray(axis, np.float64) / max(float(np.linalg.norm(axis)), 1e-300)
        self.r, self.len = float(radius), float(length)
        self.u, self.v = frame(self.a[None])
        self.u, self.v = self.u[0], self.v[0]
        self.A = 2.0 * np.pi * self.r * self.len
        self.L = np.asarray(radiance, np.float64)
        self.prim = prim

    def bounding_sphere(self):
        return self.c, float(np.hypot(self.r, 0.5 * self.len))

    def _point(self, u):
        phi = 2.0 * np.pi * u[:, 1:2]
        return self.c + (u[:, 0:1] - 0.5) * self.len * self.a + self.r * (np.cos(phi) * self.u + np.sin(phi) * self.v)

    def _cos(self, wi, q):
        rel = q - self.c
        return -dot(wi, normalize(rel - (rel @ self.a)[:, None] * self.a))  # the outward normal at q

    def _hit(self, o, d):
        rel = o - self.c
        dp = d - (d @ self.a)[:, None] * self.a  # components across the axis
        rp = rel - (rel @ self.a)[:, None] * self.a
        qa, qb, qc = dot(dp, dp), dot(dp, rp), dot(rp, rp) - self.r * self.r
        disc = qb * qb - qa * qc
        t = (-qb - np.sqrt(np.maximum(disc, 0.0))) / np.maximum(qa, 1e-300)  # the near crossing: entering from outside
        along = (rel @ self.a) + t * (d @ self.a)
        ok = (qa > 1e-300) & (disc >= 0) & (qc > 0) & (t > 0) & (np.abs(along) <= 0.5 * self.len)
        return np.where(ok, t, INF)


class RectLight(_SurfaceLight):
    def __init__(self, center, axis_x, axis_y, radiance, prim: str = "", spread: float = MAX_SPREAD) -> None:
        """axis_x / axis_y: full edge vectors (width and height, world space, scale included); ``spread``: its
        nasset:spread (radians)."""
        self.spread = float(spread)
        self.c = np.asarray(center, np.float64)
        self.ex = np.asarray(axis_x, np.float64)
        self.ey = np.asarray(axis_y, np.float64)
        cr = np.cross(self.ex, self.ey)
        self.A = float(np.linalg.norm(cr))
        self.n = -cr / max(self.A, 1e-300)  # emission direction: local -Z
        self.L = np.asarray(radiance, np.float64)
        self.prim = prim

    def bounding_sphere(self):
        return self.c, 0.5 * float(max(np.linalg.norm(self.ex + self.ey), np.linalg.norm(self.ex - self.ey)))  # the corners

    def _point(self, u):
        """Points [N, 3] on the light, uniform by area, for samples ``u`` [N, 2]."""
        return self.c + (u[:, 0:1] - 0.5) * self.ex + (u[:, 1:2] - 0.5) * self.ey

    def _inside(self, q):
        """True where ``q`` [N, 3] (from the centre, in the light's plane) lies on the light: q = a e_x + b e_y with |a|,
        |b| <= 1/2. Edges that are not orthogonal (a sheared prim) take the dual basis, so that what rays hit is the
        parallelogram the light's samples cover."""
        exy = self.ex @ self.ey
        if abs(exy) > 1e-12 * np.sqrt((self.ex @ self.ex) * (self.ey @ self.ey)):
            g = np.array([[self.ex @ self.ex, exy], [exy, self.ey @ self.ey]])
            ab = np.stack([q @ self.ex, q @ self.ey], 1) @ np.linalg.inv(g)
            return (np.abs(ab[:, 0]) <= 0.5) & (np.abs(ab[:, 1]) <= 0.5)
        sx = (q @ self.ex) / (self.ex @ self.ex)
        sy = (q @ self.ey) / (self.ey @ self.ey)
        return (np.abs(sx) <= 0.5) & (np.abs(sy) <= 0.5)

    def _cos(self, wi, q):
        return -(wi @ self.n)

    def _hit(self, o, d):
        den = d @ self.n
        front = den < -1e-12  # ray travels against the emission direction
        t = np.where(front, ((self.c - o) @ self.n) / np.where(front, den, -1.0), INF)
        q = o + d * np.where(np.isfinite(t), t, 0.0)[:, None] - self.c
        ok = front & (t > 0) & self._inside(q)
        return np.where(ok, t, INF)


class DiskLight(RectLight):
    """UsdLux.DiskLight: the ellipse ``c + a e_x + b e_y``, a² + b² <= 1 (``axis_x`` / ``axis_y``: radius vectors, world
    space, scale included: a disk under non-uniform scale is an ellipse), emitting along -(e_x x e_y), sampled
    uniformly by area."""

    def __init__(self, center, axis_x, axis_y, radiance, prim: str = "", spread: float = MAX_SPREAD) -> None:
        super().__init__(center, axis_x, axis_y, radiance, prim, spread)
        self.A *= np.pi  # pi |e_x x e_y|
        g = np.array([[self.ex @ self.ex, self.ex @ self.ey], [self.ex @ self.ey, self.ey @ self.ey]])
        self.g_inv = np.linalg.inv(g) if abs(np.linalg.det(g)) > 1e-300 else np.zeros((2, 2))

    def bounding_sphere(self):
        # a e_x + b e_y with a^2 + b^2 <= 1 lies within sqrt(|e_x|^2 + |e_y|^2) of the centre (Cauchy-Schwarz)
        return self.c, float(np.sqrt(self.ex @ self.ex + self.ey @ self.ey))

    def _point(self, u):
        q = square_to_uniform_disk(u)  # uniform on the unit disk, so on its affine image
        return self.c + q[:, 0:1] * self.ex + q[:, 1:2] * self.ey

    def _inside(self, q):
        ab = np.stack([q @ self.ex, q @ self.ey], 1) @ self.g_inv  # q = a e_x + b e_y
        return (ab * ab).sum(1) <= 1.0


#: rays x light shapes tested at once by :func:`rays_near_shapes` (bounds its matrices' memory)
_CULL_CHUNK = 1 << 21


def rays_near_shapes(spheres: list, o: np.ndarray, d: np.ndarray, t_end: np.ndarray) -> list:
    """For each bounding sphere (centre [3], radius) of ``spheres`` (None: not bounded), the rows [k] of the rays ``o``,
    ``d`` [n,3] that may meet it before ``t_end`` [n] (every row where None): the rays whose line passes within the
    radius of the centre and whose segment (0, t_end) reaches the sphere's span along the ray. Conservative: a slack
    of 1e-9 of the squared coordinates covers the rounding of the expansion |c - o|^2 = |c|^2 - 2 o.c + |o|^2, which
    needs no [n, m, 3] array, so the exact test of the shape on these rows finds every hit."""
    n = len(o)
    out: list = [None] * len(spheres)
    idx = [i for i, sph in enumerate(spheres) if sph is not None]
    if not idx:
        return [np.arange(n)] * len(spheres)
    c = np.array([spheres[i][0] for i in idx], np.float64)
    r = np.array([spheres[i][1] for i in idx], np.float64)
    origin = c.mean(0)  # about the shapes' mean centre: the expansion keeps its precision far from the world's origin
    c = c - origin
    cc = np.einsum("mk,mk->m", c, c)
    parts: list = [[] for _ in idx]
    step = max(1, _CULL_CHUNK // len(idx))
    for s in range(0, n, step):
        oo, dd = o[s:s + step] - origin, d[s:s + step]
        o2, d2 = np.einsum("nk,nk->n", oo, oo), np.maximum(np.einsum("nk,nk->n", dd, dd), 1e-300)
        vv = cc[None] - 2.0 * (oo @ c.T) + o2[:, None]  # |c - o|^2
        vd = dd @ c.T - np.einsum("nk,nk->n", dd, oo)[:, None]  # (c - o).d
        slack = 1e-9 * (cc[None] + o2[:, None] + r * r)
        near = vv - vd * vd / d2[:, None] <= r * r + slack
        t_c, half = vd / d2[:, None], (r + np.sqrt(slack)) / np.sqrt(d2)[:, None]
        near &= (t_c + half > 0) & (t_c - half < t_end[s:s + step, None])
        rows, cols = np.nonzero(near)
        order = np.argsort(cols, kind="stable")
        rows, cols = rows[order] + s, cols[order]
        ends = np.cumsum(np.bincount(cols, minlength=len(idx)))
        for j, (a, b) in enumerate(zip(np.concatenate([[0], ends[:-1]]), ends, strict=True)):
            parts[j].append(rows[a:b])
    for j, i in enumerate(idx):
        out[i] = np.concatenate(parts[j])
    for i, sph in enumerate(spheres):
        if sph is None:
            out[i] = np.arange(n)
    return out


#: Emissive meshes with at most this many triangles are sampled as lights (``MeshLight.pdf`` tests each triangle).
MAX_MESH_LIGHT_TRIANGLES = 64


class MeshLight(Light):
    """An emissive mesh instance sampled as a light (spec/renderer.md#mesh-lights): uniform by area over its
    world triangles [T,3,3]; radiance ``L`` [3] from the front side (winding normal), ``L_back`` [3] from the back
    (0 for a one-sided prim, the back material's emission for a prim with ``nasset:backMaterial``, else ``L``).

    Its triangles are ordinary geometry (rays hit them through the scene's accelerator; ``area`` is
    False); ``pdf(p, wi)`` intersects them itself, so it is meant for small emitters
    (MAX_MESH_LIGHT_TRIANGLES)."""

    def __init__(self, triangles, radiance, *, back_radiance, instance: int, prim: str = "", textures=None) -> None:
        self.tri = np.asarray(triangles, np.float64)
        self.L = np.asarray(radiance, np.float64)
        self.L_back = np.asarray(back_radiance, np.float64)
        # (st corners [T,3,2], front texture, back texture): textured emission at the sampled points (None: constant)
        self.textures = textures
        self.instance, self.prim = int(instance), prim
        cr = np.cross(self.tri[:, 1] - self.tri[:, 0], self.tri[:, 2] - self.tri[:, 0])
        areas = 0.5 * np.linalg.norm(cr, axis=1)
        self.n = cr / np.maximum(2.0 * areas, 1e-300)[:, None]
        self.area_total = float(areas.sum())
        self.cdf = np.cumsum(areas) / max(self.area_total, 1e-300)
        # [3] area-weighted centroid of the triangles (where light selection measures its distance from)
        self.centroid = (areas @ self.tri.mean(1)) / max(self.area_total, 1e-300) if len(areas) else np.zeros(3)

    def power_is_zero(self):
        return not ((self.L > 0).any() or (self.L_back > 0).any()) or not self.area_total > 0

    def _emitted(self, n, wi):
        """(|cos| at the light toward -wi, 0 where that side emits nothing; [n, 3] radiance of that side)."""
        c = -dot(n, wi)
        back = c < 0
        lit = np.where(back, (self.L_back > 0).any(), (self.L > 0).any())
        return np.where(lit, np.abs(c), 0.0), np.where(back[:, None], self.L_back, self.L)

    def sample(self, p, u):
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0] * self.cdf[-1], side="right"), len(self.tri) - 1)
        lo = np.concatenate([[0.0], self.cdf[:-1]])[k]
        u0 = np.clip((u[:, 0] * self.cdf[-1] - lo) / np.maximum(self.cdf[k] - lo, 1e-300), 0.0, 1.0)  # reuse u[:, 0]
        su = np.sqrt(u0)
        b1, b2 = 1.0 - su, u[:, 1] * su
        t = self.tri[k]
        q = barycentric(t, b1, b2)
        v = q - p
        d2 = np.maximum(dot(v, v), 1e-300)
        dist = np.sqrt(d2)
        wi = v / dist[:, None]
        cos, L = self._emitted(self.n[k], wi)
        if self.textures is not None:  # the emitting side's texture at the sample's texture coordinates
            st_c, front, back = self.textures
            c = st_c[k]
            st = barycentric(c, b1, b2)
            is_back = dot(self.n[k], wi) > 0
            for side, tex in ((~is_back, front), (is_back, back)):
                if tex is not None and side.any():
                    L[side] = np.maximum(tex.sample(st[side]), 0.0)
        ok = cos > 0
        pdf = np.where(ok, d2 / (self.area_total * np.maximum(cos, 1e-300)), 0.0)
        return wi, dist, np.where(ok[:, None], L, 0.0), pdf

    def pdf(self, p, wi):
        """Solid-angle pdf of ``sample`` for direction wi from p: the nearest of its triangles along the ray."""
        t_best = np.full(len(p), INF)
        cos_best = np.zeros(len(p))
        for k in range(len(self.tri)):  # Moller-Trumbore, one triangle against every row
            v0, e1, e2 = self.tri[k, 0], self.tri[k, 1] - self.tri[k, 0], self.tri[k, 2] - self.tri[k, 0]
            pv = np.cross(wi, e2)
            det = pv @ e1
            ok = np.abs(det) > 1e-300
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            tv = p - v0
            bu = dot(tv, np.broadcast_to(pv, tv.shape) if pv.ndim == 1 else pv) * inv
            qv = np.cross(tv, e1)
            bv = (wi * qv).sum(1) * inv
            tt = (qv @ e2) * inv
            hit = ok & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (tt > 0) & (tt < t_best)
            t_best = np.where(hit, tt, t_best)
            cos_best = np.where(hit, self._emitted(np.broadcast_to(self.n[k], wi.shape), wi)[0], cos_best)
        ok = np.isfinite(t_best) & (cos_best > 0)
        return np.where(ok, t_best ** 2 / (self.area_total * np.maximum(cos_best, 1e-300)), 0.0)


class DomeLight(Light):
    infinite = True

    def __init__(self, scale, image=None, rotation=None, prim: str = "") -> None:
        """scale: RGB multiplier; image: [H, W, 3] lat-long radiance or None (constant);
        rotation: 3x3 local->world (row-vector convention: world = local @ rotation)."""
        self.scale = np.asarray(scale, np.float64)
        self.prim = prim
        self.R = np.eye(3) if rotation is None else np.asarray(rotation, np.float64)
        self.Rinv = np.linalg.inv(self.R)
        self.image = None if image is None else np.asarray(image, np.float64)
        self.mean_radiance = self.scale  # [3] over the sphere of directions
        if self.image is not None:
            h, w = self.image.shape[:2]
            sin_t = np.sin((np.arange(h) + 0.5) / h * np.pi)  # the rows' solid angle
            lum = np.maximum(luminance(self.image * self.scale), 0.0)
            self.dist = Distribution2D(lum * sin_t[:, None])
            self.mean_radiance = self.scale * (sin_t @ self.image.mean(1)) / max(float(sin_t.sum()), 1e-300)

    def power_is_zero(self):
        if not (self.scale > 0).any():
            return True
        return self.image is not None and not (self.image > 0).any()

    # direction <-> lat-long uv in the local frame
    @staticmethod
    def dir_to_uv(d):
        u = 0.5 + np.arctan2(np.ascontiguousarray(d[:, 0]), -d[:, 2]) / (2.0 * np.pi)  # contiguous: the same bits in every thread
        v = np.arccos(np.clip(d[:, 1], -1.0, 1.0)) / np.pi
        return np.stack([np.mod(u, 1.0), v], 1)

    @staticmethod
    def uv_to_dir(uv):
        phi = (uv[:, 0] - 0.5) * 2.0 * np.pi
        theta = uv[:, 1] * np.pi
        s = np.sin(theta)
        return np.stack([s * np.sin(phi), np.cos(theta), -s * np.cos(phi)], 1), s

    def _lookup(self, uv):
        h, w = self.image.shape[:2]
        c = np.clip((uv[:, 0] * w).astype(np.int64), 0, w - 1)
        r = np.clip((uv[:, 1] * h).astype(np.int64), 0, h - 1)
        return self.image[r, c] * self.scale

    def sample(self, p, u):
        n = len(p)
        if self.image is None:
            wi = square_to_uniform_sphere(u)
            return wi, np.full(n, INF), np.broadcast_to(self.scale, (n, 3)).copy(), np.full(n, INV_4PI)
        uv, pdf_uv = self.dist.sample(u)
        dl, s = self.uv_to_dir(uv)
        pdf = np.where(s > 0, pdf_uv / (2.0 * np.pi * np.pi * np.maximum(s, 1e-300)), 0.0)
        return dl @ self.R, np.full(n, INF), self._lookup(uv), pdf

    def pdf(self, p, wi):
        if self.image is None:
            return np.full(len(wi), INV_4PI)
        dl = wi @ self.Rinv
        uv = self.dir_to_uv(dl)
        s = np.sqrt(np.maximum(0.0, 1.0 - np.clip(dl[:, 1], -1, 1) ** 2))
        return np.where(s > 0, self.dist.pdf(uv) / (2.0 * np.pi * np.pi * np.maximum(s, 1e-300)), 0.0)

    def le_escaped(self, d):
        if self.image is None:
            return np.broadcast_to(self.scale, (len(d), 3)).copy()
        return self._lookup(self.dir_to_uv(d @ self.Rinv))
