"""Image files: EXR (OpenEXR) read / write with bounded headers, the ACES tone curve, 8-bit PNG with the
standard library only (zlib), the finite-float32 guard every image writer applies, and atomic writes with
typed errors (previews, plots, error maps, renders)."""

from __future__ import annotations

import contextlib
import os
import struct
import tempfile
import zlib
from pathlib import Path

import numpy as np

from .arrays import real_array, real_dtype
from .errors import NassetError, UsageError, error, path_arg

#: Largest magnitude any float image file holds: float32 max (spec/renderer.md#limits).
IMAGE_VALUE_MAX = float(np.finfo(np.float32).max)
#: Image files read (dome / environment textures): side, pixels and pixels x channels, checked on the
#: header before any decoder sees the file (spec/renderer.md#limits).
MAX_TEXTURE_SIDE = 1 << 15
MAX_TEXTURE_PIXELS = 1 << 26
MAX_TEXTURE_VALUES = 1 << 28  # pixels x channels (1 GiB as float32)
#: Scan lines per chunk of each OpenEXR compression id (none, rle, zips, zip, piz, pxr24, b44, b44a, dwaa, dwab);
#: another id is counted at 256, the most any takes, so the chunk count is never overestimated.
EXR_LINES_PER_CHUNK = (1, 1, 1, 16, 32, 16, 32, 32, 32, 256)
#: Offsets of the chunk table read and checked one by one (8 MiB); a longer table is checked for its size only.
MAX_EXR_OFFSETS_CHECKED = 1 << 20


#: largest image file read out of a package (usdz) into a temporary file
MAX_PACKAGED_IMAGE_BYTES = 1 << 30


def packaged_name(resolved: str) -> str:
    """The file name inside a package of a package-relative resolved path (``a.usdz[tex/wood.png]`` -> ``tex/wood.png``,
    the innermost for nested packages), or "" for a plain path."""
    from pxr import Ar

    if not resolved or not Ar.IsPackageRelativePath(resolved):
        return ""
    inner = resolved
    while Ar.IsPackageRelativePath(inner):
        inner = Ar.SplitPackageRelativePathInner(inner)[1]
    return inner


@contextlib.contextmanager
def local_image_copy(resolved: str):
    """A file path holding the image USD resolved to ``resolved``: the path itself, or for a file inside a package (usdz)
    a temporary copy read through USD's resolver (at most :data:`MAX_PACKAGED_IMAGE_BYTES`; ``IMAGE_INVALID``
    otherwise), named with the packaged file's suffix."""
    from pxr import Ar

    packaged = packaged_name(resolved)
    if not packaged:
        yield resolved
        return
    handle = Ar.GetResolver().OpenAsset(Ar.ResolvedPath(resolved))
    if handle is None:
        raise error("IMAGE_INVALID", "cannot be read from its package", file=resolved)
    size = handle.GetSize()
    if size > MAX_PACKAGED_IMAGE_BYTES:
        raise error("IMAGE_INVALID", f"{size} bytes in its package, above {MAX_PACKAGED_IMAGE_BYTES}", file=resolved)
    with tempfile.TemporaryDirectory() as tmp:
        local = os.path.join(tmp, "image" + os.path.splitext(packaged)[1].lower())
        with open(local, "wb") as fh:
            fh.write(bytes(handle.GetBuffer()))
        yield local


def finite_float32(image) -> np.ndarray:
    """``image`` as a contiguous float32 array with NaN -> 0 and every value clamped to
    [-IMAGE_VALUE_MAX, IMAGE_VALUE_MAX], so no Inf/NaN ever reaches a file (same shape)."""
    a = real_array(image, "an image must be a real number array", dtype=np.float64)
    a = np.nan_to_num(a, nan=0.0, posinf=IMAGE_VALUE_MAX, neginf=-IMAGE_VALUE_MAX)
    return np.ascontiguousarray(np.clip(a, -IMAGE_VALUE_MAX, IMAGE_VALUE_MAX), np.float32)


@contextlib.contextmanager
def atomic_output(path, what: str = "image"):
    """Yield a temporary path beside ``path``; on success it is renamed over ``path``.

    Any failure (missing or unwritable folder, full disk, the writer raising) leaves ``path``
    untouched and raises ``WRITE_FAILED`` naming the file; the temporary file is removed.
    """
    target = path_arg(path, f"the {what}'s file")
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


def write_text_atomic(path, text: str, what: str = "report") -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (:func:`atomic_output`: a reader never sees half a report, a
    failure leaves the old file and raises ``WRITE_FAILED``); returns the path."""
    with atomic_output(path, what) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return Path(path)


def output_folder(path, what: str = "output folder") -> Path:
    """Create the folder ``path`` (and its parents) for a command's outputs; ``WRITE_FAILED`` naming it when that is
    not possible (a file in the way, a read-only parent), instead of the OSError's traceback."""
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise error("WRITE_FAILED", f"cannot create the {what}: {exc.strerror or exc}", file=str(folder)) from None
    return folder


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def png_bytes(rgb8: np.ndarray) -> bytes:
    """An [H, W, 3] uint8 image as 8-bit RGB PNG bytes (filter type 0 on every row)."""
    _check_rgb(rgb8, "a PNG image")
    rgb8 = np.ascontiguousarray(rgb8, np.uint8)
    h, w, _ = rgb8.shape
    raw = b"".join(b"\x00" + rgb8[r].tobytes() for r in range(h))

    def chunk(tag, data):
        return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)

    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    return png + chunk(b"IDAT", zlib.compress(raw, 6)) + chunk(b"IEND", b"")


def _check_rgb(image, what: str) -> None:
    """USAGE unless ``image`` is a real number array [H, W, 3] with H, W >= 1."""
    shape = np.shape(image)
    if real_dtype(image) is None or len(shape) != 3 or shape[2] != 3 or min(shape[:2]) < 1:
        raise UsageError(f"{what} must be a real number array [H, W, 3] (H, W >= 1), got shape {shape}")


def write_png(path, rgb8: np.ndarray) -> Path:
    """Write an [H, W, 3] uint8 image as an 8-bit RGB PNG atomically; returns the path (``WRITE_FAILED`` on failure)."""
    path = Path(path)
    data = png_bytes(rgb8)
    with atomic_output(path, "PNG") as tmp:
        Path(tmp).write_bytes(data)
    return path


def write_exr(path, image: np.ndarray) -> None:
    """Write [H, W, 3] as float32 RGB OpenEXR atomically; values pass :func:`finite_float32` (``WRITE_FAILED``)."""
    import OpenEXR

    _check_rgb(image, "an OpenEXR image")
    img = finite_float32(image)
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_output(path, "OpenEXR image") as tmp:
        OpenEXR.File(header, {"RGB": img}).write(tmp)


def exr_header_size(path) -> tuple[int, int, int]:
    """(width, height, channels) from an OpenEXR file's header, read with bounded reads before any
    decoder sees the file. ``IMAGE_INVALID`` for a file that is not a single-part scanline/tiled EXR, or whose
    chunk table (one file offset per chunk, after the header) does not fit the file or points outside it: a header
    without its pixels, a truncated file. OpenEXR's own reader was left to find those, and on a header-only file
    it once did not return under load."""
    path = path_arg(path, "the OpenEXR image's file")

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
    pos, window, channels, compression, tiles = 8, None, None, None, None
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
        elif name == b"compression" and size == 1:
            compression = value[0]
        elif name == b"tiles" and size == 9:
            tiles = struct.unpack("<II", value[:8])
        pos = vstart + size
    if window is None or channels is None:
        raise bad("header lacks dataWindow or channels")
    x0, y0, x1, y1 = window
    w, h = x1 - x0 + 1, y1 - y0 + 1
    if 1 <= w <= MAX_TEXTURE_SIDE and 1 <= h <= MAX_TEXTURE_SIDE:  # (beyond: read_exr's bounds say so)
        if flags & 0x200:  # tiled: the first level's tiles (mipmaps and ripmaps have more)
            if tiles is None or min(tiles) < 1:
                raise bad("a tiled image without a valid tile size")
            chunks = -(-w // tiles[0]) * -(-h // tiles[1])
        else:
            per = EXR_LINES_PER_CHUNK[compression] if compression is not None and compression < len(EXR_LINES_PER_CHUNK) else 256
            chunks = -(-h // per)
        _check_chunk_table(path, pos + 1, chunks, bad)
    return w, h, channels


def _check_chunk_table(path, start: int, chunks: int, bad) -> None:
    """The ``chunks`` offsets at ``start`` (a lower bound of the file's count) fit the file, and each points past the
    table to at least a chunk header (8 bytes) inside it."""
    size = os.path.getsize(path)
    end = start + 8 * chunks
    if end > size:
        raise bad(f"the file ends at {size} bytes, before its table of {chunks} chunk offsets (pixels missing or truncated)")
    n = min(chunks, MAX_EXR_OFFSETS_CHECKED)
    with open(path, "rb") as fh:
        fh.seek(start)
        offsets = np.frombuffer(fh.read(8 * n), "<u8")
    outside = (offsets < end) | (offsets > size - 8)
    if outside.any():
        i = int(np.argmax(outside))
        raise bad(f"chunk offset {i} ({int(offsets[i])}) points outside the file's {size} bytes (pixels missing or truncated)")


def _chlist_names(value: bytes):
    pos = 0
    while pos < len(value) and value[pos] != 0:
        end = value.find(b"\0", pos)
        if end < 0:
            return
        yield value[pos:end]
        pos = end + 1 + 16


def read_exr(path, *, alpha: bool = False) -> np.ndarray:
    """[H, W, 3] float32 RGB (a single-channel image is repeated; alpha is dropped), or with ``alpha`` [H, W, 4]:
    RGB and the ``A`` channel (1 where the file has none).

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
            if alpha:
                a = np.asarray(ch["A"].pixels, np.float32) if "A" in ch else np.ones(img.shape[:2], np.float32)
                img = np.concatenate([img, a.reshape(img.shape[:2])[..., None]], -1)
    except (RuntimeError, OSError, ValueError, TypeError, StopIteration) as exc:  # OpenEXR's own errors are RuntimeError
        detail = str(exc).strip().splitlines()[-1][:200] if str(exc).strip() else type(exc).__name__
        raise error("IMAGE_INVALID", f"cannot decode the OpenEXR image: {detail}", file=str(path)) from None
    if img.ndim != 3 or img.shape[:2] != (h, w):
        raise error("IMAGE_INVALID", f"decoded pixels {img.shape} differ from the header's {w} x {h}", file=str(path))
    return img


#: 8-bit / 16-bit image formats :func:`read_png_jpeg` decodes (Pillow's names)
PNG_JPEG = ("PNG", "JPEG")


def read_png_jpeg(path, *, alpha: bool = False) -> tuple[np.ndarray, int]:
    """(image [H, W, 3] float32 in 0 .. 1, bits per channel: 8 or 16) of a PNG or JPEG file, values as stored (no
    colour decoding); grey is repeated, alpha dropped (with ``alpha``: kept as a fourth channel, 1 where the file has
    none; a palette's transparency included), a palette expanded. The size is checked from the header before
    anything is decoded (each side 1 .. MAX_TEXTURE_SIDE, at most MAX_TEXTURE_PIXELS pixels); any other format or a
    corrupt file is ``IMAGE_INVALID``. Needs Pillow (the ``render`` extra)."""
    from PIL import Image

    def bad(msg):
        return error("IMAGE_INVALID", msg, file=str(path))

    try:
        with Image.open(path, formats=PNG_JPEG) as im:
            w, h = im.size
            if not (1 <= w <= MAX_TEXTURE_SIDE and 1 <= h <= MAX_TEXTURE_SIDE) or w * h > MAX_TEXTURE_PIXELS:
                raise bad(f"image of {w} x {h} pixels is outside the bounds (each side 1 .. {MAX_TEXTURE_SIDE}, at most "
                          f"{MAX_TEXTURE_PIXELS} pixels)")
            mode = im.mode
            if mode in ("I;16", "I;16B", "I;16L", "I"):  # 16-bit grey PNG
                grey = np.asarray(im, np.float32) / 65535.0
                img, bits = np.repeat(grey[..., None], 3, -1), 16
                if alpha:
                    img = np.concatenate([img, np.ones((h, w, 1), np.float32)], -1)
            else:
                img, bits = np.asarray(im.convert("RGBA" if alpha else "RGB"), np.float32) / 255.0, 8
    except NassetError:
        raise
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        raise bad(f"cannot decode it as PNG or JPEG: {str(exc).strip()[:200] or type(exc).__name__}") from None
    if img.shape != (h, w, 4 if alpha else 3):
        raise bad(f"decoded pixels {img.shape} differ from the header's {w} x {h}")
    return img, bits


def tonemap(image: np.ndarray, exposure: float = 0.0) -> np.ndarray:
    """ACES filmic curve (Narkowicz fit) then sRGB encoding -> uint8."""
    x = np.maximum(finite_float32(image).astype(np.float64), 0.0) * float(np.clip(2.0 ** np.clip(exposure, -200, 200), 0, 1e60)) * 0.6
    y = np.clip((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)
    s = np.where(y <= 0.0031308, 12.92 * y, 1.055 * np.power(y, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)
