"""nasset merge-quality: presets of one bake combined as quality variants."""

from __future__ import annotations

import numpy as np
import pytest

import nasset_sdk as ns
from nasset_sdk.cli import main
from nasset_sdk.examples import example_builder
from nasset_sdk.quality import merge_quality


@pytest.fixture
def levels(tmp_path):
    small = example_builder("rna", size="tiny", seed=1).write(tmp_path / "small.usdc")
    hq = example_builder("rna", size="small", seed=2).write(tmp_path / "hq.usdc")  # same default geometry
    return small, hq


def test_levels_round_trip(levels, tmp_path):
    small, hq = levels
    out = merge_quality({"small": small, "hq": hq}, tmp_path / "m.usdc")
    merged = ns.Asset.open(out, load="none")
    info = merged.components()["core"]
    assert set(info.qualities) == {"small", "hq"} and info.quality == "small"
    for q, src in (("small", small), ("hq", hq)):
        a, s = ns.Asset.open(out, quality=q), ns.Asset.open(src)
        assert np.array_equal(a.tensor("core", "triplane"), s.tensor("core", "triplane"))
        assert a.network_bytes("core", "decoder") == s.network_bytes("core", "decoder")
    assert set(ns.Asset.open(out).provenance["qualityLevels"]) == {"small", "hq"}
    from nasset_sdk.validate import validate_file

    assert validate_file(out).ok


def test_mismatched_inputs_are_refused(levels, tmp_path):
    small, _ = levels
    other = example_builder("rna", variant="fiber", size="tiny").write(tmp_path / "fiber.usdc")
    with pytest.raises(ns.UsageError, match="fiber"):
        merge_quality({"a": small, "b": other}, tmp_path / "m.usdc")
    with pytest.raises(ns.UsageError):
        merge_quality({"a": small}, tmp_path / "m.usdc")
    assert main(["merge-quality", "-o", str(tmp_path / "m.usdc"), f"a={small}", f"a={small}"]) == 2
    assert not (tmp_path / "m.usdc").exists()
