"""Image files: EXR (OpenEXR) read / write, the ACES tone curve, and 8-bit PNG output with the standard
library only (zlib), for previews, plots and error maps."""

from __future__ import annotations

import struct
import zlib
from pathlib import Path

import numpy as np


def write_png(path, rgb8: np.ndarray) -> Path:
    """Write an [H, W, 3] uint8 image as an 8-bit RGB PNG (filter type 0 on every row); returns the path."""
    rgb8 = np.ascontiguousarray(rgb8, np.uint8)
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[r].tobytes() for r in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")
    path = Path(path)
    path.write_bytes(png)
    return path


def write_exr(path, image: np.ndarray) -> None:
    import OpenEXR

    img = np.ascontiguousarray(np.asarray(image, np.float32))
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    OpenEXR.File(header, {"RGB": img}).write(str(path))


def read_exr(path) -> np.ndarray:
    """[H, W, 3] float32 RGB (a single-channel image is repeated; alpha is dropped)."""
    import OpenEXR

    with OpenEXR.File(str(path), separate_channels=True) as f:
        ch = f.channels()
        if all(k in ch for k in "RGB"):
            return np.stack([np.asarray(ch[k].pixels, np.float32) for k in "RGB"], -1)
        if "Y" in ch:
            y = np.asarray(ch["Y"].pixels, np.float32)
            return np.stack([y, y, y], -1)
        first = np.asarray(next(iter(ch.values())).pixels, np.float32)
        return np.stack([first] * 3, -1)


def tonemap(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """ACES filmic curve (Narkowicz fit) then sRGB encoding -> uint8."""
    x = np.maximum(np.nan_to_num(np.asarray(image, np.float64)), 0.0) * 2.0 ** exposure * 0.6
    y = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    s = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)
