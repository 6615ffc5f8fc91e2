"""Film accumulation and image files: EXR (OpenEXR), PNG preview (zlib, no extra dependency).

Numeric limits (spec/renderer.md#limits): image size and sample counts are checked before
anything is allocated, every camera sample's radiance is clamped to ``SAMPLE_RADIANCE_MAX``
before it reaches the film, and every image written goes through
:func:`nasset_sdk.images.finite_float32`, so no file ever holds Inf or NaN.
"""

from __future__ import annotations

import struct

import numpy as np

from nasset_sdk.errors import UsageError, error
from nasset_sdk.images import (
    atomic_output,
    finite_float32,
    write_png,  # noqa: F401  (re-exported: film output API)
)

#: Largest magnitude of one camera sample's radiance per channel (NaN -> 0 first). Far above any
#: physical radiance and far below float32 max, so pixel means stay finite in float32.
SAMPLE_RADIANCE_MAX = 1e30
MAX_IMAGE_SIDE = 1 << 16  # pixels per image side
MAX_IMAGE_PIXELS = 1 << 26  # 67 M pixels: the film holds 56 bytes per pixel (3.5 GiB)
MAX_SPP = 1 << 20  # samples per pixel
MAX_SAMPLES = 1 << 40  # spp x pixels of one render
#: Dome (environment) textures: side, pixels and pixels x channels, checked on the header before reading.
MAX_TEXTURE_SIDE = 1 << 15
MAX_TEXTURE_PIXELS = 1 << 26
MAX_TEXTURE_VALUES = 1 << 28  # pixels x channels (1 GiB as float32)


def check_image_size(width, height, spp=None) -> tuple[int, int]:
    """(width, height) as ints after checking 1 <= side <= MAX_IMAGE_SIDE, pixels <= MAX_IMAGE_PIXELS and,
    with ``spp``, 1 <= spp <= MAX_SPP and spp x pixels <= MAX_SAMPLES; ``USAGE`` error otherwise."""
    try:
        w, h = int(width), int(height)
    except (TypeError, ValueError, OverflowError):
        raise UsageError(f"image size {width!r} x {height!r} is not a pair of integers") from None
    if not (1 <= w <= MAX_IMAGE_SIDE and 1 <= h <= MAX_IMAGE_SIDE) or w * h > MAX_IMAGE_PIXELS:
        raise UsageError(f"image size {w} x {h} outside the bounds: each side 1 .. {MAX_IMAGE_SIDE}, at most "
                         f"{MAX_IMAGE_PIXELS} pixels (--width/--height)")
    if spp is not None:
        n = int(spp)
        if not 1 <= n <= MAX_SPP:
            raise UsageError(f"--spp {n} outside 1 .. {MAX_SPP}")
        if n * w * h > MAX_SAMPLES:
            raise UsageError(f"--spp {n} x {w} x {h} pixels = {n * w * h} samples, above the bound {MAX_SAMPLES}")
    return w, h


def clamp_radiance(value: np.ndarray) -> np.ndarray:
    """Camera-sample radiance [n, 3] in float64 with NaN -> 0 and |value| <= SAMPLE_RADIANCE_MAX."""
    v = np.asarray(value, np.float64)
    if np.isfinite(v).all() and (v.size == 0 or np.abs(v).max() <= SAMPLE_RADIANCE_MAX):
        return v  # the common case: no copy
    v = np.nan_to_num(v, nan=0.0, posinf=SAMPLE_RADIANCE_MAX, neginf=-SAMPLE_RADIANCE_MAX)
    return np.clip(v, -SAMPLE_RADIANCE_MAX, SAMPLE_RADIANCE_MAX)


class Film:
    """Per-pixel sums of samples and of their squares (for the variance of the pixel mean)."""

    def __init__(self, width: int, height: int) -> None:
        width, height = check_image_size(width, height)
        self.width, self.height = width, height
        self.sum = np.zeros((height * width, 3))
        self.sum2 = np.zeros((height * width, 3))
        self.count = np.zeros(height * width)

    def add(self, pix: np.ndarray, value: np.ndarray) -> None:
        n = self.width * self.height
        value = clamp_radiance(value)
        self.count += np.bincount(pix, minlength=n)
        for c in range(3):
            self.sum[:, c] += np.bincount(pix, weights=value[:, c], minlength=n)
            self.sum2[:, c] += np.bincount(pix, weights=value[:, c] ** 2, minlength=n)

    def add_passes(self, pix: np.ndarray, value: np.ndarray) -> None:
        """Same as ``add(np.tile(pix, k), value)`` for distinct ``pix`` and value [k len(pix), 3].

        Sums the k samples of each pixel in sample order (as np.bincount does) without the
        full-film temporaries of :meth:`add`.
        """
        v = clamp_radiance(value).reshape(-1, len(pix), value.shape[-1])
        self.count[pix] += len(v)
        self.sum[pix] += v.sum(0)
        self.sum2[pix] += (v * v).sum(0)

    def image(self) -> np.ndarray:
        cnt = np.maximum(self.count, 1)[:, None]
        return (self.sum / cnt).reshape(self.height, self.width, 3)

    def variance(self) -> np.ndarray:
        """Estimated variance of each pixel's mean: s^2 / n (0 where n < 2)."""
        n = self.count[:, None]
        mean = self.sum / np.maximum(n, 1)
        s2 = np.maximum(self.sum2 - n * mean * mean, 0.0) / np.maximum(n - 1, 1)
        return np.where(n > 1, s2 / np.maximum(n, 1), 0.0).reshape(self.height, self.width, 3)


def write_exr(path, image: np.ndarray) -> None:
    """Write [H, W, 3] as float32 RGB OpenEXR atomically; values pass :func:`finite_float32` (``WRITE_FAILED``)."""
    import OpenEXR

    img = finite_float32(image)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_output(path, "OpenEXR image") as tmp:
        OpenEXR.File(header, {"RGB": img}).write(tmp)


def exr_header_size(path) -> tuple[int, int, int]:
    """(width, height, channels) from an OpenEXR file's header, read with bounded reads before any
    decoder sees the file. ``IMAGE_INVALID`` for a file that is not a single-part scanline/tiled EXR."""
    def bad(msg):
        return error("IMAGE_INVALID", msg, file=str(path))

    try:
        with open(path, "rb") as fh:
            head = fh.read(1 << 16)  # attribute headers are small; 64 KiB holds any sane one
    except OSError as exc:
        raise bad(f"cannot read it: {exc.strerror or exc}") from None
    if len(head) < 8 or head[:4] != b"\x76\x2f\x31\x01":
        raise bad("not an OpenEXR file (magic number)")
    flags = struct.unpack("<I", head[4:8])[0]
    if flags & 0xFF != 2 or flags & (0x800 | 0x1000):  # version 2; no deep data, no multi-part
        raise bad(f"unsupported OpenEXR version/flags 0x{flags:x} (single-part scanline or tiled images only)")
    pos, window, channels = 8, None, None
    while True:
        end = head.find(b"\0", pos)
        if end < 0:
            raise bad("header truncated or larger than 64 KiB")
        name = head[pos:end]
        if not name:
            break
        tend = head.find(b"\0", end + 1)
        if tend < 0 or tend + 5 > len(head):
            raise bad("header truncated")
        size = struct.unpack("<i", head[tend + 1:tend + 5])[0]
        vstart = tend + 5
        if size < 0 or vstart + size > len(head):
            raise bad(f"header attribute {name[:64]!r} has an invalid size {size}")
        value = head[vstart:vstart + size]
        if name == b"dataWindow":
            if size != 16:
                raise bad("dataWindow is not a box2i")
            window = struct.unpack("<4i", value)
        elif name == b"channels":
            channels = sum(1 for _ in _chlist_names(value))
        pos = vstart + size
    if window is None or channels is None:
        raise bad("header lacks dataWindow or channels")
    x0, y0, x1, y1 = window
    w, h = x1 - x0 + 1, y1 - y0 + 1
    return w, h, channels


def _chlist_names(value: bytes):
    pos = 0
    while pos < len(value) and value[pos] != 0:
        end = value.find(b"\0", pos)
        if end < 0:
            return
        yield value[pos:end]
        pos = end + 1 + 16


def read_exr(path) -> np.ndarray:
    """[H, W, 3] float32 RGB (a single-channel image is repeated; alpha is dropped).

    The header is checked first (:func:`exr_header_size`): each side 1 .. MAX_TEXTURE_SIDE, at most
    MAX_TEXTURE_PIXELS pixels and MAX_TEXTURE_VALUES values; a corrupt file is ``IMAGE_INVALID``.
    """
    import OpenEXR

    w, h, nch = exr_header_size(path)
    if not (1 <= w <= MAX_TEXTURE_SIDE and 1 <= h <= MAX_TEXTURE_SIDE) or w * h > MAX_TEXTURE_PIXELS \
            or not 1 <= nch or w * h * nch > MAX_TEXTURE_VALUES:
        raise error("IMAGE_INVALID", f"image of {w} x {h} pixels and {nch} channels is outside the bounds (each side 1 .. "
                    f"{MAX_TEXTURE_SIDE}, at most {MAX_TEXTURE_PIXELS} pixels and {MAX_TEXTURE_VALUES} values)", file=str(path))
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = f.channels()
            if all(k in ch for k in "RGB"):
                img = np.stack([np.asarray(ch[k].pixels, np.float32) for k in "RGB"], -1)
            elif "Y" in ch:
                y = np.asarray(ch["Y"].pixels, np.float32)
                img = np.stack([y, y, y], -1)
            else:
                first = np.asarray(next(iter(ch.values())).pixels, np.float32)
                img = np.stack([first] * 3, -1)
    except (RuntimeError, OSError, ValueError, TypeError, StopIteration) as exc:  # OpenEXR's own errors are RuntimeError
        detail = str(exc).strip().splitlines()[-1][:200] if str(exc).strip() else type(exc).__name__
        raise error("IMAGE_INVALID", f"cannot decode the OpenEXR image: {detail}", file=str(path)) from None
    if img.ndim != 3 or img.shape[:2] != (h, w):
        raise error("IMAGE_INVALID", f"decoded pixels {img.shape} differ from the header's {w} x {h}", file=str(path))
    return img


def tonemap(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """ACES filmic curve (Narkowicz fit) then sRGB encoding -> uint8."""
    x = np.maximum(finite_float32(image).astype(np.float64), 0.0) * float(np.clip(2.0 ** np.clip(exposure, -200, 200), 0, 1e60)) * 0.6
    y = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    s = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


