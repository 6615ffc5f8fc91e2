"""Cycles renders of an open Blender scene for ground truth: unclamped, box-filtered, read back from EXR.

Used by the benchmarks (``nasset bench blender``, ``nasset bench accuracy SCENE.blend``). The
scene's own camera, lights and world are kept; only the render settings below change.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def setup_cycles(bpy, width: int, height: int | None = None, max_bounces: int = 32) -> None:
    """CPU Cycles at ``width`` x ``height`` (default square) pixels: box filter 1 px, persistent data,
    32-bit EXR, and none of Cycles' biased shortcuts whatever the scene sets: no clamping, no Filter
    Glossy (it widens glossy lobes after the first bounce: +15-19 % on the dense blond hair example),
    caustics on, no Fast GI, no denoising or adaptive sampling, ``max_bounces`` of every type."""
    sc = bpy.context.scene
    sc.render.engine = "CYCLES"
    sc.render.resolution_x = int(width)
    sc.render.resolution_y = int(width if height is None else height)
    sc.render.resolution_percentage = 100
    sc.render.use_persistent_data = True
    sc.render.film_transparent = False
    sc.render.image_settings.file_format = "OPEN_EXR"
    sc.render.image_settings.color_depth = "32"
    sc.render.image_settings.color_mode = "RGB"
    sc.view_settings.view_transform = "Standard"
    c = sc.cycles
    c.device = "CPU"
    c.use_denoising = False
    c.use_adaptive_sampling = False
    c.pixel_filter_type = "BOX"
    c.filter_width = 1.0
    c.sample_clamp_direct = 0.0
    c.sample_clamp_indirect = 0.0
    c.blur_glossy = 0.0
    c.caustics_reflective = c.caustics_refractive = True
    c.use_fast_gi = False
    c.max_bounces = c.diffuse_bounces = c.glossy_bounces = c.transmission_bounces = max_bounces
    c.volume_bounces = c.transparent_max_bounces = max_bounces


def render_cycles(bpy, path: Path, spp: int, seed: int, *, alpha: bool = False) -> np.ndarray:
    """One Cycles render at ``spp`` samples with ``seed``, written to ``path`` (EXR) and read back:
    float64 [H, W, 3] radiance (NaN/Inf -> 0), or [H, W, 4] with the film's alpha when ``alpha``."""
    import OpenEXR

    from . import quiet_stdout

    sc = bpy.context.scene
    sc.cycles.samples = int(spp)
    sc.cycles.seed = int(seed)
    sc.render.image_settings.color_mode = "RGBA" if alpha else "RGB"
    sc.render.filepath = str(path)
    with quiet_stdout():
        bpy.ops.render.render(write_still=True)
    with OpenEXR.File(str(path)) as f:
        ch = f.parts[0].channels
        names = ("R", "G", "B", "A") if alpha else ("R", "G", "B")
        packed = "RGBA" if alpha else "RGB"
        img = np.asarray(ch[packed].pixels, np.float64) if packed in ch else np.stack(
            [np.asarray(ch[k].pixels, np.float64) for k in names], -1)
    return np.nan_to_num(img[..., : len(names)], nan=0.0, posinf=0.0, neginf=0.0)


def object_coverage(bpy, objects, path: Path, spp: int = 16) -> np.ndarray:
    """Fraction [H, W] of each pixel's camera samples whose first visible surface belongs to ``objects``
    (their particle hair included): every other object is made a holdout on a transparent film, so
    the film's alpha is that fraction. Render settings are restored afterwards."""
    sc = bpy.context.scene
    keep = {o.name for o in objects}
    saved = [(o, o.is_holdout) for o in sc.objects if hasattr(o, "is_holdout")]
    film, bounces = sc.render.film_transparent, sc.cycles.max_bounces
    try:
        for o, _ in saved:
            o.is_holdout = o.name not in keep
        sc.render.film_transparent = True
        sc.cycles.max_bounces = 0
        rgba = render_cycles(bpy, path, spp, seed=7, alpha=True)
    finally:
        for o, h in saved:
            o.is_holdout = h
        sc.render.film_transparent, sc.cycles.max_bounces = film, bounces
        Path(path).unlink(missing_ok=True)
    return np.clip(rgba[..., 3], 0.0, 1.0)
