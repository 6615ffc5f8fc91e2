"""Near-field calibration of rna surface assets: where a renderer fetches a hit's light (spec/bake.md#near-field).

An rna asset's T is the response to a *distant* light. A renderer fetches the light of a hit x at the point
p = x + f (c - x), c the centre of the asset's encoding box (spec/kinds/rna.md#near-field-fetch); f = 0 is the
distant-light rule, which is too bright next to geometry that shadows the asset, because light that leaves a
translucent object at x entered it elsewhere. f is a property of the transport inside the asset, measured here:

1. ``views`` Mitsuba renders of the asset alone, each lit by a small sphere light at ``distance`` bounding-sphere
   radii from its centre, in a random direction on the camera's side, unclamped, in two independent halves. (Lights
   behind the asset were measured too, on the high-albedo pebble: seen from the far side the asset wants a fetch
   point beyond its centre, 0.75-1, seen from the light's side 0.4-0.9, and one f serves both poorly; the sum over
   random directions moved little with f and its estimate was unstable between the halves.)
2. the asset's prediction of the same pixels for each f of :data:`FETCH_GRID`: ``T(x, wo, wi_p) E_p`` with
   ``wi_p`` the direction from p to the light, ``E_p`` the sphere's irradiance at p and the branch chosen by the
   asset's own shadow ray from x along ``wi_p`` (the renderer's rule);
3. f is where the predicted energy over all pixels has the same ratio to Mitsuba's as the asset has under the
   distant lights of its own held-out views (:func:`fetch_fraction`): the fetch point removes the near-field error,
   not the network's own bias; f = 0 where the prediction at f = 0 is within MIN_NEAR_FIELD_ERROR of that. Where
   that ratio is known no better than TARGET_SE (a `tiny` bake's two held-out views: +-20-60 %), the target is 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .dataset import camera_rays, half_seeds, unit_sphere

#: the largest standard error (per channel) of the held-out distant-light energy ratio used as the target
TARGET_SE = 0.02
#: the distant-light rule is kept (f = 0) when, under the near lights, it is at most this much brighter than the target:
#: f from 32 views moved by +-0.06 between view sets, about +-0.8 % of energy on the pebble; on the built-in example
#: (1.3 % over) a measured f = 0.06 cost 0.4-1.2 points and 0.5 dB in its scene (spec/bake.md#near-field)
MIN_NEAR_FIELD_ERROR = 0.02
#: the fractions f at which the prediction is evaluated; f between grid points is interpolated linearly
FETCH_GRID = np.linspace(0.0, 1.0, 21)


@dataclass(frozen=True)
class NearFieldSettings:
    views: int = 8
    res: int = 48
    spp: int = 1024  # paths per pixel, in two halves of spp / 2
    distance: float = 3.0  # the light's centre from the asset's centre, in bounding-sphere radii
    light_radius: float = 0.05  # the sphere light's radius, in bounding-sphere radii
    camera_distance: float = 2.6  # in bounding-sphere radii (the dataset's)
    seed: int = 0


class SphereLight:
    """The isolated asset's shapes plus one small spherical area light of unit intensity (irradiance 1 / d^2 at a
    distance d from its centre, normal to the direction to it), moved with :meth:`place`."""

    def __init__(self, mi, iso, radius: float) -> None:
        from .scene import scene_of

        self.mi, self.iso, self.radius = mi, iso, float(radius)
        radiance = 1.0 / (math.pi * self.radius ** 2)  # a sphere's intensity is L pi r^2 in every direction
        light = {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": 1.0,
                 "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [radiance] * 3}}}
        self.scene = scene_of(mi, iso.shapes, light=light)
        self._params = mi.traverse(self.scene)

    def place(self, position) -> None:
        """Centre the light at ``position`` [3] (the scene's frame)."""
        mi = self.mi
        at = self.iso.to_render(np.asarray(position, np.float64)).tolist()
        self._params["light.to_world"] = mi.ScalarTransform4f().translate(at) @ mi.ScalarTransform4f().scale(self.radius)
        self._params.update()

    def irradiance(self, p: np.ndarray, position: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(unit directions [N,3] from points p [N,3] to the light's centre, irradiance [N] at p normal to them):
        ``pi L sin^2(alpha)`` with ``sin alpha = r / d`` (exact for a uniform sphere seen from outside it)."""
        v = np.asarray(position, np.float64)[None] - p
        d = np.maximum(np.linalg.norm(v, axis=1), 1e-12)
        s2 = np.minimum((self.radius / d) ** 2, 1.0)
        return v / d[:, None], s2 / (self.radius ** 2)


def render_near_views(renderer, center, radius: float, s: NearFieldSettings, progress=None) -> tuple[list[dict], SphereLight]:
    """Mitsuba's radiance of the asset alone under a sphere light near it, ``s.views`` views: per view the asset's
    pixels (o, d [M,3], hit x, normal n [M,3]), the light's centre ``light`` [3] and two independent unclamped
    halves ``rgb_a``, ``rgb_b`` [M,3]; and the light. Deterministic in ``s.seed``; ``progress()`` is called after
    each view."""
    light = SphereLight(renderer.mi, renderer.iso, s.light_radius * radius)
    rng = np.random.default_rng([s.seed, 2, 0])
    center = np.asarray(center, np.float64)
    half_fov = float(np.arcsin(min(1.0 / max(s.camera_distance, 1.0 + 1e-6), 0.999))) * 1.04
    out = []
    for _ in range(s.views):
        cam, to_light = unit_sphere(rng, 2, False)
        to_light = to_light if to_light @ cam >= 0 else -to_light  # on the camera's side (module docstring)
        o, d = camera_rays(center + s.camera_distance * radius * cam, center, half_fov, s.res)
        mask, x, n = renderer.hits(o, d)
        pix = np.nonzero(mask)[0]
        view = {"o": o[pix], "d": d[pix], "x": x[pix].astype(np.float64), "n": n[pix],
                "light": center + s.distance * radius * to_light}
        light.place(view["light"])
        for key, seed in zip(("rgb_a", "rgb_b"), half_seeds(int(rng.integers(0, 1 << 22))), strict=True):
            view[key] = (renderer.transport(view["o"], view["d"], max(1, s.spp // 2), seed=seed, clamp=0.0, scene=light.scene)
                         .astype(np.float64) if len(pix) else np.zeros((0, 3)))
        out.append(view)
        if progress is not None:
            progress()
    return out, light


def predicted_energy(views: list[dict], light: SphereLight, evaluate, visibility, center_obj: np.ndarray,
                     grid: np.ndarray = FETCH_GRID) -> np.ndarray:
    """The asset's predicted energy [F,3] (summed over every view's pixels) for each fetch fraction of ``grid``.
    ``evaluate(x, n, wo, wi) -> (unshadowed, shadowed)`` [M,3] is the asset's T; ``visibility(o, d, wi) -> [M] bool``
    says the asset does not block wi at the primary hit of (o, d) (the renderer's branch test from x);
    ``center_obj``: the encoding box's centre (the scene's frame is the asset's object space)."""
    out = np.zeros((len(grid), 3))
    for view in views:
        if not len(view["x"]):
            continue
        x = view["x"]
        wo = (-view["d"]).astype(np.float32)
        for k, f in enumerate(grid):
            wi, e = light.irradiance(x + f * (center_obj[None] - x), view["light"])
            wi32 = wi.astype(np.float32)
            tu, ts = evaluate(x.astype(np.float32), view["n"].astype(np.float32), wo, wi32)
            t = np.where(np.asarray(visibility(view["o"], view["d"], wi32), bool)[:, None], tu, ts)
            out[k] += (np.asarray(t, np.float64) * e[:, None]).sum(0)
    return out


def fetch_fraction(predicted: np.ndarray, reference: np.ndarray, target_ratio, grid: np.ndarray = FETCH_GRID,
                   min_error: float = MIN_NEAR_FIELD_ERROR) -> float:
    """f at which the ratio of predicted [F,3] to reference [3] energy (channels summed, each reference channel
    scaled by ``target_ratio`` [3], the asset's distant-light energy ratio) falls to 1, interpolated linearly on
    ``grid``. The ratio falls with f (a light outside the asset: p moves away from it); 0 when it exceeds 1 by no
    more than ``min_error`` at f = 0 (the distant-light rule is right within the measurement), 1 when it is still
    above 1 at f = 1, 0 when the reference holds no energy."""
    want = float(np.sum(np.asarray(reference, np.float64) * np.asarray(target_ratio, np.float64)))
    if not want > 0:
        return 0.0
    r = np.asarray(predicted, np.float64).sum(1) / want - 1.0
    if r[0] <= min_error:
        return 0.0
    below = np.nonzero(r <= 0)[0]
    if not len(below):
        return 1.0
    k = int(below[0])
    t = r[k - 1] / (r[k - 1] - r[k])  # r[k - 1] > 0 >= r[k]
    return float(grid[k - 1] + t * (grid[k] - grid[k - 1]))


def calibrate(renderer, center, radius: float, s: NearFieldSettings, evaluate, center_obj, target_ratio,
              progress=None) -> dict:
    """Render the views and fit f (module docstring). Returns {fetch, fetch_halves (f from each half alone), energy
    ratio at f = 0 and at the fitted f, the settings}; ``fetch`` is rounded to 3 decimals."""
    views, light = render_near_views(renderer, center, radius, s, progress)
    pred = predicted_energy(views, light, evaluate, renderer.visibility, np.asarray(center_obj, np.float64))
    ref = {k: np.sum([v[k].sum(0) for v in views], axis=0) for k in ("rgb_a", "rgb_b")}
    both = 0.5 * (ref["rgb_a"] + ref["rgb_b"])
    f = fetch_fraction(pred, both, target_ratio)
    at = np.array([np.interp(f, FETCH_GRID, pred[:, c]) for c in range(3)])
    return {
        "fetch": round(f, 3),
        "fetch_halves": [round(fetch_fraction(pred, ref[k], target_ratio), 3) for k in ("rgb_a", "rgb_b")],
        "target_ratio": [float(t) for t in target_ratio],
        "energy_ratio_f0": (pred[0] / np.maximum(both, 1e-30)).tolist(),
        "energy_ratio": (at / np.maximum(both, 1e-30)).tolist(),
        "pixels": int(sum(len(v["x"]) for v in views)),
        "settings": {**s.__dict__},
    }
