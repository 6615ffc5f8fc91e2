"""``nasset render``: render a USD scene (or a lone asset in the studio scene) to EXR."""

from __future__ import annotations

import sys

from nasset_sdk.errors import UsageError


def run(args) -> int:
    import warnings

    from .film import tonemap, write_exr, write_png
    from .integrator import RenderSettings, prepare_assets, render
    from .plan import make_plan
    from .scene import SceneWarning, load_scene

    if args.spp < 1 or args.max_depth < 1 or args.batch < 1 or args.tile < 1 or args.threads < 0:
        raise UsageError("--spp, --max-depth, --batch and --tile must be >= 1; --threads >= 0")
    if not str(args.output).lower().endswith(".exr"):
        raise UsageError(f"output must be an .exr file: {args.output}")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", SceneWarning)
        scene = load_scene(args.scene)
    for w in scene.warnings:
        print(f"warning: {w}", file=sys.stderr)
    settings = RenderSettings(spp=args.spp, seed=args.seed, width=args.width, height=args.height, max_depth=args.max_depth,
                              batch=args.batch, tile=args.tile, threads=args.threads, progress=not args.quiet,
                              neupress_sampling=getattr(args, "neupress_sampling", "auto"), prt=bool(getattr(args, "prt", False)),
                              eightdna_sampling=getattr(args, "eightdna_sampling", "mis"))
    width, height = scene.camera.default_resolution(args.width, args.height)
    plan = make_plan(scene, width=width, height=height, spp=args.spp, max_depth=args.max_depth, tile=args.tile,
                     batch=args.batch, neupress_sampling=settings.neupress_sampling, prt=settings.prt,
                     eightdna_sampling=settings.eightdna_sampling)
    if args.explain:
        print(plan.explain())
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
