"""``nasset bench NAME``: the benchmarks against path-traced ground truth."""

from __future__ import annotations

from nasset_sdk.cli import Verb, load_target

#: ``nasset bench NAME``: each benchmark module defines ``add_args(parser)`` and ``run(args) -> int``.
BENCHES = {
    "error-vs-time": ("rna: Mitsuba path tracing vs the reference renderer with a baked asset, error against time",
                      "nasset_benchmarks.error_vs_time"),
    "neupress": ("neupress: the paper's Table 1 (path tracing, dome / lobe / MIS sampling, SH PRT) at equal spp and time",
                 "nasset_benchmarks.neupress"),
    "8dna": ("8dna: near-field light, 8D flow vs 6D far-field baseline vs path tracing (the paper's Tables 1-2)",
             "nasset_benchmarks.eightdna"),
    "blender": ("rna from Blender: Cycles path tracing vs the reference renderer, surface and hair examples, h ablation",
                "nasset_benchmarks.blender"),
    "accuracy": ("a baked asset in its own Mitsuba scene against unclamped two-half ground truth: energy, PSNR with "
                 "the noise ceiling, FLIP over the object's pixels", "nasset_benchmarks.accuracy"),
    "cluster": ("the view stage of a bake in one process and on 1 and N local Ray workers (times, ratios, equal datasets)",
                "nasset_benchmarks.cluster"),
}


def add_args(p) -> None:
    sub = p.add_subparsers(dest="which", metavar="NAME", required=True)
    for name, (help_text, module) in BENCHES.items():
        load_target(f"{module}:add_args")(sub.add_parser(name, help=help_text, description=help_text))


def run(args) -> int:
    """Run the benchmark module picked by ``args.which``."""
    from nasset_sdk.extras import require_extras

    require_extras("render", "bench", purpose="nasset bench")
    return load_target(f"{BENCHES[args.which][1]}:run")(args)


#: ``nasset bench`` (entry point ``nasset.verbs``)
VERB = Verb("benchmarks against path-traced ground truth (nasset bench NAME --help)", add_args, "nasset_benchmarks.cli:run")
