"""Lights of spec/renderer.md#lights, each sampled on its own (NEE samples every light once).

Point, delta distant, sphere and rectangle lights are Mitsuba emitters (``point``,
``directional``, ``area`` on a ``sphere`` / ``rectangle`` shape) and are sampled and evaluated
through Mitsuba. Mitsuba has no cone-shaped distant light, and its ``envmap`` interpolates
bilinearly with another lat-long origin, so the cone distant light and the dome are implemented
here with the spec's exact conventions.

Interface (world space, numpy): ``sample(p, n, u) -> (wi, dist, le, pdf)`` with ``le`` the
radiance arriving along wi (for delta lights, irradiance and pdf 1), ``delta`` attribute;
infinite lights also have ``eval_dir(d)`` and ``pdf_dir(d)``; shape lights ``eval_hit`` via
Mitsuba (see integrator).
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.errors import SceneError

from .usdscene import Light


def _norm(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-30)


def v3(mi, a):
    a = np.ascontiguousarray(a, np.float32)
    return mi.Vector3f(a[:, 0], a[:, 1], a[:, 2])


def p3(mi, a):
    a = np.ascontiguousarray(a, np.float32)
    return mi.Point3f(a[:, 0], a[:, 1], a[:, 2])


def _col(arr, n):
    a = np.asarray(arr, np.float64)
    if a.ndim == 1:
        return np.broadcast_to(a, (n,)).copy()
    return np.broadcast_to(a.T, (n, a.shape[0])).copy()


class MitsubaLight:
    """A light backed by a Mitsuba emitter (point, directional, area sphere, rectangle, disk, cylinder)."""

    infinite = False

    def __init__(self, desc: Light, key: str, mi_dict: dict, delta: bool, has_shape: bool, area: float = 0.0) -> None:
        self.desc, self.key, self.mi_dict, self.delta, self.has_shape = desc, key, mi_dict, delta, has_shape
        self.area = area  # world area of a light surface (has_shape)
        self.emitter = None  # bound after mi.load_dict

    def sample(self, mi, p, n, u):
        m = len(p)
        it = mi.Interaction3f()
        it.p = p3(mi, p)
        it.n = v3(mi, n)
        it.t = mi.Float(np.zeros(m, np.float32))
        it.time = mi.Float(np.zeros(m, np.float32))
        uu = np.ascontiguousarray(u, np.float32)
        ds, w = self.emitter.sample_direction(it, mi.Point2f(uu[:, 0], uu[:, 1]), True)
        wi = _col(ds.d.numpy(), m)
        dist = _col(ds.dist.numpy(), m)
        pdf = _col(ds.pdf.numpy(), m)
        wv = _col(w.numpy(), m)
        if self.delta:
            return wi, dist, wv, np.ones(m)
        le = wv * pdf[:, None]
        ok = pdf > 0
        le[~ok] = 0.0
        if self.has_profile:  # the emission toward p leaves the sampled point along -wi
            le *= self.profile(-wi, _col(ds.n.numpy(), m))[:, None]
        return wi, dist, le, np.where(ok, pdf, 1.0)

    @property
    def has_profile(self) -> bool:
        """Whether the light surface's emission depends on its direction (:meth:`profile`)."""
        return self.has_shape and (self.desc.spread < np.pi or self.desc.shaping is not None)

    def profile(self, emitted, normal):
        """The factor [N] of the surface's radiance along unit directions ``emitted`` [N, 3] leaving points of normal
        ``normal`` [N, 3]: a RectLight's or DiskLight's spread (spec/renderer.md#lights), a SphereLight's spot cone
        against its prim's -Z (spec/renderer.md#spot-lights)."""
        f = np.ones(len(emitted))
        if self.desc.spread < np.pi:
            f = f * spread_factor((emitted * normal).sum(1), self.desc.spread)
        if self.desc.shaping is not None:
            axis = -_norm(self.desc.to_world[2, :3][None])[0]
            f = f * spot_falloff(emitted @ axis, *self.desc.shaping)
        return f


def spread_factor(cos_a, spread: float):
    """spec/renderer.md#lights: the factor [N] of a RectLight's or DiskLight's radiance at cos_a [N] from its emitting
    normal for nasset:spread ``spread`` < pi: (tan h - tan a)+ / (tan h - h), h = spread / 2 (3 / h^3 for h <= 0.05)."""
    h = 0.5 * spread
    c = np.clip(np.asarray(cos_a, np.float64), 1e-300, 1.0)
    scale = 3.0 / (h * h * h) if h <= 0.05 else 1.0 / (np.tan(h) - h)
    return np.where(np.asarray(cos_a) > 0.0, np.maximum(np.tan(h) - np.sqrt(1.0 - c * c) / c, 0.0) * scale, 0.0)


def spot_falloff(cos_theta, cone_deg: float, softness: float, profile: str):
    """spec/renderer.md#spot-lights: the factor of a point light's intensity at angle theta from its axis; ``linear``
    (in the angle, 1 inside the beam c (1 - softness), 0 outside the cone c) or ``smoothstep`` (Cycles' spot)."""
    ct = np.clip(np.asarray(cos_theta, np.float64), -1.0, 1.0)
    c = np.radians(cone_deg)
    if profile == "smoothstep":
        cc = np.cos(c)
        if softness <= 0.0:
            return np.where(ct > cc, 1.0, 0.0)
        x = np.clip((ct - cc) / max((1.0 - cc) * softness, 1e-300), 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)
    b = c * (1.0 - softness)
    th = np.arccos(ct)
    ramp = (c - th) / max(c - b, 1e-300)
    return np.where(th <= b, 1.0, np.where(th < c, ramp, 0.0))


class SpotLight(MitsubaLight):
    """A point light with a UsdLux.ShapingAPI cone: Mitsuba's point emitter, its samples scaled by :func:`spot_falloff`
    of the emitted direction against the prim's local -Z axis."""

    def __init__(self, desc: Light, key: str, mi_dict: dict) -> None:
        super().__init__(desc, key, mi_dict, delta=True, has_shape=False)
        self.axis = -_norm(desc.to_world[2, :3][None])[0]

    def sample(self, mi, p, n, u):
        wi, dist, le, pdf = super().sample(mi, p, n, u)
        f = spot_falloff(-(_norm(wi) @ self.axis), *self.desc.shaping)
        return wi, dist, le * f[:, None], pdf


class ConeDistantLight:
    """DistantLight with angle > 0: uniform cone of half-angle t around +Z, radiance E / (pi sin^2 t)."""

    infinite = True
    delta = False
    has_shape = False

    def __init__(self, desc: Light) -> None:
        self.desc = desc
        self.axis = _norm(desc.to_world[2, :3][None])[0]
        t = np.radians(0.5 * desc.angle)
        if t >= np.pi / 2:
            raise SceneError("SCENE_UNSUPPORTED", f"DistantLight angle {desc.angle} >= 180 degrees", prim=desc.prim)
        self.cos_t = np.cos(t)
        self.le = desc.radiance / (np.pi * np.sin(t) ** 2)
        self.pdf_value = 1.0 / (2.0 * np.pi * (1.0 - self.cos_t))
        a = self.axis
        h = np.array([0.0, 1.0, 0.0]) if abs(a[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        self.t = _norm(np.cross(h, a)[None])[0]
        self.b = np.cross(a, self.t)

    def sample(self, mi, p, n, u):
        m = len(p)
        c = 1.0 - u[:, 0] * (1.0 - self.cos_t)
        s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
        ph = 2.0 * np.pi * u[:, 1]
        wi = (s * np.cos(ph))[:, None] * self.t + (s * np.sin(ph))[:, None] * self.b + c[:, None] * self.axis
        return wi, np.full(m, np.inf), np.broadcast_to(self.le, (m, 3)).copy(), np.full(m, self.pdf_value)

    def inside(self, d):
        return d @ self.axis >= self.cos_t

    def eval_dir(self, d):
        return np.where(self.inside(d)[:, None], self.le, 0.0)

    def pdf_dir(self, d):
        return np.where(self.inside(d), self.pdf_value, 0.0)


def latlong_pmf(tex: np.ndarray) -> np.ndarray:
    """Texel sampling pmf [H*W] (row-major) of a lat-long image [H, W, 3]: luminance (plus 1e-3 of its
    mean, so that no texel is impossible) times sin theta at the texel's centre row, normalised."""
    h = tex.shape[0]
    lum = np.maximum(np.asarray(tex[..., :3], np.float64) @ np.array([0.2126, 0.7152, 0.0722]), 0.0)
    theta_c = (np.arange(h) + 0.5) / h * np.pi
    wgt = (lum + 1e-3 * max(lum.mean(), 1e-12)) * np.sin(theta_c)[:, None]
    return (wgt / wgt.sum()).ravel()


class DomeLight:
    """Constant or lat-long dome: u = 0.5 + atan2(d.x, -d.z)/2pi, v = acos(d.y)/pi, nearest texel."""

    infinite = True
    delta = False
    has_shape = False

    def __init__(self, desc: Light) -> None:
        self.desc = desc
        # the dome's orientation: the orthogonal polar factor of its linear part (scale is ignored)
        u, _, vt = np.linalg.svd(desc.to_world[:3, :3])
        self.m3 = u @ vt
        self.m3_inv = self.m3.T
        self.tex = desc.texture
        if self.tex is not None:
            h, w = self.tex.shape[:2]
            self.pmf = latlong_pmf(self.tex)
            self.cdf = np.cumsum(self.pmf)
            self.cdf[-1] = 1.0
            self.h, self.w = h, w

    def _local(self, d):
        return _norm(d @ self.m3_inv)

    def _uv(self, dl):
        u = 0.5 + np.arctan2(dl[:, 0], -dl[:, 2]) / (2.0 * np.pi)
        v = np.arccos(np.clip(dl[:, 1], -1.0, 1.0)) / np.pi
        return u, v

    def eval_dir(self, d):
        m = len(d)
        if self.tex is None:
            return np.broadcast_to(self.desc.radiance, (m, 3)).copy()
        u, v = self._uv(self._local(d))
        col = np.clip(np.floor(u * self.w).astype(np.int64), 0, self.w - 1)
        row = np.clip(np.floor(v * self.h).astype(np.int64), 0, self.h - 1)
        return self.tex[row, col] * self.desc.radiance

    def pdf_dir(self, d):
        if self.tex is None:
            return np.full(len(d), 1.0 / (4.0 * np.pi))
        dl = self._local(d)
        u, v = self._uv(dl)
        col = np.clip(np.floor(u * self.w).astype(np.int64), 0, self.w - 1)
        row = np.clip(np.floor(v * self.h).astype(np.int64), 0, self.h - 1)
        p_uv = self.pmf[row * self.w + col] * (self.w * self.h)
        sin_t = np.sqrt(np.maximum(0.0, 1.0 - dl[:, 1] ** 2))
        pdf_local = np.where(sin_t > 1e-12, p_uv / (2.0 * np.pi * np.pi * np.maximum(sin_t, 1e-12)), 0.0)
        return pdf_local * self._jacobian(d)

    def _jacobian(self, d):
        """d(omega_local)/d(omega_world) of the normalised linear map (1 for rotations)."""
        v = d @ self.m3_inv
        r = np.linalg.norm(v, axis=-1)
        return abs(np.linalg.det(self.m3_inv)) / np.maximum(r, 1e-30) ** 3

    def sample(self, mi, p, n, u):
        m = len(p)
        if self.tex is None:
            z = 1.0 - 2.0 * u[:, 0]
            s = np.sqrt(np.maximum(0.0, 1.0 - z * z))
            ph = 2.0 * np.pi * u[:, 1]
            wi = np.stack([s * np.cos(ph), s * np.sin(ph), z], 1)
            return wi, np.full(m, np.inf), np.broadcast_to(self.desc.radiance, (m, 3)).copy(), np.full(m, 1.0 / (4.0 * np.pi))
        # pick a texel, then a uniform (u, v) inside it; reuse u[:, 0] for the in-texel offset
        k = np.minimum(np.searchsorted(self.cdf, u[:, 0], side="right"), len(self.cdf) - 1)
        lo = np.where(k > 0, self.cdf[np.maximum(k - 1, 0)], 0.0)
        fu = np.clip((u[:, 0] - lo) / np.maximum(self.pmf[k], 1e-300), 0.0, 1.0 - 1e-7)
        row, col = k // self.w, k % self.w
        uu = (col + fu) / self.w
        vv = (row + np.clip(u[:, 1], 0.0, 1.0 - 1e-7)) / self.h
        phi = 2.0 * np.pi * (uu - 0.5)
        th = np.pi * vv
        dl = np.stack([np.sin(th) * np.sin(phi), np.cos(th), -np.sin(th) * np.cos(phi)], 1)
        wi = _norm(dl @ self.m3)
        return wi, np.full(m, np.inf), self.eval_dir(wi), self.pdf_dir(wi)


def _surface_light(d: Light, key: str, rad: np.ndarray, shape: dict, area: float) -> MitsubaLight | None:
    """A light surface: the Mitsuba ``shape`` with an area emitter of radiance ``rad``, per unit of its world ``area``
    when the light normalizes; None for a surface of zero area."""
    if area <= 0:
        return None
    le = rad / area if d.normalize else rad
    ent = {**shape, "emitter": {"type": "area", "radiance": {"type": "rgb", "value": le.tolist()}}}
    return MitsubaLight(d, key, ent, delta=False, has_shape=True, area=area)


def _planar_to_world(sx: float, sy: float, mw: np.ndarray):
    """Mitsuba ``to_world`` of a planar light of half extents ``sx``, ``sy`` (row-vector prim transform ``mw``): Mitsuba's
    rectangle and disk lie in local XY emitting toward +Z, USD's toward -Z, so local (x, y, z) -> (sx x, -sy y, -z) (a
    rotation by pi about X: handedness kept) before ``mw``."""
    import mitsuba as mi

    row = np.diag([sx, -sy, -1.0, 1.0]) @ mw  # row-vector: p_world = p_local_mitsuba @ local @ mw
    return mi.ScalarTransform4f(row.T.tolist())


def build_lights(desc_lights: list[Light], scene_path: str):
    """-> (lights, mitsuba dict entries)."""
    lights, entries = [], {}
    for i, d in enumerate(desc_lights):
        rad = np.asarray(d.radiance, np.float64)
        mw = d.to_world
        key = f"nasset_light_{i}"
        if d.type == "DistantLight":
            if d.angle > 0:
                lights.append(ConeDistantLight(d))
                continue
            toward = _norm(mw[2, :3][None])[0]
            ent = {"type": "directional", "direction": (-toward).tolist(), "irradiance": {"type": "rgb", "value": rad.tolist()}}
            lights.append(MitsubaLight(d, key, ent, delta=True, has_shape=False))
        elif d.type == "SphereLight":
            scale = float(np.cbrt(abs(np.linalg.det(mw[:3, :3]))))  # "world scale": cube root of the volume scale
            r = d.radius * scale
            c = mw[3, :3]
            if r <= 0:
                ent = {"type": "point", "position": c.tolist(), "intensity": {"type": "rgb", "value": rad.tolist()}}
                lights.append(MitsubaLight(d, key, ent, delta=True, has_shape=False) if d.shaping is None else SpotLight(d, key, ent))
            else:
                lights.append(_surface_light(d, key, rad, {"type": "sphere", "center": c.tolist(), "radius": r}, 4.0 * np.pi * r * r))
        elif d.type == "RectLight":
            ex, ey = mw[0, :3] * d.width, mw[1, :3] * d.height  # Mitsuba's rectangle is [-1, 1]^2
            shape = {"type": "rectangle", "to_world": _planar_to_world(0.5 * d.width, 0.5 * d.height, mw)}
            lights.append(_surface_light(d, key, rad, shape, float(np.linalg.norm(np.cross(ex, ey)))))
        elif d.type == "DiskLight":
            ex, ey = mw[0, :3] * d.radius, mw[1, :3] * d.radius  # Mitsuba's disk is the unit disk
            shape = {"type": "disk", "to_world": _planar_to_world(d.radius, d.radius, mw)}
            lights.append(_surface_light(d, key, rad, shape, float(np.pi * np.linalg.norm(np.cross(ex, ey)))))
        elif d.type == "CylinderLight":
            # the side of a round cylinder along the prim's local X (the reference renderer's reading: the mean scale
            # across the axis), emitting outward; Mitsuba's cylinder has no caps and its normals point outward
            axis = mw[0, :3]
            lw = d.length * float(np.linalg.norm(axis))
            rw = d.radius * float(np.linalg.norm(mw[1:3, :3], axis=1).mean())
            c, u = mw[3, :3], axis / max(float(np.linalg.norm(axis)), 1e-300)
            shape = {"type": "cylinder", "p0": (c - 0.5 * lw * u).tolist(), "p1": (c + 0.5 * lw * u).tolist(), "radius": rw}
            lights.append(_surface_light(d, key, rad, shape, 2.0 * np.pi * rw * lw if lw > 0 and rw > 0 else 0.0))
        elif d.type == "DomeLight":
            lights.append(DomeLight(d))
        else:
            raise SceneError("SCENE_UNSUPPORTED", f"light type {d.type}", file=scene_path, prim=d.prim)
        if lights and lights[-1] is None:  # a light surface of zero area emits nothing
            lights.pop()
            continue
        if isinstance(lights[-1], MitsubaLight):
            entries[key] = lights[-1].mi_dict
    return lights, entries
