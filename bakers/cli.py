"""``nasset bake``: an object of a Mitsuba 3 (.xml) or Blender (.blend) scene -> a neural asset."""

from __future__ import annotations

import json
import sys

from nasset_sdk.cli import Verb, seed_arg


def add_args(p) -> None:
    p.add_argument("scene", nargs="?", help="Mitsuba 3 scene .xml or Blender scene .blend (omit with --example)")
    p.add_argument("--asset", action="append", default=None, metavar="ID",
                   help="id of a scene shape (Mitsuba) or object name (Blender) that belongs to the asset (repeat for several)")
    p.add_argument("--kind", default="rna", choices=["rna", "neupress", "8dna"], help="asset kind to bake (default rna)")
    p.add_argument("--size", default="small", choices=["tiny", "small", "hq"], help="preset (default small)")
    p.add_argument("-o", "--output", required=True, help="output asset .usdc")
    p.add_argument("--example", nargs="?", const="default", default=None, metavar="NAME",
                   help="bake a built-in example scene (no files needed); NAME picks one where a kind has several "
                        "(rna: default, high-albedo, hair-dense, blender-surface, blender-hair, blender-hair-dense; neupress: default, high-albedo; "
                        "8dna: default, heterogeneous)")
    p.add_argument("--resume", default=None, metavar="DIR", help="dataset folder to continue (default OUTPUT.bake)")
    p.add_argument("--views", type=int, default=None,
                   help="training views, fixed (without it an rna or neupress bake adds views where its data is too noisy, "
                        "spec/bake.md#data-noise); held-out views: views/8 (rna), /16 (neupress), /12 (Blender)")
    p.add_argument("--res", type=int, default=None, help="image resolution per view")
    p.add_argument("--epochs", type=int, default=None)
    p.add_argument("--spp", type=int, default=None, help="paths per pixel of the training views (held-out views use the preset's val_spp)")
    p.add_argument("--light-angle", type=float, default=None,
                   help="angular radius of the distant light in degrees (0 = delta; default 0, or 5 behind smooth dielectrics)")
    p.add_argument("--clamp", type=float, default=None, metavar="C",
                   help="clamp training path samples at C /sr (rna, neupress; default 0: none; Mitsuba bakes measure and "
                        "store the energy removed, spec/accuracy.md; Blender sets Cycles' direct and indirect clamps)")
    p.add_argument("--suns-per-view", type=int, default=None, metavar="K",
                   help="Blender: suns per training view, each in its own Cycles light group, so one render gives every "
                        "pixel K samples (default: the preset's, small 8, tiny and hq 1; spec/bake-blender.md#light-groups)")
    p.add_argument("--near-field-fetch", default=None, metavar="auto|F",
                   help="rna and neupress from Mitsuba: where renderers fetch a hit's light, F in [0, 1] of the way to the "
                        "asset's centre (spec/kinds/rna.md#near-field-fetch); default auto: measured after training under "
                        "lights near the asset (rna fibers keep 0), spec/bake.md#near-field")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="render the views (8dna: trace the tuples) on N Ray workers (pip install 'nasset-sdk[cluster]'; default: this process)")
    p.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="the Ray cluster to use with --workers (default: a local one on this machine)")
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--device", default="auto", metavar="auto|cpu|cuda|cuda:N",
                   help="torch device of the training (default auto: cuda if torch sees one, else cpu); under torchrun "
                        "each process trains on cuda:LOCAL_RANK (spec/bake.md#training-devices)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")


def near_field_arg(text: str) -> str | float:
    """``--near-field-fetch``: 'auto' or a number in [0, 1]."""
    from nasset_sdk.errors import UsageError

    if text == "auto":
        return "auto"
    try:
        f = float(text)
    except ValueError:
        f = float("nan")
    if not 0.0 <= f <= 1.0:
        raise UsageError(f"--near-field-fetch must be auto or a number in [0, 1], got {text!r}")
    return f


def run(args) -> int:
    """CLI entry: see ``nasset bake --help``."""
    from pathlib import Path

    from nasset_sdk.errors import UsageError, error
    from nasset_sdk.extras import require_extras

    from . import baker_for
    from .registry import source_of
    from .stages import finite

    fn = baker_for(args.kind, args.scene, args.example)
    if args.scene is not None and not Path(args.scene).is_file():  # before the extras: a typo is not a missing package
        raise error("CONVERT_SCENE_MISSING", "scene file does not exist", file=str(args.scene))
    require_extras("train", source_of(args.scene, args.example), purpose="nasset bake")
    from .train.common import pick_device, require_torch

    pick_device(require_torch(), args.device)  # a bad --device fails before any rendering
    if getattr(args, "clamp", None) is not None and args.kind == "8dna":
        raise UsageError("--clamp applies to rna and neupress bakes only")
    near = getattr(args, "near_field_fetch", None)
    if near is not None:
        if args.kind not in ("rna", "neupress") or source_of(args.scene, args.example) != "mitsuba":
            raise UsageError("--near-field-fetch applies to rna and neupress bakes from Mitsuba scenes only")
        near = near_field_arg(near)
    suns = getattr(args, "suns_per_view", None)  # its value is checked by the Blender baker, before any work
    if suns is not None and source_of(args.scene, args.example) != "blender":
        raise UsageError("--suns-per-view applies to bakes from Blender scenes only")
    summary = fn(
        args.scene, args.asset, args.output, size=args.size, example=args.example, resume=args.resume,
        views=args.views, res=args.res, epochs=args.epochs, spp=args.spp, light_angle=args.light_angle,
        seed=args.seed, device=args.device, quiet=args.quiet,
        **({"clamp": args.clamp} if getattr(args, "clamp", None) is not None else {}),
        **({"near_field_fetch": near} if near is not None else {}),
        **({"lights_per_view": suns} if suns is not None else {}),
        **({"workers": args.workers, "cluster": args.cluster} if args.workers is not None or args.cluster else {}),
        summary_stream=sys.stderr if getattr(args, "json", False) else sys.stdout,
    )
    if getattr(args, "json", False):
        print(json.dumps(finite(summary), indent=2))
    return 0


#: ``nasset bake`` (entry point ``nasset.verbs``)
VERB = Verb("bake an object of a Mitsuba 3 (.xml) or Blender (.blend) scene into a neural asset (render data, train, export)",
            add_args, "nasset_bakers.cli:run")
