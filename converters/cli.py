"""``nasset convert-scene``: a Mitsuba 3 (.xml) or Blender (.blend) scene to a USD stage."""

from __future__ import annotations

from nasset_sdk.cli import Verb, load_target
from nasset_sdk.errors import UsageError


def add_args(p) -> None:
    p.add_argument("scene", nargs="?", help="Mitsuba 3 scene .xml or Blender scene .blend (omit with --example)")
    p.add_argument("-o", "--output", required=True, help="output .usda / .usdc")
    p.add_argument("--example", nargs="?", const="default", default=None, metavar="NAME",
                   help="convert a built-in example scene, written next to OUTPUT (default: the Mitsuba example; "
                        "blender-surface, blender-hair, blender-hair-dense: the Blender examples)")
    p.add_argument("--replace", action="append", default=None, metavar="SHAPE_ID[,SHAPE_ID]=ASSET",
                   help="reference this baked asset in place of these shapes (repeatable; path stored relative to the output)")
    p.add_argument("--no-usd-checks", action="store_true", help="skip OpenUSD's validators on the written stage")
    p.add_argument("--json", action="store_true", help="print the report (prims, warnings, USD checks) as JSON")


def run(args) -> int:
    """``nasset convert-scene``: Blender for ``.blend`` files and ``blender-*`` examples, Mitsuba otherwise."""
    blender = (args.scene or "").lower().endswith(".blend") or (args.example or "").startswith("blender")
    if not blender and args.example not in (None, "default"):
        raise UsageError(f"unknown example {args.example!r} (default, blender-surface, blender-hair, blender-hair-dense)")
    module = "nasset_converters.blender.usd_export" if blender else "nasset_converters.mitsuba.usd_export"
    return load_target(f"{module}:run")(args)


#: ``nasset convert-scene`` (entry point ``nasset.verbs``)
VERB = Verb("convert a Mitsuba 3 (.xml) or Blender (.blend) scene (camera, lights, plain shapes) to USD, "
            "baked assets in place of their shapes", add_args, "nasset_converters.cli:run")
