"""Emitters of spec/renderer.md#lights in Dr.Jit, which Mitsuba has no emitter for:

- ``nasset_cone``: the DistantLight with ``angle > 0``. Uniform cone of half-angle t around
  ``direction`` (toward the light), radiance ``E / (pi sin^2 t)`` (``irradiance`` E at normal
  incidence), sampled uniformly in solid angle (pdf ``1 / (2 pi (1 - cos t))``).
- ``nasset_dome``: the DomeLight. Constant ``radiance``, or times a lat-long ``bitmap`` (a
  ``mi.Bitmap``, or ``filename``: an RGB image file, linear values) looked up
  in the dome's local frame with ``u = 0.5 + atan2(d.x, -d.z) / 2pi``, ``v = acos(d.y) / pi`` (row
  0 = +Y), nearest texel; ``to_world`` (Mitsuba's column-vector convention, orthogonal: the polar
  factor of the prim's M3, a mirror kept) maps local to world directions. Mitsuba's ``envmap``
  interpolates bilinearly and puts u = 0 elsewhere. Sampled by texel (pmf of luminance times
  sin theta, the second implementation's) then uniformly in the texel's (u, v): pdf
  ``pmf W H / (2 pi^2 sin theta)``; the constant dome uniformly on the sphere.

Sample points lie :data:`FAR` along the direction (shadow rays end there). ``camera_visible`` false (USD
``nasset:cameraVisibility``, spec/renderer.md#light-surfaces): :meth:`eval_camera`, what an escaping camera ray sees,
is black; every other ray sees the light.

- ``nasset_sky``: several of the two above as one emitter (``part_0``, ``part_1``, ... : cone and dome emitters).
  Mitsuba keeps one environment emitter per scene (the one an escaping ray sees), so a USD scene with a dome and a
  sun of non-zero angle, or two such suns, gets their sum: radiance ``sum_j L_j(d)``, a part chosen with
  probability ``w_j`` (its irradiance at normal incidence: a cone's ``E``, a dome's pi times its mean radiance over
  the sphere) and sampled as alone, pdf ``sum_j w_j pdf_j(d)`` (the one-sample mixture).

- ``nasset_spot``: a point light with ``UsdLux.ShapingAPI`` (spec/renderer.md#spot-lights): radiant intensity
  ``intensity`` times the falloff at the angle theta between the emitted direction and ``axis``: ``linear`` in theta
  (1 inside the beam ``cone (1 - softness)``, 0 outside ``cone``, degrees) or ``smoothstep`` (Cycles' spot).

- ``nasset_area``: the emission of a mesh (spec/renderer.md#sidedness, #mesh-lights), attached to its shape:
  ``front`` radiance on the side its triangles' winding faces, ``back`` radiance on the other (Mitsuba's
  ``area`` emits from the front alone). Sampled by the shape's area (pdf ``d^2 / (A |cos theta_l|)``).

- ``nasset_profiled``: a light surface whose emission depends on its direction, attached to its shape: ``radiance`` on
  the normal's side times a RectLight's or DiskLight's ``nasset:spread`` below pi (Cycles' soft-box profile
  ``(tan h - tan a)+ / (tan h - h)``, ``h = spread / 2``, ``3 / h^3`` for ``h <= 0.05``, ``a`` the angle from the normal;
  spec/renderer.md#lights), or a SphereLight's spot cone (:func:`spot_falloff` of the emitted direction against
  ``axis``; spec/renderer.md#spot-lights). Sampled by the shape, as Mitsuba's ``area``.
"""

from __future__ import annotations

import math
import os

import drjit as dr
import numpy as np

from nasset_mitsuba_renderer.lights import latlong_pmf
from nasset_sdk.errors import error

NAME = "nasset_cone"
DOME = "nasset_dome"
AREA = "nasset_area"
SKY = "nasset_sky"
SPOT = "nasset_spot"
PROFILED = "nasset_profiled"
SPOT_PROFILES = ("linear", "smoothstep")
#: distance of the sample point along a direction (shadow rays end there): far beyond any scene the
#: renderer accepts (spec/renderer.md#limits), still exact enough in float32 for the ray direction
FAR = 1e9
_REGISTERED: set[str] = set()


def sphere_mean(image: np.ndarray) -> np.ndarray:
    """Mean over the sphere [3] of a lat-long image [H, W, 3] (row r at polar angle pi (r + 0.5) / H, weights sin theta)."""
    h = image.shape[0]
    sin_t = np.sin(np.pi * (np.arange(h) + 0.5) / h)
    return (image.mean(axis=1) * sin_t[:, None]).sum(0) / max(sin_t.sum(), 1e-30)


def luminance(rgb) -> float:
    """Rec. 709 luminance of an RGB triple (negative channels count as 0)."""
    r, g, b = np.maximum(np.asarray(rgb, np.float64).reshape(3), 0.0)
    return float(0.2126 * r + 0.7152 * g + 0.0722 * b)


def light_power(lt, radius: float) -> float:
    """Emitted power (luminance) of a light as the second implementation's ``build_lights`` reads it (``lt``): the weight
    by which Mitsuba picks it for a light sample (pbrt's power light sampler). Lights at infinity send their
    irradiance through the cross-section of the scene's bounding sphere of ``radius``: a sun E pi r^2, a dome of mean
    radiance L 4 pi^2 r^2 L; a point light 4 pi I, a spot the same (it aims at the scene); a light surface pi L A (its
    emitted radiance, per area where it normalizes, times its world area)."""
    d = lt.desc
    if d.type == "DistantLight":
        return luminance(d.radiance) * math.pi * radius * radius
    if d.type == "DomeLight":
        tex = getattr(lt, "tex", None)
        mean = np.asarray(d.radiance, np.float64) * (1.0 if tex is None else sphere_mean(np.asarray(tex, np.float64)[..., :3]))
        return luminance(mean) * 4.0 * math.pi * math.pi * radius * radius
    if getattr(lt, "has_shape", False):
        return luminance(lt.mi_dict["emitter"]["radiance"]["value"]) * math.pi * float(lt.area)
    return luminance(d.radiance) * 4.0 * math.pi  # a point light; a spot as if it had no cone (it aims at the scene)


#: share of a light sample's emitter choice made by power; the rest is uniform over the emitters (a defensive mixture)
POWER_SHARE = 0.5


def selection_weights(powers: dict, share: float | None = None) -> dict:
    """``sampling_weight`` of each emitter {key: power}: ``share`` (:data:`POWER_SHARE`) of the choice by power, the rest
    uniform. Power alone can starve a light that is weak but aimed at what the camera sees (a spot on the subject
    beside bright lamps far off); the uniform part keeps every emitter's probability at least (1 - share) / n."""
    share = POWER_SHARE if share is None else share
    p = {k: v if math.isfinite(v) and v > 0 else 0.0 for k, v in powers.items()}
    total = sum(p.values())
    n = max(len(p), 1)
    if total <= 0:
        return {k: 1.0 for k in p}
    return {k: float((1.0 - share) / n + share * v / total) for k, v in p.items()}

def spot_falloff(cos_t, cone: float, softness: float, profile: str):
    """spec/renderer.md#spot-lights in Dr.Jit: the factor of a spot's emission at cos_t from its axis, ``cone`` its
    half-angle (radians), ``linear`` in the angle or ``smoothstep`` (Cycles')."""
    ct = dr.clip(cos_t, -1.0, 1.0)
    if profile == "smoothstep":
        cc = math.cos(cone)
        if softness <= 0.0:
            return dr.select(ct > cc, 1.0, 0.0)
        x = dr.clip((ct - cc) / max((1.0 - cc) * softness, 1e-30), 0.0, 1.0)
        return x * x * (3.0 - 2.0 * x)
    beam = cone * (1.0 - softness)
    th = dr.acos(ct)
    ramp = (cone - th) / max(cone - beam, 1e-30)
    return dr.select(th <= beam, 1.0, dr.select(th < cone, ramp, 0.0))


def register(mi) -> None:
    """Register ``nasset_cone``, ``nasset_dome``, ``nasset_area``, ``nasset_sky``, ``nasset_spot`` and
    ``nasset_profiled`` for the active variant (idempotent)."""
    if mi.variant() in _REGISTERED:
        return

    class AtInfinity(mi.Emitter):
        """What the lights at infinity share: Mitsuba's interface on their ``radiance(d)`` and ``pdf(d)`` (world
        directions), samples :data:`FAR` along the direction, and ``camera_visible``."""

        def far_sample(self, it, d, pdf):
            ds = dr.zeros(mi.DirectionSample3f)
            ds.d = d
            ds.p = it.p + d * FAR
            ds.n = -d
            ds.dist = FAR
            ds.pdf = pdf
            ds.delta = False
            ds.emitter = mi.EmitterPtr(self)
            return ds

        def pdf_direction(self, it, ds, active=True):
            return self.pdf(ds.d, active)

        def eval_direction(self, it, ds, active=True):
            return self.radiance(ds.d, active)

        def eval(self, si, active=True):
            return self.radiance(-si.wi, active)

        def eval_camera(self, si, active=True):
            return self.eval(si, active) if self.camera_visible else mi.Spectrum(0.0)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return dr.zeros(mi.Ray3f), mi.Spectrum(0)

        def traverse(self, callback):
            pass

    class ConeLight(AtInfinity):
        def __init__(self, props):
            super().__init__(props)
            a = np.asarray(props.get("direction", mi.ScalarVector3f(0, 0, 1)), np.float64).reshape(3)
            self.axis_np = a / max(np.linalg.norm(a), 1e-30)
            half = math.radians(0.5 * float(props.get("angle", 0.53)))
            if not 0.0 < half < 0.5 * math.pi:
                raise error("SCENE_UNSUPPORTED", f"nasset_cone: angle {2 * math.degrees(half)} outside (0, 180) degrees")
            self.cos_t = math.cos(half)
            e = np.asarray(props.get("irradiance", mi.ScalarColor3f(1.0)), np.float64).reshape(3)
            self.sky_weight = float(np.mean(e))  # irradiance at normal incidence (nasset_sky's choice of a part)
            self.camera_visible = bool(props.get("camera_visible", True))
            self.le = mi.Color3f(*(e / (math.pi * math.sin(half) ** 2)).tolist())
            self.pdf_value = 1.0 / (2.0 * math.pi * (1.0 - self.cos_t))
            self.frame = mi.Frame3f(mi.Vector3f(*self.axis_np.tolist()))
            self.m_flags = mi.EmitterFlags.Infinite

        def _inside(self, d):
            return dr.dot(d, self.frame.n) >= self.cos_t

        def radiance(self, d, active=True):
            return dr.select(active & self._inside(d), mi.Spectrum(self.le), 0.0)

        def pdf(self, d, active=True):
            return dr.select(active & self._inside(d), self.pdf_value, 0.0)

        def sample_direction(self, it, sample, active=True):
            d = self.frame.to_world(mi.warp.square_to_uniform_cone(sample, self.cos_t))
            return self.far_sample(it, d, mi.Float(self.pdf_value)), mi.Spectrum(self.le) / self.pdf_value

        def to_string(self):
            return f"NassetConeLight[cos_t={self.cos_t}]"

    class DomeLight(AtInfinity):
        def __init__(self, props):
            super().__init__(props)
            self.scale = np.asarray(props.get("radiance", mi.ScalarColor3f(1.0)), np.float64).reshape(3)
            m = np.asarray(props.get("to_world", mi.ScalarTransform4f()).matrix, np.float64).reshape(4, 4)[:3, :3]
            if not np.allclose(m @ m.T, np.eye(3), atol=1e-4):
                raise error("SCENE_INVALID", "nasset_dome: to_world is not a rotation or mirror (pass the polar factor of the dome's M3)")
            self.rotation = m.T  # [3, 3] row-vector R: world = local @ R (numpy, for load-time projections)
            self.rot = [[float(v) for v in row] for row in m.T]  # row-vector R: world_j = sum_i local_i R[i][j]
            self.le = mi.Color3f(*self.scale.tolist())
            bitmap = props.get("bitmap", None)
            filename = str(props.get("filename", ""))
            if bitmap is None and filename:
                path = str(mi.file_resolver().resolve(filename))
                if not os.path.isfile(path):
                    raise error("FILE_NOT_FOUND", "no such dome texture", file=str(path))
                try:
                    bitmap = mi.Bitmap(str(path)).convert(mi.Bitmap.PixelFormat.RGB, mi.Struct.Type.Float32, srgb_gamma=False)
                except Exception as exc:  # Mitsuba reports unreadable images as RuntimeError
                    raise error("FILE_UNREADABLE", f"dome texture: {str(exc).splitlines()[0][:200]}", file=str(path)) from None
            self.tex = None
            self.image = None  # [H, W, 3] float64 lat-long radiance before ``radiance`` scaling (numpy), or None
            if bitmap is not None:
                img = np.asarray(bitmap, np.float64)
                if img.ndim != 3 or img.shape[2] < 3 or not np.isfinite(img[..., :3]).all():
                    raise error("SCENE_INVALID", f"nasset_dome: bitmap of shape {img.shape} is not finite RGB")
                img = img[..., :3]
                self.image = img
                self.h, self.w = img.shape[:2]
                self.tex = mi.Float(np.ascontiguousarray(img * self.scale, np.float32).ravel())
                self.dist = mi.DiscreteDistribution(mi.Float(np.asarray(latlong_pmf(img), np.float32)))
            self.sky_weight = math.pi * float(np.mean(self.scale * (1.0 if self.image is None else sphere_mean(self.image))))
            self.camera_visible = bool(props.get("camera_visible", True))
            self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying

        def _to_local(self, d):
            r = self.rot
            return mi.Vector3f(*[r[j][0] * d.x + r[j][1] * d.y + r[j][2] * d.z for j in range(3)])

        def _to_world(self, d):
            r = self.rot
            return mi.Vector3f(*[r[0][j] * d.x + r[1][j] * d.y + r[2][j] * d.z for j in range(3)])

        def _texel(self, d):
            """(flat texel index, sin theta) of world directions d (nearest texel, clamped to the image)."""
            dl = dr.normalize(self._to_local(d))
            u = 0.5 + dr.atan2(dl.x, -dl.z) * (0.5 / math.pi)
            v = dr.acos(dr.clip(dl.y, -1.0, 1.0)) * (1.0 / math.pi)
            col = mi.UInt32(dr.clip(mi.Int32(dr.floor(u * self.w)), 0, self.w - 1))
            row = mi.UInt32(dr.clip(mi.Int32(dr.floor(v * self.h)), 0, self.h - 1))
            return row * self.w + col, dr.safe_sqrt(1.0 - dr.square(dr.clip(dl.y, -1.0, 1.0)))

        def radiance(self, d, active=True):
            if self.tex is None:
                return mi.Spectrum(self.le)
            idx, _ = self._texel(d)
            return mi.Spectrum(dr.gather(mi.Color3f, self.tex, idx, active))

        def pdf(self, d, active=True):
            if self.tex is None:
                return mi.Float(1.0 / (4.0 * math.pi))
            idx, sin_t = self._texel(d)
            p_uv = self.dist.eval_pmf_normalized(idx, active) * (self.w * self.h)
            return dr.select(sin_t > 0, p_uv / (2.0 * math.pi * math.pi * dr.select(sin_t > 0, sin_t, 1.0)), 0.0)

        def sample_direction(self, it, sample, active=True):
            if self.tex is None:
                d = mi.warp.square_to_uniform_sphere(sample)
                pdf = mi.Float(1.0 / (4.0 * math.pi))
                value = mi.Spectrum(self.le) * (4.0 * math.pi)
            else:
                idx, fu = self.dist.sample_reuse(sample.x, active)
                row, col = idx // self.w, idx % self.w
                uu = (mi.Float(col) + fu) / self.w
                vv = (mi.Float(row) + dr.minimum(sample.y, 1.0 - 1e-7)) / self.h
                sin_p, cos_p = dr.sincos(2.0 * math.pi * (uu - 0.5))
                sin_t, cos_t = dr.sincos(math.pi * vv)
                d = dr.normalize(self._to_world(mi.Vector3f(sin_t * sin_p, cos_t, -sin_t * cos_p)))
                p_uv = self.dist.eval_pmf_normalized(idx, active) * (self.w * self.h)
                ok = sin_t > 0
                pdf = dr.select(ok, p_uv / (2.0 * math.pi * math.pi * dr.select(ok, sin_t, 1.0)), 0.0)
                le = mi.Spectrum(dr.gather(mi.Color3f, self.tex, idx, active))
                value = dr.select(pdf > 0, le / dr.select(pdf > 0, pdf, 1.0), 0.0)
            return self.far_sample(it, d, pdf), value

        def to_string(self):
            return f"NassetDomeLight[{'constant' if self.tex is None else f'{self.w}x{self.h} lat-long'}]"

    class SkyLight(AtInfinity):
        """Cone and dome emitters (``part_<i>``) as one environment emitter: their sum, sampled as a mixture."""

        def __init__(self, props):
            super().__init__(props)
            keys = sorted((k for k in props.keys() if k.startswith("part_")), key=lambda k: int(k[5:]))
            self.parts = [props[k] for k in keys]
            if not self.parts or not all(hasattr(p, "sky_weight") for p in self.parts):
                raise error("SCENE_INVALID", f"{SKY}: its parts must be {NAME} or {DOME} emitters")
            w = np.maximum([p.sky_weight for p in self.parts], 0.0)
            w = w / w.sum() if w.sum() > 0 else np.full(len(w), 1.0 / len(w))
            self.weights = [float(v) for v in w]
            self.starts = [float(v) for v in np.concatenate([[0.0], np.cumsum(w)[:-1]])]
            self.camera_visible = all(p.camera_visible for p in self.parts)
            self.m_flags = mi.EmitterFlags.Infinite | mi.EmitterFlags.SpatiallyVarying

        def radiance(self, d, active=True):
            return sum((p.radiance(d, active) for p in self.parts[1:]), self.parts[0].radiance(d, active))

        def eval_camera(self, si, active=True):
            return sum((p.eval_camera(si, active) for p in self.parts[1:]), self.parts[0].eval_camera(si, active))

        def pdf(self, d, active=True):
            return sum((w * p.pdf(d, active) for w, p in zip(self.weights[1:], self.parts[1:], strict=True)),
                       self.weights[0] * self.parts[0].pdf(d, active))

        def sample_direction(self, it, sample, active=True):
            k, lo, w = mi.UInt32(0), mi.Float(0.0), mi.Float(self.weights[0])
            for j in range(1, len(self.parts)):  # the part whose interval [start, start + weight) holds sample.x
                past = sample.x >= self.starts[j]
                k, lo, w = dr.select(past, j, k), dr.select(past, self.starts[j], lo), dr.select(past, self.weights[j], w)
            reused = mi.Point2f(dr.minimum((sample.x - lo) / dr.select(w > 0, w, 1.0), 1.0 - 1e-7), sample.y)
            d = mi.Vector3f(0.0, 0.0, 1.0)
            for j, p in enumerate(self.parts):
                ds_j, _ = p.sample_direction(it, reused, active & (k == j))
                d = dr.select(k == j, ds_j.d, d)
            pdf = self.pdf(d, active)
            value = self.radiance(d, active)
            return self.far_sample(it, d, pdf), dr.select(pdf > 0, value / dr.select(pdf > 0, pdf, 1.0), 0.0)

        def to_string(self):
            return f"NassetSkyLight[{', '.join(p.to_string() for p in self.parts)}]"

    class SpotLight(mi.Emitter):
        """A point light whose intensity falls off around ``axis`` (delta position)."""

        def __init__(self, props):
            super().__init__(props)
            self.position = mi.Point3f(*np.asarray(props.get("position", mi.ScalarPoint3f(0.0)), np.float64).reshape(3).tolist())
            self.intensity = mi.Color3f(*np.asarray(props.get("intensity", mi.ScalarColor3f(1.0)), np.float64).reshape(3).tolist())
            a = np.asarray(props.get("axis", mi.ScalarVector3f(0, 0, -1)), np.float64).reshape(3)
            if not np.isfinite(a).all() or np.linalg.norm(a) < 1e-30:
                raise error("SCENE_INVALID", f"{SPOT}: axis {a.tolist()} is not a direction")
            self.axis = mi.Vector3f(*(a / np.linalg.norm(a)).tolist())
            self.cone = math.radians(float(props.get("cone", 90.0)))
            self.softness = min(max(float(props.get("softness", 0.0)), 0.0), 1.0)
            self.profile = str(props.get("profile", "linear"))
            if self.profile not in SPOT_PROFILES or not math.isfinite(self.cone):
                raise error("SCENE_INVALID", f"{SPOT}: profile {self.profile!r} / cone {self.cone} (profiles: {', '.join(SPOT_PROFILES)})")
            self.m_flags = mi.EmitterFlags.DeltaPosition

        def falloff(self, cos_t):
            return spot_falloff(cos_t, self.cone, self.softness, self.profile)

        def irradiance(self, d, dist):
            """I falloff / dist^2 at a point seen along the unit direction ``d`` toward the light, ``dist`` away."""
            inv2 = dr.select(dist > 0, dr.rcp(dr.square(dist)), 0.0)
            return mi.Spectrum(self.intensity) * self.falloff(dr.dot(-d, self.axis)) * inv2

        def sample_direction(self, it, sample, active=True):
            v = self.position - it.p
            dist = dr.norm(v)
            d = v / dr.select(dist > 0, dist, 1.0)
            ds = dr.zeros(mi.DirectionSample3f)
            ds.p, ds.d, ds.dist, ds.pdf, ds.delta = self.position, d, dist, mi.Float(1.0), True
            ds.emitter = mi.EmitterPtr(self)
            return ds, self.irradiance(d, dist)

        def pdf_direction(self, it, ds, active=True):
            return mi.Float(0.0)

        def eval_direction(self, it, ds, active=True):
            return self.irradiance(ds.d, ds.dist)

        def eval(self, si, active=True):
            return mi.Spectrum(0.0)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return dr.zeros(mi.Ray3f), mi.Spectrum(0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"NassetSpotLight[cone={math.degrees(self.cone)}, softness={self.softness}, {self.profile}]"

    class ShapeEmitter(mi.Emitter):
        """What the emitters attached to a shape share: the shape's samples (by area) and their pdf, and the radiance
        :meth:`leaving` a point of normal ``n`` (texture coordinates ``uv``) along the unit direction ``emitted``."""

        def leaving(self, emitted, n, uv, active):
            raise NotImplementedError

        def sample_direction(self, it, sample, active=True):
            ds = self.get_shape().sample_direction(it, sample, active)
            ok = active & (ds.pdf != 0.0)
            ds.emitter = mi.EmitterPtr(self)
            return ds, self.leaving(-ds.d, ds.n, ds.uv, ok) / dr.select(ok, ds.pdf, 1.0)

        def pdf_direction(self, it, ds, active=True):
            return self.get_shape().pdf_direction(it, ds, active)

        def eval_direction(self, it, ds, active=True):
            return self.leaving(-ds.d, ds.n, ds.uv, active)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return dr.zeros(mi.Ray3f), mi.Spectrum(0)

        def traverse(self, callback):
            pass

    class AreaLight(ShapeEmitter):
        """Emission of a mesh on both sides of its triangles: ``front`` (the winding's side) and ``back`` RGB. With a
        ``texture`` (a textures.ImageLookup, attached after loading) the sides flagged ``textured_front`` /
        ``textured_back`` emit max(texture, 0) at the point's texture coordinates instead (spec/renderer.md#textures:
        the constants are its mean, so Mitsuba's light selection by power is unchanged)."""

        def __init__(self, props):
            super().__init__(props)
            self.front, self.back = (mi.Color3f(*np.asarray(props.get(k, mi.ScalarColor3f(0.0)), np.float64).reshape(3).tolist())
                                     for k in ("front", "back"))
            self.textured = (bool(props.get("textured_front", False)), bool(props.get("textured_back", False)))
            self.texture = None
            self.m_flags = mi.EmitterFlags.Surface

        def _side(self, seen_from_front, uv, active):
            value = dr.select(seen_from_front, self.front, self.back)
            if self.texture is not None and any(self.textured):
                textured = dr.select(seen_from_front, mi.Bool(self.textured[0]), mi.Bool(self.textured[1]))
                value = dr.select(textured, dr.maximum(self.texture.eval(uv.x, uv.y, active & textured), 0.0), value)
            return dr.select(active, value, mi.Color3f(0))

        def eval(self, si, active=True):
            return self._side(mi.Frame3f.cos_theta(si.wi) > 0, si.uv, active)

        def leaving(self, emitted, n, uv, active):
            return self._side(dr.dot(emitted, n) > 0, uv, active)

        def to_string(self):
            return "NassetAreaLight"

    class ProfiledLight(ShapeEmitter):
        """``nasset_profiled`` (module docstring): Mitsuba's ``area`` emission times a profile of the emitted direction:
        a RectLight's or DiskLight's ``spread``, or a SphereLight's spot cone (``axis``, ``cone``, ``softness``,
        ``profile``)."""

        def __init__(self, props):
            super().__init__(props)
            self.radiance = mi.Color3f(*np.asarray(props.get("radiance", mi.ScalarColor3f(1.0)), np.float64).reshape(3).tolist())
            h = 0.5 * float(props.get("spread", math.pi))
            self.tan_h = math.tan(h) if h < 0.5 * math.pi else math.inf
            self.scale = 3.0 / h**3 if h <= 0.05 else 1.0 / (self.tan_h - h)
            a = np.asarray(props.get("axis", mi.ScalarVector3f(0, 0, 0)), np.float64).reshape(3)
            self.axis = mi.Vector3f(*(a / np.linalg.norm(a)).tolist()) if np.linalg.norm(a) > 0 else None
            self.cone = math.radians(float(props.get("cone", 180.0)))
            self.softness = min(max(float(props.get("softness", 0.0)), 0.0), 1.0)
            self.profile = str(props.get("profile", "linear"))
            self.m_flags = mi.EmitterFlags.Surface

        def leaving(self, emitted, n, uv, active):
            """Radiance along the unit direction ``emitted`` leaving a point of normal ``n`` (0 behind it)."""
            cos_a = dr.dot(emitted, n)
            f = mi.Float(1.0)
            if math.isfinite(self.tan_h):
                c = dr.maximum(cos_a, 1e-30)
                f = dr.maximum(self.tan_h - dr.safe_sqrt(1.0 - c * c) / c, 0.0) * self.scale
            if self.axis is not None:
                f = f * spot_falloff(dr.dot(emitted, self.axis), self.cone, self.softness, self.profile)
            return dr.select(active & (cos_a > 0), self.radiance * f, mi.Color3f(0))

        def eval(self, si, active=True):
            return self.leaving(si.to_world(si.wi), si.n, si.uv, active)

        def to_string(self):
            return f"NassetProfiledLight[tan_h={self.tan_h}, cone={math.degrees(self.cone)}]"

    mi.register_emitter(NAME, lambda props: ConeLight(props))
    mi.register_emitter(PROFILED, lambda props: ProfiledLight(props))
    mi.register_emitter(DOME, lambda props: DomeLight(props))
    mi.register_emitter(AREA, lambda props: AreaLight(props))
    mi.register_emitter(SKY, lambda props: SkyLight(props))
    mi.register_emitter(SPOT, lambda props: SpotLight(props))
    _REGISTERED.add(mi.variant())
