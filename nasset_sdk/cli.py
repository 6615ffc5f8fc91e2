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


@verb("example", "write a built-in example asset of a kind (random networks until that kind's bake lands)", "nasset_sdk.examples:run")
def _example_args(p):
    from .kinds import kind_ids

    p.add_argument("-o", "--output", required=True, help="output .usdc")
    p.add_argument("--kind", default="rna", choices=list(kind_ids()))
    p.add_argument("--variant", default="surface", help="surface or fiber (rna)")
    p.add_argument("--size", default="small", help="preset: tiny, small, hq")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--quality-variants", action="store_true", help="store small and hq cores as a quality variant set")


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


@verb("bake", "bake an object of a Mitsuba 3 scene into a neural asset (render data, train, export)", "nasset_sdk.bake:run")
def _bake_args(p):
    p.add_argument("scene", nargs="?", help="Mitsuba 3 scene .xml (omit with --example)")
    p.add_argument("--asset", action="append", default=None, metavar="SHAPE_ID",
                   help="id of a scene shape that belongs to the asset (repeat for several)")
    p.add_argument("--kind", default="rna", choices=["rna"], help="asset kind to bake (rna)")
    p.add_argument("--size", default="small", choices=["tiny", "small", "hq"], help="preset (default small)")
    p.add_argument("-o", "--output", required=True, help="output asset .usdc")
    p.add_argument("--example", action="store_true", help="bake the built-in example scene (no files needed)")
    p.add_argument("--resume", default=None, metavar="DIR", help="dataset folder to continue (default OUTPUT.bake)")
    p.add_argument("--views", type=int, default=None, help="training views (held-out views: views/8)")
    p.add_argument("--res", type=int, default=None, help="image resolution per view")
    p.add_argument("--epochs", type=int, default=None)
    p.add_argument("--spp", type=int, default=None, help="paths per pixel (held-out views: 2x)")
    p.add_argument("--light-angle", type=float, default=None,
                   help="angular radius of the distant light in degrees (0 = delta; default 0, or 5 behind smooth dielectrics)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default="auto", help="torch device (default: cuda if available, else cpu)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


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
