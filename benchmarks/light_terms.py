"""Light terms of an in-scene accuracy figure (spec/accuracy.md#light-terms).

    python -m nasset_benchmarks.light_terms SCENE.xml --replace ID[,ID]=ASSET [-o DIR] [--res W]
        [--spp N] [--nr-spp M] [--seed K] [--json]

Splits ``nasset bench accuracy`` over the emitters of a Mitsuba scene. For each emitter E two variants
of the scene: E alone (every other emitter removed), and E alone with every shape that is not replaced
made black (its BSDF a black diffuse; media, emission and geometry unchanged). The second is **E, direct**
(light reaching the asset straight from E); the difference is **E, via the scene** (light reaching it after
other shapes). The full scene is measured too. Each variant is a copy of the XML in DIR with its file
names made absolute, measured by :func:`nasset_benchmarks.accuracy.bench_accuracy` in DIR/<variant> (a
rerun reuses its reference). A term's energy ratio is taken over the object's mask (Mitsuba's, as the
bench's) with its standard error from the reference halves' difference images and the estimates'
variances (variants taken as independent). Emitters must be defined inline (top-level ``<emitter>``, or
an area ``<emitter>`` inside a shape).
"""

from __future__ import annotations

import argparse
import json
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from nasset_sdk.cli import MAX_IMAGE_SIDE, MAX_SPP, count_arg, seed_arg
from nasset_sdk.errors import NassetError, UsageError, error
from nasset_sdk.images import output_folder

#: a black diffuse BSDF for the shapes that are not replaced, in "direct" variants
BLACK = '<bsdf type="diffuse"><rgb name="reflectance" value="0, 0, 0"/></bsdf>'


def emitters(root: ET.Element) -> list[tuple[str, ET.Element, ET.Element]]:
    """(label, emitter element, its parent) of every inline emitter: the scene's own and the area emitters of shapes."""
    out = []
    for k, e in enumerate(root.findall("emitter")):
        out.append((e.get("id") or f"{e.get('type', 'emitter')}{k}", e, root))
    for s in root.findall("shape"):
        for e in s.findall("emitter"):
            out.append((e.get("id") or f"{s.get('id') or s.get('type', 'shape')} (area)", e, s))
    return out


def variant_xml(scene_file: Path, keep: str | None, black: bool, replaced: set[str]) -> str:
    """The scene XML with only emitter ``keep`` (None: all), the shapes not in ``replaced`` black when ``black``,
    and every ``filename`` made absolute (relative to the original XML's folder)."""
    root = ET.parse(scene_file).getroot()
    for label, e, parent in emitters(root):
        if keep is not None and label != keep:
            parent.remove(e)
    bsdf_ids = {b.get("id") for b in root.findall("bsdf") if b.get("id")}
    if black:
        for s in root.findall("shape"):
            if s.get("id") in replaced:
                continue
            for c in list(s):
                if c.tag == "bsdf" or (c.tag == "ref" and c.get("id") in bsdf_ids and c.get("name") not in ("interior", "exterior")):
                    s.remove(c)
            s.insert(0, ET.fromstring(BLACK))
    for f in root.iter("string"):
        if f.get("name") == "filename" and not Path(f.get("value", "")).is_absolute():
            f.set("value", str((scene_file.parent / f.get("value", "")).resolve()))
    return ET.tostring(root, encoding="unicode")


def _sums(d: Path, mask: np.ndarray) -> dict:
    """Per-channel sums over the mask of a bench folder's reference halves, estimate and estimate variance."""
    from nasset_sdk.images import read_exr

    img = {n: read_exr(d / f"{n}.exr").astype(np.float64)[..., :3] for n in ("reference_a", "reference_b", "neural", "neural_var")}
    return {"a": img["reference_a"], "b": img["reference_b"], "est": img["neural"][mask].sum(0),
            "est_var": img["neural_var"][mask].sum(0)}


def term(plus: list[dict], minus: list[dict], mask: np.ndarray) -> dict:
    """Energy ratio [3] of (sum of ``plus`` variants - sum of ``minus``) over the mask, and its standard error:
    the difference images of the reference halves (shared seeds cancel) plus the estimates' variances."""
    a = sum(v["a"] for v in plus) - sum((v["a"] for v in minus), np.zeros_like(plus[0]["a"]))
    b = sum(v["b"] for v in plus) - sum((v["b"] for v in minus), np.zeros_like(plus[0]["b"]))
    est = sum(v["est"] for v in plus) - sum((v["est"] for v in minus), np.zeros(3))
    ref = (0.5 * (a + b))[mask].sum(0)
    safe = np.where(ref != 0, ref, np.nan)
    ratio = est / safe
    var = ((a - b) ** 2 / 4)[mask].sum(0) * ratio ** 2 + sum(v["est_var"] for v in plus + minus)
    return {"energy_ratio": [float(x) for x in ratio], "energy_se": [float(x) for x in np.sqrt(var) / np.abs(safe)],
            "reference_energy": [float(x) for x in ref]}


def light_terms(scene_file, replace, out_dir, *, res: int = 64, spp: int = 1024, nr_spp: int = 256, seed: int = 0,
                quiet: bool = False) -> dict:
    """Measure every variant (module docstring) and return {"terms": [{name, energy_ratio, energy_se, share,
    excess}], "variants": {name: folder}}; also written to DIR/light_terms.json. ``share``: the term's part of
    the full scene's reference energy over the mask; ``excess``: its contribution to the full scene's energy
    error (both per channel)."""
    from nasset_converters.mitsuba import load_mitsuba
    from nasset_converters.mitsuba import scene as msc
    from nasset_converters.mitsuba.usd_export import parse_replace

    from .accuracy import bench_accuracy, object_mask, sensor_for

    scene_file = Path(scene_file)
    if scene_file.suffix.lower() != ".xml":
        raise UsageError(f"light terms need a Mitsuba 3 .xml scene, got {scene_file.name!r}")
    if not scene_file.is_file():
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(scene_file))
    rep = parse_replace(replace)
    ids = set(rep)
    try:
        lights = [label for label, _, _ in emitters(ET.parse(scene_file).getroot())]
    except ET.ParseError as exc:
        raise error("CONVERT_SCENE_LOAD", f"the scene XML does not parse: {exc}", file=str(scene_file)) from None
    if not lights:
        raise error("CONVERT_SCENE_LOAD", "the scene has no inline emitter to split", file=str(scene_file))
    if len(set(lights)) != len(lights):
        raise error("CONVERT_SCENE_LOAD", f"emitter labels are not unique: {lights}; give the emitters ids", file=str(scene_file))
    out = Path(out_dir)
    output_folder(out)
    variants = {"full": (None, False)}
    for k, label in enumerate(lights):
        variants[f"light{k}"] = (label, False)
        variants[f"light{k}_direct"] = (label, True)
    folders = {}
    for name, (keep, black) in variants.items():
        xml = out / f"{name}.xml"
        text = variant_xml(scene_file, keep, black, ids)
        if not xml.is_file() or xml.read_text() != text:  # unchanged files keep the bench's cached reference
            tmp = xml.with_suffix(".xml.part")
            tmp.write_text(text)
            tmp.replace(xml)
        if not quiet:
            print(f"light terms: {name} ({keep or 'all emitters'}{', other shapes black' if black else ''})", file=sys.stderr)
        bench_accuracy(xml, rep, out / name, res=res, spp=spp, nr_spp=nr_spp, seed=seed, quiet=True)
        folders[name] = out / name
    mi = load_mitsuba()
    mscene = msc.load_scene(mi, scene_file)
    sensor, hw = sensor_for(mi, mscene, res, file=str(scene_file))
    mask = object_mask(mi, mscene, sensor, sorted(ids), hw) >= 0.5
    sums = {name: _sums(folder, mask) for name, folder in folders.items()}
    full = term([sums["full"]], [], mask)
    rows = [{"name": "full scene", **full}]
    for k, label in enumerate(lights):
        rows.append({"name": f"{label}, direct", **term([sums[f"light{k}_direct"]], [], mask)})
        rows.append({"name": f"{label}, via the scene", **term([sums[f"light{k}"]], [sums[f"light{k}_direct"]], mask)})
    rows.append({"name": "sum of the emitters", **term([sums[f"light{k}"] for k in range(len(lights))], [], mask)})
    total = np.asarray(full["reference_energy"])
    for r in rows:
        e, ratio = np.asarray(r["reference_energy"]), np.asarray(r["energy_ratio"])
        r["share"] = [float(x) for x in e / total]
        r["excess"] = [float(x) for x in e * (ratio - 1.0) / total]
    for r in rows:  # a term with no reference energy (an emitter that does not reach the asset): None, never NaN
        for k in ("energy_ratio", "energy_se", "share", "excess"):
            r[k] = [x if np.isfinite(x) else None for x in r[k]]
    report = {"scene": str(scene_file), "mask_pixels": int(mask.sum()), "res": res, "spp": spp, "nr_spp": nr_spp,
              "terms": rows, "variants": {k: str(v) for k, v in folders.items()}}
    tmp = out / "light_terms.json.part"
    tmp.write_text(json.dumps(report, indent=2))
    tmp.replace(out / "light_terms.json")
    return report


def table(report: dict) -> str:
    """The terms as a markdown table (energy %, share, points of the full scene's excess; R / G / B)."""
    def pct(v, sign=""):
        return " / ".join("n/a" if x is None else f"{100 * x:{sign}.1f}" for x in v)

    lines = ["| term | energy % (R / G / B, ± s.e.) | share | points of the excess |", "|---|---|---|---|"]
    for r in report["terms"]:
        lines.append(f"| {r['name']} | {pct(r['energy_ratio'])} (± {pct(r['energy_se'])}) | {pct(r['share'])} % | "
                     f"{pct(r['excess'], '+')} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m nasset_benchmarks.light_terms", description=__doc__.split("\n\n")[0])
    p.add_argument("scene")
    p.add_argument("--replace", action="append", required=True, metavar="SHAPE_ID[,SHAPE_ID]=ASSET")
    p.add_argument("-o", "--output", default="light_terms")
    p.add_argument("--res", type=count_arg(8, MAX_IMAGE_SIDE), default=64)
    p.add_argument("--spp", type=count_arg(1, MAX_SPP), default=1024, help="Mitsuba reference spp per variant, both halves")
    p.add_argument("--nr-spp", type=count_arg(1, MAX_SPP), default=256, help="reference-renderer spp per variant")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    try:
        r = light_terms(a.scene, a.replace, a.output, res=a.res, spp=a.spp, nr_spp=a.nr_spp, seed=a.seed, quiet=a.json)
    except NassetError as exc:  # typed errors: a message and the exit code of the nasset CLI (2 usage, 1 failure)
        print(f"error: {exc}", file=sys.stderr)
        return 2 if isinstance(exc, UsageError) else 1
    print(json.dumps(r, indent=2) if a.json else table(r))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
