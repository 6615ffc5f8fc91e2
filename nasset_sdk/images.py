"""Image files: 8-bit PNG with the standard library only (zlib), the finite-float32 guard every image
writer applies, and atomic writes with typed errors (previews, plots, error maps, renders)."""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np

from .errors import error

#: Largest magnitude any float image file holds: float32 max (spec/renderer.md#limits).
IMAGE_VALUE_MAX = float(np.finfo(np.float32).max)


def finite_float32(image) -> np.ndarray:
    """``image`` as a contiguous float32 array with NaN -> 0 and every value clamped to
    [-IMAGE_VALUE_MAX, IMAGE_VALUE_MAX], so no Inf/NaN ever reaches a file (same shape)."""
    a = np.asarray(image, np.float64)
    a = np.nan_to_num(a, nan=0.0, posinf=IMAGE_VALUE_MAX, neginf=-IMAGE_VALUE_MAX)
    return np.ascontiguousarray(np.clip(a, -IMAGE_VALUE_MAX, IMAGE_VALUE_MAX), np.float32)


@contextlib.contextmanager
def atomic_output(path, what: str = "image"):
    """Yield a temporary path beside ``path``; on success it is renamed over ``path``.

    Any failure (missing or unwritable folder, full disk, the writer raising) leaves ``path``
    untouched and raises ``WRITE_FAILED`` naming the file; the temporary file is removed.
    """
    target = Path(path)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{target.stem}.tmp-", suffix=target.suffix, dir=target.parent)
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())  # the permissions a plain open() would give
        yield tmp
        os.replace(tmp, target)
        tmp = None
    except (OSError, RuntimeError, ValueError) as exc:  # OpenEXR reports I/O failures as RuntimeError
        detail = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc).strip().splitlines()[-1][:200]
        raise error("WRITE_FAILED", f"cannot write the {what}: {detail}", file=str(target)) from None
    finally:
        if tmp is not None and os.path.exists(tmp):
            os.unlink(tmp)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def png_bytes(rgb8: np.ndarray) -> bytes:
    """An [H, W, 3] uint8 image as 8-bit RGB PNG bytes (filter type 0 on every row)."""
    rgb8 = np.ascontiguousarray(rgb8, np.uint8)
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[r].tobytes() for r in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    return png + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def write_png(path, rgb8: np.ndarray) -> Path:
    """Write an [H, W, 3] uint8 image as an 8-bit RGB PNG atomically; returns the path (``WRITE_FAILED`` on failure)."""
    path = Path(path)
    data = png_bytes(rgb8)
    with atomic_output(path, "PNG") as tmp:
        Path(tmp).write_bytes(data)
    return path
