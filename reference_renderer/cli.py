"""``nasset render``: render a USD scene (or a lone asset in the studio scene) to EXR."""

from __future__ import annotations

import os
import sys

from nasset_sdk.cli import Verb, finite_arg, seed_arg
from nasset_sdk.errors import UsageError


def input_files(scene) -> list[str]:
    """Real paths of the files a render reads: the scene (or lone asset) and every referenced asset file."""
    files = {os.path.realpath(scene.file)} if scene.file and os.path.exists(scene.file) else set()
    files |= {os.path.realpath(str(a.path)) for a in scene.assets}
    return sorted(files)


def check_outputs(outputs: dict[str, str | None], inputs: list[str]) -> None:
    """``USAGE`` error when an output path is an input file (same file, through links too) or two outputs coincide."""
    seen: dict[str, str] = {}
    for opt, out in outputs.items():
        if not out:
            continue
        real = os.path.realpath(out)
        for src in inputs:
            same = real == src
            if not same and os.path.exists(out):
                try:
                    same = os.path.samefile(out, src)
                except OSError:
                    same = False
            if same:
                raise UsageError(f"{opt} {out} would overwrite the input file {src}", file=out)
        if real in seen:
            raise UsageError(f"{opt} and {seen[real]} name the same file {out}", file=out)
        seen[real] = opt


def check_writable(outputs: dict[str, str | None]) -> None:
    """``WRITE_FAILED`` before rendering when an output's folder is missing or not writable."""
    from nasset_sdk.errors import error

    for opt, out in outputs.items():
        if not out:
            continue
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            raise error("WRITE_FAILED", f"{opt}: the output folder {folder} does not exist", file=out)
        if not os.access(folder, os.W_OK | os.X_OK) or os.path.isdir(out):
            raise error("WRITE_FAILED", f"{opt}: cannot write {out} (folder not writable, or the path is a folder)", file=out)


def run(args) -> int:
    import warnings

    from nasset_sdk.extras import require_extras

    require_extras("render", purpose="nasset render")
    from .film import check_image_size, tonemap, write_exr, write_png
    from .integrator import RenderSettings, check_settings, prepare_assets, render, resolve_settings
    from .plan import make_plan
    from .scene import SceneWarning, load_scene

    if not str(args.output).lower().endswith(".exr"):
        raise UsageError(f"output must be an .exr file: {args.output}")
    settings = RenderSettings(spp=args.spp, seed=args.seed, width=args.width, height=args.height, max_depth=args.max_depth,
                              batch=args.batch, tile=args.tile, threads=args.threads, workers=getattr(args, "workers", 0),
                              progress=not args.quiet,
                              neupress_sampling=getattr(args, "neupress_sampling", "auto"), prt=bool(getattr(args, "prt", False)),
                              eightdna_sampling=getattr(args, "eightdna_sampling", "mis"),
                              rna_continuation=getattr(args, "rna_continuation", "lobes"),
                              light_draws=getattr(args, "light_draws", RenderSettings.light_draws))
    check_settings(settings)
    # sizes given on the command line are checked before the scene is read; the final size again below
    check_image_size(1 if args.width is None else args.width, 1 if args.height is None else args.height, args.spp)
    outputs = {"-o": args.output, "--png": args.png, "--variance": args.variance}
    check_writable(outputs)
    check_outputs(outputs, [os.path.realpath(args.scene)] if os.path.exists(args.scene) else [])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(args.scene, time=args.time, search_paths=getattr(args, "search_path", None))
    check_outputs(outputs, input_files(scene))
    settings = resolve_settings(settings, scene)
    for w in scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    width, height = check_image_size(*scene.camera.default_resolution(args.width, args.height), args.spp)
    plan = make_plan(scene, width=width, height=height, spp=args.spp, max_depth=settings.max_depth, tile=args.tile,
                     batch=args.batch, neupress_sampling=settings.neupress_sampling, prt=settings.prt,
                     eightdna_sampling=settings.eightdna_sampling, rna_continuation=settings.rna_continuation)
    if args.explain:
        from .light_selection import LightSelection

        print(plan.explain())
        print("  " + LightSelection(scene.lights, plan.nee, settings.light_draws).describe())
    prepare_assets(scene, plan, settings)
    result = render(scene, settings, plan=plan)
    write_exr(args.output, result.image)
    if args.png:
        write_png(args.png, tonemap(result.image))
    if args.variance:
        write_exr(args.variance, result.variance)
    st = result.stats
    if not args.quiet:
        print(f"wrote {args.output} ({width}x{height}, {args.spp} spp) in {st.time_total:.2f} s: "
              f"{st.camera_samples / max(st.time_total, 1e-9):,.0f} camera samples/s, {st.rays:,} rays, "
              f"{st.network_evals:,} network evaluations")
    return 0


def add_args(p) -> None:
    p.add_argument("scene", help="scene .usda/.usdc, or an asset file (rendered in a default studio scene)")
    p.add_argument("-o", "--output", required=True, help="output .exr")
    p.add_argument("--spp", type=int, default=16)
    p.add_argument("--seed", type=seed_arg, default=0)
    p.add_argument("--width", type=int, default=None)
    p.add_argument("--height", type=int, default=None)
    p.add_argument("--max-depth", type=int, default=None,
                   help="scattering vertices per path, 0: only the emitters in view (default: the scene's nasset:maxDepth render "
                        "setting, else 5)")
    p.add_argument("--search-path", action="append", default=None, metavar="DIR",
                   help="folder where USD's resolver looks up bare asset paths of the scene (repeatable; "
                        "PXR_AR_DEFAULT_SEARCH_PATH works too)")
    p.add_argument("--time", type=finite_arg, default=None, metavar="T",
                   help="USD time code to render at (default: the stage's startTimeCode when it authors a range, else "
                        "each attribute's default value or first time sample)")
    p.add_argument("--png", default=None, help="also write a tone-mapped PNG preview")
    p.add_argument("--variance", default=None, help="also write a per-pixel variance EXR")
    p.add_argument("--explain", action="store_true", help="print the render plan")
    p.add_argument("--threads", type=int, default=0, help="onnxruntime intra-op threads (0 = auto: 1 with several workers)")
    p.add_argument("--workers", type=int, default=0,
                   help="render threads, each tracing whole wavefronts (0 = one per core; the image does not depend on it)")
    p.add_argument("--batch", type=int, default=65536,
                   help="camera rays in flight per pass over a tile (traced in wavefronts of at most 8192)")
    p.add_argument("--tile", type=int, default=64, help="tile edge in pixels")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--neupress-sampling", default="auto", choices=["auto", "dome", "lobe", "mis"],
                   help="neupress: light sampling (dome), the sampling network's lobe, or both with MIS "
                        "(auto: mis when the asset has the sampling component, else dome)")
    p.add_argument("--prt", action="store_true", help="neupress: shade with the PRT component and the dome's SH projection")
    p.add_argument("--8dna-sampling", dest="eightdna_sampling", default="mis", choices=["light", "flow", "mis"],
                   help="8dna: emitter sampling, the asset's own sampling (GGX lobe, flow directions), or both with MIS")
    p.add_argument("--light-draws", type=int, default=8,
                   help="light samples per shading vertex for each kind of light (delta / other) with more lights than "
                        "this, drawn by power (0 = sample every light; the expected image is the same)")
    p.add_argument("--rna-continuation", default="lobes", choices=["uniform", "lobes"],
                   help="rna: continuation directions from the uniform sphere, or from a mixture of it with lobes "
                        "(surfaces: cosine and mirror; fibers: forward and specular cone; default: same expectation, "
                        "less variance)")


#: ``nasset render`` (entry point ``nasset.verbs``)
VERB = Verb("render a USD scene with the reference path tracer", add_args, "nasset_reference_renderer.cli:run")
