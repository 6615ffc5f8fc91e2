"""Rewrite an asset smaller and report what it cost (``nasset optimize A.usdc -o B.usdc``, spec/format.md#editing).

Passes, applied in this order to an :meth:`AssetBuilder.from_asset` copy:

1. ``drop``: remove optional components (a required one is a usage error);
2. ``keep_quality``: keep only the named quality levels of every component that has quality variants
   (one level left: stored as a plain component; the old default, if kept, stays the default);
3. ``dtype``: re-encode every tensor as float16 or float32;
4. ``portable``: add (or rebuild) the optional ``portable`` component, the evaluation graphs any
   onnxruntime host can run (nasset_sdk.portable, spec/format.md#portable-evaluation-graphs), built
   from the tensors as passes 1-3 left them; its parity with the evaluator goes into the report.

The report compares the two files: sizes, tensor bytes, and the accuracy change of the shared
evaluator interface (:meth:`Evaluator.radiance`) on a fixed random query set, plus the PSNR of a small
preview render (``nasset view --per-pixel``, surface assets) of the new file against the old one. Both
are deterministic, so the old file's figures are exact references (no noise ceiling).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from . import limits
from .asset import Asset, AssetBuilder
from .errors import UsageError, path_arg
from .geometry import MeshGeometry
from .kinds.query import Query

#: rows of the accuracy query set, its seed, and the side of the preview render, pixels
QUERY_ROWS = 2048
QUERY_SEED = 12345
PREVIEW_SIZE = 64


@dataclass
class OptimizeOptions:
    """What to change; the defaults change nothing."""

    dtype: str | None = None  # "float16" | "float32" | None (keep each tensor's)
    drop: tuple[str, ...] = ()  # optional component names
    keep_quality: tuple[str, ...] = ()  # quality level names; empty keeps all
    samples: int = QUERY_ROWS
    preview: bool = True
    probe: bool = True  # open the input in a child process first (nasset_sdk.safeopen); off only for files this process wrote
    portable: bool = False  # add the portable evaluation graphs (pass 4)


def query_set(asset: Asset, rows: int = QUERY_ROWS, seed: int = QUERY_SEED) -> Query:
    """A fixed random :class:`Query` [rows] on the asset's geometry.

    Mesh: uniform points on the triangles (area-weighted), n the face normal, w_o and w_i uniform on the
    hemisphere of n. Curves: uniform points on the segments (length-weighted), n the segment tangent,
    w_o and w_i uniform on the sphere. shadowed all False."""
    if not isinstance(rows, int) or not 1 <= rows <= 1 << 20:
        raise UsageError(f"query rows must be an int in 1 .. {1 << 20}, got {rows!r}", file=str(asset.path))
    rng = np.random.default_rng(seed)
    geo = asset.geometry()
    p = np.asarray(geo.points, np.float64)
    if isinstance(geo, MeshGeometry):
        f = np.asarray(geo.faces, np.int64)
        cross = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        area = np.linalg.norm(cross, axis=1)
        if not area.sum() > 0:
            raise UsageError("the mesh has no area to sample", file=str(asset.path), prim="/Asset/Geometry")
        tri = rng.choice(len(f), rows, p=area / area.sum())
        r1, r2 = np.sqrt(rng.random(rows)), rng.random(rows)
        x = (1 - r1)[:, None] * p[f[tri, 0]] + (r1 * (1 - r2))[:, None] * p[f[tri, 1]] + (r1 * r2)[:, None] * p[f[tri, 2]]
        n = cross[tri] / np.where(area[tri] > 0, area[tri], 1.0)[:, None]
        n[area[tri] <= 0] = (0.0, 0.0, 1.0)
    else:
        ends = np.cumsum(np.asarray(geo.counts, np.int64))
        seg = np.setdiff1d(np.arange(len(p) - 1), ends[:-1] - 1)  # segments inside one curve
        d = p[seg + 1] - p[seg]
        length = np.linalg.norm(d, axis=1)
        if not length.sum() > 0:
            raise UsageError("the curves have no length to sample", file=str(asset.path), prim="/Asset/Geometry")
        k = rng.choice(len(seg), rows, p=length / length.sum())
        x = p[seg[k]] + rng.random(rows)[:, None] * d[k]
        n = d[k] / np.where(length[k] > 0, length[k], 1.0)[:, None]
        n[length[k] <= 0] = (0.0, 1.0, 0.0)

    def sphere() -> np.ndarray:
        z = rng.uniform(-1, 1, rows)
        phi = rng.uniform(0, 2 * np.pi, rows)
        s = np.sqrt(np.maximum(1 - z * z, 0.0))
        return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1)

    wo, wi = sphere(), sphere()
    if isinstance(geo, MeshGeometry):  # flip into the hemisphere of n
        wo *= np.where((wo * n).sum(1) < 0, -1.0, 1.0)[:, None]
        wi *= np.where((wi * n).sum(1) < 0, -1.0, 1.0)[:, None]
    return Query(x, n, wo, wi)


def _apply(b: AssetBuilder, opts: OptimizeOptions, where: dict) -> None:
    specs = b.components
    for name in opts.drop:
        if name not in specs:
            raise UsageError(f"--drop {name}: no such component (have {sorted(specs)})", **where)
        levels = specs[name]
        if next(iter(levels.values())).required:
            raise UsageError(f"--drop {name}: the component is required by kind {b.kind}", **where)
        del specs[name]
        b.default_quality.pop(name, None)
    if opts.keep_quality:
        found = set()
        for name, levels in specs.items():
            if "" in levels:
                continue
            kept = {q: d for q, d in levels.items() if q in opts.keep_quality}
            found |= kept.keys()
            if not kept:
                raise UsageError(f"--keep-quality {','.join(opts.keep_quality)}: component {name!r} has none of them "
                                 f"(it has {sorted(levels)})", **where)
            if len(kept) == 1:
                specs[name] = {"": next(iter(kept.values()))}
                b.default_quality[name] = ""
            else:
                specs[name] = kept
                if b.default_quality[name] not in kept:
                    b.default_quality[name] = next(q for q in opts.keep_quality if q in kept)
        unknown = set(opts.keep_quality) - found
        if unknown:
            raise UsageError(f"--keep-quality: no component has quality {sorted(unknown)}", **where)
    if opts.dtype is not None:
        for levels in specs.values():
            for data in levels.values():
                for tname, (arr, _, layout) in list(data.tensors.items()):
                    data.add_tensor(tname, arr, dtype=opts.dtype, layout=layout)


def _tensor_bytes(path: Path) -> int:
    """Bytes of the tensors of every component at its default quality level."""
    asset = Asset.open(path, load="all")
    return sum(r.nbytes for c in asset.components() for r in asset.tensor_refs(c).values())


def _preview(asset: Asset):
    from .view import shade_pixels

    rgb, hit = shade_pixels(asset, size=(PREVIEW_SIZE, PREVIEW_SIZE))
    return rgb.reshape(-1, 3).astype(np.float64), hit.reshape(-1)


def compare(before: Asset, after: Asset, *, samples: int = QUERY_ROWS, preview: bool = True) -> dict:
    """Accuracy of ``after`` against ``before`` (both opened with their default quality and required components).

    ``radiance``: max and mean |after - before| of :meth:`Evaluator.radiance` over :func:`query_set`
    (1/sr), and the mean radiance of ``before`` for scale. ``preview``: PSNR (dB, peak = the 99.5th
    percentile of the old image over the object's pixels) of the new preview render; None for fibers."""
    q = query_set(before, samples)
    ra = before.evaluator().radiance(q).astype(np.float64)
    rb = after.evaluator().radiance(q).astype(np.float64)
    d = np.abs(rb - ra)
    out = {"query_rows": samples, "query_seed": QUERY_SEED, "max_abs_diff": float(d.max()), "mean_abs_diff": float(d.mean()),
           "mean_radiance": float(ra.mean())}
    out["preview_psnr_db"] = None
    if preview and before.variant == "surface":
        from .metrics import accuracy

        img_a, mask = _preview(before)
        img_b, _ = _preview(after)
        if mask.any():
            acc = accuracy(img_b, img_a, img_a, mask, flip=False)
            out["preview_psnr_db"] = None if acc.mse == 0 else acc.psnr_db
            out["preview_identical"] = acc.mse == 0
            out["preview_size"] = PREVIEW_SIZE
    return out


def optimize(src: str | os.PathLike, dst: str | os.PathLike, opts: OptimizeOptions | None = None) -> dict:
    """Rewrite ``src`` as ``dst`` with ``opts`` applied; return the report (see :func:`format_report`)."""
    opts = opts or OptimizeOptions()
    if not isinstance(opts, OptimizeOptions):
        raise UsageError(f"optimize: opts must be an OptimizeOptions, got {type(opts).__name__}")
    src, dst = path_arg(src, "optimize: the input"), path_arg(dst, "optimize: the output")
    where = {"file": str(src)}
    if opts.dtype not in (None, *limits.TENSOR_DTYPES):
        raise UsageError(f"--dtype must be one of {limits.TENSOR_DTYPES}, got {opts.dtype!r}", **where)
    if dst.exists() and src.exists() and os.path.samefile(src, dst):
        raise UsageError("the output must be another file than the input", file=str(dst))
    asset = Asset.open(src, load="all", probe=opts.probe)
    b = AssetBuilder.from_asset(asset)
    _apply(b, opts, where)
    b.provenance["optimize"] = {"dtype": opts.dtype, "drop": list(opts.drop), "keepQuality": list(opts.keep_quality),
                                "portable": opts.portable}
    b.write(dst)
    portable = None
    if opts.portable:
        from .portable import add_portable

        portable = add_portable(dst, dst)["graphs"]
    before, after = Asset.open(src), Asset.open(dst)
    report = {
        "input": str(src), "output": str(dst), "kind": asset.kind, "variant": asset.variant,
        "options": {"dtype": opts.dtype, "drop": list(opts.drop), "keep_quality": list(opts.keep_quality)},
        "file_bytes": {"before": src.stat().st_size, "after": dst.stat().st_size},
        "tensor_bytes_default": {"before": _tensor_bytes(src), "after": _tensor_bytes(dst)},
        "components": {"before": sorted(asset.components()), "after": sorted(after.components())},
        "accuracy": compare(before, after, samples=opts.samples, preview=opts.preview),
        "portable": portable,
    }
    return report


def format_report(r: dict) -> str:
    fb, tb, acc = r["file_bytes"], r["tensor_bytes_default"], r["accuracy"]
    lines = [
        f"wrote {r['output']} ({r['kind']}/{r['variant']}) from {r['input']}",
        f"  file size     {fb['before']:>12,d} B -> {fb['after']:>12,d} B  ({fb['after'] / max(fb['before'], 1):.3f}x)",
        f"  tensor bytes  {tb['before']:>12,d} B -> {tb['after']:>12,d} B  (every component, default quality)",
        f"  components    {', '.join(r['components']['before'])} -> {', '.join(r['components']['after'])}",
        f"  radiance diff max {acc['max_abs_diff']:.3g}, mean {acc['mean_abs_diff']:.3g} /sr over {acc['query_rows']} "
        f"fixed random queries (mean radiance {acc['mean_radiance']:.3g} /sr)",
    ]
    for name, g in (r.get("portable") or {}).items():
        worst = max(v["max_abs"] for v in g["parity"].values())
        lines.append(f"  portable graph {name}: {g['bytes']:,d} B, {g['nodes']} nodes, opset {g['opset']}; "
                     f"max |difference| to the evaluator {worst:.2g}")
    if acc.get("preview_identical"):
        lines.append(f"  preview render {acc['preview_size']}x{acc['preview_size']}: identical")
    elif acc["preview_psnr_db"] is not None:
        lines.append(f"  preview render {acc['preview_size']}x{acc['preview_size']}: PSNR {acc['preview_psnr_db']:.1f} dB "
                     "against the input's (deterministic, no noise ceiling)")
    return "\n".join(lines)


def _names(values) -> tuple[str, ...]:
    return tuple(n for v in (values or ()) for n in v.split(",") if n)


def run(args) -> int:
    """CLI: nasset optimize A.usdc -o B.usdc [--dtype float16|float32] [--drop C] [--keep-quality Q] [--json]."""
    opts = OptimizeOptions(dtype=args.dtype, drop=_names(args.drop), keep_quality=_names(args.keep_quality),
                           samples=args.samples, preview=not args.no_preview, portable=args.portable)
    report = optimize(args.file, args.output, opts)
    print(json.dumps({"ok": True, **report}, indent=2) if args.json else format_report(report))
    return 0
