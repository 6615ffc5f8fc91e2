"""Typed errors cross process boundaries (multiprocessing, Ray workers) unchanged."""

from __future__ import annotations

import pickle

from nasset_sdk.errors import CODES, error


def test_every_code_survives_pickling():
    for code in CODES:
        e = error(code, f"message of {code}", file="a.usdc", prim="/Asset", attribute="nasset:kind")
        back = pickle.loads(pickle.dumps(e))
        assert type(back) is type(e) and back.code == code and str(back) == str(e)
        assert (back.file, back.prim, back.attribute) == (e.file, e.prim, e.attribute)


def test_unparsable_usda_names_the_parsers_reason(tmp_path):
    """``Asset.open`` of a ``.usda`` USD cannot parse is FILE_UNREADABLE with the parser's message (prim, attribute);
    it kept only the exception's last line, a lone quote."""
    import pytest

    from nasset_sdk import Asset
    from nasset_sdk.errors import NassetError

    path = tmp_path / "a.usda"
    path.write_text('#usda 1.0\ndef Xform "W" {\n  def Mesh "M" {\n    point3f[] points = [(0, 0, 0), (1, 1)]\n  }\n}\n')
    with pytest.raises(NassetError) as info:
        Asset.open(path)
    assert info.value.code == "FILE_UNREADABLE" and "</W/M.points>" in str(info.value), str(info.value)
