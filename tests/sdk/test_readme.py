"""The README's Python section runs as written, against a tiny example asset of each kind."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from nasset_sdk.examples import example_builder
from nasset_sdk.validate import validate_file

README = Path(__file__).resolve().parents[2] / "README.md"


def python_blocks() -> list[str]:
    """The ```python blocks of the README's '## Python' section, in order."""
    text = README.read_text()
    section = text[text.index("\n## Python\n"):]
    section = section[:section.index("\n## ", 1)]
    return re.findall(r"```python\n(.*?)```", section, re.S)


def test_the_section_has_code():
    blocks = python_blocks()
    assert len(blocks) >= 2 and any("radiance" in b for b in blocks) and any("from_asset" in b for b in blocks)


@pytest.mark.parametrize("kind", ["rna", "neupress", "8dna"])
def test_readme_python_section_runs(tmp_path, monkeypatch, kind):
    (tmp_path / "out").mkdir()
    example_builder(kind, size="tiny", seed=2).write(tmp_path / "out" / "example.usdc")
    monkeypatch.chdir(tmp_path)
    ns: dict = {}
    for block in python_blocks():
        exec(compile(block, f"README.md ({kind})", "exec"), ns)  # noqa: S102 - our own documentation
    assert ns["rgb"].shape == (8, 3) and np.isfinite(ns["rgb"]).all()
    assert ns["lit_or_not"].shape == (8, 3)
    assert validate_file(tmp_path / "out" / "edited.usdc", probe=False).ok
