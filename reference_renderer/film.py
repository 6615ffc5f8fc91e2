"""Film accumulation and image files: EXR (OpenEXR), PNG preview (zlib, no extra dependency)."""

from __future__ import annotations

import numpy as np

from nasset_sdk.images import write_png  # noqa: F401  (re-exported: film output API)


class Film:
    """Per-pixel sums of samples and of their squares (for the variance of the pixel mean)."""

    def __init__(self, width: int, height: int) -> None:
        self.width, self.height = width, height
        self.sum = np.zeros((height * width, 3))
        self.sum2 = np.zeros((height * width, 3))
        self.count = np.zeros(height * width)

    def add(self, pix: np.ndarray, value: np.ndarray) -> None:
        n = self.width * self.height
        self.count += np.bincount(pix, minlength=n)
        for c in range(3):
            self.sum[:, c] += np.bincount(pix, weights=value[:, c], minlength=n)
            self.sum2[:, c] += np.bincount(pix, weights=value[:, c] ** 2, minlength=n)

    def add_passes(self, pix: np.ndarray, value: np.ndarray) -> None:
        """Same as ``add(np.tile(pix, k), value)`` for distinct ``pix`` and value [k len(pix), 3].

        Sums the k samples of each pixel in sample order (as np.bincount does) without the
        full-film temporaries of :meth:`add`.
        """
        v = value.reshape(-1, len(pix), value.shape[-1])
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


