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
