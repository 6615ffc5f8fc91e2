"""Emitter ``nasset_cone``: the DistantLight with ``angle > 0`` of spec/renderer.md#lights, in Dr.Jit.

Uniform cone of half-angle t around ``direction`` (toward the light), radiance ``E / (pi sin^2 t)``
(``irradiance`` E at normal incidence), sampled uniformly in solid angle (pdf ``1 / (2 pi (1 - cos t))``).
Mitsuba has no emitter with these conventions.
"""

from __future__ import annotations

import math

import drjit as dr
import numpy as np

from nasset_sdk.errors import error

NAME = "nasset_cone"
#: distance of the sample point along a direction (shadow rays end there): far beyond any scene the
#: renderer accepts (spec/renderer.md#limits), still exact enough in float32 for the ray direction
FAR = 1e9
_REGISTERED: set[str] = set()


def register(mi) -> None:
    """Register ``nasset_cone`` for the active variant (idempotent)."""
    if mi.variant() in _REGISTERED:
        return

    class ConeLight(mi.Emitter):
        def __init__(self, props):
            super().__init__(props)
            a = np.asarray(props.get("direction", mi.ScalarVector3f(0, 0, 1)), np.float64).reshape(3)
            self.axis_np = a / max(np.linalg.norm(a), 1e-30)
            half = math.radians(0.5 * float(props.get("angle", 0.53)))
            if not 0.0 < half < 0.5 * math.pi:
                raise error("SCENE_UNSUPPORTED", f"nasset_cone: angle {2 * math.degrees(half)} outside (0, 180) degrees")
            self.cos_t = math.cos(half)
            e = np.asarray(props.get("irradiance", mi.ScalarColor3f(1.0)), np.float64).reshape(3)
            self.le = mi.Color3f(*(e / (math.pi * math.sin(half) ** 2)).tolist())
            self.pdf_value = 1.0 / (2.0 * math.pi * (1.0 - self.cos_t))
            self.frame = mi.Frame3f(mi.Vector3f(*self.axis_np.tolist()))
            self.m_flags = mi.EmitterFlags.Infinite

        def _inside(self, d):
            return dr.dot(d, self.frame.n) >= self.cos_t

        def sample_direction(self, it, sample, active=True):
            d = self.frame.to_world(mi.warp.square_to_uniform_cone(sample, self.cos_t))
            ds = dr.zeros(mi.DirectionSample3f)
            ds.d = d
            ds.p = it.p + d * FAR
            ds.n = -d
            ds.dist = FAR
            ds.pdf = mi.Float(self.pdf_value)
            ds.delta = False
            ds.emitter = mi.EmitterPtr(self)
            return ds, mi.Spectrum(self.le) / self.pdf_value

        def pdf_direction(self, it, ds, active=True):
            return dr.select(self._inside(ds.d), self.pdf_value, 0.0)

        def eval_direction(self, it, ds, active=True):
            return dr.select(self._inside(ds.d), mi.Spectrum(self.le), 0.0)

        def eval(self, si, active=True):
            return dr.select(self._inside(-si.wi), mi.Spectrum(self.le), 0.0)

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            return dr.zeros(mi.Ray3f), mi.Spectrum(0)

        def traverse(self, callback):
            pass

        def to_string(self):
            return f"NassetConeLight[cos_t={self.cos_t}]"

    mi.register_emitter(NAME, lambda props: ConeLight(props))
    _REGISTERED.add(mi.variant())
