"""``nasset inspect``: summarise an asset (kind, components, tensors, networks, geometry, metadata, sizes).

Uses only the public :class:`~nasset_sdk.asset.Asset` API. Components that are not loaded (``--load
none`` / ``required``) are listed without their tensors and networks, and none of their bytes is read.
Tensor sizes come from the declared shape and dtype (values are not read); network sizes and
parameter counts come from the verified model bytes (:meth:`Asset.network_bytes`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from .asset import GEOMETRY, Asset
from .errors import NassetError, path_arg
from .geometry import MeshGeometry
from .networks import parameter_count


def _vec(v) -> list[float]:
    return [float(x) for x in np.asarray(v, np.float64).reshape(-1)]


def _geometry(asset: Asset) -> dict:
    from pxr import UsdGeom

    try:
        geo = asset.geometry()
    except NassetError as exc:
        return {"error": exc.to_dict()}
    pts = np.asarray(geo.points, np.float64)
    out: dict = {"prim": GEOMETRY, "points": int(len(pts))}
    if isinstance(geo, MeshGeometry):
        out.update(type="Mesh", faces=int(len(geo.faces)), normals=geo.normals is not None)
    else:
        widths = np.asarray(geo.widths, np.float64)
        out.update(type="BasisCurves", curves=int(len(geo.counts)),
                   widthRange=[float(widths.min()), float(widths.max())])
    out["bounds"] = {"min": _vec(pts.min(0)), "max": _vec(pts.max(0))}
    extent = UsdGeom.Boundable(asset.stage.GetPrimAtPath(GEOMETRY)).GetExtentAttr().Get()
    out["extent"] = {"min": _vec(extent[0]), "max": _vec(extent[1])} if extent is not None and len(extent) == 2 else None
    return out


def _component(asset: Asset, info) -> dict:
    comp = {
        "prim": info.prim_path,
        "required": info.required,
        "purpose": info.purpose,
        "loaded": info.loaded,
        "qualities": list(info.qualities),
        "quality": info.quality,
        "tensors": {},
        "networks": {},
        "tensorBytes": 0,
        "networkBytes": 0,
        "parameters": 0,
    }
    if not info.loaded:
        return comp
    for name, ref in asset.tensor_refs(info.name).items():
        comp["tensors"][name] = {"prim": ref.prim_path, "shape": list(ref.shape), "dtype": ref.dtype,
                                 "layout": ref.layout, "bytes": ref.nbytes}
        comp["tensorBytes"] += ref.nbytes
    for name, ref in asset.network_refs(info.name).items():
        i = o = ref.info
        net = {"prim": ref.prim_path,
               "inputs": [{"name": n, "width": int(w)} for n, w in zip(i.input_names, i.input_widths, strict=False)],
               "outputs": [{"name": n, "width": int(w)} for n, w in zip(o.output_names, o.output_widths, strict=False)],
               "opset": ref.info.opset, "bytes": None, "parameters": None}
        try:
            data = asset.network_bytes(info.name, name)
        except NassetError as exc:  # report, keep summarising the rest
            net["error"] = exc.to_dict()
        else:
            net["bytes"] = len(data)
            net["parameters"] = parameter_count(data)
            comp["networkBytes"] += len(data)
            comp["parameters"] += net["parameters"]
        comp["networks"][name] = net
    return comp


def inspect_asset(path: str | os.PathLike, load: str = "all") -> dict:
    """Summary of the asset at ``path`` as a JSON-ready dict; ``load``: 'all', 'required' or 'none'."""
    return describe_asset(Asset.open(path_arg(path, "inspect: the asset"), load=load), path)


def describe_asset(asset: Asset, path: str | os.PathLike) -> dict:
    """:func:`inspect_asset`'s summary of an ``asset`` already opened from ``path``."""
    path = Path(path)
    stage = asset.stage
    lo, hi = asset.domain
    report: dict = {
        "file": str(path),
        "fileBytes": path.stat().st_size,
        "specVersion": asset.spec_version,
        "kind": asset.kind,
        "variant": asset.variant,
        "upAxis": str(stage.GetMetadata("upAxis")),
        "metersPerUnit": float(stage.GetMetadata("metersPerUnit")),
        "domain": {"min": _vec(lo), "max": _vec(hi)},
        "geometry": _geometry(asset),
    }
    try:  # rna, format 0.3 (spec/kinds/rna.md#near-field-fetch); 0 when not authored
        report["nearFieldFetch"] = asset.near_field_fetch
    except NassetError as exc:
        report["nearFieldFetch"] = {"error": exc.to_dict()}
    try:
        report["provenance"] = asset.provenance
    except NassetError as exc:
        report["provenance"] = {"error": exc.to_dict()}
    comps = {name: _component(asset, info) for name, info in asset.components().items()}
    report["components"] = comps
    report["totals"] = {
        "components": len(comps),
        "loaded": sum(c["loaded"] for c in comps.values()),
        "tensors": sum(len(c["tensors"]) for c in comps.values()),
        "networks": sum(len(c["networks"]) for c in comps.values()),
        "tensorBytes": sum(c["tensorBytes"] for c in comps.values()),
        "networkBytes": sum(c["networkBytes"] for c in comps.values()),
        "parameters": sum(c["parameters"] for c in comps.values()),
    }
    return report


def _size(n: int | None) -> str:
    if n is None:
        return "?"
    for unit in ("B", "KiB", "MiB"):
        if n < 1024 or unit == "MiB":
            return f"{n} B" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    return f"{n:.1f} GiB"  # pragma: no cover


def _fmt_vec(v) -> str:
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"


def format_report(r: dict) -> str:
    """Human-readable form of :func:`inspect_asset`'s result."""
    lines = [
        f"{r['file']}  ({_size(r['fileBytes'])})",
        f"  kind {r['kind']}  variant {r['variant']}  specVersion {r['specVersion']}",
        f"  upAxis {r['upAxis']}  metersPerUnit {r['metersPerUnit']:g}",
        f"  domain {_fmt_vec(r['domain']['min'])} .. {_fmt_vec(r['domain']['max'])}",
    ]
    near = r.get("nearFieldFetch")
    if isinstance(near, dict):
        lines.append(f"  near-field fetch: [{near['error']['code']}] {near['error']['message']}")
    elif near:
        lines.append(f"  near-field fetch f = {near:g} (light fetched at x + f (c - x), spec/kinds/rna.md#near-field-fetch)")
    g = r["geometry"]
    if "error" in g:
        lines.append(f"  geometry: [{g['error']['code']}] {g['error']['message']}")
    else:
        what = f"{g['faces']} triangles" if g["type"] == "Mesh" else f"{g['curves']} curves"
        lines.append(f"  geometry {g['type']}: {g['points']} points, {what}")
        lines.append(f"    bounds {_fmt_vec(g['bounds']['min'])} .. {_fmt_vec(g['bounds']['max'])}")
        if g["extent"]:
            lines.append(f"    extent {_fmt_vec(g['extent']['min'])} .. {_fmt_vec(g['extent']['max'])}")
    lines.append("  components:")
    for name, c in r["components"].items():
        q = f"  quality {c['quality']} of {','.join(c['qualities'])}" if c["qualities"] else ""
        state = "loaded" if c["loaded"] else "not loaded"
        lines.append(f"    {name:<16} {'required' if c['required'] else 'optional':<8} {state:<10} {c['purpose']}{q}")
        for tname, t in c["tensors"].items():
            shape = "x".join(map(str, t["shape"]))
            lines.append(f"      tensor  {tname:<14} {shape:<18} {t['dtype']:<8} {_size(t['bytes']):>10}  {t['layout']}")
        for nname, n in c["networks"].items():
            io = (",".join(f"{i['name']}[{i['width']}]" for i in n["inputs"]) + " -> "
                  + ",".join(f"{o['name']}[{o['width']}]" for o in n["outputs"]))
            extra = f"[{n['error']['code']}]" if "error" in n else f"{n['parameters']} params"
            lines.append(f"      network {nname:<14} {io:<18} opset {n['opset']:<3} {_size(n['bytes']):>10}  {extra}")
    t = r["totals"]
    lines.append(f"  totals: {t['loaded']}/{t['components']} components loaded, {t['tensors']} tensors "
                 f"({_size(t['tensorBytes'])}), {t['networks']} networks ({_size(t['networkBytes'])}, "
                 f"{t['parameters']} params), file {_size(r['fileBytes'])}")
    prov = r["provenance"]
    lines.append("  provenance:")
    for key in sorted(prov):
        lines.append(f"    {key}: {json.dumps(prov[key], sort_keys=True)}")
    return "\n".join(lines)


def run(args) -> int:
    """CLI: nasset inspect FILE [--json] [--load all|required|none]."""
    from .errors import UsageError

    if args.load not in ("all", "required", "none"):
        raise UsageError(f"--load must be all, required or none, not {args.load!r}")
    report = inspect_asset(args.file, load=args.load)
    if args.json:
        print(json.dumps(report, indent=2))
    else:
        print(format_report(report))
    return 0
