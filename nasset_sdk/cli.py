"""The ``nasset`` command line: ``nasset <verb> --help`` for each verb.

Exit codes: 0 ok, 1 failure (invalid asset, failed render, typed error), 2 usage error.
Verbs live in their own modules; this file only wires argparse to them.
"""

from __future__ import annotations

import argparse
import json
import sys
from typing import Callable

from .errors import NassetError

VERBS: dict[str, tuple[str, Callable[[argparse.ArgumentParser], None], str]] = {}


def verb(name: str, help_text: str, target: str):
    """Register a verb: ``target`` is 'module:function' taking the parsed args, returning an exit code."""

    def deco(add_args: Callable[[argparse.ArgumentParser], None]):
        VERBS[name] = (help_text, add_args, target)
        return add_args

    return deco


@verb("validate", "check an asset against the spec; lists findings with codes", "nasset_sdk.validate.cli:run")
def _validate_args(p):
    p.add_argument("file", nargs="?", help="asset file (.usdc / .usda)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--dump-rules", action="store_true", help="list every rule (code, severity, spec section) and exit")
    p.add_argument("--usd-checks", action="store_true", help="also run OpenUSD's own validators (as usdchecker does)")


@verb("inspect", "summarise an asset: kind, components, tensors, networks, geometry, metadata", "nasset_sdk.inspect:run")
def _inspect_args(p):
    p.add_argument("file", help="asset file")
    p.add_argument("--json", action="store_true", help="print as JSON")
    p.add_argument("--load", default="all", help="components to load: all, required, none (default all)")


@verb("example", "write an example asset of any kind with random networks (format and renderer tests; real bakes: nasset bake --example)",
      "nasset_sdk.examples:run")
def _example_args(p):
    from .kinds import kind_ids

    p.add_argument("-o", "--output", required=True, help="output .usdc")
    p.add_argument("--kind", default="rna", choices=list(kind_ids()))
    p.add_argument("--variant", default="surface", help="surface or fiber (rna)")
    p.add_argument("--size", default="small", help="preset: tiny, small, hq")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quality-variants", action="store_true", help="store small and hq cores as a quality variant set")


@verb("merge-quality", "combine assets baked at several presets into one asset with a quality variant set",
      "nasset_sdk.quality:run")
def _merge_quality_args(p):
    p.add_argument("levels", nargs="+", metavar="LEVEL=ASSET", help="quality name and asset file; the first is the default")
    p.add_argument("-o", "--output", required=True, help="output .usdc")


@verb("render", "render a USD scene with the reference path tracer", "reference_renderer.cli:run")
def _render_args(p):
    p.add_argument("scene", help="scene .usda/.usdc, or an asset file (rendered in a default studio scene)")
    p.add_argument("-o", "--output", required=True, help="output .exr")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--width", type=int, default=None)
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--max-depth", type=int, default=5)
    p.add_argument("--png", default=None, help="also write a tone-mapped PNG preview")
    p.add_argument("--variance", default=None, help="also write a per-pixel variance EXR")
    p.add_argument("--explain", action="store_true", help="print the render plan")
    p.add_argument("--threads", type=int, default=0, help="onnxruntime intra-op threads (0 = auto)")
    p.add_argument("--batch", type=int, default=65536, help="rays per wavefront batch")
    p.add_argument("--tile", type=int, default=64, help="tile edge in pixels")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--neupress-sampling", default="auto", choices=["auto", "dome", "lobe", "mis"],
                   help="neupress: light sampling (dome), the sampling network's lobe, or both with MIS "
                        "(auto: mis when the asset has the sampling component, else dome)")
    p.add_argument("--prt", action="store_true", help="neupress: shade with the PRT component and the dome's SH projection")
    p.add_argument("--8dna-sampling", dest="eightdna_sampling", default="mis", choices=["light", "flow", "mis"],
                   help="8dna: emitter sampling, the asset's own sampling (GGX lobe, flow directions), or both with MIS")


@verb("conformance", "run a renderer on the conformance cases and compare with the reference images (spec/conformance.md)",
      "nasset_sdk.conformance:run")
def _conformance_args(p):
    p.add_argument("--renderer", default="nasset render {scene} -o {out} --spp {spp} --seed {seed} --width {width} --height {height} --quiet",
                   help="command template, split like a shell command line; placeholders {scene} {out} {spp} {width} {height} "
                   "{seed} (default: the reference renderer)")
    p.add_argument("--cases", nargs="+", default=None, metavar="NAME", help="run only these cases")
    p.add_argument("--suite", default=None, metavar="DIR", help="cases folder (default: the checkout's tests/conformance/cases)")
    p.add_argument("--workdir", default=None, metavar="DIR", help="where images, logs and error maps go (default: a new temp folder)")
    p.add_argument("--seed", type=int, default=0, help="value of {seed} (default 0)")
    p.add_argument("--spp-scale", type=int, default=1, metavar="K", help="render at K x the case's spp (tolerances unchanged)")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per case before the render counts as failed")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


@verb("bake", "bake an object of a Mitsuba 3 (.xml) or Blender (.blend) scene into a neural asset (render data, train, export)",
      "nasset_sdk.bake:run")
def _bake_args(p):
    p.add_argument("scene", nargs="?", help="Mitsuba 3 scene .xml or Blender scene .blend (omit with --example)")
    p.add_argument("--asset", action="append", default=None, metavar="ID",
                   help="id of a scene shape (Mitsuba) or object name (Blender) that belongs to the asset (repeat for several)")
    p.add_argument("--kind", default="rna", choices=["rna", "neupress", "8dna"], help="asset kind to bake (default rna)")
    p.add_argument("--size", default="small", choices=["tiny", "small", "hq"], help="preset (default small)")
    p.add_argument("-o", "--output", required=True, help="output asset .usdc")
    p.add_argument("--example", nargs="?", const="default", default=None, metavar="NAME",
                   help="bake a built-in example scene (no files needed); NAME picks one where a kind has several "
                        "(rna: default, high-albedo, blender-surface, blender-hair; neupress: default, high-albedo; "
                        "8dna: default, heterogeneous)")
    p.add_argument("--resume", default=None, metavar="DIR", help="dataset folder to continue (default OUTPUT.bake)")
    p.add_argument("--views", type=int, default=None, help="training views (held-out views: views/8)")
    p.add_argument("--res", type=int, default=None, help="image resolution per view")
    p.add_argument("--epochs", type=int, default=None)
    p.add_argument("--spp", type=int, default=None, help="paths per pixel of the training views (held-out views use the preset's val_spp)")
    p.add_argument("--light-angle", type=float, default=None,
                   help="angular radius of the distant light in degrees (0 = delta; default 0, or 5 behind smooth dielectrics)")
    p.add_argument("--clamp", type=float, default=None, metavar="C",
                   help="clamp training path samples at C /sr (Mitsuba rna, neupress; default 0: none; the energy removed "
                        "is measured and stored, spec/accuracy.md)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", help="torch device (default: cuda if available, else cpu)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


@verb("view", "preview an asset shaded by its neural transport under one distant light (pyvista; PNG when headless)",
      "nasset_sdk.view:run")
def _view_args(p):
    p.add_argument("file", help="asset file")
    p.add_argument("--light-dir", nargs=3, type=float, default=[0.5, 0.8, 0.6], metavar=("X", "Y", "Z"),
                   help="object-space direction from the asset towards the distant light (default 0.5 0.8 0.6)")
    p.add_argument("--view-dir", nargs=3, type=float, default=[0.3, 0.35, 1.0], metavar=("X", "Y", "Z"),
                   help="object-space direction from the asset towards the camera (default 0.3 0.35 1)")
    p.add_argument("--png", default=None, help="write the picture to this PNG off-screen instead of opening a window "
                   "(without a display the default is ./ASSET.view.png or ./ASSET.channelK.png)")
    p.add_argument("--fallback", action="store_true", help="shade with the fallback UsdPreviewSurface colour (Lambertian)")
    p.add_argument("--channel", type=int, default=None, metavar="K",
                   help="show triplane channel K (rna, 8dna): planes XY, YZ, ZX side by side, colour-mapped")
    p.add_argument("--size", nargs=2, type=int, default=[800, 600], metavar=("W", "H"), help="image size (default 800 600)")
    p.add_argument("--per-pixel", action="store_true", help="ray-cast the mesh and evaluate at every pixel (default: per vertex)")
    p.add_argument("--exposure", type=float, default=0.0, help="exposure in stops before the sRGB curve (default 0)")


@verb("convert-scene", "convert a Mitsuba 3 (.xml) or Blender (.blend) scene (camera, lights, plain shapes) to USD, "
      "baked assets in place of their shapes", "nasset_sdk.cli:run_convert_scene")
def _convert_scene_args(p):
    p.add_argument("scene", nargs="?", help="Mitsuba 3 scene .xml or Blender scene .blend (omit with --example)")
    p.add_argument("-o", "--output", required=True, help="output .usda / .usdc")
    p.add_argument("--example", nargs="?", const="default", default=None, metavar="NAME",
                   help="convert a built-in example scene, written next to OUTPUT (default: the Mitsuba example; "
                        "blender-surface, blender-hair: the Blender examples)")
    p.add_argument("--replace", action="append", default=None, metavar="SHAPE_ID[,SHAPE_ID]=ASSET",
                   help="reference this baked asset in place of these shapes (repeatable; path stored relative to the output)")
    p.add_argument("--no-usd-checks", action="store_true", help="skip OpenUSD's validators on the written stage")
    p.add_argument("--json", action="store_true", help="print the report (prims, warnings, USD checks) as JSON")


#: ``nasset bench NAME``: each benchmark module defines ``add_args(parser)`` and ``run(args) -> int``.
BENCHES = {
    "error-vs-time": ("rna: Mitsuba path tracing vs the reference renderer with a baked asset, error against time",
                      "converters.mitsuba.bench"),
    "neupress": ("neupress: the paper's Table 1 (path tracing, dome / lobe / MIS sampling, SH PRT) at equal spp and time",
                 "converters.mitsuba.neupress_bench"),
    "8dna": ("8dna: near-field light, 8D flow vs 6D far-field baseline vs path tracing (the paper's Tables 1-2)",
             "converters.mitsuba.eightdna_bench"),
    "blender": ("rna from Blender: Cycles path tracing vs the reference renderer, surface and hair examples, h ablation",
                "converters.blender.bench"),
    "accuracy": ("a baked asset in its own Mitsuba scene against unclamped two-half ground truth: energy, PSNR with "
                 "the noise ceiling, FLIP over the object's pixels", "converters.mitsuba.accuracy_bench"),
}


@verb("bench", "benchmarks against path-traced ground truth (nasset bench NAME --help)", "nasset_sdk.cli:run_bench")
def _bench_args(p):
    sub = p.add_subparsers(dest="which", metavar="NAME", required=True)
    for name, (help_text, module) in BENCHES.items():
        _load(f"{module}:add_args")(sub.add_parser(name, help=help_text, description=help_text))


def run_convert_scene(args) -> int:
    """``nasset convert-scene``: Blender for ``.blend`` files and ``blender-*`` examples, Mitsuba otherwise."""
    blender = (args.scene or "").lower().endswith(".blend") or (args.example or "").startswith("blender")
    if not blender and args.example not in (None, "default"):
        from .errors import UsageError

        raise UsageError(f"unknown example {args.example!r} (default, blender-surface, blender-hair)")
    module = "converters.blender.usd_export" if blender else "converters.mitsuba.usd_export"
    return _load(f"{module}:run")(args)


def run_bench(args) -> int:
    """Run the benchmark module picked by ``args.which``."""
    return _load(f"{BENCHES[args.which][1]}:run")(args)


@verb("schema-path", "print the folder to add to PXR_PLUGINPATH_NAME for hosts that start USD first", "nasset_sdk.plugin:run_schema_path")
def _schema_args(p):
    pass


def _load(target: str):
    import importlib

    mod, fn = target.split(":")
    return getattr(importlib.import_module(mod), fn)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nasset", description="Relightable neural 3D assets: SDK and tools.")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for name, (help_text, add_args, _) in VERBS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add_args(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not args.verb:
        parser.print_help()
        return 2
    try:
        return int(_load(VERBS[args.verb][2])(args) or 0)
    except NassetError as exc:
        if getattr(args, "json", False):
            print(json.dumps({"ok": False, "error": exc.to_dict()}, indent=2))
        else:
            print(f"nasset {args.verb}: {exc}", file=sys.stderr)
        return 2 if exc.code == "USAGE" else 1
    except BrokenPipeError:  # output piped into e.g. `head`
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print(f"nasset {args.verb}: interrupted", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
