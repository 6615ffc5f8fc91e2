"""nasset_sdk.images, the image files every command writes: bad arguments are USAGE errors naming what was wrong."""

from __future__ import annotations

import numpy as np
import pytest

from nasset_sdk.errors import UsageError
from nasset_sdk.images import read_exr, tonemap, write_exr, write_png


@pytest.mark.parametrize("bad", [np.zeros((4, 4)), np.zeros((4, 4, 4)), np.zeros((0, 4, 3)), [["a", "b", "c"]],
                                 np.zeros((2, 2, 3), complex)])
def test_images_that_are_not_rgb_arrays_are_refused(tmp_path, bad):
    """A 2-D array or 4 channels used to be written as an EXR whose RGB layout was not [H, W, 3]; strings and an
    empty image failed as numpy or OpenEXR exceptions."""
    with pytest.raises(UsageError, match=r"must be a real number array \[H, W, 3\]"):
        write_exr(tmp_path / "x.exr", bad)
    with pytest.raises(UsageError, match=r"must be a real number array \[H, W, 3\]"):
        write_png(tmp_path / "x.png", bad)
    assert not list(tmp_path.iterdir())


def test_paths_that_are_not_paths_and_string_images_are_refused(tmp_path):
    img = np.random.default_rng(0).random((3, 5, 3))
    with pytest.raises(UsageError, match="must be a file path"):
        write_exr(None, img)
    with pytest.raises(UsageError, match="must be a file path"):
        read_exr(None)
    with pytest.raises(UsageError, match="real number array"):
        tonemap([["a"]])
    write_exr(tmp_path / "ok.exr", img)
    np.testing.assert_allclose(read_exr(tmp_path / "ok.exr"), img, rtol=1e-6)


def test_reports_are_written_atomically(tmp_path, monkeypatch):
    """write_text_atomic (every bench's JSON and markdown report, the conformance logs): a failed write leaves the old
    file whole and raises WRITE_FAILED, with no temporary file left behind."""
    from pathlib import Path

    from nasset_sdk.errors import NassetError
    from nasset_sdk.images import write_text_atomic

    target = tmp_path / "report.json"
    write_text_atomic(target, '{"old": 1}')

    def fail(self, *a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(Path, "write_text", fail)
    with pytest.raises(NassetError) as exc:
        write_text_atomic(target, '{"new": 2}')
    monkeypatch.undo()
    assert exc.value.code == "WRITE_FAILED" and "No space left" in exc.value.message
    assert target.read_text() == '{"old": 1}' and [p.name for p in tmp_path.iterdir()] == ["report.json"]


# -- the chunk table is checked before OpenEXR decodes (nasset_sdk.images.exr_header_size) ---------------------

COMPRESSIONS = ("NO", "RLE", "ZIPS", "ZIP", "PIZ", "PXR24", "B44", "B44A", "DWAA", "DWAB", "HTJ2K256", "HTJ2K32", "ZSTD")


def _write(path, image, **header):
    import OpenEXR

    OpenEXR.File({"type": OpenEXR.scanlineimage, **header}, {"RGB": image}).write(str(path))
    return path


@pytest.mark.parametrize("name", COMPRESSIONS)
def test_every_compression_reads_back(tmp_path, name):
    """The chunk count is a lower bound for every compression (lines per chunk), so no valid file is refused."""
    import OpenEXR

    compression = getattr(OpenEXR, f"{name}_COMPRESSION", None)
    if compression is None:
        pytest.skip(f"this OpenEXR has no {name} compression")
    image = np.random.default_rng(3).uniform(0, 4, (67, 45, 3)).astype(np.float32)  # 67 rows: a partial last chunk
    path = _write(tmp_path / "a.exr", image, compression=compression)
    got = read_exr(path)
    assert got.shape == image.shape and np.isfinite(got).all()
    if name in ("NO", "RLE", "ZIPS", "ZIP", "PIZ", "ZSTD"):  # lossless
        np.testing.assert_array_equal(got, image)


def test_tiled_images_read_back(tmp_path):
    """One level only: OpenEXR's Python writer leaves a mipmap's other levels out of the file (its own reader then
    refuses it), so our check's lower bound (the first level's tiles) is exercised on single-level files."""
    import OpenEXR

    image = np.random.default_rng(4).uniform(0, 1, (40, 70, 3)).astype(np.float32)
    tiles = OpenEXR.TileDescription()
    tiles.xSize, tiles.ySize, tiles.mode = 16, 8, OpenEXR.ONE_LEVEL
    path = tmp_path / "t.exr"
    OpenEXR.File({"type": OpenEXR.tiledimage, "tiles": tiles, "compression": OpenEXR.ZIP_COMPRESSION},
                 {"RGB": image}).write(str(path))
    np.testing.assert_array_equal(read_exr(path), image)


def test_files_without_their_pixels_are_image_invalid(tmp_path):
    """A header without its chunk table, a file cut short and a zeroed table are refused by our check, naming the
    cause, before OpenEXR's reader sees them."""
    from nasset_sdk.errors import NassetError

    image = np.random.default_rng(5).uniform(0, 1, (64, 32, 3)).astype(np.float32)
    import OpenEXR

    whole = _write(tmp_path / "whole.exr", image, compression=OpenEXR.ZIP_COMPRESSION).read_bytes()  # 4 chunks of 16 lines
    assert read_exr(tmp_path / "whole.exr").shape == image.shape
    header_end = _header_end(whole)
    for name, data, says in (
        ("header_only", whole[:header_end], "before its table"),
        ("cut_short", whole[: int(0.6 * len(whole))], "points outside the file"),
        ("zeroed_table", whole[:header_end] + bytes(8 * 4) + whole[header_end + 32:], "points outside the file"),
    ):
        path = tmp_path / f"{name}.exr"
        path.write_bytes(data)
        with pytest.raises(NassetError) as exc:
            read_exr(path)
        assert exc.value.code == "IMAGE_INVALID" and says in exc.value.message, (name, exc.value.message)


def _header_end(data: bytes) -> int:
    """Offset of the chunk table: after the magic, version and the attributes (name, type, size, value), the empty
    name that ends the header."""
    import struct

    pos = 8
    while data[pos] != 0:
        name_end = data.index(b"\0", pos)
        type_end = data.index(b"\0", name_end + 1)
        size = struct.unpack("<i", data[type_end + 1:type_end + 5])[0]
        pos = type_end + 5 + size
    return pos + 1
