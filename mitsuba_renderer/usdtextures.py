"""UsdPreviewSurface inputs that vary per hit, read from a USD stage (spec/renderer.md#textures, #primvar-colors).

A ``diffuseColor``, ``roughness`` or ``metallic`` fed by a ``UsdUVTexture`` (its ``rgb``, or one channel for the two
floats) whose ``st`` comes from a ``UsdPrimvarReader_float2`` (optionally through one ``UsdTransform2d``), and a
``diffuseColor`` fed by a ``UsdPrimvarReader_float3``. This module reads them; the Mitsuba plugin looks them up per hit
(``nasset_mitsuba_plugin.preview``). This package's own integrator shades with the inputs' constant values (warned).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from nasset_sdk.errors import NassetError, SceneError

WRAP_MODES = ("repeat", "mirror", "clamp", "black")
#: image files read (OpenEXR, PNG, JPEG)
SUFFIXES = (".exr", ".png", ".jpg", ".jpeg")
#: UsdPreviewSurface inputs read per hit -> the UsdUVTexture outputs that may feed them
PER_HIT_INPUTS = {"diffuseColor": ("rgb",), "roughness": ("r", "g", "b", "a"), "metallic": ("r", "g", "b", "a"),
                  "emissiveColor": ("rgb",), "normal": ("rgb",), "opacity": ("r", "g", "b", "a")}
#: those of the BSDF's formulas for kd, F0 and alpha (emissiveColor is the emission's; normal a tangent-space normal map)
SHADING_INPUTS = ("diffuseColor", "roughness", "metallic")

Warn = Callable[[str, str], None]  # (message, prim path)
#: USD interpolations of per-element values a mesh's corners read (:func:`at_corners`)
INTERPOLATIONS = ("vertex", "varying", "faceVarying", "uniform", "constant")


@dataclass
class Texture:
    """A UsdUVTexture as read: linear texels, wrap modes, ``texel * scale + bias`` (a channel output: its texels and
    its components of scale and bias repeated over three colours), the st map of a UsdTransform2d."""

    image: np.ndarray  # [H, W, 3] float32, linear
    wrap: tuple[str, str]  # (wrapS, wrapT), each one of WRAP_MODES
    scale: np.ndarray  # [3]
    bias: np.ndarray  # [3]
    uv: np.ndarray | None  # [2, 3] affine map st -> st (None: the identity)
    varname: str  # the float2 primvar its st reads
    st_fallback: np.ndarray  # [2] the primvar reader's fallback where a mesh lacks the primvar


@dataclass
class PerHit:
    """A material's inputs per hit: each of ``diffuse``, ``roughness``, ``metallic`` is a constant unless ``textures``
    holds it (and ``emissiveColor``: the emission per hit, max(texture, 0), whose mean is the material's constant
    emission; ``normal``: a tangent-space normal map, spec/renderer.md#normal-maps; ``opacity``: a cut-out's opacity,
    #cutouts); ``color`` (primvar name, fallback
    [3]) makes the diffuse colour a primvar's. ``metallic`` None is the specular workflow (kd = c, F0 = ``specular``),
    else kd = c (1 - m), F0 = (1 - m) ``r0`` + m c."""

    diffuse: np.ndarray  # [3] in [0, 1]
    roughness: float
    metallic: float | None
    specular: np.ndarray  # [3]
    r0: float  # ((1 - ior) / (1 + ior))^2
    textures: dict = field(default_factory=dict)  # input name -> Texture
    color: tuple | None = None  # (primvar name, fallback [3])

    @property
    def varies_material(self) -> bool:
        """kd, F0 or alpha vary per hit (some input of their formulas does)."""
        return self.color is not None or any(name in self.textures for name in SHADING_INPUTS)

    @property
    def varname(self) -> str:
        """The st primvar the material's textures are read at (the first texture's; spec/renderer.md#textures)."""
        return next(iter(self.textures.values())).varname if self.textures else "st"


def _srgb_decode(c: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1's transfer function on values clamped to [0, 1]."""
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, np.power((c + 0.055) / 1.055, 2.4))


def input_value(shader, name: str, t):
    """The value reaching ``shader``'s input ``name`` (None when unset or fed by a shader output)."""
    from nasset_sdk import stage_rules

    inp = shader.GetInput(name)
    if not inp:
        return None
    producer, v = stage_rules.input_source(inp, t)
    return None if producer is not None else v


def _finite(value, n: int, what: str, scene: str, prim: str, bound: float = 1e9) -> np.ndarray:
    v = np.asarray(value, np.float64).ravel()
    if len(v) < n or not np.isfinite(v[:n]).all() or np.abs(v[:n]).max(initial=0.0) > bound:
        raise SceneError("SCENE_INVALID", f"{what} = {value!r} is not {n} finite number(s) within {bound:g}", file=scene,
                         prim=prim, attribute=f"inputs:{what}")
    return v[:n]


def primvar_color(node, t, scene: str) -> tuple[str, np.ndarray]:
    """(primvar name, fallback colour [3]) of a ``UsdPrimvarReader_float3`` feeding diffuseColor
    (spec/renderer.md#primvar-colors): ``varname`` (fallback ``displayColor``), ``fallback`` clamped to [0, 1] (else
    0.18 grey); SCENE_INVALID naming the reader for a fallback that is not 3 finite numbers."""
    fb = input_value(node, "fallback", t)
    if fb is None:
        return str(input_value(node, "varname", t) or "displayColor"), np.full(3, 0.18)
    try:
        v = np.asarray(fb, np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.full(1, np.nan)
    if len(v) != 3 or not np.isfinite(v).all():
        raise SceneError("SCENE_INVALID", f"fallback = {fb!r} is not 3 finite number(s)", file=scene, prim=str(node.GetPath()),
                         attribute="inputs:fallback")
    return str(input_value(node, "varname", t) or "displayColor"), np.clip(v, 0.0, 1.0)


def texture_fallback(node, output: str, t):
    """A UsdUVTexture's authored ``inputs:fallback`` as the output ``output`` gives it (its rgb, or one channel; a
    shorter value keeps (0, 0, 0, 1) for the rest), None when not authored: the value of a texture that is not read."""
    v = input_value(node, "fallback", t)
    if v is None:
        return None
    v = np.asarray(v, np.float64).ravel()[:4]
    rgba = np.concatenate([v, [0.0, 0.0, 0.0, 1.0][len(v):]])
    if not np.isfinite(rgba).all():
        return None
    return rgba[:3] if output == "rgb" else float(rgba["rgba".find(output)])


class TextureReader:
    """Reads the UsdUVTextures of one scene: each image file decoded once, each (file, channel, colour decode) made
    once, each (UsdUVTexture, output) read once, so the meshes and materials that share a texture share its arrays
    (a scene of many meshes bound to one textured material holds one copy of its texels, not one per mesh)."""

    def __init__(self, scene: str, t, warn: Warn) -> None:
        self.scene, self.t, self.warn = scene, t, warn
        self.images: dict[str, tuple[np.ndarray, int]] = {}  # resolved path -> (rgba [H, W, 4], bits)
        self.texels: dict[tuple, np.ndarray] = {}  # (resolved path, channel, decoded) -> [H, W, 3] float32
        self.textures: dict[tuple[str, str], Texture | None] = {}  # (UsdUVTexture path, output) -> as read

    def read(self, node, output: str) -> Texture | None:
        """The texture ``node`` (a UsdUVTexture) gives through ``output``; None, warned, when its image cannot be used
        (no file, not found, a format other than OpenEXR / PNG / JPEG, a UDIM set). A file inside a package (usdz) is
        read through USD's resolver. Read once per (node, output): later calls return the same object."""
        key = (str(node.GetPath()), str(output))
        if key not in self.textures:
            self.textures[key] = self._read(node, output)
        return self.textures[key]

    def _read(self, node, output: str) -> Texture | None:
        from nasset_sdk.images import packaged_name

        where = str(node.GetPath())
        asset = input_value(node, "file", self.t)
        path = getattr(asset, "path", "") or ""
        resolved = getattr(asset, "resolvedPath", "") or ""
        packaged = packaged_name(resolved)
        problem = ("has no inputs:file" if not path else "is a UDIM tile set" if "<UDIM>" in path
                   else "is not found" if not resolved or not (packaged or os.path.isfile(resolved))
                   else "is not OpenEXR, PNG or JPEG" if not (packaged or resolved).lower().endswith(SUFFIXES) else "")
        if problem:
            self.warn(f"texture {path or '(none)'} {problem}; its fallback, else the input's own value, is used", where)
            return None
        rgba, bits = self._image(resolved, where)
        channel = -1 if output == "rgb" else "rgba".find(output)
        space = str(input_value(node, "sourceColorSpace", self.t) or "auto")
        if space not in ("auto", "raw", "sRGB"):
            self.warn(f"sourceColorSpace {space!r} read as raw (linear)", where)
        decode = channel != 3 and (space == "sRGB" or (space == "auto" and bits == 8))  # alpha is never decoded
        if (resolved, channel, decode) not in self.texels:
            image = rgba[..., :3] if channel < 0 else np.repeat(rgba[..., channel:channel + 1], 3, -1)
            self.texels[resolved, channel, decode] = np.ascontiguousarray(_srgb_decode(image) if decode else image,
                                                                          np.float32)
        image = self.texels[resolved, channel, decode]
        wrap = []
        for name in ("wrapS", "wrapT"):
            mode = str(input_value(node, name, self.t) or "useMetadata")
            if mode == "useMetadata":  # none of these formats carries a wrap mode: UsdUVTexture then gives black
                mode = "black"
            elif mode not in WRAP_MODES:
                self.warn(f"{name} {mode!r} is not a wrap mode: black", where)
                mode = "black"
            wrap.append(mode)
        scale, bias = np.ones(4), np.zeros(4)
        for name, out in (("scale", scale), ("bias", bias)):
            v = input_value(node, name, self.t)
            if v is not None:
                v = np.asarray(v, np.float64).ravel()[:4]
                if not np.isfinite(v).all():
                    raise SceneError("SCENE_INVALID", f"UsdUVTexture {name} must be finite", file=self.scene, prim=where,
                                     attribute=f"inputs:{name}")
                out[:len(v)] = v
        pick = slice(0, 3) if channel < 0 else [channel] * 3
        varname, uv, st_fallback = self._st(node)
        return Texture(image, (wrap[0], wrap[1]), scale[pick], bias[pick], uv, varname, st_fallback)

    def _image(self, resolved: str, where: str) -> tuple[np.ndarray, int]:
        """(rgba [H, W, 4] float32, bits per channel) of an image file, decoded once, through the SDK's bounded
        readers (the header's size is checked before any pixel is decoded)."""
        from nasset_sdk.images import local_image_copy, packaged_name, read_exr, read_png_jpeg

        if resolved not in self.images:
            try:
                with local_image_copy(resolved) as local:  # a file inside a package: a temporary copy
                    exr = (packaged_name(resolved) or resolved).lower().endswith(".exr")
                    img, bits = (read_exr(local, alpha=True), 32) if exr else read_png_jpeg(local, alpha=True)
            except NassetError as exc:
                raise SceneError("IMAGE_INVALID", f"texture {resolved}: {exc.message}", file=self.scene, prim=where,
                                 attribute="inputs:file") from None
            if not np.isfinite(img).all() or (img < 0).any():
                raise SceneError("SCENE_INVALID", f"texture {resolved} holds NaN/Inf or negative values", file=self.scene,
                                 prim=where, attribute="inputs:file")
            self.images[resolved] = (np.asarray(img, np.float32), bits)
        return self.images[resolved]

    def _st(self, node) -> tuple[str, np.ndarray | None, np.ndarray]:
        """(primvar name, UsdTransform2d map [2, 3] or None, the reader's fallback st [2]) of a UsdUVTexture's st."""
        from nasset_sdk import stage_rules

        def source(shader, name):
            inp = shader.GetInput(name)
            producer = stage_rules.input_source(inp, self.t)[0] if inp else None
            return producer[0] if producer else None

        uv = None
        reader = source(node, "st")
        if reader is not None and reader.GetIdAttr().Get() == "UsdTransform2d":
            where = str(reader.GetPath())
            vals = {name: input_value(reader, name, self.t) for name in ("scale", "rotation", "translation")}
            scale = _finite((1.0, 1.0) if vals["scale"] is None else vals["scale"], 2, "scale", self.scene, where)
            angle = np.radians(_finite(0.0 if vals["rotation"] is None else vals["rotation"], 1, "rotation", self.scene, where)[0])
            move = _finite((0.0, 0.0) if vals["translation"] is None else vals["translation"], 2, "translation", self.scene, where)
            c, s = np.cos(angle), np.sin(angle)
            uv = np.concatenate([np.array([[c, -s], [s, c]]) @ np.diag(scale), move[:, None]], 1)
            reader = source(reader, "in")
        if reader is not None and reader.GetIdAttr().Get() == "UsdPrimvarReader_float2":
            fb = input_value(reader, "fallback", self.t)
            fallback = np.zeros(2) if fb is None else _finite(fb, 2, "fallback", self.scene, str(reader.GetPath()))
            return str(input_value(reader, "varname", self.t) or "st"), uv, fallback
        self.warn("UsdUVTexture st is not read from a UsdPrimvarReader_float2 (directly or through a UsdTransform2d); "
                  "primvar 'st' is used", str(node.GetPath()))
        return "st", uv, np.zeros(2)


def corner_values(primvar, width: int, layout: tuple, t) -> np.ndarray | None:
    """Values [F, 3, width] of ``primvar`` (flattened if indexed) at the triangles' corners, None when it is missing or
    unusable (not finite, another width, a length its interpolation does not give). ``layout``: (triangles [F, 3] point
    indices, their face-vertex slots [F, 3], face of each triangle [F], points, face-vertex slots, faces)."""
    vals = primvar.ComputeFlattened(t) if primvar is not None else None
    if vals is None or not len(vals):
        return None
    v = np.asarray(vals, np.float64)
    if v.size % width or not np.isfinite(v).all():
        return None
    return at_corners(v.reshape(-1, width), primvar.GetInterpolation(), layout)


def at_corners(v: np.ndarray, interp: str, layout: tuple, interpolations=INTERPOLATIONS) -> np.ndarray | None:
    """Values [F, 3, w] at the triangles' corners of per-element values ``v`` [N, w] of USD interpolation ``interp``
    (one of ``interpolations``), None when it is another or ``N`` is not the count it gives. ``layout``: as
    :func:`corner_values`'."""
    tri, corners, face_of, n_points, n_slots, n_faces = layout
    if interp not in interpolations:
        return None
    if interp in ("vertex", "varying") and len(v) == n_points:
        return v[tri]
    if interp == "faceVarying" and len(v) == n_slots:
        return v[corners]
    if interp == "uniform" and len(v) == n_faces:
        return np.repeat(v[face_of][:, None], 3, 1)
    if interp == "constant" and len(v) == 1:
        return np.broadcast_to(v[0], (len(tri), 3, v.shape[1])).copy()
    return None
