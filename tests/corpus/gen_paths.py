"""Hostile asset paths (spec/security.md#paths): ``python -m tests.corpus.gen_paths OUT_DIR``.

Every case is its own package folder ``OUT_DIR/<name>/asset.usdc`` built from a valid asset, with one
path authored through one arc: sublayer, reference, payload (plain and inside a variant), value clip,
asset-valued attribute, metadata, time sample. Path forms: absolute, ``..``, unbalanced and nested
package-relative paths, URLs, ``~``, backslashes, bare search paths, variable expressions, in-folder
symlinks to outside files and folders, and in-folder named pipes / folders / devices.

Composition targets outside the package are named pipes (``target="pipe"``, the default): a reader
that opens one blocks, so a regression hangs a bounded child instead of passing. ``target="file"``
points them at an ordinary USD layer instead (for measuring other implementations without hanging).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

from tests.corpus.make_corpus import Case

CODE = "ASSET_PATH_ESCAPES"
ARCS = ("sublayer", "reference", "payload", "variant_reference", "variant_payload", "clip")
VALUES = ("attribute", "metadata", "time_sample")
#: arcs crossed with every form; the others with the short list (the validator costs ~1 s a file)
FULL_ARCS = ("sublayer", "reference")
#: form -> (path as authored, needs the composition target to be a layer)
FORMS = (
    "absolute", "dotdot", "dotdot_deep", "bracket_unbalanced", "package_inner_dotdot", "package_inner_absolute",
    "package_nested_inner", "url_https", "url_file", "home", "backslash_dotdot", "search_path", "expression",
    "symlink_file", "symlink_dir", "symlink_chain", "pipe_inside", "folder_inside", "device_link", "dot_dotdot_mix",
)
SHORT_FORMS = ("absolute", "dotdot", "bracket_unbalanced", "package_inner_dotdot", "search_path", "symlink_file", "pipe_inside")


def _write_outside(out: Path, target: str) -> Path:
    outside = out / "_outside"
    outside.mkdir(parents=True, exist_ok=True)
    evil = outside / "evil.usda"
    if not evil.exists() and not evil.is_fifo():
        if target == "pipe":
            os.mkfifo(evil)
        else:
            evil.write_text('#usda 1.0\ndef "Evil" { custom string secret = "outside" }\n')
    secret = outside / "secret.png"
    if not secret.exists():
        secret.write_bytes(b"\x89PNG secret")
    return outside


def _form(form: str, pkg: Path, outside: Path, leaf: str) -> str:
    """The authored path for ``form`` inside package ``pkg``; creates links / pipes it needs."""
    rel_out = os.path.relpath(outside, pkg)
    if form == "absolute":
        return str(outside / leaf)
    if form == "dotdot":
        return f"../{os.path.basename(outside)}/{leaf}"
    if form == "dotdot_deep":
        return f"./a/b/../../../{os.path.basename(outside)}/{leaf}"
    if form == "bracket_unbalanced":
        return f"./x[/../../{os.path.basename(outside)}/{leaf}"
    if form == "package_inner_dotdot":
        return f"./p.usdz[../../{leaf}]"
    if form == "package_inner_absolute":
        return f"./p.usdz[{outside / leaf}]"
    if form == "package_nested_inner":
        return f"./p.usdz[q.usdz[../../../{leaf}]]"
    if form == "url_https":
        return f"https://example.com/{leaf}"
    if form == "url_file":
        return f"file://{outside / leaf}"
    if form == "home":
        return f"~/{leaf}"
    if form == "backslash_dotdot":
        return f".\\..\\{os.path.basename(outside)}\\{leaf}"
    if form == "search_path":
        return leaf
    if form == "expression":
        return f'`"{rel_out}/{leaf}"`'
    if form == "symlink_file":
        link = pkg / f"link_{leaf}"
        link.symlink_to(outside / leaf)
        return f"./{link.name}"
    if form == "symlink_dir":
        (pkg / "linkdir").symlink_to(outside, target_is_directory=True)
        return f"./linkdir/{leaf}"
    if form == "symlink_chain":
        (pkg / "hop2").symlink_to(outside / leaf)
        (pkg / "hop1").symlink_to(pkg / "hop2")
        return "./hop1"
    if form == "pipe_inside":
        os.mkfifo(pkg / f"pipe_{leaf}")
        return f"./pipe_{leaf}"
    if form == "folder_inside":
        (pkg / f"dir_{leaf}").mkdir()
        return f"./dir_{leaf}"
    if form == "device_link":
        (pkg / f"dev_{leaf}").symlink_to("/dev/zero")
        return f"./dev_{leaf}"
    if form == "dot_dotdot_mix":
        return f"./.././{os.path.basename(outside)}/./{leaf}"
    raise ValueError(form)


def _author(layer, arc: str, path: str) -> None:
    """Author ``path`` through ``arc`` with the Sdf API only: nothing composes, so no target is ever opened."""
    from pxr import Sdf, Vt

    def extra():
        spec = layer.GetPrimAtPath("/Asset/Extra") or Sdf.CreatePrimInLayer(layer, "/Asset/Extra")
        spec.specifier = Sdf.SpecifierDef
        return spec

    if arc == "sublayer":
        layer.subLayerPaths.append(path)
    elif arc == "reference":
        extra().referenceList.prependedItems.append(Sdf.Reference(path))
    elif arc == "payload":
        extra().payloadList.prependedItems.append(Sdf.Payload(path))
    elif arc in ("variant_reference", "variant_payload"):
        spec = extra()
        vset = Sdf.VariantSetSpec(spec, "look")
        Sdf.VariantSpec(vset, "plain")
        evil = Sdf.VariantSpec(vset, "evil")
        inner = Sdf.PrimSpec(evil.primSpec, "Inner", Sdf.SpecifierDef)
        if arc == "variant_reference":
            inner.referenceList.prependedItems.append(Sdf.Reference(path))
        else:
            inner.payloadList.prependedItems.append(Sdf.Payload(path))
        spec.variantSetNameList.prependedItems.append("look")
        spec.variantSelections["look"] = "plain"
    elif arc == "clip":
        geo = layer.GetPrimAtPath("/Asset/Geometry")
        geo.SetInfo("clips", {"default": {"assetPaths": Sdf.AssetPathArray([Sdf.AssetPath(path)]), "primPath": "/Evil",
                                          "active": Vt.Vec2dArray([(0.0, 0.0)])}})
    elif arc == "attribute":
        shader = layer.GetPrimAtPath("/Asset/Looks/Fallback/PreviewSurface")
        Sdf.AttributeSpec(shader, "inputs:file", Sdf.ValueTypeNames.Asset).default = Sdf.AssetPath(path)
    elif arc == "metadata":
        layer.GetPrimAtPath("/Asset").SetInfo("assetInfo", {"identifier": Sdf.AssetPath(path)})
    elif arc == "time_sample":
        attr = Sdf.AttributeSpec(layer.GetPrimAtPath("/Asset/Looks/Fallback"), "thumb", Sdf.ValueTypeNames.Asset)
        layer.SetTimeSample(attr.path, 1.0, Sdf.AssetPath(path))
    else:
        raise ValueError(arc)


def make_cases(out_dir: str | Path, *, target: str = "pipe") -> list[Case]:
    """Write every path case below ``out_dir``; each expects ASSET_PATH_ESCAPES."""
    from pxr import Sdf

    from nasset_sdk.examples import example_builder

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    outside = _write_outside(out, target)
    base = example_builder("rna", variant="surface", size="tiny", seed=0).write(out / "_base.usdc")
    cases: list[Case] = []
    for arc in ARCS + VALUES:
        leaf = "evil.usda" if arc in ARCS else "secret.png"
        for form in FORMS if arc in FULL_ARCS else SHORT_FORMS:
            name = f"path_{arc}_{form}"
            pkg = out / name
            pkg.mkdir(exist_ok=True)
            authored = _form(form, pkg, outside, leaf)
            layer = Sdf.Layer.OpenAsAnonymous(str(base))
            _author(layer, arc, authored)
            path = pkg / "asset.usdc"
            if not layer.Export(str(path)):
                raise RuntimeError(f"case {name} did not export")
            cases.append(Case(name, path, CODE))
    return cases


if __name__ == "__main__":
    for case in make_cases(Path(sys.argv[1] if len(sys.argv) > 1 else "gen_paths_out")):
        print(f"{case.code:<24} {case.path}")
