"""Every error code points at a spec paragraph that exists, and spec-internal links resolve."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from nasset_sdk.errors import CODES

SPEC = Path(__file__).resolve().parents[2] / "spec"


def _slug(heading: str) -> str:
    """GitHub-style anchor of a markdown heading."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    """Heading anchors: an explicit ``{#id}`` at the end of a heading, else the GitHub slug."""
    heads = re.findall(r"^#{1,6}\s+(.+)$", path.read_text(), re.M)
    return {m.group(1) if (m := re.search(r"\{#([\w-]+)\}\s*$", h)) else _slug(h) for h in heads}


@pytest.mark.parametrize("code", sorted(CODES))
def test_code_spec_anchor_exists(code):
    target = CODES[code].spec
    file, _, anchor = target.partition("#")
    path = SPEC / file
    assert path.is_file(), f"{code}: spec file {file} missing"
    if anchor:
        assert anchor in _anchors(path), f"{code}: no heading for #{anchor} in {file}"


def test_relative_links_in_spec_resolve():
    bad = []
    for md in SPEC.rglob("*.md"):
        for link in re.findall(r"\]\(([^)\s]+)\)", md.read_text()):
            if re.match(r"^[a-z]+:", link):
                continue
            file, _, anchor = link.partition("#")
            target = (md.parent / file).resolve() if file else md
            if not target.exists():
                bad.append(f"{md.relative_to(SPEC)} -> {link}")
            elif anchor and target.suffix == ".md" and anchor not in _anchors(target):
                bad.append(f"{md.relative_to(SPEC)} -> {link} (anchor)")
    assert not bad, bad


def test_test_files_named_in_the_docs_exist():
    """``tests/....py`` named in spec/, docs/ and the README is a file (a renamed test left two stale names)."""
    root = SPEC.parent
    missing = []
    for md in [*SPEC.rglob("*.md"), *(root / "docs").rglob("*.md"), root / "README.md"]:
        for name in set(re.findall(r"\btests/[\w/]+\.py\b", md.read_text(encoding="utf-8"))):
            if not (root / name).is_file():
                missing.append(f"{md.relative_to(root)}: {name}")
    assert not missing, "\n".join(missing)
