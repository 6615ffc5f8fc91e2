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
