"""Film accumulation; the image files (EXR, PNG preview) come from the SDK's :mod:`nasset_sdk.images`.

Numeric limits (spec/renderer.md#limits): image size and sample counts are checked before
anything is allocated, every camera sample's radiance is clamped to ``SAMPLE_RADIANCE_MAX``
before it reaches the film, and every image written goes through
:func:`nasset_sdk.images.finite_float32`, so no file ever holds Inf or NaN.
"""

from __future__ import annotations

import numpy as np

from nasset_sdk.errors import UsageError
from nasset_sdk.images import read_exr, tonemap, write_exr, write_png  # noqa: F401  (re-exported: film output API)

#: Largest magnitude of one camera sample's radiance per channel (NaN -> 0 first). Far above any
#: physical radiance and far below float32 max, so pixel means stay finite in float32.
SAMPLE_RADIANCE_MAX = 1e30
MAX_IMAGE_SIDE = 1 << 16  # pixels per image side
MAX_IMAGE_PIXELS = 1 << 26  # 67 M pixels: the film holds 56 bytes per pixel (3.5 GiB)
MAX_SPP = 1 << 20  # samples per pixel
MAX_SAMPLES = 1 << 40  # spp x pixels of one render


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


#: Pixel filters (spec/renderer.md#render-settings, nasset_sdk.stage_rules.PIXEL_FILTERS): ``box`` (uniform over the
#: pixel) or a truncated Gaussian of standard deviation ``stddev`` pixels (Mitsuba's ``gaussian``: radius 4 stddev),
#: applied by drawing each camera sample's offset from the filter (filter importance sampling, every weight 1).


def pixel_offsets(rng, n: int, kind: str = "box", stddev: float = 0.5) -> np.ndarray:
    """Offsets [n, 2] (pixels) of camera samples from their pixel's corner, distributed as the pixel filter.

    Gaussian: per axis the density ``exp(-x^2 / 2s^2) - exp(-r^2 / 2s^2)`` on |x| < r = 4 s around the
    pixel centre (separable, Mitsuba's ``gaussian``), sampled by inverting its tabulated CDF."""
    if kind == "box":
        return rng.random((n, 2))
    r = 4.0 * stddev
    x = np.linspace(-r, r, 4097)
    f = np.maximum(np.exp(-x * x / (2 * stddev * stddev)) - np.exp(-r * r / (2 * stddev * stddev)), 0.0)
    cdf = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(x))])
    cdf /= cdf[-1]
    return 0.5 + np.interp(rng.random((n, 2)), cdf, x)


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

