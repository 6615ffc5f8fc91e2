"""``nasset convert-scene``: a Mitsuba 3 scene (camera, lights, plain shapes) -> a USD stage.

The stage is what the reference renderer reads (spec/renderer.md#scene-input): one
``UsdGeom.Camera``, ``UsdGeom.Mesh`` / ``UsdGeom.Sphere`` prims bound to ``UsdPreviewSurface``
materials, ``UsdLux`` lights, and one NeuralAsset prim per ``--replace`` asset file, which takes
the place of the shapes it was baked from. The mapping of every Mitsuba plugin, and what it
loses, is written down in spec/bake.md#scene-conversion; everything not converted exactly is a
warning (stderr, and the ``warnings`` list of ``--json``).

Parsing: the scene is loaded by Mitsuba itself (``mi.load_file(..., optimize=False)``), so
includes, ``<default>`` parameters, ``<ref>``s, transforms, named materials (``Au``) and mesh
files are resolved exactly as Mitsuba resolves them; values are then read with ``mi.traverse``
(world-space mesh vertices, ``to_world`` of analytic shapes, emitters and the sensor, BSDF
parameters) and plugin classes from the objects' ``str()``. Nothing is re-implemented from the
XML, so what is converted is what Mitsuba renders.

Conventions (Mitsuba -> USD, both right-handed, scene units kept, +Y declared up, 1 unit = 1 m):

* matrices are written in USD's row-vector form (``p_world = p_local M``, i.e. Mitsuba's
  ``to_world`` transposed);
* Mitsuba's camera looks down local +Z with local +X to the image's *left*; USD's looks down -Z
  with +X right: the camera gets ``diag(-1, 1, -1)`` applied in its local frame;
* ``directional``: ``to_world`` +Z is the direction light travels; a DistantLight's +Z points
  toward the light, so +Z := -direction; ``intensity`` = irradiance, ``angle`` = 0 (delta);
* ``rectangle`` area lights emit toward local +Z; a RectLight toward -Z: rotated 180 deg about X,
  ``width`` = ``height`` = 2 (Mitsuba's rectangle spans [-1, 1]^2);
* ``envmap``: Mitsuba looks up ``u = atan2(d.x, -d.z) / 2pi``, the renderer
  ``u = 0.5 + atan2(d.x, -d.z) / 2pi`` (spec/renderer.md#lights): the dome is rotated 180 deg about
  its local +Y before ``to_world``; the texture Mitsuba loaded is written as OpenEXR next to the
  output; ``scale`` becomes ``intensity``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from nasset_sdk.errors import UsageError, error, path_arg
from nasset_sdk.safeopen import trust

from . import analytic
from .scene import (
    BOX_TOLERANCE,
    bounds_offset,
    camera_medium,
    hides_emitters,
    image_integrator,
    integrator_depths,
    load_scene,
    no_such_shape,
    refuse_emitter,
    shapegroup_children,
)
from .sidedness import sampled_normal, turned_faces

#: Mitsuba shape classes whose vertices ``mi.traverse`` exposes in world space.
MESH_CLASSES = ("PLYMesh", "OBJMesh", "SerializedMesh", "Cube", "Mesh")
#: how far behind its light an emitter's own surface is written, in units of the shape's size (a sphere: the fraction
#: of its radius it is shrunk by): far beyond the renderers' float32 intersection error, invisible in an image
LIGHT_SURFACE_SET_BACK = 1e-3
#: Mitsuba's uv at a triangle's corners on a mesh without texture coordinates: its barycentric coordinates (b1, b2)
BARYCENTRIC_UV = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
#: an envmap is written at up to this many times its resolution (resampled with Mitsuba's own lookup), as
#: long as the written map stays within ENVMAP_MAX_PIXELS
ENVMAP_UPSAMPLE = 8
ENVMAP_MAX_PIXELS = 1 << 22
#: the lat-long size a sunsky's sky is resampled at (times ENVMAP_UPSAMPLE): smooth, apart from its horizon
SUNSKY_HW = (64, 128)
#: latitude rings of the mesh written for a textured Mitsuba ``sphere`` (twice as many longitude segments)
SPHERE_RINGS = 48
#: focal length (mm) of the written camera; the apertures carry the field of view
FOCAL_LENGTH = 0.5  # 50 mm in USD's lens unit, tenths of a scene unit (the stage's metersPerUnit is 1)

_FLIP_CAMERA = np.diag([-1.0, 1.0, -1.0, 1.0])  # Mitsuba camera local -> USD camera local
_FLIP_RECT = np.diag([1.0, -1.0, -1.0, 1.0])  # rotate 180 deg about X: RectLight -Z -> rectangle +Z
_FLIP_DOME = np.diag([-1.0, 1.0, -1.0, 1.0])  # rotate 180 deg about Y: lat-long u shift by 1/2


@dataclass
class ConvertResult:
    """What ``convert_scene`` wrote: the file, its prims (path -> what it came from) and the warnings."""

    output: Path
    prims: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    replaced: dict = field(default_factory=dict)  # prim path -> {"asset": relative path, "shapes": [...]}
    resolution: tuple = (0, 0)
    integrator: dict = field(default_factory=dict)
    textures: list = field(default_factory=list)
    usd_checks: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {
            "ok": True, "output": str(self.output), "prims": self.prims, "replaced": self.replaced,
            "resolution": list(self.resolution), "integrator": self.integrator, "textures": self.textures,
            "warnings": list(self.warnings), "usd_checks": self.usd_checks,
        }


# -- small helpers ------------------------------------------------------------------------------
def _np(v) -> np.ndarray:
    return np.asarray(v, np.float64)


def _matrix(transform) -> np.ndarray:
    """Mitsuba Transform4f (scalar or JIT) -> 4x4 float64 column-vector matrix."""
    m = np.asarray(transform.matrix, np.float64)
    return m.reshape(4, 4, -1)[:, :, 0] if m.size > 16 else m.reshape(4, 4)


def _row(m_col: np.ndarray) -> np.ndarray:
    """Column-vector (Mitsuba) -> row-vector (USD) matrix."""
    return np.ascontiguousarray(m_col.T)


#: Mitsuba integrators whose image is the path tracer's at their depth (direct: depth 2; the path-replay and
#: projective ones differ in their derivatives, the particle tracer in its noise; measured on a lit ball over a floor
#: at max_depth 3, 24^2, 64 spp: 0.998-1.019 of Mitsuba's mean, MSE / noise 0.95-1.32)
PATH_TRACERS = ("PathIntegrator", "VolumetricPathIntegrator", "VolumetricSimplePathIntegrator", "VolumetricMisPathIntegrator",
                "DirectIntegrator", "PRBIntegrator", "PRBVolpathIntegrator", "PathProjectiveIntegrator",
                "DirectProjectiveIntegrator", "ParticleTracerIntegrator")


def _class_name(obj) -> str:
    s = str(obj)
    return re.split(r"[\[:]", s, maxsplit=1)[0].strip().replace(" BSDF", "") if s else type(obj).__name__


def _frame_row(z_axis, position=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Row-vector 4x4 whose local +Z maps to ``z_axis`` (unit), at ``position``."""
    w = _np(z_axis)
    w = w / max(float(np.linalg.norm(w)), 1e-300)
    a = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    t = np.cross(a, w)
    t /= np.linalg.norm(t)
    b = np.cross(w, t)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3], m[3, :3] = t, b, w, position
    return m


def fresnel_dielectric(cos_i: np.ndarray, eta: float) -> np.ndarray:
    """Unpolarised Fresnel reflectance of a dielectric interface (incident from the outside)."""
    cos_i = np.clip(cos_i, 0.0, 1.0)
    sin2_t = (1.0 - cos_i ** 2) / (eta * eta)
    tir = sin2_t >= 1.0
    cos_t = np.sqrt(np.maximum(1.0 - sin2_t, 0.0))
    rs = (cos_i - eta * cos_t) / np.maximum(cos_i + eta * cos_t, 1e-300)
    rp = (eta * cos_i - cos_t) / np.maximum(eta * cos_i + cos_t, 1e-300)
    return np.where(tir, 1.0, 0.5 * (rs * rs + rp * rp))


def diffuse_fresnel(eta: float, n: int = 4096) -> float:
    """Cosine-weighted hemispherical mean of the Fresnel reflectance (Mitsuba's ``fresnel_diffuse_reflectance``)."""
    mu = (np.arange(n) + 0.5) / n
    return float(np.sum(2.0 * mu * fresnel_dielectric(mu, eta)) / n)


def ggx_alpha_of_beckmann(alpha):
    """The GGX alpha that stands for a Beckmann one (spec/bake.md#materials): ``alpha (0.928 - 0.115 min(alpha, 1))``,
    the least-squares fit of the scale whose GGX lobe f cos(theta_i) is closest to Beckmann's (relative L2 over incident
    directions, views 2-86 deg weighted by cos theta_o, Smith masking, F = 1): 0.92 at alpha 0.05, 0.88 at 0.4, 0.81
    at 1 (the lobe error 19-36 % below the same alpha's). Works on arrays (texture maps)."""
    a = np.maximum(alpha, 0.0)
    return a * (0.928 - 0.115 * np.minimum(a, 1.0))


def plastic_diffuse_scale(eta: float, nonlinear_reflectance=None) -> float | np.ndarray:
    """Factor turning Mitsuba's plastic ``diffuse_reflectance`` into a Lambertian albedo.

    Mitsuba's (rough)plastic diffuse lobe is ``R / (1 - fdr_int) / eta^2 * t_i t_o / pi`` with
    ``t = 1 - F``; with ``t`` replaced by its cosine-weighted mean ``1 - fdr_ext`` this is a
    Lambertian lobe of albedo ``R * (1 - fdr_ext)^2 / (eta^2 (1 - fdr_int))``. ``nonlinear``
    plastics divide by ``1 - R fdr_int`` instead (pass R as ``nonlinear_reflectance``).
    """
    fdr_ext = diffuse_fresnel(eta)
    fdr_int = diffuse_fresnel(1.0 / eta)
    den = 1.0 - (fdr_int if nonlinear_reflectance is None else np.asarray(nonlinear_reflectance) * fdr_int)
    return (1.0 - fdr_ext) ** 2 / (eta * eta * den)


def texel_values(data, raw: bool) -> np.ndarray:
    """A Mitsuba bitmap's stored texels [H, W, C] -> linear float64 [H, W, 3].

    8-bit data is what the file held: divided by 255 and, unless the texture is ``raw``, decoded from
    sRGB (as Mitsuba decodes it on lookup); float data is already linear. One channel is repeated.
    """
    from nasset_reference_renderer.textures import srgb_to_linear

    a = np.asarray(data)
    img = a.astype(np.float64)
    if a.dtype == np.uint8:
        img = img / 255.0 if raw else srgb_to_linear(img / 255.0)
    img = img.reshape(img.shape[0], img.shape[1], -1)
    return np.repeat(img[..., :1], 3, -1) if img.shape[-1] < 3 else img[..., :3]


#: procedural Mitsuba textures of uv alone, written as images of their values (Mitsuba evaluates them at the texel
#: centres; before 2026-12-07 replaced by the mean of their colours), at RASTERIZED_TEXELS² in their texture space
RASTERIZED_TEXTURES = ("Checkerboard",)
RASTERIZED_TEXELS = 256

#: UsdPreviewSurface float inputs a converted texture feeds through its ``r`` output (its texels are grey)
SCALAR_TEXTURE_INPUTS = ("roughness", "metallic", "opacity")


@dataclass
class TextureMap:
    """A converted bitmap: linear texels [H, W, 3] (BSDF-specific per-texel factors applied) and where it came from."""

    image: np.ndarray
    what: str
    scale_bias: tuple | None = None  # UsdUVTexture (scale, bias) float4s, e.g. a tangent-space normal map's 2, -1
    wrap: str = "repeat"  # UsdUVTexture wrapS / wrapT
    uv: tuple | None = None  # UsdTransform2d (scale [2], rotation in degrees, translation [2]) of st; None: identity


@dataclass
class Glass:
    """A transmitting surface (renderer.md#transmission), written beside the UsdPreviewSurface as a MaterialX
    ``standard_surface`` on ``outputs:mtlx:surface``: transmission ``weight`` tinted by ``color``, the dielectric's
    ``ior`` and specular ``roughness`` (alpha = roughness^2), its reflection tinted by ``specular``, ``thin`` walled
    or solid. The rest of the surface, weight
    ``1 - weight``, is a dielectric of base colour ``base`` (its mean where textured) and ``metalness``: no texture
    reaches the MaterialX shader."""

    weight: float
    color: tuple
    ior: float
    roughness: float
    thin: bool
    base: tuple = (0.0, 0.0, 0.0)
    metalness: float = 0.0
    specular: tuple = (1.0, 1.0, 1.0)  # the reflection's tint (standard_surface specular_color)


@dataclass
class ColorPrimvar:
    """A diffuse colour read from a mesh attribute (a Blender colour attribute, a Mitsuba ``mesh_attribute``) through a
    ``UsdPrimvarReader_float3`` (renderer.md#primvar-colors): the mesh's primvar :attr:`primvar` holds the attribute's
    values times ``scale``."""

    attribute: str  # the source's attribute name ("" for its default colour attribute)
    scale: float = 1.0

    @property
    def primvar(self) -> str:
        return "color_" + (re.sub(r"[^A-Za-z0-9_]", "_", self.attribute) or "default")


def st_transform(to_uv: np.ndarray) -> tuple | None:
    """UsdTransform2d (scale [2], rotation (degrees), translation [2]) acting on USD's st = (u, 1 - v) as Mitsuba's
    3x3 ``to_uv`` acts on its uv (spec/bake.md#materials); None when it shears (no scale-rotate-translate
    form)."""
    (a, b, c), (d, e, f) = np.asarray(to_uv, np.float64)[:2]
    lin, offset = np.array([[a, -b], [-d, e]]), np.array([b + c, 1.0 - e - f])  # in t = 1 - v
    sx = float(np.hypot(lin[0, 0], lin[1, 0]))
    if sx <= 0.0:
        return None
    theta = math.atan2(lin[1, 0], lin[0, 0])
    axis_y = np.array([-math.sin(theta), math.cos(theta)])
    sy = float(lin[:, 1] @ axis_y)
    if np.abs(lin[:, 1] - sy * axis_y).max() > 1e-6 * max(abs(sx), abs(sy), 1.0):
        return None
    return (sx, sy), math.degrees(theta), tuple(float(x) for x in offset)


def emission_rgb(mi, lam: np.ndarray, radiance: np.ndarray) -> np.ndarray:
    """Linear sRGB [3] that a spectral variant's RGB film records for an emission spectrum ``radiance`` sampled at the
    wavelengths ``lam`` (nm, 1 nm apart over 360-830): integrated against Mitsuba's own CIE 1931 table, divided by the
    integral of y, then XYZ -> linear sRGB."""
    cmf = np.array([np.asarray(ch, np.float64) for ch in mi.cie1931_xyz(mi.Float(lam))])  # [3, N]
    xyz = cmf @ radiance / cmf[1].sum()
    to_srgb = np.array([[3.240479, -1.537150, -0.498535], [-0.969256, 1.875991, 0.041556],
                        [0.055648, -0.204043, 1.057311]])
    return np.maximum(to_srgb @ xyz, 0.0)


#: the wavelengths (nm) emission spectra are integrated over (Mitsuba's CIE table)
VISIBLE_NM = np.arange(360.0, 831.0, 1.0)


def blackbody_rgb(mi, kelvin: float) -> np.ndarray:
    """Linear sRGB [3] of Mitsuba's ``blackbody`` spectrum at ``kelvin``: Planck's spectral radiance in W / (m^2 sr nm)
    (Mitsuba's units) through :func:`emission_rgb`: what a spectral variant's RGB film records for it (measured: within
    0.4 % of a 4096-spp ``scalar_spectral`` render at 3000 K). The RGB variants the converter loads cannot evaluate it
    at all."""
    h, c, k = 6.62607004e-34, 2.99792458e8, 1.38064852e-23
    m = VISIBLE_NM * 1e-9
    with np.errstate(over="ignore"):
        planck = 2.0 * h * c * c * m ** -5 / np.expm1(h * c / (m * k * max(float(kelvin), 1.0))) * 1e-9
    return emission_rgb(mi, VISIBLE_NM, planck)


def tabulated_rgb(mi, nodes: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Linear sRGB [3] of a tabulated emission spectrum (``irregular``: its wavelengths; ``regular``: evenly over its
    range), linear between the nodes and 0 outside them as Mitsuba evaluates it, through :func:`emission_rgb`."""
    nodes, values = np.asarray(nodes, np.float64).ravel(), np.asarray(values, np.float64).ravel()
    inside = (VISIBLE_NM >= nodes[0]) & (VISIBLE_NM <= nodes[-1])
    return emission_rgb(mi, VISIBLE_NM, np.where(inside, np.interp(VISIBLE_NM, nodes, values), 0.0))


#: a ``filter_type`` nearest bitmap is written with each texel repeated up to this many times per axis (the renderer
#: filters bilinearly: the blend then spans 1 / NEAREST_REPEAT of a texel), at most TEXTURE_MAX_PIXELS texels
NEAREST_REPEAT = 8
TEXTURE_MAX_PIXELS = 1 << 22


def _eval_texture(mi, tex, uv: np.ndarray, scalar: bool = False) -> np.ndarray:
    """Mitsuba's own value [N, 3] of texture ``tex`` at texture coordinates ``uv`` [N, 2] (before its ``to_uv``);
    ``scalar``: its float value (``eval_1``, what a float parameter reads) in the three channels. (Mitsuba 3.9's
    checkerboard swaps its two colours in ``eval_1``: a float parameter reads the other colour than ``eval``.)"""
    si = mi.SurfaceInteraction3f()
    if mi.variant().startswith("scalar"):
        out = []
        for u, v in uv:
            si.uv = mi.Point2f(float(u), float(v))
            out.append(np.resize(_np(tex.eval_1(si) if scalar else tex.eval(si)).ravel(), 3))
        return np.array(out)
    si.uv = mi.Point2f(*np.ascontiguousarray(uv.T, np.float32))
    if scalar:
        return np.repeat(np.asarray(tex.eval_1(si), np.float64).ravel()[:, None], 3, 1)
    val = tex.eval(si)
    return np.stack([np.asarray(val[c], np.float64).ravel() for c in range(3)], 1)


def _on_axis(axis: int, x: float, other: float) -> tuple[float, float]:
    """The point (u, v) with ``x`` on ``axis`` (0: u, 1: v) and ``other`` on the other."""
    return (x, other) if axis == 0 else (other, x)


def bitmap_sampling(mi, tex, shape_hw, to_uv) -> tuple[str, bool]:
    """``(wrap, nearest)`` of a Mitsuba ``bitmap``: its ``wrap_mode`` (``repeat``, ``mirror`` or ``clamp``, the
    UsdUVTexture wrap tokens of the same name) and whether its ``filter_type`` is ``nearest``. Mitsuba's description
    of a bitmap names neither, so both are read off the texture itself: its values just outside the unit square
    against the three wrap modes' images of those points inside it, and its jump across texel edges (nearest: the
    whole step between neighbours; bilinear: half of it a quarter texel either side). A texture on which the modes
    agree (uniform along its edges, say) is taken as Mitsuba's default, repeat and bilinear."""
    h, w = shape_hw
    inv = np.linalg.inv(np.asarray(to_uv, np.float64)) if to_uv is not None else np.eye(3)

    def ev(pts):  # values at points [N, 2] of the unit square, i.e. after to_uv
        pts = np.asarray(pts, np.float64)
        before = (np.concatenate([pts, np.ones((len(pts), 1))], 1) @ inv.T)[:, :2]
        return _eval_texture(mi, tex, before)

    outside, images = [], {"repeat": [], "mirror": [], "clamp": []}
    for f in (0.13, 0.31):  # beyond each edge by f, and where each mode takes that point inside (u or v)
        for axis, n, m in ((0, w, h), (1, h, w)):
            for beyond, inside in (((1.0 + f), {"repeat": f, "mirror": 1.0 - f, "clamp": 1.0 - 0.5 / n}),
                                   ((-f), {"repeat": 1.0 - f, "mirror": f, "clamp": 0.5 / n})):
                lines = (np.arange(min(m, 16)) + 0.5) / min(m, 16)  # across the other axis
                outside += [_on_axis(axis, beyond, o) for o in lines]
                for mode, x in inside.items():
                    images[mode] += [_on_axis(axis, x, o) for o in lines]
    at = ev(outside)
    err = {mode: float(np.abs(ev(pts) - at).sum()) for mode, pts in images.items()}
    best = min(err, key=err.get)
    wrap = best if err[best] < err["repeat"] - 1e-6 * (1.0 + np.abs(at).sum()) else "repeat"
    # texel edges along both axes, at the centre line of the other
    k = np.arange(1, min(w, 32))
    j = np.arange(1, min(h, 32))
    xe, ye = k * (w // min(w, 32)) / w, j * (h // min(h, 32)) / h
    q = (0.25 / w, 0.25 / h)
    lo = [(x - q[0], 0.5) for x in xe] + [(0.5, y - q[1]) for y in ye]
    hi = [(x + q[0], 0.5) for x in xe] + [(0.5, y + q[1]) for y in ye]
    c_lo = [(x - 0.5 / w, 0.5) for x in xe] + [(0.5, y - 0.5 / h) for y in ye]
    c_hi = [(x + 0.5 / w, 0.5) for x in xe] + [(0.5, y + 0.5 / h) for y in ye]
    if not lo:
        return wrap, False
    jump = float(np.abs(ev(hi) - ev(lo)).sum())
    step = float(np.abs(ev(c_hi) - ev(c_lo)).sum())
    return wrap, bool(step > 1e-6 and jump > 0.75 * step)


class _Params:
    """Reads Mitsuba parameter values by name: bitmaps kept as :class:`TextureMap`, other textures by their mean."""

    def __init__(self, mi, obj, prefix: str = "") -> None:
        self.mi = mi
        self.p = mi.traverse(obj)
        self.obj = obj
        self.prefix = prefix
        self.textured: list[str] = []  # procedural textures replaced by their mean
        self.unread: list[str] = []  # parameters present but of a kind the reader cannot evaluate (default used)
        self.bitmaps: dict[str, TextureMap] = {}

    def keys(self):
        return [k[len(self.prefix):] for k in self.p.keys() if k.startswith(self.prefix)]

    def has(self, name: str) -> bool:
        """Whether parameter ``name`` is there: a value, a bitmap, or a texture of its own parameters (a checkerboard
        roughness was taken for an absent one, and the BSDF's other parameters read instead, before 2026-12-07)."""
        k = self.prefix + name
        return any(x in self.p for x in (k, k + ".value", k + ".data")) or any(x.startswith(k + ".") for x in self.p.keys())

    def bitmap(self, name: str, scalar: bool = False) -> np.ndarray | None:
        """Linear texels [H, W, 3] of a bitmap texture parameter, or of a procedural one of
        :data:`RASTERIZED_TEXTURES` (:meth:`rasterized`; ``scalar``: as a float parameter reads it); None for
        anything else."""
        k = self.prefix + name
        if k + ".data" not in self.p:
            return self.rasterized(name, scalar)
        # the texture's own description says whether it is raw (the owner's would name its first bitmap's flag: the
        # front's for a twosided BSDF's back)
        flag = re.search(r"raw\s*=\s*(\d)", str(self.p.properties[k + ".data"][2]))
        return texel_values(self.p[k + ".data"], bool(flag and flag.group(1) == "1"))

    def rasterized(self, name: str, scalar: bool = False) -> np.ndarray | None:
        """Linear texels [N, N, 3] (:data:`RASTERIZED_TEXELS`) of a procedural texture parameter whose value depends on
        uv alone (:data:`RASTERIZED_TEXTURES`), in its texture space (before its ``to_uv``, as a bitmap's texels are),
        evaluated by Mitsuba at the texel centres (``scalar``: its float value, grey); None for anything else."""
        k = self.prefix + name + ".to_uv"
        if k not in self.p or _class_name(tex := self.p.properties[k][2]) not in RASTERIZED_TEXTURES:
            return None
        n = RASTERIZED_TEXELS
        g = (np.arange(n) + 0.5) / n
        v, u = np.meshgrid(g, g, indexing="ij")  # row r holds v = (r + 0.5) / n: Mitsuba's top row first
        inv = np.linalg.inv(np.asarray(self.p[k].matrix, np.float64).reshape(3, 3))
        shape_uv = np.stack([u.ravel(), v.ravel()], 1) @ inv[:2, :2].T + inv[:2, 2]
        return np.maximum(_eval_texture(self.mi, tex, shape_uv, scalar), 0.0).reshape(n, n, 3)

    def texture_map(self, name: str, texels: np.ndarray, what: str, scale_bias=None) -> TextureMap:
        """A :class:`TextureMap` of the bitmap parameter ``name`` holding ``texels`` (its converted values) with the
        bitmap's wrap mode; a nearest-filtered bitmap has each texel repeated (:data:`NEAREST_REPEAT`) so that the
        renderer's bilinear lookup keeps its edges (:func:`bitmap_sampling`)."""
        k = self.prefix + name + ".data"
        tex = self.p.properties[k][2] if k in self.p else None
        wrap, nearest = ("repeat", False) if tex is None else bitmap_sampling(
            self.mi, tex, texels.shape[:2], self.uv_transform(name))
        if nearest:
            n = NEAREST_REPEAT
            while n > 1 and texels.shape[0] * texels.shape[1] * n * n > TEXTURE_MAX_PIXELS:
                n //= 2
            texels = np.repeat(np.repeat(texels, n, 0), n, 1)
        return TextureMap(texels, what, scale_bias, wrap)

    def uv_transform(self, name: str) -> np.ndarray | None:
        """The texture's ``to_uv`` 3x3 matrix, or None when it is the identity (or absent)."""
        k = self.prefix + name + ".to_uv"
        if k not in self.p:
            return None
        m = np.asarray(self.p[k].matrix, np.float64).reshape(3, 3)
        return None if np.allclose(m, np.eye(3)) else m

    def rgb(self, name: str, default=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Constant colour [3] of a parameter; a bitmap gives its linear mean, a procedural texture the mean of
        its constant colours (noted in ``textured``), a ``blackbody`` spectrum its linear sRGB (:func:`blackbody_rgb`)."""
        k = self.prefix + name
        if k + ".temperature" in self.p:  # a BlackBodySpectrum: Mitsuba's RGB variants cannot evaluate it
            v = blackbody_rgb(self.mi, float(_np(self.p[k + ".temperature"]).ravel()[0]))
        elif k + ".values" in self.p and isinstance(self.obj, self.mi.Emitter) and (
                k + ".wavelengths" in self.p or k + ".range" in self.p):  # an irregular / regular emission spectrum
            values = _np(self.p[k + ".values"]).ravel()
            nodes = (_np(self.p[k + ".wavelengths"]).ravel() if k + ".wavelengths" in self.p
                     else np.linspace(*_np(self.p[k + ".range"]).ravel()[:2], len(values)))
            v = tabulated_rgb(self.mi, nodes, values)
        elif k + ".value" in self.p:
            v = _np(self.p[k + ".value"]).ravel()
        elif k + ".data" in self.p:
            v = self.bitmap(name).reshape(-1, 3).mean(0)
        elif k in self.p:
            v = _np(self.p[k]).ravel()
        else:
            nested = [x for x in self.p.keys() if x.startswith(k + ".") and x.endswith(".value")]
            if not nested:
                if any(x.startswith(k + ".") for x in self.p.keys()):  # present, but nothing the reader knows
                    self.unread.append(name)
                return _np(default).copy()
            # a procedural texture (checkerboard, ...): the mean of its constant colours, each linear
            v = np.mean([np.resize(_np(self.p[x]).ravel(), 3) for x in nested], axis=0)
            self.textured.append(name)
        if v.size == 1:
            v = np.repeat(v, 3)
        return v[:3].copy()

    def mesh_attribute(self, name: str) -> ColorPrimvar | None:
        """A ``mesh_attribute`` texture on parameter ``name`` as a :class:`ColorPrimvar` of its attribute and scale
        (the shape's meshes carry the values), else None."""
        k = self.prefix + name + ".scale"
        if k not in self.p:
            return None
        at = re.search(r"MeshAttribute\[\s*name\s*=\s*\"([^\"]+)\",\s*scale\s*=\s*\"([^\"]+)\"", self.owner_text(name + ".scale"))
        return None if at is None else ColorPrimvar(at.group(1), float(at.group(2)))

    def bsdf_text(self) -> str | None:
        """The description of the BSDF at :attr:`prefix` itself: the owner of one of its parameters, up the parameter
        hierarchy one level per dot of the parameter's name below the prefix (``alpha.value`` is held by a texture
        nested in the BSDF); None when it has no parameters. A wrapper's description (:attr:`obj`) would show its first
        nested BSDF's values."""
        for k in self.p.keys():
            if k.startswith(self.prefix):
                node = self.p.properties[k][2]
                for _ in range(k[len(self.prefix):].count(".")):
                    node = self.p.hierarchy[node][0]
                return str(node)
        return None

    def owner_text(self, name: str) -> str:
        """The description of the object that holds parameter ``name`` (under :attr:`prefix`): a nested BSDF's or
        texture's own, where the wrapper's (:attr:`obj`) would show the first of its nested objects' values (the front's
        for a twosided BSDF's back). The wrapper's when there is no such parameter."""
        k = self.prefix + name
        return str(self.p.properties[k][2]) if k in self.p else str(self.obj)

    def texture_or_rgb(self, name: str, default, what: str, per_texel=None):
        """A :class:`TextureMap` for a bitmap parameter (texels through ``per_texel``), a :class:`ColorPrimvar` for a
        ``mesh_attribute`` one (when there is no ``per_texel``), else its colour [3] (through ``per_texel`` too)."""
        if per_texel is None and (attr := self.mesh_attribute(name)) is not None:
            return attr
        f = per_texel or (lambda c: c)
        img = self.bitmap(name)
        if img is None:
            return f(self.rgb(name, default))
        self.bitmaps[name] = self.texture_map(name, f(img), what)
        return self.bitmaps[name]

    def scalar(self, name: str, default: float) -> float:
        return float(self.rgb(name, (default,) * 3).mean())

    def scalar_or_texture(self, name: str, default: float, what: str, per_texel=None):
        """A grey :class:`TextureMap` (a colour bitmap read as its luminance, as Mitsuba evaluates a float texture)
        for a bitmap parameter, else its value; both through ``per_texel`` (e.g. alpha -> sqrt for a roughness)."""
        f = per_texel or (lambda x: x)
        img = self.bitmap(name, scalar=True)
        if img is None:
            return float(f(self.scalar(name, default)))
        lum = img @ np.array([0.212671, 0.715160, 0.072169])
        self.bitmaps[name] = self.texture_map(name, np.repeat(f(np.maximum(lum, 0.0))[..., None], 3, -1), what)
        return self.bitmaps[name]


# -- the converter ------------------------------------------------------------------------------
class StageConverter:
    def __init__(self, mi, scene, scene_path: Path, output: Path, replace: dict, check_usd: bool,
                 layer: Path | None = None) -> None:
        """Converts into a new stage at ``layer`` (default ``output``; a temporary file beside it that the caller
        renames over ``output``, and then checks); paths written into the stage are relative to ``output``'s folder."""
        from pxr import Usd, UsdGeom

        self.mi, self.scene, self.scene_path, self.output = mi, scene, scene_path, output
        self.replace = replace  # shape id -> asset Path
        self.check_usd = check_usd
        self.result = ConvertResult(output)
        self.names: set[str] = set()
        self.materials: dict = {}
        self.textured_materials: set[str] = set()
        self.uv_metrics: dict[int, tuple] = {}  # id(shape) -> (shape, its uv layout for bump maps: _uv_metric)
        self.color_primvars: dict = {}  # material path -> ColorPrimvar its meshes carry
        self.prototypes: dict[str, str] = {}  # shapegroup name -> class prim path
        self.hide_emitters = False  # the integrator's hide_emitters (read by integrator())
        self.geometry_root, self.looks_root = "/World/Geometry", "/World/Looks"
        self.layer_path = output
        self.stage = Usd.Stage.CreateNew(str(layer or output))
        UsdGeom.SetStageUpAxis(self.stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(self.stage, 1.0)
        world = UsdGeom.Xform.Define(self.stage, "/World")
        self.stage.SetDefaultPrim(world.GetPrim())
        for group in ("Geometry", "Lights", "Looks", "Assets"):
            UsdGeom.Scope.Define(self.stage, f"/World/{group}")

    # bookkeeping
    def warn(self, msg: str) -> None:
        self.result.warnings.append(msg)

    def _name(self, parent: str, wanted: str) -> str:
        from pxr import Tf

        base = Tf.MakeValidIdentifier(wanted or "unnamed")
        name, k = base, 1
        while f"{parent}/{name}" in self.names:
            k += 1
            name = f"{base}_{k}"
        path = f"{parent}/{name}"
        self.names.add(path)
        return path

    def _xform(self, prim, row_matrix) -> None:
        from pxr import Gf, UsdGeom

        m = np.asarray(row_matrix, np.float64)
        if np.allclose(m, np.eye(4), atol=0, rtol=0):
            return
        UsdGeom.Xformable(prim).AddTransformOp().Set(Gf.Matrix4d(*m.ravel().tolist()))

    def _texture_file(self, stem: str) -> Path:
        """A new file ``OUTPUT_textures/STEM.exr`` for this conversion (``STEM_2.exr``, ... when taken: materials of one
        name in two prototypes, ids that become one identifier, would otherwise overwrite each other's texels)."""
        tex_dir = self.output.parent / f"{self.output.stem}_textures"
        tex_dir.mkdir(parents=True, exist_ok=True)
        file, k = tex_dir / f"{stem}.exr", 1
        while str(file) in self.result.textures:
            k += 1
            file = tex_dir / f"{stem}_{k}.exr"
        return file

    def _to_world(self, shape) -> np.ndarray:
        """A shape's ``to_world`` as Mitsuba draws it (a sphere round: :func:`.analytic.drawn_to_world`)."""
        return analytic.drawn_to_world(self.mi, shape)

    def record(self, path: str, what: str) -> None:
        self.result.prims[path] = what

    # -- camera -----------------------------------------------------------------------------
    def camera(self) -> None:
        from pxr import Gf, Sdf, UsdGeom, UsdRender

        sensors = list(self.scene.sensors())
        if not sensors:
            self.warn("the scene has no sensor: no camera written (the reference renderer needs one)")
            return
        if len(sensors) > 1:
            self.warn(f"{len(sensors)} sensors: only the first is converted")
        sensor = sensors[0]
        cls = _class_name(sensor)
        if cls not in ("PerspectiveCamera", "ThinLensCamera", "OrthographicCamera"):
            self.warn(f"sensor {cls} is not a perspective, thinlens or orthographic camera: no camera written")
            return
        p = self.mi.traverse(sensor)
        if fog := camera_medium(self.scene):
            self.warn(fog)
        film = sensor.film()
        size = tuple(int(v) for v in film.size())
        crop, off = tuple(int(v) for v in film.crop_size()), tuple(int(v) for v in film.crop_offset())
        if crop != size or off != (0, 0):
            self.warn(f"film crop window {crop} at {off} ignored (the full {size} film is described)")
        filt = str(film.rfilter()) if hasattr(film, "rfilter") else ""
        pixel_filter = ("box", None)
        if filt.startswith("GaussianFilter"):
            m = re.search(r"stddev\s*=\s*([0-9.eE+-]+)", filt)
            pixel_filter = ("gaussian", float(m.group(1)) if m else 0.5)
        elif filt and not filt.startswith("BoxFilter"):
            self.warn(f"film reconstruction filter {_class_name(film.rfilter())}: written as a box filter")
        shift = [float(_np(p[k]).ravel()[0]) if k in p else 0.0
                 for k in ("principal_point_offset_x", "principal_point_offset_y")]
        row = _FLIP_CAMERA @ _row(_matrix(p["to_world"]))
        scale = np.linalg.norm(row[:3, :3], axis=1)
        row[:3, :3] /= np.maximum(scale, 1e-300)[:, None]
        path = self._name("/World", sensor.id() or "Camera")
        cam = UsdGeom.Camera.Define(self.stage, path)
        if cls == "OrthographicCamera":
            # Mitsuba's orthographic film spans x in [-1, 1] and y in [-h/w, h/w] before to_world: its scale is the
            # view's size (USD: the apertures, in tenths of a scene unit)
            ha = 20.0 * float(scale[0])
            if not math.isclose(scale[0], scale[1], rel_tol=1e-4):
                self.warn(f"orthographic camera to_world scales x by {scale[0]:.4g} and y by {scale[1]:.4g}: the vertical "
                          "extent follows the image aspect (square pixels)")
            cam.CreateProjectionAttr(UsdGeom.Tokens.orthographic)
            x_fov = None
        else:
            if not np.allclose(scale, 1.0, atol=1e-4):
                self.warn(f"camera to_world has scale {scale.round(4).tolist()}: removed")
            x_fov = float(_np(p["x_fov"]).ravel()[0])
            ha = 2.0 * FOCAL_LENGTH * math.tan(math.radians(x_fov) / 2.0)
            cam.CreateProjectionAttr(UsdGeom.Tokens.perspective)
        cam.CreateFocalLengthAttr(FOCAL_LENGTH)
        cam.CreateHorizontalApertureAttr(ha)
        cam.CreateVerticalApertureAttr(ha * size[1] / size[0])
        if cls == "ThinLensCamera":  # USD's lens diameter is focalLength / fStop, in tenths of a scene unit
            radius, focus = (float(_np(p[k]).ravel()[0]) for k in ("aperture_radius", "focus_distance"))
            if radius > 0 and focus > 0:
                cam.CreateFStopAttr(0.1 * FOCAL_LENGTH / (2.0 * radius))
                cam.CreateFocusDistanceAttr(focus)
        if shift[0] or shift[1]:  # Mitsuba's principal point offset: film widths right, film heights down
            cam.CreateHorizontalApertureOffsetAttr(shift[0] * ha)
            cam.CreateVerticalApertureOffsetAttr(-shift[1] * ha * size[1] / size[0])
        near, far = float(_np(p["near_clip"]).ravel()[0]), float(_np(p["far_clip"]).ravel()[0])
        cam.CreateClippingRangeAttr(Gf.Vec2f(near, far))
        box = self.scene.bbox()
        corners = np.array([[(box.min, box.max)[i >> k & 1][k] for k in range(3)] for i in range(8)], np.float64)
        m = _matrix(p["to_world"])
        view = m[:3, 2] / max(float(np.linalg.norm(m[:3, 2])), 1e-300)  # Mitsuba's camera looks down local +Z
        reach = float(((corners - m[:3, 3]) @ view).max()) if np.all(np.isfinite(corners)) else 0.0
        if reach > far:  # the renderer ignores clipping ranges (renderer.md#cameras)
            self.warn(f"sensor far_clip {far:g}: Mitsuba does not draw what lies farther along the view (the scene "
                      f"reaches {reach:.4g}; Mitsuba's default is 10000, 10 m in a millimetre scene), the reference "
                      "renderer draws it")
        self._xform(cam.GetPrim(), row)
        view = f"x_fov {x_fov:.4g} deg" if x_fov is not None else f"{0.1 * ha:.4g} units wide"
        self.record(path, f"sensor {sensor.id() or '(unnamed)'} ({cls}, {view})")
        self.result.resolution = size
        # resolution: the standard place is a UsdRender.Settings prim (outside the defaultPrim)
        settings = UsdRender.Settings.Define(self.stage, "/Render/Settings")
        settings.CreateResolutionAttr(Gf.Vec2i(*size))
        settings.CreateCameraRel().SetTargets([path])
        settings.CreatePixelAspectRatioAttr(1.0)
        prim = settings.GetPrim()
        prim.CreateAttribute("nasset:pixelFilter", Sdf.ValueTypeNames.Token, custom=True).Set(pixel_filter[0])
        if pixel_filter[1] is not None:
            prim.CreateAttribute("nasset:pixelFilterStddev", Sdf.ValueTypeNames.Float, custom=True).Set(pixel_filter[1])

    # -- integrator (recorded, not converted) -------------------------------------------------
    def integrator(self) -> None:
        integ = self.scene.integrator()
        if integ is None:
            return
        cls = _class_name(integ)
        info = {"type": cls}
        image = image_integrator(integ)
        if image != cls:  # a wrapper (aov, stokes, moment): the nested integrator makes the image
            info["image_integrator"] = cls = image
        md = integrator_depths(integ).get("max_depth")
        if md is not None:
            info["max_depth"] = md
            info["renderer_max_depth"] = -1 if md < 0 else max(md - 1, 0)
            from pxr import Sdf, UsdRender

            # the renderer counts scattering vertices, Mitsuba path segments (spec/bake.md#scene-conversion)
            settings = UsdRender.Settings.Define(self.stage, "/Render/Settings")
            settings.GetPrim().CreateAttribute("nasset:maxDepth", Sdf.ValueTypeNames.Int, custom=True).Set(
                info["renderer_max_depth"])
            if md == 0:  # renderer depth 0 still shows the emitters in view
                self.warn("integrator max_depth 0 (a black image) written as renderer depth 0 (the emitters in view)")
        self.hide_emitters = hides_emitters(self.mi, integ)
        if self.hide_emitters:  # camera rays see no emitter: each light is written hidden from the camera
            info["hide_emitters"] = True
        self.result.integrator = info
        if cls == "BasicPRBIntegrator":  # BSDF samples only: no light is sampled, so delta lights light nothing
            self.warn("integrator prb_basic samples no light: in Mitsuba point, spot and directional lights light nothing; "
                      "the reference renderer samples them")
        elif cls not in PATH_TRACERS:
            self.warn(f"integrator {cls} has no USD counterpart: the reference renderer path-traces")

    # -- materials ----------------------------------------------------------------------------
    def material(self, bsdf, shape_name: str, emission=None, back: bool = False, shape=None) -> str:
        """Material prim path for a Mitsuba BSDF (deduplicated by the BSDF's id, and for a bump map by the uv layout of
        ``shape``: the normal map it becomes depends on it); ``back``: a twosided BSDF's back."""
        bump = None
        if shape is not None and "BumpMap" in str(bsdf):
            metric = self._uv_metric(shape)
            bump = metric.key if metric is not None else "no uv"
        key = (bsdf.id() or f"@{shape_name}", None if emission is None else ("texture", id(emission))
               if isinstance(emission, TextureMap) else tuple(np.round(emission, 9)), back, self.looks_root, bump)
        if key in self.materials:
            return self.materials[key]
        inputs, notes = self.map_bsdf(bsdf, back=back, shape=shape)
        for n in notes:
            self.warn(f"shape {shape_name}: {n}")
        if emission is not None:
            inputs["emissiveColor"] = emission if isinstance(emission, TextureMap) else tuple(float(x) for x in emission)
        path = self._write_material((bsdf.id() or f"{shape_name}_bsdf") + ("_back" if back else ""), inputs)
        self.record(path, f"bsdf {bsdf.id() or '(inline)'} ({_class_name(bsdf)})")
        self.materials[key] = path
        return path

    def _write_material(self, name: str, inputs: dict) -> str:
        from pxr import Gf, Sdf, UsdShade

        inputs = dict(inputs)
        glass = inputs.pop("glass", None)
        microfacet = inputs.pop("microfacet", None)
        path = self._name(self.looks_root, name)
        mat = UsdShade.Material.Define(self.stage, path)
        sh = UsdShade.Shader.Define(self.stage, f"{path}/PreviewSurface")
        sh.CreateIdAttr("UsdPreviewSurface")
        if microfacet is not None:  # renderer.md#materials: the lobe's microfacet distribution
            sh.GetPrim().CreateAttribute("nasset:microfacet", Sdf.ValueTypeNames.Token, custom=True).Set(microfacet)
        types = {"diffuseColor": Sdf.ValueTypeNames.Color3f, "specularColor": Sdf.ValueTypeNames.Color3f,
                 "emissiveColor": Sdf.ValueTypeNames.Color3f, "useSpecularWorkflow": Sdf.ValueTypeNames.Int,
                 "roughness": Sdf.ValueTypeNames.Float, "metallic": Sdf.ValueTypeNames.Float,
                 "ior": Sdf.ValueTypeNames.Float, "opacity": Sdf.ValueTypeNames.Float,
                 "opacityThreshold": Sdf.ValueTypeNames.Float}
        for k, v in inputs.items():
            if isinstance(v, TextureMap):
                self._texture_input(path, sh, k, v)
                continue
            if isinstance(v, ColorPrimvar):
                reader = UsdShade.Shader.Define(self.stage, f"{path}/{k}_primvar")
                reader.CreateIdAttr("UsdPrimvarReader_float3")
                reader.CreateInput("varname", Sdf.ValueTypeNames.Token).Set(v.primvar)
                reader.CreateOutput("result", Sdf.ValueTypeNames.Float3)
                sh.CreateInput(k, Sdf.ValueTypeNames.Color3f).ConnectToSource(reader.ConnectableAPI(), "result")
                self.color_primvars[path] = v  # its meshes write the primvar
                continue
            if types[k] == Sdf.ValueTypeNames.Color3f:
                v = Gf.Vec3f(*(float(x) for x in v))
            elif types[k] == Sdf.ValueTypeNames.Int:
                v = int(v)
            else:
                v = float(v)
            sh.CreateInput(k, types[k]).Set(v)
        mat.CreateSurfaceOutput().ConnectToSource(sh.ConnectableAPI(), "surface")
        if glass is not None:
            self._write_glass(mat, path, glass)
        return path

    def _write_glass(self, mat, path: str, glass: Glass) -> None:
        """The MaterialX ``standard_surface`` of a transmitting material on ``outputs:mtlx:surface`` (read before the
        UsdPreviewSurface by renderers of MaterialX, renderer.md#materials)."""
        from pxr import Gf, Sdf, UsdShade

        sh = UsdShade.Shader.Define(self.stage, f"{path}/StandardSurface")
        sh.CreateIdAttr("ND_standard_surface_surfaceshader")
        f, c = Sdf.ValueTypeNames.Float, Sdf.ValueTypeNames.Color3f
        sh.CreateInput("base", f).Set(1.0)
        sh.CreateInput("base_color", c).Set(Gf.Vec3f(*(float(x) for x in np.clip(glass.base, 0.0, 1.0))))
        sh.CreateInput("metalness", f).Set(float(np.clip(glass.metalness, 0.0, 1.0)))
        sh.CreateInput("specular_IOR", f).Set(float(glass.ior))
        sh.CreateInput("specular_roughness", f).Set(float(glass.roughness))
        sh.CreateInput("specular_color", c).Set(Gf.Vec3f(*(float(x) for x in np.clip(glass.specular, 0.0, 1.0))))
        sh.CreateInput("transmission", f).Set(float(glass.weight))
        sh.CreateInput("transmission_color", c).Set(Gf.Vec3f(*(float(x) for x in glass.color)))
        sh.CreateInput("thin_walled", Sdf.ValueTypeNames.Bool).Set(bool(glass.thin))
        sh.CreateOutput("out", Sdf.ValueTypeNames.Token)
        mat.CreateSurfaceOutput("mtlx").ConnectToSource(sh.ConnectableAPI(), "out")

    def _uv_mesh(self, shape):
        """``(points [V, 3] world space, faces [F, 3], uv [V, 2], normals [V, 3] or None)`` of a shape as the converter
        writes it, for its uv layout; None for a shape without per-vertex texture coordinates (a disk or a mesh without
        them, whose faceVarying uv has no layout to bake a map on; curves)."""
        cls = _class_name(shape)
        p = self.mi.traverse(shape)
        if cls in MESH_CLASSES or "vertex_positions" in p:
            pts = _np(p["vertex_positions"]).reshape(-1, 3)
            uv = _np(p["vertex_texcoords"]).reshape(-1, 2) if "vertex_texcoords" in p else None
            nrm = _np(p["vertex_normals"]).reshape(-1, 3) if "vertex_normals" in p else None
            if uv is None or len(uv) != len(pts):
                return None
            return pts, np.asarray(p["faces"], np.int64).reshape(-1, 3), uv, nrm if nrm is not None and nrm.shape == pts.shape else None
        if cls not in ("Rectangle", "Sphere", "Cylinder"):
            return None
        pts, faces, nrm, uv = analytic.local_mesh(cls)
        if cls == "Sphere":
            pts, faces, uv = latlong_sphere()
            nrm = pts
        m = self._to_world(shape)
        return pts @ m[:3, :3].T + m[:3, 3], faces, uv, nrm @ np.linalg.inv(m[:3, :3])

    def _uv_metric(self, shape):
        """:func:`.bump.uv_metric` of a shape (None without a usable uv layout), worked out once per shape (its material
        key and each of its bump maps read it)."""
        from .bump import uv_metric

        key = id(shape)
        if key not in self.uv_metrics:
            mesh = self._uv_mesh(shape)
            self.uv_metrics[key] = (shape, None if mesh is None else uv_metric(*mesh))  # the shape held: its id stays
        return self.uv_metrics[key][1]

    def _bump_map(self, bsdf, prefix: str, shape, notes: list) -> TextureMap | None:
        """A ``bumpmap``'s height bitmap as the tangent-space normal map it amounts to on ``shape`` (:mod:`.bump`), or
        None (a procedural height, a shape without texture coordinates: the bump is dropped)."""
        from .bump import bump_normal_texels, normal_map_size

        p = _Params(self.mi, bsdf, prefix)
        key = prefix + "nested_texture.data"
        if key not in p.p or shape is None:
            return None
        to_uv = p.uv_transform("nested_texture")
        metric = self._uv_metric(shape)
        if metric is None:
            notes.append(f"bumpmap on a {_class_name(shape)} written without usable texture coordinates: dropped")
            return None
        hw = np.asarray(p.p[key]).shape[:2]
        height = p.p.properties[key][2]
        texels = bump_normal_texels(self.mi, height, normal_map_size(hw, TEXTURE_MAX_PIXELS), p.scalar("scale", 1.0),
                                    metric, to_uv)
        wrap = bitmap_sampling(self.mi, height, hw, to_uv)[0]
        tex = TextureMap(texels, "bump map as a normal map", ((2.0, 2.0, 2.0, 1.0), (-1.0, -1.0, -1.0, 0.0)), wrap)
        if to_uv is not None:
            tex.uv = st_transform(to_uv)
        if metric.k is None:
            notes.append("bumpmap: its strength varies over the shape's uv layout; the normal map takes each texel's from "
                         "the nearest triangle" + (" (the texture repeats over the shape: approximate)"
                                                   if to_uv is not None and abs(np.linalg.det(to_uv[:2, :2])) > 1.0 + 1e-6
                                                   else ""))
        return tex

    def _texture_input(self, mat_path: str, surface, name: str, tex: TextureMap) -> None:
        """Write ``tex`` as OpenEXR (linear) beside the output and connect ``name`` of ``surface`` to a
        ``UsdUVTexture`` reading primvar ``st`` (spec/bake.md#scene-conversion)."""
        from pxr import Sdf, UsdShade

        from nasset_sdk.images import write_exr

        file = self._texture_file(f"{mat_path.rsplit('/', 1)[-1]}_{name}")
        write_exr(file, tex.image.astype(np.float32))
        self.result.textures.append(str(file))
        reader = UsdShade.Shader.Define(self.stage, f"{mat_path}/{name}_st")
        reader.CreateIdAttr("UsdPrimvarReader_float2")
        reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
        node = UsdShade.Shader.Define(self.stage, f"{mat_path}/{name}_texture")
        node.CreateIdAttr("UsdUVTexture")
        node.CreateInput("file", Sdf.ValueTypeNames.Asset).Set(Sdf.AssetPath("./" + file.relative_to(self.output.parent).as_posix()))
        node.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("raw")
        for w in ("wrapS", "wrapT"):
            node.CreateInput(w, Sdf.ValueTypeNames.Token).Set(tex.wrap)
        st = reader
        if tex.uv is not None:  # texture tiling: a UsdTransform2d between the reader and the texture
            from pxr import Gf

            st = UsdShade.Shader.Define(self.stage, f"{mat_path}/{name}_st_transform")
            st.CreateIdAttr("UsdTransform2d")
            st.CreateInput("in", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
            st.CreateInput("scale", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*tex.uv[0]))
            st.CreateInput("rotation", Sdf.ValueTypeNames.Float).Set(float(tex.uv[1]))
            st.CreateInput("translation", Sdf.ValueTypeNames.Float2).Set(Gf.Vec2f(*tex.uv[2]))
        node.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(st.ConnectableAPI(), "result")
        if tex.scale_bias is not None:
            from pxr import Gf

            node.CreateInput("scale", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*tex.scale_bias[0]))
            node.CreateInput("bias", Sdf.ValueTypeNames.Float4).Set(Gf.Vec4f(*tex.scale_bias[1]))
        if name in SCALAR_TEXTURE_INPUTS:  # a float input: the texture's r channel (the converted texels are grey)
            node.CreateOutput("r", Sdf.ValueTypeNames.Float)
            surface.CreateInput(name, Sdf.ValueTypeNames.Float).ConnectToSource(node.ConnectableAPI(), "r")
        else:
            node.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
            kind = Sdf.ValueTypeNames.Normal3f if name == "normal" else Sdf.ValueTypeNames.Color3f
            surface.CreateInput(name, kind).ConnectToSource(node.ConnectableAPI(), "rgb")
        self.textured_materials.add(mat_path)  # its prims need texture coordinates

    def map_bsdf(self, bsdf, prefix: str = "", cls: str | None = None, back: bool = False,
                 shape=None) -> tuple[dict, list]:
        """UsdPreviewSurface inputs for a Mitsuba BSDF and notes on what the mapping loses.

        Returns ``({input: value}, [notes])``; the table is in spec/bake.md#scene-conversion. Wrappers
        (``twosided``, ``normalmap``, ``bumpmap``, ``mask``, ``blendbsdf``) recurse into their nested BSDFs,
        whose parameters carry ``prefix``; ``back`` maps a twosided BSDF's back side; ``shape``: the shape the
        material is for (a bump map becomes a normal map for its uv layout).
        """
        mi = self.mi
        notes: list[str] = []
        # a nested BSDF's own description (the top-level one shows the first nested BSDF of each kind, not this one)
        own = _Params(mi, bsdf, prefix).bsdf_text() if prefix else None
        text = own if own is not None else str(bsdf)
        cls = _class_name(own) if own is not None else (cls or _class_name(bsdf))
        if cls == "TwoSided":
            k = 1 if back and _two_sides_differ(text) else 0
            inner = re.search(rf"brdf\[{k}\]\s*=\s*(\w+)", text)
            return self.map_bsdf(bsdf, f"{prefix}brdf_{k}.", inner.group(1) if inner else "SmoothDiffuse", shape=shape)
        if cls in WRAPPERS:
            inner = re.search(r"nested_bsdf\s*=\s*(\w+)", text)
            out, notes = self.map_bsdf(bsdf, f"{prefix}nested_bsdf.", inner.group(1) if inner else "SmoothDiffuse",
                                       shape=shape)
            if cls == "Mask":  # Mitsuba's mask is presence: UsdPreviewSurface opacity, threshold 0 (renderer.md#cutouts)
                p = _Params(mi, bsdf, prefix)
                img = p.bitmap("opacity", scalar=True)
                if img is None:
                    out["opacity"] = float(np.clip(p.scalar("opacity", 1.0), 0.0, 1.0))
                    if p.textured or p.unread:  # a procedural opacity (a bitmap one is a texture below)
                        notes.append(f"mask opacity is a texture the converter cannot map: replaced by its mean "
                                     f"{out['opacity']:.3g}")
                else:  # a colour bitmap is read as its luminance, as Mitsuba's mask does
                    lum = np.clip(img @ np.array([0.212671, 0.715160, 0.072169]), 0.0, 1.0)
                    out["opacity"] = p.texture_map("opacity", np.repeat(lum[..., None], 3, -1), "mask opacity")
                    to_uv = p.uv_transform("opacity")
                    if to_uv is not None:
                        out["opacity"].uv = st_transform(to_uv)
                integrator = self.scene.integrator()
                if (img is not None or out["opacity"] < 1.0) and integrator is not None \
                        and _class_name(integrator) == "PathIntegrator":
                    notes.append("mask: Mitsuba's path integrator stops shadow rays at a mask whatever its opacity "
                                 "(measured: no light through opacity 0.25); the converted surface lets 1 - opacity "
                                 "through, as volpath does")
            elif cls == "NormalMap" and (img := (pn := _Params(mi, bsdf, prefix)).bitmap("normalmap")) is not None:
                # tangent-space normals stored as (n + 1) / 2, as UsdPreviewSurface's normal input expects them; the
                # renderer's frame is Mitsuba's (dP/du, N x dP/du, N: renderer.md#normal-maps)
                out["normal"] = pn.texture_map("normalmap", img, "normal map", ((2.0, 2.0, 2.0, 1.0), (-1.0, -1.0, -1.0, 0.0)))
                to_uv = pn.uv_transform("normalmap")
                if to_uv is not None:
                    out["normal"].uv = st_transform(to_uv)
            elif cls == "BumpMap" and (normal := self._bump_map(bsdf, prefix, shape, notes)) is not None:
                out["normal"] = normal
            else:
                notes.append(f"{cls}: the nested BSDF is converted, its {WRAPPERS[cls]} is dropped (the reference "
                             "renderer shades with the mesh normals)")
            return out, notes
        if cls == "BlendBSDF":
            pw = _Params(mi, bsdf, prefix)
            w = float(np.clip(pw.scalar("weight", 0.5), 0.0, 1.0))
            c0, c1 = (re.search(rf"nested_bsdf\[{k}\]\s*=\s*(\w+)", text) for k in (0, 1))
            a, na = self.map_bsdf(bsdf, f"{prefix}bsdf_0.", c0.group(1) if c0 else "SmoothDiffuse", shape=shape)
            b, nb = self.map_bsdf(bsdf, f"{prefix}bsdf_1.", c1.group(1) if c1 else "SmoothDiffuse", shape=shape)
            out, how = blend_inputs(a, b, w)
            textured = pw.bitmap("weight") is not None or bool(pw.textured or pw.unread)
            return out, na + nb + [f"blendbsdf (weight {w:.3g}): {how}"] + (
                [f"blendbsdf weight is a texture: replaced by its mean {w:.3g} (the blend is one mix everywhere)"]
                if textured else [])
        p = _Params(mi, bsdf, prefix)
        spec_wf = {"useSpecularWorkflow": 1}
        if cls == "SmoothDiffuse":
            out = {**spec_wf, "diffuseColor": p.texture_or_rgb("reflectance", (0.5,) * 3, "diffuse reflectance"),
                   "specularColor": (0.0, 0.0, 0.0), "roughness": 1.0}
        elif cls in ("RoughPlastic", "SmoothPlastic"):
            eta = p.scalar("eta", 1.49)
            r = p.rgb("diffuse_reflectance", (0.5,) * 3)
            nonlinear = bool(re.search(r"nonlinear\s*=\s*(1|true)", text))
            kd = r * plastic_diffuse_scale(eta, r if nonlinear else None)
            diffuse = p.texture_or_rgb("diffuse_reflectance", (0.5,) * 3, "plastic diffuse reflectance",
                                       lambda c: np.clip(c * plastic_diffuse_scale(eta, c if nonlinear else None), 0, 1))
            f0 = ((eta - 1.0) / (eta + 1.0)) ** 2 * p.rgb("specular_reflectance", (1.0,) * 3)
            microfacet = None
            if cls == "RoughPlastic":  # Beckmann (Mitsuba's default) written as nasset:microfacet (renderer.md#materials)
                microfacet = "beckmann" if "beckmann" in text else None
                rough = p.scalar_or_texture("alpha", 0.1, "roughplastic alpha", lambda a: np.sqrt(np.maximum(a, 0.0)))
            else:
                rough = 0.0
                notes.append("plastic: smooth specular approximated by GGX with the renderer's minimum roughness")
            notes.append(f"{cls}: dielectric Fresnel (eta {eta:.3g}) approximated by Schlick F0 {f0.mean():.4f}; "
                         f"diffuse_reflectance x {float(np.mean(kd / np.maximum(r, 1e-12))):.3f} for the coating's "
                         "transmission (spec/bake.md#scene-conversion)")
            out = {**spec_wf, "diffuseColor": diffuse, "specularColor": np.clip(f0, 0, 1), "roughness": rough}
            if microfacet:
                out["microfacet"] = microfacet
        elif cls in ("SmoothConductor", "RoughConductor"):
            eta, k = p.rgb("eta", (0.0,) * 3), p.rgb("k", (1.0,) * 3)
            f0 = ((eta - 1.0) ** 2 + k * k) / np.maximum((eta + 1.0) ** 2 + k * k, 1e-12)
            f0 = f0 * p.rgb("specular_reflectance", (1.0,) * 3)
            microfacet = None
            if cls == "RoughConductor":  # Beckmann (Mitsuba's default) written as nasset:microfacet
                microfacet = "beckmann" if "beckmann" in text else None
                if p.has("alpha"):
                    rough = p.scalar_or_texture("alpha", 0.1, "roughconductor alpha", lambda a: np.sqrt(np.maximum(a, 0.0)))
                else:
                    au, av = p.scalar("alpha_u", 0.1), p.scalar("alpha_v", 0.1)
                    if abs(au - av) > 1e-6:
                        notes.append(f"anisotropic roughness ({au:.3g}, {av:.3g}) replaced by their mean")
                    rough = math.sqrt(max(0.5 * (au + av), 0.0))
            else:
                rough = 0.0
                notes.append("conductor: mirror approximated by GGX with the renderer's minimum roughness")
            notes.append(f"{cls}: complex Fresnel approximated by Schlick with F0 {np.round(f0, 4).tolist()}")
            out = {"useSpecularWorkflow": 0, "metallic": 1.0, "diffuseColor": np.clip(f0, 0, 1), "roughness": rough}
            if microfacet:
                out["microfacet"] = microfacet
        elif cls == "Principled":
            spec = p.scalar("specular", 0.5)
            s = math.sqrt(min(max(0.08 * spec, 0.0), 0.99))
            out = {"useSpecularWorkflow": 0, "diffuseColor": p.texture_or_rgb("base_color", (0.5,) * 3, "principled base_color"),
                   "metallic": p.scalar_or_texture("metallic", 0.0, "principled metallic"),
                   "roughness": p.scalar_or_texture("roughness", 0.5, "principled roughness"),
                   "ior": (1.0 + s) / (1.0 - s)}
            for lobe in ("clearcoat", "sheen", "spec_trans", "anisotropic", "flatness"):
                if p.scalar(lobe, 0.0) > 0:
                    notes.append(f"principled {lobe} ignored")
        elif cls == "Hair":  # a fibre's colour: the absorption's inverse of Chiang et al.'s colour mapping
            colour = hair_colour(p)
            notes.append(f"hair BSDF written as a diffuse surface of its colour {np.round(colour, 3).tolist()} (from its "
                         "absorption); a fur or hair is better baked (nasset bake --kind rna) and put in place with --replace")
            eta = p.scalar("eta", 1.55)
            f0 = ((eta - 1.0) / (eta + 1.0)) ** 2  # the cuticle's reflection (its R lobe), rough as the fibre is
            out = {**spec_wf, "diffuseColor": colour, "specularColor": (f0,) * 3,
                   "roughness": float(np.clip(p.scalar("longitudinal_roughness", 0.3), 0.0, 1.0))}
        elif cls in ("SmoothDielectric", "RoughDielectric", "ThinDielectric"):
            eta = p.scalar("eta", 1.5)
            rough = 0.0
            if cls == "RoughDielectric":
                beckmann = "beckmann" in text
                rough = math.sqrt(float(ggx_alpha_of_beckmann(p.scalar("alpha", 0.1)) if beckmann
                                        else max(p.scalar("alpha", 0.1), 0.0)))
                if beckmann:
                    notes.append(f"{cls}: Beckmann distribution approximated by GGX (alpha x 0.82-0.93, "
                                 "usd_export.ggx_alpha_of_beckmann)")
            else:
                notes.append(f"{cls}: smooth glass approximated by GGX with the renderer's minimum roughness")
            tint = np.clip(p.rgb("specular_transmittance", (1.0,) * 3), 0.0, 1.0)
            reflect = np.clip(p.rgb("specular_reflectance", (1.0,) * 3), 0.0, 1.0)
            f0 = ((eta - 1.0) / (eta + 1.0)) ** 2
            # UsdPreviewSurface has no transmission: its output keeps the opaque black reflector for renderers that
            # read only it; the renderers here read the MaterialX glass (renderer.md#transmission)
            out = {**spec_wf, "diffuseColor": (0.0, 0.0, 0.0), "specularColor": (f0,) * 3, "roughness": rough,
                   "glass": Glass(1.0, tuple(float(c) for c in tint), float(eta), float(rough), cls == "ThinDielectric",
                                  specular=tuple(float(c) for c in reflect))}
        else:
            color = next((p.rgb(k) for k in ("reflectance", "diffuse_reflectance", "base_color", "albedo")
                          if p.has(k)), None)
            notes.append(f"BSDF {cls} is not convertible: written as diffuse with "
                         + ("its reflectance" if color is not None else "grey 0.5 (it has no reflectance to keep)"))
            out = {**spec_wf, "diffuseColor": (0.5, 0.5, 0.5) if color is None else np.clip(color, 0, 1),
                   "specularColor": (0.0, 0.0, 0.0), "roughness": 1.0}
        for t in p.textured:
            notes.append(f"{cls}.{t} is a procedural texture: replaced by the mean of its colours (linear)")
        for t in p.unread:
            notes.append(f"{cls}.{t} is a texture the converter cannot evaluate: Mitsuba's default for it is used")
        converted = {id(v) for v in out.values()}
        for t, tm in p.bitmaps.items():
            if id(tm) not in converted:
                continue
            to_uv = p.uv_transform(t)
            if to_uv is not None:
                tm.uv = st_transform(to_uv)
                if tm.uv is None:
                    notes.append(f"{cls}.{t}: texture to_uv transform with shear ignored (UsdTransform2d scales, "
                                 "rotates and translates)")
        for k in p.p.keys():
            name = k[len(prefix):-len(".data")] if k.startswith(prefix) and k.endswith(".data") else None
            if name and name not in p.bitmaps:
                notes.append(f"{cls}.{name} is a bitmap texture on a parameter that is not converted as a texture: "
                             "replaced by its linear mean")
        return out, notes

    # -- shapes -------------------------------------------------------------------------------
    def shapes(self) -> None:
        for k, shape in enumerate(self.scene.shapes()):
            sid = shape.id() or f"shape_{k}"
            if shape.id() in self.replace:
                continue
            self._shape(shape, sid)

    def _instance(self, shape, sid) -> None:
        """An ``instance`` of a ``shapegroup``: an instanceable Xform referencing the group's prototype, a class prim
        ``/Prototypes/GROUP`` holding the group's shapes and their materials (written once)."""
        from pxr import Sdf

        m = re.search(r'name\s*=\s*"([^"]*)"', str(shape))
        group = m.group(1) if m else ""
        proto = self.prototypes.get(group)
        if proto is None:
            children = shapegroup_children(self.mi, self.scene, group)
            from pxr import Tf

            proto = f"/Prototypes/{Tf.MakeValidIdentifier(group or 'group')}"
            self.stage.CreateClassPrim("/Prototypes")  # abstract: never rendered itself, only through instances
            self.stage.CreateClassPrim(proto)
            saved = (self.geometry_root, self.looks_root)
            self.geometry_root, self.looks_root = proto, f"{proto}/Looks"
            try:
                for cid, child in children.items():
                    self._shape(child, cid)
            finally:
                self.geometry_root, self.looks_root = saved
            self.prototypes[group] = proto
            self.record(proto, f"shapegroup {group} ({len(children)} shapes)")
        path = self._name(self.geometry_root, sid)
        prim = self.stage.DefinePrim(path, "Xform")
        prim.GetReferences().AddInternalReference(Sdf.Path(proto))
        prim.SetInstanceable(True)
        self._xform(prim, _row(_matrix(self.mi.traverse(shape)["to_world"])))
        self.record(path, f"instance {sid} of shapegroup {group}")

    def _shape(self, shape, sid) -> None:
        """Write one Mitsuba shape under ``geometry_root`` (the table in spec/bake.md#scene-conversion)."""
        cls = _class_name(shape)
        if cls == "Instance":
            self._instance(shape, sid)
            return
        for med, side in ((shape.interior_medium(), "interior"), (shape.exterior_medium(), "exterior")):
            if med is not None:
                self.warn(f"shape {sid}: {side} medium ({_class_name(med)}) ignored (no participating media in USD "
                          "preview shading); bake the object into a neural asset (--replace)")
        bsdf_cls = _class_name(shape.bsdf()) if shape.bsdf() is not None else ""
        emitter = shape.emitter()
        if cls == "Sphere" and not np.array_equal(self._to_world(shape), _matrix(self.mi.traverse(shape)["to_world"])):
            scales = np.linalg.norm(_matrix(self.mi.traverse(shape)["to_world"])[:3, :3], axis=0)
            self.warn(f"shape {sid}: sphere to_world scales its axes by {np.round(scales, 4).tolist()}: written as Mitsuba "
                      f"draws it, a sphere of radius {scales[0]:.4g} (the scale along its x axis)")
        if bsdf_cls == "Null":
            self.warn(f"shape {sid}: null BSDF (index-matched boundary): skipped" + (
                "; its area emitter too (Mitsuba's path tracer does not show it to the camera and lights the scene from "
                "it through emitter samples only, which no USD light reproduces)" if emitter is not None else ""))
            return
        emission = None if emitter is None else self._textured_radiance(emitter)
        if emitter is not None and emission is None and cls in ("Rectangle", "Disk", "Sphere"):
            self._area_light(shape, sid, cls, emitter)
            return
        if emitter is not None:  # a mesh light, or a textured emitter on any shape (UsdLux lights have no texture)
            from nasset_reference_renderer.lights import MAX_MESH_LIGHT_TRIANGLES

            if emission is None:
                p = _Params(self.mi, emitter)
                emission = p.rgb("radiance")
                self._unread(f"shape {sid}", p)
            n_tri = int(np.asarray(self.mi.traverse(shape)["faces"]).size // 3) if "faces" in self.mi.traverse(shape) else 0
            if self.hide_emitters:
                self.warn(f"shape {sid}: the integrator hides emitters from the camera, but an emitting mesh shows its "
                          "emission to camera rays in the reference renderer (only UsdLux lights can be hidden)")
            if n_tri > MAX_MESH_LIGHT_TRIANGLES:
                self.warn(f"shape {sid}: area emitter on a {cls} of {n_tri} triangles written as emissiveColor: the "
                          f"reference renderer light-samples emissive meshes of at most {MAX_MESH_LIGHT_TRIANGLES} "
                          "triangles only; this one is reached by BSDF rays only: right mean, more noise")
        if cls in MESH_CLASSES or "vertex_positions" in self.mi.traverse(shape):
            self._mesh(shape, sid, cls, emission)
        elif cls in ("Rectangle", "Sphere", "Disk", "Cylinder"):
            self._analytic(shape, sid, cls, emission)
        elif cls in ("LinearCurve", "BSplineCurve", "BSpline"):
            self._curves(shape, sid, cls, emission)
        else:
            self.warn(f"shape {sid}: {cls} is not convertible (obj, ply, serialized, cube, rectangle, disk, sphere, "
                      f"cylinder, linearcurve, bsplinecurve are): skipped")

    def _analytic(self, shape, sid, cls, emission, placed: np.ndarray | None = None) -> None:
        """A ``rectangle``, ``sphere``, ``disk`` or ``cylinder``; ``placed`` [4, 4]: a world transform applied after the
        shape's own (an emitter's surface set back behind its light, :meth:`_light_surface`)."""
        m = self._to_world(shape) if placed is None else placed @ self._to_world(shape)
        if cls == "Rectangle":
            pts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float64)
            uv = 0.5 * (pts[:, :2] + 1.0)  # Mitsuba's rectangle parameterisation
            self._write_mesh(sid, pts, np.array([[0, 1, 2, 3]]), np.tile([0.0, 0.0, 1.0], (4, 1)),
                             shape, cls, emission, local_to_world=True, uv=uv, to_world=m)
        elif cls == "Sphere":
            self._sphere(shape, sid, emission, to_world=m)
        else:  # world space, the tessellation bakes use (spec/bake.md#analytic-shapes)
            pts, faces, nrm = analytic.world_mesh(self.mi, shape)
            if placed is None:
                self.warn(f"shape {sid}: {cls.lower()} tessellated into {len(faces)} triangles")
            else:
                pts = pts @ placed[:3, :3].T + placed[:3, 3]
            self._write_mesh(sid, pts, faces, nrm, shape, cls, emission, uv=analytic.corner_uv(cls))

    def _light_surface(self, shape, sid, cls) -> None:
        """The surface of a Mitsuba emitter shape written as a UsdLux light: the shape with its BSDF, set back behind
        the light's emitting side by :data:`LIGHT_SURFACE_SET_BACK` of its size (a sphere shrunk by it about its
        centre). In Mitsuba the shape is opaque: it shadows the scene's other lights and shows its back (black for a
        one-sided BSDF); a light surface occludes nothing (renderer.md#light-surfaces), and rays that reach the
        light's emitting side end there (``nasset:opaqueSurface``), before its surface."""
        m = self._to_world(shape)
        placed = np.eye(4)
        if cls == "Sphere":
            placed[:3, :3] *= 1.0 - LIGHT_SURFACE_SET_BACK
            placed[:3, 3] = LIGHT_SURFACE_SET_BACK * m[:3, 3]
        else:
            size = float(max(np.linalg.norm(m[:3, 0]), np.linalg.norm(m[:3, 1])))
            placed[:3, 3] = -LIGHT_SURFACE_SET_BACK * size * sampled_normal(self.mi, shape)[1]
        self._analytic(shape, sid, cls, None, placed=placed)

    def _curves(self, shape, sid, cls, emission) -> None:
        """A ``linearcurve`` / ``bsplinecurve`` as UsdGeom.BasisCurves (``linear``, or ``cubic`` ``bspline``) of its
        world-space control points, widths twice their radii: the renderer's tubes (renderer.md#curves-and-points).
        A light hair or fur is better baked (nasset bake --kind rna) and put in place with --replace."""
        from pxr import UsdGeom, Vt

        p = self.mi.traverse(shape)
        cp = np.asarray(p["control_points"], np.float64).reshape(-1, 4)
        seg = np.asarray(p["segment_indices"], np.int64).ravel()
        reach = 1 if cls == "LinearCurve" else 3  # the control points a segment uses after its first (B-spline: 3)
        breaks = np.flatnonzero(np.diff(seg) != 1) + 1  # a new curve where the segments stop following each other
        runs = np.split(seg, breaks) if len(seg) else []
        idx = np.concatenate([np.arange(r[0], r[-1] + reach + 1) for r in runs]) if runs else np.zeros(0, np.int64)
        if emission is not None:
            self.warn(f"shape {sid}: area emitter on a {cls} dropped (the curves are converted, not their emission)")
        path = self._name(self.geometry_root, sid)
        curves = UsdGeom.BasisCurves.Define(self.stage, path)
        curves.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(cp[idx, :3], np.float32)))
        curves.CreateCurveVertexCountsAttr(Vt.IntArray.FromNumpy(np.array([len(r) + reach for r in runs], np.int32)))
        curves.CreateTypeAttr(UsdGeom.Tokens.linear if cls == "LinearCurve" else UsdGeom.Tokens.cubic)
        curves.CreateBasisAttr(UsdGeom.Tokens.bspline)
        curves.CreateWrapAttr(UsdGeom.Tokens.nonperiodic)
        curves.CreateWidthsAttr(Vt.FloatArray.FromNumpy(np.ascontiguousarray(2.0 * cp[idx, 3], np.float32)))
        curves.SetWidthsInterpolation(UsdGeom.Tokens.vertex)
        self._bind(curves.GetPrim(), shape, sid, None)
        self.warn(f"shape {sid}: {cls} of {len(runs)} curves written as BasisCurves (rendered as 8-sided tubes; a fur or "
                  f"hair is better baked: nasset bake --kind rna --asset {sid}, then --replace {sid}=ASSET)")
        self.record(path, f"shape {sid} ({cls}, {len(runs)} curves, {len(idx)} control points)")

    def _bind(self, prim, shape, sid, emission) -> str:
        from pxr import UsdShade

        mat_path = self.material(shape.bsdf(), sid, emission, shape=shape)
        UsdShade.MaterialBindingAPI.Apply(prim).Bind(UsdShade.Material(self.stage.GetPrimAtPath(mat_path)))
        if _has_back_bsdf(shape.bsdf()) or (emission is not None and not _is_one_sided(shape.bsdf())):
            # the back side's own material (spec/renderer.md#sidedness): no USD schema names one. Mitsuba's area
            # emitter emits from the front only, so the back material of an emitter has no emission.
            back = self.material(shape.bsdf(), sid, None, back=True, shape=shape)
            prim.CreateRelationship("nasset:backMaterial", custom=True).SetTargets([back])
        return mat_path

    def _one_sided(self, gprim, shape) -> None:
        """Author ``doubleSided = false`` for a one-sided BSDF (black from behind in Mitsuba and in the renderer)."""
        if _is_one_sided(shape.bsdf()):
            gprim.CreateDoubleSidedAttr(False)

    @staticmethod
    def _sided(shape, emission) -> bool:
        """True when the shape's front side shows: a one-sided BSDF, a twosided one with two BSDFs, an emitter, or a
        solid dielectric (its front is its outside)."""
        return (emission is not None or _is_one_sided(shape.bsdf()) or _has_back_bsdf(shape.bsdf())
                or (shape.bsdf() is not None and _class_name(shape.bsdf()) in ("SmoothDielectric", "RoughDielectric")))

    def _mesh(self, shape, sid, cls, emission) -> None:
        p = self.mi.traverse(shape)
        pts = _np(p["vertex_positions"]).reshape(-1, 3)
        faces = np.asarray(p["faces"], np.int64).reshape(-1, 3)
        nrm = _np(p["vertex_normals"]).reshape(-1, 3) if "vertex_normals" in p else None
        if nrm is not None and nrm.shape != pts.shape:
            nrm = None
        uv = _np(p["vertex_texcoords"]).reshape(-1, 2) if "vertex_texcoords" in p else None
        if uv is not None and len(uv) != len(pts):
            uv = None
        if uv is None and self.material(shape.bsdf(), sid, emission, shape=shape) in self.textured_materials:
            uv = np.tile(BARYCENTRIC_UV, (len(faces), 1, 1))  # Mitsuba's uv on a mesh without them: (b1, b2)
        self._write_mesh(sid, pts, faces, nrm, shape, cls, emission, uv=uv)

    def _write_mesh(self, sid, pts, faces, normals, shape, cls, emission, local_to_world=False, uv=None,
                    to_world: np.ndarray | None = None) -> None:
        """A UsdGeom.Mesh; ``uv`` in Mitsuba's convention (v = 0 at the image's top row), per point [V, 2] or per face
        corner [F, 3, 2], becomes the vertex or faceVarying primvar ``st = (u, 1 - v)`` (USD: t = 0 at the bottom
        row). ``local_to_world``: ``pts`` are in the shape's local space, placed by ``to_world`` (default the shape's)."""
        from pxr import Sdf, UsdGeom, Vt

        m = (self._to_world(shape) if to_world is None else to_world) if local_to_world else np.eye(4)
        if self._sided(shape, emission) and abs(np.linalg.det(m[:3, :3])) > 1e-300:  # (a flat transform has no sides)
            world = pts @ m[:3, :3].T + m[:3, 3]
            wn = None if normals is None else normals @ np.linalg.inv(m[:3, :3])  # the inverse transpose, on rows
            turn = turned_faces(self.mi, shape, world, faces, wn, mirrored=bool(np.linalg.det(m[:3, :3]) < 0))
            faces = np.where(turn[:, None], np.asarray(faces)[:, ::-1], faces)
            if uv is not None and uv.ndim == 3:  # a face's corners turn with it
                uv = np.where(turn[:, None, None], uv[:, ::-1], uv)
        path = self._name(self.geometry_root, sid)
        mesh = UsdGeom.Mesh.Define(self.stage, path)
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(pts, np.float32)))
        faces = np.asarray(faces, np.int32)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.full(len(faces), faces.shape[1], np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(faces.ravel())))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
        if normals is not None:
            mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(normals, np.float32)))
            mesh.SetNormalsInterpolation(UsdGeom.Tokens.vertex)
        lo, hi = np.asarray(pts, np.float32).min(0), np.asarray(pts, np.float32).max(0)
        mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([lo, hi])))
        if uv is not None:
            interp = UsdGeom.Tokens.faceVarying if uv.ndim == 3 else UsdGeom.Tokens.vertex
            uv = uv.reshape(-1, 2)
            st = np.stack([uv[:, 0], 1.0 - uv[:, 1]], 1)
            pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, interp)
            pv.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(st, np.float32)))
        if local_to_world:
            self._xform(mesh.GetPrim(), _row(m))
        mat = self._bind(mesh.GetPrim(), shape, sid, emission)
        if mat in self.color_primvars:
            self._color_primvar(mesh, shape, sid, self.color_primvars[mat], len(pts), len(faces))
        self._one_sided(mesh, shape)
        self.record(path, f"shape {sid} ({cls}, {len(faces)} faces)")

    def _color_primvar(self, mesh, shape, sid, want: ColorPrimvar, n_points: int, n_faces: int) -> None:
        """The shape's attribute ``want.attribute`` (``vertex_*`` per point, ``face_*`` per face; 1 or 3 channels) times
        ``want.scale`` as the colour primvar its material reads (renderer.md#primvar-colors)."""
        from pxr import Sdf, UsdGeom, Vt

        name = want.attribute
        values = None
        if hasattr(shape, "has_attribute") and shape.has_attribute(name):
            values = np.asarray(shape.attribute_buffer(name), np.float64)
        per, interp = (n_points, UsdGeom.Tokens.vertex) if name.startswith("vertex_") else (n_faces, UsdGeom.Tokens.uniform)
        if values is None or values.size not in (per, 3 * per):
            self.warn(f"shape {sid}: its BSDF reads mesh attribute {name!r}, which the shape lacks (or of another size): "
                      "the reader's fallback (grey) is used")
            return
        rgb = np.repeat(values.reshape(per, 1), 3, 1) if values.size == per else values.reshape(per, 3)
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar(want.primvar, Sdf.ValueTypeNames.Color3fArray, interp)
        pv.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(rgb * want.scale, np.float32)))

    def _sphere(self, shape, sid, emission, to_world: np.ndarray | None = None) -> None:
        """A ``sphere`` placed by ``to_world`` (default the shape's as Mitsuba draws it)."""
        from pxr import Gf, UsdGeom

        m = self._to_world(shape) if to_world is None else to_world
        if self.material(shape.bsdf(), sid, emission, shape=shape) in self.textured_materials:
            pts, faces, uv = latlong_sphere()  # textured: a mesh carrying Mitsuba's sphere parameterisation
            self._write_mesh(sid, pts, faces, pts.copy(), shape, "Sphere", emission, local_to_world=True, uv=uv,
                             to_world=m)
            return
        path = self._name(self.geometry_root, sid)
        sph = UsdGeom.Sphere.Define(self.stage, path)
        sph.CreateRadiusAttr(1.0)
        sph.CreateExtentAttr([Gf.Vec3f(-1, -1, -1), Gf.Vec3f(1, 1, 1)])
        self._xform(sph.GetPrim(), _row(m))
        self._bind(sph.GetPrim(), shape, sid, emission)
        self._one_sided(sph, shape)
        if self._sided(shape, emission):
            p, n = sampled_normal(self.mi, shape)
            if float(n @ (p - m[:3, 3])) < 0.0:  # Mitsuba's front is the inside (flip_normals, or a mirror)
                sph.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
        self.record(path, f"shape {sid} (Sphere)")

    # -- lights -------------------------------------------------------------------------------
    def _light_common(self, light, rgb, prim_path: str, what: str) -> None:
        from pxr import Gf

        rgb = np.maximum(_np(rgb), 0.0)
        peak = float(rgb.max())
        light.CreateIntensityAttr(peak)
        light.CreateExposureAttr(0.0)
        light.CreateColorAttr(Gf.Vec3f(*(rgb / peak if peak > 0 else np.ones(3)).tolist()))
        light.CreateNormalizeAttr(False)
        if self.hide_emitters:  # Mitsuba's hide_emitters: camera rays pass through (renderer.md#light-surfaces)
            from pxr import Sdf

            light.GetPrim().CreateAttribute("nasset:cameraVisibility", Sdf.ValueTypeNames.Bool, custom=True).Set(False)
        self.record(prim_path, what)

    def _textured_radiance(self, emitter) -> TextureMap | None:
        """An area emitter's bitmap ``radiance`` as a :class:`TextureMap` (its ``to_uv`` as a UsdTransform2d): the
        shape becomes a mesh with a textured emissiveColor (renderer.md#textures); None for a constant radiance."""
        p = _Params(self.mi, emitter)
        img = p.bitmap("radiance")
        if img is None:
            return None
        tex = p.texture_map("radiance", img, "emitter radiance")
        if (to_uv := p.uv_transform("radiance")) is not None:
            tex.uv = st_transform(to_uv)
        return tex

    def _area_light(self, shape, sid, cls, emitter) -> None:
        from pxr import Sdf

        p = _Params(self.mi, emitter)
        radiance = p.rgb("radiance")
        self._unread(f"shape {sid}", p)
        bsdf_params = _Params(self.mi, shape.bsdf())
        if any(k.endswith("reflectance.value") and np.any(bsdf_params.rgb(k[: -len(".value")]) > 0) for k in bsdf_params.keys()):
            self.warn(f"shape {sid}: the reflectance of the emitting {cls}'s emitting side is dropped (rays end at its "
                      "light); its other side keeps it")
        m = self._to_world(shape)
        path = self._name("/World/Lights", sid)
        light = self._area_light_prim(shape, cls, m, radiance, path, sid)
        # Mitsuba's emitter shape is opaque: rays end on it (renderer.md#light-surfaces; Cycles' lights occlude nothing),
        # and its surface behind the light shadows the other lights
        light.GetPrim().CreateAttribute("nasset:opaqueSurface", Sdf.ValueTypeNames.Bool, custom=True).Set(True)
        self._light_surface(shape, sid, cls)

    def _area_light_prim(self, shape, cls, m, radiance, path, sid):
        """The UsdLux light of an area emitter on a Mitsuba rectangle, disk or sphere (its transform ``m``)."""
        from pxr import UsdLux

        if cls in ("Rectangle", "Disk"):  # the local [-1, 1]^2 square or unit disk, as a RectLight or DiskLight
            if cls == "Rectangle":
                light = UsdLux.RectLight.Define(self.stage, path)
                light.CreateWidthAttr(2.0)
                light.CreateHeightAttr(2.0)
            else:
                light = UsdLux.DiskLight.Define(self.stage, path)
                light.CreateRadiusAttr(1.0)
            rows = _FLIP_RECT @ _row(m)
            if float(np.cross(rows[0, :3], rows[1, :3]) @ sampled_normal(self.mi, shape)[1]) > 0.0:
                rows = np.diag([-1.0, 1.0, -1.0, 1.0]) @ rows  # it emits along -(e_x x e_y): turn it to Mitsuba's side
            self._xform(light.GetPrim(), rows)
            self._light_common(light, radiance, path, f"area emitter on {cls.lower()} {sid}")
        else:
            light = UsdLux.SphereLight.Define(self.stage, path)
            light.CreateRadiusAttr(float(np.linalg.norm(m[:3, 0])))
            light.CreateTreatAsPointAttr(False)
            self._xform(light.GetPrim(), _frame_row([0.0, 0.0, 1.0], m[:3, 3]))
            self._light_common(light, radiance, path, f"area emitter on sphere {sid}")
        return light

    def lights(self) -> None:
        from pxr import UsdLux

        for k, em in enumerate(self.scene.emitters()):
            cls = _class_name(em)
            if cls == "AreaLight":
                continue  # handled with its shape
            eid = em.id() or f"emitter_{k}"
            p = _Params(self.mi, em)
            if cls == "DirectionalEmitter":
                m = _matrix(p.p["to_world"])
                path = self._name("/World/Lights", eid)
                light = UsdLux.DistantLight.Define(self.stage, path)
                light.CreateAngleAttr(0.0)
                self._xform(light.GetPrim(), _frame_row(-m[:3, 2]))
                self._light_common(light, p.rgb("irradiance"), path, f"emitter {eid} (directional)")
            elif cls == "PointLight":
                path = self._name("/World/Lights", eid)
                light = UsdLux.SphereLight.Define(self.stage, path)
                light.CreateRadiusAttr(0.0)
                light.CreateTreatAsPointAttr(True)
                self._xform(light.GetPrim(), _frame_row([0.0, 0.0, 1.0], _np(p.p["position"]).ravel()[:3]))
                self._light_common(light, p.rgb("intensity"), path, f"emitter {eid} (point)")
            elif cls == "SpotLight":
                m = _matrix(p.p["to_world"])
                path = self._name("/World/Lights", eid)
                light = UsdLux.SphereLight.Define(self.stage, path)
                light.CreateRadiusAttr(0.0)
                light.CreateTreatAsPointAttr(True)
                cutoff = p.scalar("cutoff_angle", 20.0)
                beam = p.scalar("beam_width", cutoff * 0.75)
                shaping = UsdLux.ShapingAPI.Apply(light.GetPrim())
                shaping.CreateShapingConeAngleAttr(cutoff)
                shaping.CreateShapingConeSoftnessAttr(float(np.clip((cutoff - beam) / max(cutoff, 1e-9), 0.0, 1.0)))
                self._xform(light.GetPrim(), _FLIP_CAMERA @ _row(m))  # USD shaping emits along -Z
                self._light_common(light, p.rgb("intensity"), path, f"emitter {eid} (spot, cutoff {cutoff:.3g} deg)")
                if p.textured:
                    self.warn(f"emitter {eid}: spot texture ignored")
            elif cls == "ConstantBackgroundEmitter":
                path = self._name("/World/Lights", eid)
                light = UsdLux.DomeLight.Define(self.stage, path)
                self._light_common(light, p.rgb("radiance"), path, f"emitter {eid} (constant)")
            elif cls == "EnvironmentMapEmitter":
                self._envmap(em, eid, p)
            elif cls == "SunskyEmitter":
                self._sunsky(em, eid)
            else:
                self.warn(f"emitter {eid}: {cls} is not convertible (directional, point, spot, area on "
                          "rectangle/sphere, constant, envmap, sunsky are): skipped")
            self._unread(f"emitter {eid}", p)

    def _unread(self, what: str, p) -> None:
        """Warn about parameters of ``p`` (a :class:`_Params`) present in the scene but of a kind the reader cannot
        evaluate: their default was written (a light would otherwise go dark without a word)."""
        for name in p.unread:
            self.warn(f"{what}: {name} is a texture or spectrum the converter cannot evaluate: its default is used")

    def _envmap(self, em, eid, p) -> None:
        data = _np(p.p["data"])
        if data.ndim != 3:
            self.warn(f"emitter {eid}: envmap data of shape {data.shape} not understood: skipped")
            return
        image = data[:, 1:-1, :3] if data.shape[1] > 2 else data[..., :3]  # Mitsuba pads one wrap column per side
        if image.shape[-1] == 1:
            image = np.repeat(image, 3, -1)
        m = _matrix(p.p["to_world"])
        scales = np.linalg.norm(m[:3, :3], axis=0)
        if not np.allclose(scales, 1.0, rtol=1e-4):
            self.warn(f"emitter {eid}: envmap to_world scales its axes by {np.round(scales, 4).tolist()}: Mitsuba looks the "
                      "map up with the unnormalised directions this gives, and its lighting does not follow that lookup "
                      "(measured: scale 3 lit 10 % darker than the converted dome, which follows the lookup); remove the "
                      "scale")
        rot = m[:3, :3] / np.maximum(scales, 1e-300)
        row = np.eye(4)
        row[:3, :3] = rot.T
        resampled = self._envmap_resampled(em, image.shape[:2], (_FLIP_DOME @ row)[:3, :3], p.scalar("scale", 1.0))
        if resampled is None:
            self.warn(f"emitter {eid}: envmap looked up with nearest texels by the reference renderer (Mitsuba: bilinear)")
        else:
            image = resampled
        self._dome(eid, image, row, p.scalar("scale", 1.0), f"envmap {image.shape[1]}x{image.shape[0]}")

    def _dome(self, eid: str, image: np.ndarray, row: np.ndarray, scale: float, what: str) -> None:
        """A lat-long DomeLight of ``image`` [H, W, 3] (written as OpenEXR beside the output) times ``scale``, its
        transform ``_FLIP_DOME @ row`` (the renderer's lookup of Mitsuba's, spec/bake.md#lights)."""
        from pxr import Gf, Sdf, Tf, UsdLux

        from nasset_reference_renderer.film import write_exr

        tex = self._texture_file(Tf.MakeValidIdentifier(eid))
        write_exr(tex, image.astype(np.float32))
        rel = "./" + tex.relative_to(self.output.parent).as_posix()  # anchored: never a search-path lookup
        self.result.textures.append(str(tex))
        path = self._name("/World/Lights", eid)
        light = UsdLux.DomeLight.Define(self.stage, path)
        light.CreateTextureFileAttr(Sdf.AssetPath(rel))
        light.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
        self._xform(light.GetPrim(), _FLIP_DOME @ row)
        self._light_common(light, np.full(3, scale), path, f"emitter {eid} ({what})")
        light.GetColorAttr().Set(Gf.Vec3f(1.0, 1.0, 1.0))

    def _sunsky(self, em, eid: str) -> None:
        """Mitsuba's ``sunsky`` as it renders: its sky (``sun_scale`` 0) resampled with Mitsuba's own lookup into a
        lat-long DomeLight, as an envmap is, and its sun (``sky_scale`` 0) a DistantLight of the sun's aperture whose
        irradiance is the sun's radiance integrated over its disk (spec/bake.md#lights)."""
        from pxr import UsdLux

        params = self.mi.traverse(em)
        sun_scale, sky_scale = float(params["sun_scale"]), float(params["sky_scale"])
        aperture = float(re.search(r"Sun aperture\s*=\s*([0-9.eE+-]+)", str(em)).group(1))
        sun = _np(params["sun_direction"]).ravel()[:3]
        sun = sun / max(float(np.linalg.norm(sun)), 1e-300)  # world space (Mitsuba's to_world does not move it)
        try:
            params["sun_scale"] = 0.0
            params.update()
            sky = self._envmap_resampled(em, SUNSKY_HW, _FLIP_DOME[:3, :3], 1.0)  # world directions: no rotation
            params["sun_scale"], params["sky_scale"] = sun_scale, 0.0
            params.update()
            irradiance = self._cap_irradiance(em, sun, math.radians(aperture) * 0.5 * 1.25)
        finally:
            params["sun_scale"], params["sky_scale"] = sun_scale, sky_scale
            params.update()
        if sky is None:
            self.warn(f"emitter {eid}: sunsky is evaluated with Mitsuba's JIT variants only (this is a scalar one): "
                      "skipped")
            return
        self._dome(eid, sky, np.eye(4), 1.0, f"sunsky's sky {sky.shape[1]}x{sky.shape[0]}")
        path = self._name("/World/Lights", f"{eid}_sun")
        light = UsdLux.DistantLight.Define(self.stage, path)
        light.CreateAngleAttr(aperture)
        self._xform(light.GetPrim(), _frame_row(sun))
        self._light_common(light, irradiance, path, f"emitter {eid} (sunsky's sun, {aperture:.4g} deg)")

    def _cap_irradiance(self, em, axis: np.ndarray, half_angle: float, n: int = 128) -> np.ndarray:
        """Irradiance [3] at normal incidence from the directions within ``half_angle`` (radians) of ``axis``: the
        emitter's own radiance (``em.eval``) on an n x 4n grid uniform in solid angle, times the cap's solid angle."""
        mi = self.mi
        u = (np.arange(n) + 0.5) / n
        cos_t = 1.0 - u * (1.0 - math.cos(half_angle))
        phi = (np.arange(4 * n) + 0.5) / (4 * n) * 2.0 * np.pi
        ct, ph = np.meshgrid(cos_t, phi, indexing="ij")
        st = np.sqrt(np.maximum(1.0 - ct * ct, 0.0))
        t = np.cross(axis, [0.0, 1.0, 0.0] if abs(axis[1]) < 0.9 else [1.0, 0.0, 0.0])
        t /= np.linalg.norm(t)
        b = np.cross(axis, t)
        d = (st * np.cos(ph))[..., None] * t + (st * np.sin(ph))[..., None] * b + ct[..., None] * axis
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d.reshape(-1, 3).T).astype(np.float32))
        val = em.eval(si)
        rgb = np.stack([np.asarray(val[c], np.float64).ravel() for c in range(3)], 1)
        return rgb.mean(0) * 2.0 * np.pi * (1.0 - math.cos(half_angle))

    def _envmap_resampled(self, em, hw, rotation, scale: float) -> np.ndarray | None:
        """Mitsuba's own (bilinear) envmap radiance / ``scale`` at the texel centres of a lat-long map of
        up to ENVMAP_UPSAMPLE x the size ``hw``, in the renderer's convention (spec/renderer.md#lights) for a dome
        whose local-to-world rotation is ``rotation`` (3x3, rows): the renderer's nearest-texel lookup then
        follows Mitsuba's interpolation. None where it cannot be evaluated (scalar variants, size bounds)."""
        mi = self.mi
        f = ENVMAP_UPSAMPLE
        while f > 1 and hw[0] * hw[1] * f * f > ENVMAP_MAX_PIXELS:
            f //= 2
        h, w = hw[0] * f, hw[1] * f
        if mi.variant().startswith("scalar") or h * w > ENVMAP_MAX_PIXELS or scale <= 0:
            return None
        v, u = np.meshgrid((np.arange(h) + 0.5) / h, (np.arange(w) + 0.5) / w, indexing="ij")
        phi, theta = (u.ravel() - 0.5) * 2.0 * np.pi, v.ravel() * np.pi
        local = np.stack([np.sin(theta) * np.sin(phi), np.cos(theta), -np.sin(theta) * np.cos(phi)], 1)
        d = local @ rotation  # world direction the renderer looks up at each texel
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d.T).astype(np.float32))  # the emitter sees the ray arriving along d
        val = em.eval(si)
        rgb = np.stack([np.asarray(val[c], np.float64).ravel() for c in range(3)], 1)
        return (rgb.reshape(h, w, 3) / scale).astype(np.float32)

    # -- neural assets ------------------------------------------------------------------------
    def assets(self) -> None:
        by_file: dict[Path, list[str]] = {}
        for sid, file in self.replace.items():
            by_file.setdefault(file, []).append(sid)
        for file, ids in by_file.items():
            rel = _relpath(file, self.output.parent)
            path = self._name("/World/Assets", "_".join(ids))
            # def Xform referencing the asset's default prim (spec/format.md#referencing-an-asset): USD tools
            # without the nasset schema keep its transform; renderers find the asset's root through
            # composition. No transform: asset object space == scene world space (spec/bake.md#stages)
            prim = self.stage.DefinePrim(path, "Xform")
            prim.GetReferences().AddReference(rel)
            self.result.replaced[path] = {"asset": rel, "shapes": list(ids)}
            self.record(path, f"NeuralAsset {rel} in place of {', '.join(ids)}")

    # -- driver -------------------------------------------------------------------------------
    def run(self) -> ConvertResult:
        from pxr import Gf

        self.camera()
        self.integrator()
        self.lights()
        self.shapes()
        self.assets()
        self.stage.GetRootLayer().customLayerData = {
            "nasset:convertedFrom": {"scene": self.scene_path.name, "converter": "nasset convert-scene",
                                     "mitsuba": self.mi.__version__, "integrator": dict(self.result.integrator),
                                     "resolution": Gf.Vec2i(*self.result.resolution)},
        }
        self.stage.GetRootLayer().Save()
        trust(self.stage.GetRootLayer().realPath)  # this process wrote it: rendered without a probe while unchanged
        if self.check_usd:
            self.result.usd_checks = usd_check(self.output)
        return self.result


#: wrapper BSDFs with one nested BSDF -> what of them is not converted (``mask`` keeps its opacity)
WRAPPERS = {"NormalMap": "normal map", "BumpMap": "bump map", "Mask": "nothing"}


#: absorption per unit concentration of eumelanin and pheomelanin (Mitsuba's ``hair``, after d'Eon et al. 2011)
EUMELANIN_SIGMA_A = np.array([0.419, 0.697, 1.37])
PHEOMELANIN_SIGMA_A = np.array([0.187, 0.4, 1.05])


def hair_colour(p) -> np.ndarray:
    """The colour [3] a Mitsuba ``hair`` BSDF's absorption stands for: ``exp(-sqrt(sigma_a) f(beta_n))``, the inverse of
    Chiang et al.'s (2016) mapping from a colour to an absorption, ``f`` their polynomial of the azimuthal roughness
    ``beta_n``; ``sigma_a`` from the melanin concentrations (``use_pigmentation``) or given."""
    pigment = float(np.ravel(_np(p.p[p.prefix + "use_pigmentation"]))[0]) if p.has("use_pigmentation") else 1.0
    if pigment:
        sigma_a = p.scalar("eumelanin", 1.3) * EUMELANIN_SIGMA_A + p.scalar("pheomelanin", 0.2) * PHEOMELANIN_SIGMA_A
    else:
        sigma_a = p.rgb("sigma_a", (0.06, 0.1, 0.2))
    b = p.scalar("azimuthal_roughness", 0.3)
    f = 5.969 - 0.215 * b + 2.532 * b**2 - 10.73 * b**3 + 5.574 * b**4 + 0.245 * b**5
    return np.clip(np.exp(-np.sqrt(np.maximum(sigma_a, 0.0)) * f), 0.0, 1.0)


def latlong_sphere() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(points [V, 3], faces [F, 3], uv [V, 2])`` of the unit sphere as a latitude-longitude mesh of
    :data:`SPHERE_RINGS` rings carrying Mitsuba's parameterisation u = phi / 2pi, v = theta / pi (local +Z pole),
    with a seam of repeated vertices at phi = 0 (its normals are its points)."""
    theta = np.linspace(0.0, np.pi, SPHERE_RINGS + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, 2 * SPHERE_RINGS + 1)
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    pts = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1).reshape(-1, 3)
    uv = np.stack([ph / (2.0 * np.pi), th / np.pi], -1).reshape(-1, 2)
    cols = 2 * SPHERE_RINGS + 1
    i, j = np.meshgrid(np.arange(SPHERE_RINGS), np.arange(2 * SPHERE_RINGS), indexing="ij")
    a, b = (i * cols + j).ravel(), (i * cols + j + 1).ravel()
    c, d = a + cols, b + cols
    faces = np.concatenate([np.stack([a, c, d], 1)[i.ravel() < SPHERE_RINGS - 1], np.stack([a, d, b], 1)[i.ravel() > 0]])
    return pts, faces, uv


def blend_inputs(a: dict, b: dict, w: float) -> tuple[dict, str]:
    """UsdPreviewSurface inputs of ``(1 - w) a + w b`` and how it was made.

    Same workflow: every input blended linearly (colours, textures texel by texel or with the other's
    constant, roughness), an approximation of the blended lobes. Different workflows: the dominant one. A glass
    (:class:`Glass`) blends by its transmission weight: ``(1 - w) t_a + w t_b``, the rest of the surface the other
    BSDF's (exact for one glass and one opaque BSDF); of two glasses the heavier one's IOR and roughness."""
    ga, gb = a.get("glass"), b.get("glass")
    if ga is not None or gb is not None:
        weight = (1.0 - w) * (ga.weight if ga else 0.0) + w * (gb.weight if gb else 0.0)
        glass = dataclasses.replace(gb if gb is not None and (ga is None or w > 0.5) else ga, weight=weight)
        if ga is not None and gb is not None:
            out, how = blend_inputs({k: v for k, v in a.items() if k != "glass"},
                                    {k: v for k, v in b.items() if k != "glass"}, w)
        else:
            out, how = dict(b if ga is not None else a), "the opaque BSDF"
            glass = dataclasses.replace(glass, base=mean_color(out.get("diffuseColor", (0.0, 0.0, 0.0))))
        out["glass"] = glass
        return out, f"transmission weight {weight:.3g}, the rest {how}"
    if a.get("useSpecularWorkflow") != b.get("useSpecularWorkflow"):
        return (dict(b) if w > 0.5 else dict(a)), "BSDFs of different UsdPreviewSurface workflows: the heavier one is kept"
    out = {}
    for k in dict.fromkeys([*a, *b]):
        if k == "useSpecularWorkflow":
            out[k] = a[k]
            continue
        if k == "microfacet":  # the heavier BSDF's distribution
            if (mf := (b if w > 0.5 else a).get(k)) is not None:
                out[k] = mf
            continue
        va, vb = a.get(k, b.get(k)), b.get(k, a.get(k))
        if isinstance(va, TextureMap) or isinstance(vb, TextureMap):
            ia = va.image if isinstance(va, TextureMap) else np.asarray(va, np.float64)
            ib = vb.image if isinstance(vb, TextureMap) else np.asarray(vb, np.float64)
            if isinstance(va, TextureMap) and isinstance(vb, TextureMap) and ia.shape != ib.shape:
                ib = ib.reshape(-1, 3).mean(0)  # different resolutions: the second by its mean
            what = va.what if isinstance(va, TextureMap) else vb.what
            wrap = va.wrap if isinstance(va, TextureMap) else vb.wrap
            out[k] = TextureMap((1.0 - w) * ia + w * ib, f"blend of {what}", wrap=wrap)
        else:
            out[k] = (1.0 - w) * np.asarray(va, np.float64) + w * np.asarray(vb, np.float64)
            if np.ndim(out[k]) == 0:
                out[k] = float(out[k])
    return out, "parameters blended linearly (an approximation of the blended lobes)"


def mean_color(value) -> tuple:
    """A colour input's constant, or a texture's mean texel (a primvar colour: grey 0.5)."""
    if isinstance(value, TextureMap):
        return tuple(float(c) for c in value.image.reshape(-1, 3).mean(0))
    if isinstance(value, ColorPrimvar):
        return (0.5, 0.5, 0.5)
    return tuple(float(c) for c in np.broadcast_to(np.asarray(value, np.float64), (3,)))


def _is_one_sided(bsdf) -> bool:
    """True for a BSDF that Mitsuba shades on its front side only (not twosided, not a dielectric, not null)."""
    if bsdf is None:
        return False
    cls = _class_name(bsdf)
    return cls != "Null" and "Dielectric" not in cls and "TwoSided" not in str(bsdf)


def _has_back_bsdf(bsdf) -> bool:
    """True for a ``twosided`` BSDF with a back BSDF of its own."""
    return bsdf is not None and _class_name(bsdf) == "TwoSided" and _two_sides_differ(str(bsdf))


def _two_sides_differ(text: str) -> bool:
    m0 = re.search(r"brdf\[0\]\s*=(.*?)brdf\[1\]\s*=", text, re.S)
    m1 = re.search(r"brdf\[1\]\s*=(.*)\]\s*$", text, re.S)
    return bool(m0 and m1 and m0.group(1).strip().rstrip(",").strip() != m1.group(1).strip())


def _relpath(file: Path, start: Path) -> str:
    import os

    rel = os.path.relpath(Path(file).resolve(), Path(start).resolve())
    return rel.replace(os.sep, "/") if rel.startswith("..") else "./" + rel.replace(os.sep, "/")


def usd_check(path) -> list[dict]:
    """OpenUSD's validators (the usdchecker engine) over the written stage: [{severity, name, message, prim}]. A
    MaterialX shader id this USD's shader registry lacks (a build without MaterialX, such as usd-core) is a warning."""
    from pxr import Usd, UsdValidation

    from nasset_sdk.plugin import register_schema

    register_schema()
    stage = Usd.Stage.Open(str(path))
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    from pxr import Sdr

    mtlx = "mtlx" in Sdr.Registry().GetAllShaderNodeSourceTypes()
    sev = {UsdValidation.ValidationErrorType.Error: "error", UsdValidation.ValidationErrorType.Warn: "warning"}
    out = []
    for err in context.Validate(stage):
        prim = None
        for site in err.GetSites():
            if site.IsPrim():
                prim = str(site.GetPrim().GetPath())
            elif site.IsProperty():
                prim = str(site.GetProperty().GetPath())
            if prim:
                break
        severity, message = sev.get(err.GetType(), "info"), err.GetMessage().strip()[:300]
        if str(err.GetName()).endswith("MissingShaderIdInRegistry") and "'ND_" in message and not mtlx:
            # a MaterialX node (the glass's standard_surface): this USD build has no MaterialX in its shader
            # registry (usd-core); one built with MaterialX (usdview's) knows it
            severity, message = "warning", message + " (this USD has no MaterialX nodes in its shader registry)"
        out.append({"severity": severity, "name": str(err.GetName()), "message": message, "prim": prim})
    return out


def parse_replace(items) -> dict[str, Path]:
    """``["ID[,ID...]=ASSET", ...]`` (the CLI's) or ``{shape id: asset file}`` (the Python API's) -> {shape id: asset
    path}; USAGE on malformed items and on files that are not paths."""
    if isinstance(items, dict):
        return {str(k): path_arg(v, f"--replace {k}: the asset") for k, v in items.items()}
    out: dict[str, Path] = {}
    for item in items or []:
        ids, sep, file = str(item).partition("=")
        if not sep or not ids.strip() or not file.strip():
            raise UsageError(f"--replace expects SHAPE_ID[,SHAPE_ID...]=ASSET.usdc, got {item!r}")
        for sid in ids.split(","):
            sid = sid.strip()
            if not sid:
                raise UsageError(f"--replace has an empty shape id in {item!r}")
            if sid in out and out[sid] != Path(file.strip()):
                raise UsageError(f"shape {sid!r} is replaced twice")
            out[sid] = Path(file.strip())
    return out


def convert_scene(scene, output, *, replace=None, variant: str | None = None, check_usd: bool = True) -> ConvertResult:
    """Convert a Mitsuba 3 XML scene to a USD stage (see the module docstring and spec/bake.md#scene-conversion).

    ``replace``: {shape id: asset file} or ``["ID[,ID]=FILE", ...]``; those shapes are left out and a
    NeuralAsset reference (path relative to ``output``) takes their place.
    """
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_reference_renderer.scene import is_asset_file

    output = path_arg(output, "convert_scene: the output")
    if output.suffix not in (".usda", ".usdc", ".usd"):
        raise UsageError(f"output must end in .usda/.usdc/.usd, got {output.name!r}")
    rep = parse_replace(replace)
    scene = path_arg(scene, "convert_scene: the scene")
    if not scene.is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(scene))
    mi = load_mitsuba(variant)
    mi.set_log_level(mi.LogLevel.Error)
    mscene = load_scene(mi, scene)
    by_id = {s.id(): s for s in mscene.shapes() if s.id()}
    for sid, file in rep.items():
        if sid not in by_id:
            raise error("CONVERT_SHAPE_UNKNOWN", "--replace: " + no_such_shape(mi, mscene, sid), file=str(scene))
        refuse_emitter(by_id[sid], file=str(scene))
        if not file.is_file() or not is_asset_file(str(file)):
            raise error("CONVERT_ASSET_REFERENCE", f"--replace {sid}: {file} is not an existing neural asset file "
                        "(defaultPrim of type NeuralAsset)", file=str(file))
    misfits = replacement_misfits(mscene, rep)
    try:
        output.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error("WRITE_FAILED", f"cannot create the output folder: {exc.strerror or exc}", file=str(output)) from None
    import os

    from nasset_sdk.images import atomic_output

    # written beside the output and renamed over it at the end: a failed conversion leaves an earlier output as it was
    with atomic_output(output, "converted scene") as tmp:
        os.unlink(tmp)  # USD creates the layer file itself
        res = StageConverter(mi, mscene, scene, output, rep, False, layer=Path(tmp)).run()  # checked once renamed
    res.warnings.extend(misfits)
    if check_usd:
        res.usd_checks = usd_check(output)
    return res


def replacement_misfits(mscene, rep: dict) -> list[str]:
    """A warning per ``--replace`` asset whose geometry's box lies off the replaced shapes' by more than
    BOX_TOLERANCE of their diagonal: it was baked from other shapes (a wrong id, another object), and the stage would
    show it where they are not (``bench accuracy`` refuses the same, BENCH_ASSET_MISMATCH)."""
    from nasset_sdk.asset import Asset

    by_id = {s.id(): s for s in mscene.shapes() if s.id()}
    groups: dict[Path, list[str]] = {}
    for sid, file in rep.items():
        groups.setdefault(Path(file), []).append(sid)
    out = []
    for file, ids in groups.items():
        asset = Asset.open(file, load="none")
        off = bounds_offset([by_id[i] for i in ids], asset.geometry().points)
        if off > BOX_TOLERANCE:
            src = (asset.provenance or {}).get("source", {}).get("shapes")
            out.append(f"--replace {','.join(ids)}: {file.name} was not baked from them: its bounds differ from theirs by "
                       f"{100 * off:.0f} % of their diagonal" + (f" (it was baked from {src})" if src else ""))
    return out


def report(res: "ConvertResult", *, as_json: bool) -> int:
    """Print a conversion's warnings, USD check findings and result (or JSON); exit code 1 on USD check errors."""
    for w in res.warnings:
        print(f"warning: {w}", file=sys.stderr)
    bad = [c for c in res.usd_checks if c["severity"] == "error"]
    for c in res.usd_checks:
        print(f"usd-check {c['severity']}: {c['name']} {c['prim'] or ''}: {c['message']}", file=sys.stderr)
    if as_json:
        print(json.dumps(res.to_dict(), indent=2))
    else:
        print(f"wrote {res.output}: {len(res.prims)} prims, {len(res.replaced)} neural asset reference(s), "
              f"{len(res.warnings)} warning(s)")
        for path, what in res.prims.items():
            print(f"  {path:40s} <- {what}")
    return 1 if bad else 0


def run(args) -> int:
    """CLI entry: ``nasset convert-scene SCENE.xml -o SCENE.usda [--replace ID=ASSET ...] [--json]``."""
    scene = args.scene
    if bool(args.example) == bool(scene):
        raise UsageError("give a scene file or --example (not both)")
    if not args.example:
        return report(convert_scene(scene, args.output, replace=args.replace, check_usd=not args.no_usd_checks), as_json=args.json)
    import shutil

    from .examples import write_example_scene

    parent = Path(args.output).resolve().parent
    if not parent.is_dir():
        raise error("WRITE_FAILED", "the output folder does not exist", file=str(args.output))
    folder = parent / "example_scene"
    created = not folder.exists()
    try:
        res = convert_scene(write_example_scene(folder), args.output, replace=args.replace, check_usd=not args.no_usd_checks)
    except BaseException:
        if created:  # a failed conversion leaves nothing behind in the output folder
            shutil.rmtree(folder, ignore_errors=True)
        raise
    return report(res, as_json=args.json)
