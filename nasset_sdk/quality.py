"""Combine assets baked at different quality presets into one asset with a ``quality`` variant set
(spec/format.md#quality-variants): e.g. ``nasset merge-quality -o A.usdc small=A_small.usdc hq=A_hq.usdc``."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .asset import FALLBACK, Asset, AssetBuilder
from .errors import UsageError
from .geometry import MeshGeometry


def merge_quality(levels: dict[str, str | os.PathLike], output: str | os.PathLike) -> Path:
    """Write ``output`` holding each input's required components as quality variants (first level is the default).

    The inputs must be of one kind and variant with identical geometry and encoding domain (bakes of the
    same scene at different presets). Optional components are taken from the first input.
    """
    if len(levels) < 2:
        raise UsageError("merge-quality needs at least two LEVEL=ASSET inputs")
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
    b = builder_like(first)
    b.provenance["qualityLevels"] = {q: a.provenance for q, a in assets.items()}
    for cname, info in first.components().items():
        sources = assets.items() if info.required else [(None, first)]
        for q, a in sources:
            copy_component(b, a, cname, info, quality=q)
    return b.write(output)


def builder_like(asset) -> AssetBuilder:
    """An AssetBuilder with the kind, variant, geometry, encoding domain, units, fallback material and
    provenance (less the keys the writer sets) of an opened asset, and no components."""
    b = AssetBuilder(asset.kind, variant=asset.variant)
    b.set_geometry(asset.geometry())
    b.domain = asset.domain
    b.meters_per_unit = float(asset.stage.GetMetadata("metersPerUnit") or 1.0)
    shader = asset.stage.GetPrimAtPath(FALLBACK + "/PreviewSurface")
    for attr, field in (("inputs:diffuseColor", "fallback_color"), ("inputs:roughness", "fallback_roughness")):
        value = shader.GetAttribute(attr).Get() if shader else None
        if value is not None:
            setattr(b, field, tuple(value) if field == "fallback_color" else float(value))
    b.provenance = {k: v for k, v in asset.provenance.items() if k not in ("specVersion", "kind")}
    return b


def copy_component(builder: AssetBuilder, asset, name: str, info, *, quality: str | None = None) -> None:
    """Copy the loaded component ``name`` (its ComponentInfo ``info``) of ``asset`` into ``builder``,
    tensors with their stored dtype and layout, networks byte for byte."""
    data = builder.component(name, required=info.required, purpose=info.purpose, quality=quality)
    for tname, ref in asset.tensor_refs(name).items():
        data.add_tensor(tname, asset.tensor(name, tname), dtype=ref.dtype, layout=ref.layout)
    for nname in asset.network_refs(name):
        data.add_network(nname, asset.network_bytes(name, nname))


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
