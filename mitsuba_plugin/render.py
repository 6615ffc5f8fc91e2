"""Render a scene with neural assets inside Mitsuba's JIT (the ``nasset_path`` integrator).

    python -m nasset_mitsuba_plugin.render SCENE OUT.exr --spp N [--width W --height H --seed S --max-depth D --variant V --prt]

SCENE is a nasset USD scene (``.usda``/``.usdc``/``.usd``) or a Mitsuba XML scene with
``<shape type="nasset">`` instances. ``--prt`` shades neupress assets with their ``prt`` component and the
dome's SH projection (spec/renderer.md#neupress, PRT mode; a usage error without ``prt`` or a dome). As a
conformance renderer::

    nasset conformance --renderer "python -m nasset_mitsuba_plugin.render {scene} {out} --spp {spp} --width {width} --height {height} --seed {seed}"
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

from nasset_sdk.cli import seed_arg
from nasset_sdk.errors import NassetError, error

from .plugins import INTEGRATOR
from .scene import load_file, mitsuba_failure, usd_scene_settings
from .variant import jit_mitsuba

USD_SUFFIXES = (".usda", ".usdc", ".usd", ".usdz")


#: spec/renderer.md#render-settings: ``nasset:maxDepth`` -1 (unbounded) renders with this many vertices; absent: 5
UNBOUNDED_DEPTH, DEFAULT_DEPTH = 1024, 5


def load_scene(path: str, width: int | None = None, height: int | None = None, *, mi=None):
    """A ``mi.Scene`` of a USD or Mitsuba XML scene (film size overridden for USD scenes only)."""
    return load_scene_depth(path, width, height, mi=mi)[0]


def load_scene_depth(path: str, width: int | None = None, height: int | None = None, *, mi=None):
    """(:func:`load_scene`, the scene's own ``max_depth``: a USD scene's ``nasset:maxDepth``, else None)."""
    mi = mi or jit_mitsuba()
    if not Path(path).is_file():
        raise error("FILE_NOT_FOUND", "no such scene file", file=str(path))
    if Path(path).suffix.lower() in USD_SUFFIXES:
        try:
            entries, rs = usd_scene_settings(path, width, height, mi=mi)
            depth = rs.get("max_depth")
            return mi.load_dict(entries), (UNBOUNDED_DEPTH if depth == -1 else depth)
        except NassetError:
            raise
        except Exception as exc:  # Mitsuba reports plugin errors as RuntimeError
            raise mitsuba_failure(exc, "Mitsuba could not build the scene", str(path)) from None
    return load_file(path, mi=mi, own_integrator=True), None  # rendered with nasset_path below


def render(path: str, spp: int, *, width: int | None = None, height: int | None = None, seed: int = 0, max_depth: int | None = None,
           variant: str | None = None, prt: bool = False) -> np.ndarray:
    """float32 [H, W, 3] radiance of the scene at ``path`` rendered with ``nasset_path``.

    ``max_depth``: scattering vertices as in spec/renderer.md#integrator (1 = direct lighting only, 0 = the emitters
    in view); None: a USD
    scene's ``nasset:maxDepth`` (spec/renderer.md#render-settings), else 5. ``nasset_path`` counts like Mitsuba's
    ``path`` (the camera ray is a segment too), so it gets ``max_depth + 1``.
    ``prt``: neupress assets in PRT mode (:mod:`.prt`; USAGE error for an asset without ``prt`` or a scene without a dome)."""
    if int(spp) < 1:
        raise error("USAGE", f"spp must be >= 1 (got {spp})")
    if max_depth is not None and int(max_depth) < 0:
        raise error("USAGE", f"max_depth must be >= 0 (got {max_depth})")
    mi = jit_mitsuba(variant)
    scene, own_depth = load_scene_depth(path, width, height, mi=mi)
    if max_depth is None:
        max_depth = DEFAULT_DEPTH if own_depth is None else own_depth
    integrator = mi.load_dict({"type": INTEGRATOR, "max_depth": int(max_depth) + 1, "prt": bool(prt)})
    try:
        img = np.asarray(mi.render(scene, integrator=integrator, spp=int(spp), seed=int(seed)), np.float32)
    except RuntimeError as exc:  # Dr.Jit wraps what the integrator raised while tracing: give the typed error
        if isinstance(exc.__cause__, NassetError):
            raise exc.__cause__ from None
        raise
    return np.where(np.isfinite(img), img, 0.0).astype(np.float32)


def write_exr(path: str, img: np.ndarray, *, mi=None) -> None:
    """Write an RGB float32 EXR atomically (temporary file + rename)."""
    mi = mi or jit_mitsuba()
    path = Path(path)
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp.exr")
    try:
        mi.Bitmap(np.ascontiguousarray(img, np.float32), pixel_format=mi.Bitmap.PixelFormat.RGB).write(str(tmp))
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise error("WRITE_FAILED", str(exc), file=str(path)) from None


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m nasset_mitsuba_plugin.render", description=__doc__.splitlines()[0])
    ap.add_argument("scene")
    ap.add_argument("output")
    ap.add_argument("--spp", type=int, default=64)
    ap.add_argument("--width", type=int, default=None)
    ap.add_argument("--height", type=int, default=None)
    ap.add_argument("--seed", type=seed_arg, default=0)
    ap.add_argument("--max-depth", type=int, default=None,
                    help="scattering vertices (1 = direct lighting only; spec/renderer.md#integrator); default: the USD scene's "
                         "nasset:maxDepth, else 5")
    ap.add_argument("--variant", default=None, help="llvm_ad_rgb (default) or cuda_ad_rgb")
    ap.add_argument("--prt", action="store_true", help="neupress: shade with the PRT component and the dome's SH projection")
    args = ap.parse_args(argv)
    t0 = time.perf_counter()
    try:
        img = render(args.scene, args.spp, width=args.width, height=args.height, seed=args.seed, max_depth=args.max_depth,
                     variant=args.variant, prt=args.prt)
        write_exr(args.output, img)
    except NassetError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(f"wrote {args.output} ({img.shape[1]}x{img.shape[0]}, {args.spp} spp) in {time.perf_counter() - t0:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
