"""The ``nasset`` command line: ``nasset <verb> --help`` for each verb.

Exit codes: 0 ok, 1 failure (invalid asset, failed render, typed error), 2 usage error.
Verbs live in their own modules; this file only wires argparse to them. The SDK's own verbs are
registered below; the packages above the SDK (renderer, converters, bakers, benchmarks) declare
theirs as entry points of the group ``nasset.verbs`` (pyproject.toml), each a :class:`Verb`.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Callable, NamedTuple

from .errors import NassetError

#: entry-point group where packages declare their verbs (``name = "module:VERB"``)
ENTRY_POINT_GROUP = "nasset.verbs"


class Verb(NamedTuple):
    """A CLI verb: one-line help, ``add_args(parser)``, and ``target`` = 'module:function' taking the
    parsed args and returning an exit code (imported only when the verb runs)."""

    help: str
    add_args: Callable[[argparse.ArgumentParser], None]
    target: str


def count_arg(lo: int, hi: int):
    """argparse type of an integer option in ``lo .. hi``: anything else is a usage error (exit code 2) before the
    command runs, instead of a default silently taken for 0 or a traceback (or a huge allocation) far into it."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be an integer, got {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in {lo} .. {hi}, got {value}")
        return value

    parse.__name__ = f"integer in {lo} .. {hi}"
    return parse


def finite_arg(text: str) -> float:
    """argparse type of a real-valued option: a finite number, else a usage error (exit code 2)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


finite_arg.__name__ = "finite number"

#: largest --seed: seeds reach Mitsuba's samplers as unsigned 32-bit integers
MAX_SEED = 2**32 - 1
#: the type of every ``--seed``
seed_arg = count_arg(0, MAX_SEED)
#: bounds of the benchmarks' image side and sample counts (an image of 4096^2 pixels is ~200 MB per float32 RGB
#: buffer; 2^24 samples per pixel is ~10^5 times any reference the benches use)
MAX_IMAGE_SIDE = 4096
MAX_SPP = 1 << 24


#: the SDK's own verbs; :func:`all_verbs` adds the installed packages' ones
VERBS: dict[str, Verb] = {}


def verb(name: str, help_text: str, target: str):
    """Register an SDK verb: ``target`` is 'module:function' taking the parsed args, returning an exit code."""

    def deco(add_args: Callable[[argparse.ArgumentParser], None]):
        VERBS[name] = Verb(help_text, add_args, target)
        return add_args

    return deco


def all_verbs() -> dict[str, Verb]:
    """The SDK's verbs and those declared in the ``nasset.verbs`` entry points, sorted by name.

    A verb whose module fails to import is left out with a warning on stderr (the other verbs still work);
    an entry point cannot replace an SDK verb."""
    from importlib.metadata import entry_points

    verbs = dict(VERBS)
    for ep in entry_points(group=ENTRY_POINT_GROUP):
        if ep.name in VERBS:
            continue
        try:
            found = ep.load()
        except Exception as exc:  # a broken optional package must not take the whole CLI down
            print(f"nasset: verb {ep.name!r} unavailable ({type(exc).__name__}: {exc})", file=sys.stderr)
            continue
        verbs[ep.name] = Verb(*found)
    return dict(sorted(verbs.items()))


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
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--quality-variants", action="store_true", help="store small and hq cores as a quality variant set")


@verb("merge-quality", "combine assets baked at several presets into one asset with a quality variant set",
      "nasset_sdk.quality:run")
def _merge_quality_args(p):
    p.add_argument("levels", nargs="+", metavar="LEVEL=ASSET", help="quality name and asset file; the first is the default")
    p.add_argument("-o", "--output", required=True, help="output .usdc")


@verb("optimize", "rewrite an asset smaller (fp16/fp32 tensors, fewer components or quality levels) and report size "
      "and accuracy change", "nasset_sdk.optimize:run")
def _optimize_args(p):
    from .optimize import QUERY_ROWS

    p.add_argument("file", help="input asset (.usdc)")
    p.add_argument("-o", "--output", required=True, help="output asset (.usdc), another file than the input")
    p.add_argument("--dtype", choices=["float16", "float32"], default=None, help="re-encode every tensor (default: keep each one's)")
    p.add_argument("--drop", action="append", metavar="COMPONENT", help="drop an optional component (repeat or comma-separate)")
    p.add_argument("--keep-quality", action="append", metavar="LEVEL",
                   help="keep only these quality levels (repeat or comma-separate); one left: stored without a variant set")
    p.add_argument("--samples", type=int, default=QUERY_ROWS, help=f"rows of the fixed random query set (default {QUERY_ROWS})")
    p.add_argument("--no-preview", action="store_true", help="skip the preview-render PSNR")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.add_argument("--portable", action="store_true",
                   help="add the portable evaluation graphs (one ONNX graph per network with its encodings, for hosts "
                        "without Python; spec/format.md#portable-evaluation-graphs)")


@verb("conformance", "run a renderer on the conformance cases and compare with the reference images, or an evaluator on the "
      "evaluator test vectors (spec/conformance.md, spec/evaluator-vectors.md)",
      "nasset_sdk.conformance:run")
def _conformance_args(p):
    p.add_argument("--renderer", default="nasset render {scene} -o {out} --spp {spp} --seed {seed} --width {width} --height {height} --quiet",
                   help="command template, split like a shell command line; placeholders {scene} {out} {spp} {width} {height} "
                   "{seed} (default: the reference renderer)")
    p.add_argument("--evaluator", default=None, metavar="CMD",
                   help="check an evaluator on the evaluator test vectors instead of rendering (spec/evaluator-vectors.md): "
                   "command template with placeholders {asset} {input} {output}; 'sdk' runs the SDK's own evaluators")
    p.add_argument("--cases", nargs="+", default=None, metavar="NAME", help="run only these cases")
    p.add_argument("--suite", default=None, metavar="DIR", help="cases folder (default: the cases installed with nasset_sdk)")
    p.add_argument("--workdir", default=None, metavar="DIR", help="where images, logs and error maps go (default: a new temp folder)")
    p.add_argument("--seed", type=seed_arg, default=0, help="value of {seed} (default 0)")
    p.add_argument("--spp-scale", type=int, default=1, metavar="K", help="render at K x the case's spp (tolerances unchanged)")
    p.add_argument("--timeout", type=float, default=600.0, help="seconds per case before the render counts as failed")
    p.add_argument("--list", action="store_true", help="list the cases and exit")
    p.add_argument("--json", action="store_true", help="print the report as JSON")


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


@verb("schema-path", "print the folder to add to PXR_PLUGINPATH_NAME for hosts that start USD first", "nasset_sdk.plugin:run_schema_path")
def _schema_args(p):
    pass


def load_target(target: str):
    """The object a 'module:name' string names (imported now)."""
    import importlib

    mod, fn = target.split(":")
    return getattr(importlib.import_module(mod), fn)


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nasset-sdk")
    except PackageNotFoundError:  # running from a checkout that was never installed
        return "unknown"


def build_parser(verbs: dict[str, Verb] | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="nasset", description="Relightable neural 3D assets: SDK and tools.")
    parser.add_argument("--version", action="version", version=f"nasset {_version()}")
    sub = parser.add_subparsers(dest="verb", metavar="VERB")
    for name, (help_text, add_args, _) in (all_verbs() if verbs is None else verbs).items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        add_args(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    verbs = all_verbs()
    parser = build_parser(verbs)
    args = parser.parse_args(argv)
    if not args.verb:
        parser.print_help()
        return 2
    try:
        return int(load_target(verbs[args.verb].target)(args) or 0)
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


def console_main() -> int:
    """The ``nasset`` console script: :func:`main` in a process tuned for numpy wavefronts
    (:func:`nasset_sdk.process.tune_allocator`; in-process callers of :func:`main` keep their own settings)."""
    from .process import tune_allocator

    tune_allocator()
    return main()


if __name__ == "__main__":
    sys.exit(console_main())
