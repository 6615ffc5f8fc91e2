"""Combine assets baked at different quality presets into one asset with a ``quality`` variant set
(spec/format.md#quality-variants): e.g. ``nasset merge-quality -o A.usdc small=A_small.usdc hq=A_hq.usdc``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .asset import Asset, AssetBuilder, read_component
from .errors import UsageError, path_arg
from .geometry import MeshGeometry


def merge_quality(levels: dict[str, str | os.PathLike], output: str | os.PathLike) -> Path:
    """Write ``output`` holding each input's required components as quality variants (first level is the default).

    The inputs must be of one kind and variant with identical geometry and encoding domain (bakes of the
    same scene at different presets). Optional components are taken from the first input.
    """
    if not isinstance(levels, dict) or len(levels) < 2:
        raise UsageError("merge-quality needs at least two LEVEL=ASSET inputs ({level: asset file})")
    levels = {q: path_arg(p, f"merge-quality: level {q!r}") for q, p in levels.items()}
    output = path_arg(output, "merge-quality: the output")
    assets = {q: Asset.open(p, load="all") for q, p in levels.items()}
    names = list(assets)
    first = assets[names[0]]
    geo = first.geometry()
    for q, a in assets.items():
        where = {"file": str(a.path)}
        if (a.kind, a.variant) != (first.kind, first.variant):
            raise UsageError(f"level {q!r} is {a.kind}/{a.variant}, level {names[0]!r} is {first.kind}/{first.variant}", **where)
        if any(c.qualities for c in a.components().values()):
            raise UsageError(f"level {q!r} already has quality variants", **where)
        g = a.geometry()
        same = np.array_equal(g.points, geo.points) and all(
            np.array_equal(getattr(g, f), getattr(geo, f)) for f in (("faces",) if isinstance(geo, MeshGeometry) else ("counts", "widths")))
        if not same or not all(np.array_equal(x, y) for x, y in zip(a.domain, first.domain, strict=True)):
            raise UsageError(f"level {q!r} has other geometry or another encoding domain than level {names[0]!r}", **where)
    b = AssetBuilder.from_asset(first)
    b.provenance["qualityLevels"] = {q: a.provenance for q, a in assets.items()}
    for cname, info in first.components().items():
        if info.required:  # optional components stay as the first input has them
            b.components[cname] = {q: read_component(a, cname) for q, a in assets.items()}
            b.default_quality[cname] = names[0]
    return b.write(output)


def run(args) -> int:
    """CLI: nasset merge-quality -o OUT LEVEL=ASSET LEVEL=ASSET ..."""
    levels = {}
    for item in args.levels:
        q, sep, path = item.partition("=")
        if not sep or not q or not path or q in levels:
            raise UsageError(f"expected distinct LEVEL=ASSET pairs, got {item!r}")
        levels[q] = path
    out = merge_quality(levels, args.output)
    print(f"wrote {out}: quality levels {list(levels)} (default {next(iter(levels))!r})")
    return 0
