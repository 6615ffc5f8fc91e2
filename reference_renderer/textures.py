"""Image textures of UsdPreviewSurface inputs: ``UsdUVTexture`` read through ``UsdPrimvarReader_float2``.

Lookup (spec/renderer.md#textures): texture coordinates ``st`` [N, 2] with ``st = (0, 0)`` at the
image's bottom-left corner (USD's convention; image row 0 is the top), bilinear filtering between
texel centres, ``wrapS`` / ``wrapT`` in {repeat, mirror, clamp, black}, then ``rgb * scale + bias``.
Texels are linear radiometric values: an ``sRGB`` source colour space is decoded on load.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

WRAP_MODES = ("repeat", "mirror", "clamp", "black")


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB electro-optical transfer function (IEC 61966-2-1), element-wise on values in [0, 1]."""
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def transform2d(scale=(1.0, 1.0), rotation: float = 0.0, translation=(0.0, 0.0)) -> np.ndarray:
    """[2, 3] affine map of a UsdTransform2d: ``in * scale``, rotated counter-clockwise by ``rotation`` degrees,
    plus ``translation``."""
    c, s = np.cos(np.radians(rotation)), np.sin(np.radians(rotation))
    m = np.array([[c, -s], [s, c]]) @ np.diag(np.asarray(scale, np.float64)[:2])
    return np.concatenate([m, np.asarray(translation, np.float64)[:2, None]], 1)


def _wrap(i: np.ndarray, n: int, mode: str) -> tuple[np.ndarray, np.ndarray]:
    """Texel indices [N] (any integers) -> (indices inside 0 .. n-1, valid mask) under a wrap mode."""
    if mode == "repeat":
        return np.mod(i, n), np.ones(i.shape, bool)
    if mode == "mirror":
        k = np.mod(i, 2 * n)
        return np.where(k < n, k, 2 * n - 1 - k), np.ones(i.shape, bool)
    inside = (i >= 0) & (i < n)
    return np.clip(i, 0, n - 1), inside if mode == "black" else np.ones(i.shape, bool)


@dataclass
class ImageTexture:
    """A linear RGB image [H, W, 3] with its wrap modes and affine colour ``rgb * scale + bias``."""

    image: np.ndarray
    wrap_s: str = "repeat"
    wrap_t: str = "repeat"
    scale: np.ndarray = None  # [3]
    bias: np.ndarray = None  # [3]
    name: str = ""
    uv_matrix: np.ndarray | None = None  # [2, 3] affine st -> st of a UsdTransform2d (None: the identity)

    def __post_init__(self) -> None:
        self.image = np.ascontiguousarray(self.image, np.float64)
        self.scale = np.ones(3) if self.scale is None else np.asarray(self.scale, np.float64)
        self.bias = np.zeros(3) if self.bias is None else np.asarray(self.bias, np.float64)

    @property
    def mean(self) -> np.ndarray:
        """Mean colour [3] over the image (after scale and bias)."""
        return self.image.reshape(-1, 3).mean(0) * self.scale + self.bias

    def sample(self, st: np.ndarray) -> np.ndarray:
        """Bilinear lookup at texture coordinates ``st`` [N, 2] -> colours [N, 3]."""
        h, w = self.image.shape[:2]
        st = np.asarray(st, np.float64)
        if self.uv_matrix is not None:
            st = st @ self.uv_matrix[:, :2].T + self.uv_matrix[:, 2]
        st = np.nan_to_num(st, nan=0.0, posinf=0.0, neginf=0.0)
        st = np.clip(st, -1e6, 1e6)  # floor() below stays an exact integer
        x = st[:, 0] * w - 0.5
        y = (1.0 - st[:, 1]) * h - 0.5
        x0, y0 = np.floor(x), np.floor(y)
        fx, fy = (x - x0)[:, None], (y - y0)[:, None]
        x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
        out = np.zeros((len(st), 3))
        for dy, wy in ((0, 1.0 - fy), (1, fy)):
            yi, yok = _wrap(y0 + dy, h, self.wrap_t)
            for dx, wx in ((0, 1.0 - fx), (1, fx)):
                xi, xok = _wrap(x0 + dx, w, self.wrap_s)
                out += np.where((yok & xok)[:, None], self.image[yi, xi], 0.0) * (wx * wy)
        return out * self.scale + self.bias


@dataclass
class PrimvarColor:
    """A colour read from a mesh primvar (a ``UsdPrimvarReader_float3``, or an unbound mesh's varying
    ``displayColor``), interpolated over each triangle (spec/renderer.md#primvar-colors)."""

    varname: str
    fallback: np.ndarray  # [3] where a mesh lacks the primvar

    @property
    def mean(self) -> np.ndarray:
        return np.asarray(self.fallback, np.float64)


@dataclass
class TexturedMaterial:
    """A UsdPreviewSurface with textured inputs: kd, F0 and the GGX alpha per hit (spec/renderer.md#textures).

    ``diffuse`` ([3] or an rgb texture), ``roughness`` and ``metallic`` (floats, or one-channel textures whose value
    is their first colour component) are each a constant or a texture, read at one ``varname`` primvar.
    ``metallic`` None is the specular workflow (kd = c, F0 = ``specular``); else kd = c (1 - m) and
    F0 = (1 - m) ``f0_dielectric`` + m c. Colours, roughness and metallic are clamped to [0, 1]; alpha = max(r^2,
    ``min_alpha``).
    """

    varname: str
    diffuse: object  # [3] | ImageTexture
    roughness: object  # float | ImageTexture
    metallic: object  # float | ImageTexture | None (specular workflow)
    specular: np.ndarray  # [3] specularColor (specular workflow)
    f0_dielectric: float  # ((1 - ior) / (1 + ior))^2 (metallic workflow)
    min_alpha: float
    normal: ImageTexture | None = None  # tangent-space normal map (scale and bias applied), spec/renderer.md#normal-maps

    @property
    def reads_st(self) -> bool:
        """Some input is an image texture: lookups need the hits' texture coordinates."""
        return any(isinstance(v, ImageTexture) for v in (self.diffuse, self.roughness, self.metallic, self.normal))

    @property
    def sharpest_alpha(self) -> float:
        """The smallest GGX alpha any hit can read: over a roughness texture's texels, else the constant's."""
        r = self.roughness
        lo = float(np.clip((r.image[..., 0] * r.scale[0] + r.bias[0]).min(), 0.0, 1.0)) if isinstance(r, ImageTexture) \
            else float(np.clip(r, 0.0, 1.0))
        return max(lo * lo, self.min_alpha)

    @property
    def reads_colors(self) -> bool:
        """The diffuse colour comes from a primvar (:class:`PrimvarColor`): lookups need the hits' colours."""
        return isinstance(self.diffuse, PrimvarColor)

    @staticmethod
    def _at(v, st, channels: int):
        if isinstance(v, ImageTexture):
            out = np.clip(v.sample(st), 0.0, 1.0)
            return out if channels == 3 else out[:, 0]
        return np.broadcast_to(np.clip(np.asarray(v, np.float64), 0.0, 1.0), (len(st), channels) if channels == 3 else (len(st),))

    def lookup(self, st: np.ndarray, colors: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(kd [N, 3], F0 [N, 3], alpha [N]) at texture coordinates ``st`` [N, 2]; ``colors`` [N, 3] the hits'
        interpolated primvar colours when :attr:`reads_colors`."""
        c = np.clip(colors, 0.0, 1.0) if self.reads_colors else self._at(self.diffuse, st, 3)
        alpha = np.maximum(self._at(self.roughness, st, 1) ** 2, self.min_alpha)
        if self.metallic is None:
            return c * 1.0, np.tile(self.specular, (len(c), 1)), alpha
        m = self._at(self.metallic, st, 1)[:, None]
        return c * (1.0 - m), (1.0 - m) * self.f0_dielectric + c * m, alpha

    def constants(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(kd [3], F0 [3], alpha) with each texture replaced by its mean: the material's row for what needs one
        value per material (the lobe-sampling probability of untextured lookups, light paths)."""
        def mean(v):
            v = v.mean if isinstance(v, (ImageTexture, PrimvarColor)) else np.asarray(v, np.float64)
            return np.clip(v, 0.0, 1.0)

        c, r = mean(self.diffuse), float(np.ravel(mean(self.roughness))[0])
        alpha = max(r * r, self.min_alpha)
        if self.metallic is None:
            return c, np.asarray(self.specular, np.float64), alpha
        m = float(np.ravel(mean(self.metallic))[0])
        return c * (1.0 - m), (1.0 - m) * self.f0_dielectric + c * m, alpha


@dataclass
class Opacity:
    """UsdPreviewSurface ``opacity`` as presence (spec/renderer.md#cutouts): with ``opacityThreshold`` > 0 a
    surface point is there where its opacity is >= the threshold and absent elsewhere (a cut-out); with threshold 0
    it is there with probability ``opacity`` (what Cycles' alpha and Mitsuba's ``mask`` do)."""

    value: float  # opacity in [0, 1] where no texture gives it
    threshold: float  # opacityThreshold in [0, 1]
    texture: ImageTexture | None = None  # opacity = the texture's (first) channel at the hit
    varname: str = "st"

    def present(self, st: np.ndarray | None, u: np.ndarray) -> np.ndarray:
        """[N] bool: the surface is there at texture coordinates ``st`` [N, 2] (None without a texture); ``u`` [N]
        uniform numbers in [0, 1) draw the fractional case."""
        op = np.full(len(u), self.value) if self.texture is None else np.clip(self.texture.sample(st)[:, 0], 0.0, 1.0)
        return op >= self.threshold if self.threshold > 0 else u < op
