"""Per-hit UsdPreviewSurface inputs in Dr.Jit (spec/renderer.md#textures, #primvar-colors): image lookups and the
material formulas at each hit.

A texture is looked up at ``st`` (``(0, 0)`` the image's bottom-left corner, row 0 its top row): texel coordinates
``x = s W - 1/2``, ``y = (1 - t) H - 1/2``, bilinear between the four nearest texel centres, each axis wrapped by its
mode (``repeat``, ``mirror``, ``clamp``, ``black``: 0 outside the image), then ``texel * scale + bias``. The texels are
one flat ``Float`` gathered per corner (Dr.Jit's ``Texture2f`` has one wrap mode for both axes and no ``black``).
The st and colour of a hit are the barycentric sums of its triangle's corner values: the mesh's texcoords (``si.uv``,
and ``ds.uv`` of an emitter's position sample) and the mesh attribute :data:`COLOR_ATTRIBUTE`
(:func:`nasset_mitsuba_plugin.scene.usd_scene` writes both).
"""

from __future__ import annotations

import weakref

import drjit as dr
import numpy as np

from nasset_mitsuba_renderer import usdtextures as hit_inputs

#: the mesh attribute (per triangle corner) of primvar colours
COLOR_ATTRIBUTE = "vertex_nasset_color"
#: |s|, |t| beyond this are clamped before the wrap (float32 keeps texel precision); the clamp and black modes are
#: exact there, repeat and mirror are reduced to their period first
ST_BOUND = 1e4


def _reduce(mi, s, mode: str):
    """``s`` moved by whole periods of its wrap mode into [0, 1) (repeat) or [0, 2) (mirror); else clamped to [-2, 3]."""
    s = dr.clip(dr.select(dr.isfinite(s), s, 0.0), -ST_BOUND, ST_BOUND)
    if mode == "repeat":
        return s - dr.floor(s)
    if mode == "mirror":
        return s - 2.0 * dr.floor(0.5 * s)
    return dr.clip(s, -2.0, 3.0)


def _wrap(mi, i, n: int, mode: str):
    """(texel index in 0 .. n-1, valid) of integer texel coordinates ``i`` in [-2n - 2, 3n + 1] under a wrap mode."""
    if mode == "repeat":
        return dr.select(i < 0, i + n, dr.select(i >= n, i - n, i)), mi.Bool(True)
    if mode == "mirror":
        k = dr.select(i < 0, i + 2 * n, dr.select(i >= 2 * n, i - 2 * n, i))
        return dr.select(k < n, k, 2 * n - 1 - k), mi.Bool(True)
    inside = (i >= 0) & (i < n)
    return dr.clip(i, 0, n - 1), inside if mode == "black" else mi.Bool(True)


#: id of a texel array (``Texture.image``) -> (a weak reference to it, its texels on the device): textures that share
#: an array share one upload, for as long as the array lives
_UPLOADED: dict[int, tuple] = {}


def _device_texels(mi, image: np.ndarray):
    """``image`` [H, W, 3] as one flat device ``Float`` [H * W * 3], uploaded once per array and variant."""
    key = id(image)
    ref, texels = _UPLOADED.get(key, (None, None))
    if ref is None or ref() is not image or not isinstance(texels, mi.Float):
        texels = mi.Float(np.ascontiguousarray(image, np.float32).ravel())
        _UPLOADED[key] = (weakref.ref(image, lambda _, key=key: _UPLOADED.pop(key, None)), texels)
    return texels


class ImageLookup:
    """One texture (``nasset_mitsuba_renderer.usdtextures.Texture``) on the device."""

    def __init__(self, mi, tex) -> None:
        self.mi = mi
        self.h, self.w = (int(v) for v in tex.image.shape[:2])
        self.texels = _device_texels(mi, tex.image)  # [H * W * 3]
        self.wrap = tuple(tex.wrap)
        self.scale = mi.ScalarColor3f(*map(float, tex.scale))
        self.bias = mi.ScalarColor3f(*map(float, tex.bias))
        self.uv = None if tex.uv is None else np.asarray(tex.uv, np.float64)

    def eval(self, s, t, active=True):
        """``texel * scale + bias`` [Color3f] at texture coordinates (s, t)."""
        mi = self.mi
        if self.uv is not None:  # a UsdTransform2d: st -> A st + b
            (a, b, c), (d, e, f) = self.uv.tolist()
            s, t = a * s + b * t + c, d * s + e * t + f
        x = _reduce(mi, s, self.wrap[0]) * self.w - 0.5
        y = (1.0 - _reduce(mi, t, self.wrap[1])) * self.h - 0.5
        x0, y0 = dr.floor(x), dr.floor(y)
        fx, fy = x - x0, y - y0
        xi, yi = mi.Int32(x0), mi.Int32(y0)
        out = mi.Color3f(0.0)
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            row, row_ok = _wrap(mi, yi + dy, self.h, self.wrap[1])
            for dx, wx in ((0, 1.0 - fx), (1, fx)):
                col, col_ok = _wrap(mi, xi + dx, self.w, self.wrap[0])
                ok = active & row_ok & col_ok
                at = mi.UInt32(row * self.w + col) * 3
                texel = mi.Color3f(*(dr.gather(mi.Float, self.texels, at + k, ok) for k in range(3)))
                out += dr.select(ok, texel, 0.0) * (wx * wy)
        return out * self.scale + self.bias


class PerHitInputs:
    """A material's inputs per hit (``nasset_mitsuba_renderer.usdtextures.PerHit``): :meth:`material` gives kd, F0 and
    the GGX alpha at a hit by the formulas of spec/renderer.md#materials (colours, roughness and metallic clamped to
    [0, 1], alpha = max(r^2, 1e-3))."""

    def __init__(self, mi, hit) -> None:
        self.mi = mi
        self.textures = {name: ImageLookup(mi, tex) for name, tex in hit.textures.items() if name in hit_inputs.SHADING_INPUTS}
        self.diffuse = mi.ScalarColor3f(*np.clip(hit.diffuse, 0.0, 1.0).tolist())
        self.roughness = float(np.clip(hit.roughness, 0.0, 1.0))
        self.metallic = None if hit.metallic is None else float(np.clip(hit.metallic, 0.0, 1.0))
        self.specular = mi.ScalarColor3f(*np.clip(hit.specular, 0.0, 1.0).tolist())
        self.r0 = float(hit.r0)
        self.colored = hit.color is not None

    def material(self, si, active=True):
        """(kd, F0 [Color3f], alpha [Float]) at hit ``si`` of a mesh carrying the corner attributes."""
        mi = self.mi
        def at(name, constant):
            tex = self.textures.get(name)
            return constant if tex is None else dr.clip(tex.eval(si.uv.x, si.uv.y, active), 0.0, 1.0)

        if self.colored:
            c = dr.clip(mi.Color3f(si.shape.eval_attribute_3(COLOR_ATTRIBUTE, si, active)), 0.0, 1.0)
        else:
            c = mi.Color3f(at("diffuseColor", self.diffuse))
        r = at("roughness", mi.Color3f(self.roughness)).x
        alpha = dr.maximum(r * r, 1e-3)
        if self.metallic is None:
            return c, mi.Color3f(self.specular), alpha
        m = at("metallic", mi.Color3f(self.metallic)).x
        return c * (1.0 - m), (1.0 - m) * self.r0 + c * m, alpha


class Presence:
    """A cut-out material's presence at a hit (spec/renderer.md#cutouts): its opacity (the constant, or a texture's
    first colour component at the hit), clamped to [0, 1]; with a threshold > 0 the surface is there where the
    opacity reaches it, with threshold 0 with probability opacity (``u``: one uniform number per hit)."""

    def __init__(self, mi, opacity: float, threshold: float, texture=None) -> None:
        self.mi = mi
        self.opacity, self.threshold = float(np.clip(opacity, 0.0, 1.0)), float(np.clip(threshold, 0.0, 1.0))
        self.texture = None if texture is None else ImageLookup(mi, texture)

    def present(self, si, u, active=True):
        """[Bool] the surface is there at hit ``si``."""
        op = self.mi.Float(self.opacity)
        if self.texture is not None:
            op = dr.clip(self.texture.eval(si.uv.x, si.uv.y, active).x, 0.0, 1.0)
        return op >= self.threshold if self.threshold > 0 else u < op
