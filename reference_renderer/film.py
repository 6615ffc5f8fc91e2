"""Film accumulation; the image files (EXR, PNG preview) come from the SDK's :mod:`nasset_sdk.images`."""

from __future__ import annotations

import numpy as np

from nasset_sdk.images import read_exr, tonemap, write_exr, write_png  # noqa: F401  (re-exported: film output API)


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
